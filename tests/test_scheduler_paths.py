"""Relative paths with ``--scheduler``: resolved where the command was typed.

A Dask worker resolves a relative path against its own working directory; before,
every input of a ``--scheduler`` run typed relative to the shell's directory failed
with "no such file", and a relative ``--out`` was created beside the worker's
directory (QA, 2026-11-27).
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path

import pytest
from click.testing import CliRunner

from accal.cli import main
from accal.cli.batch_options import for_scheduler

SAMPLE = Path(__file__).resolve().parents[1] / "data" / "samples" / "ACC1B_2003-09-14_A_00.asc"


@dataclass(frozen=True)
class _Opts:
    reference: Path | None = None
    order: int = 1


def test_for_scheduler_makes_inputs_out_and_option_files_absolute(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    paths, out, opts = for_scheduler("tcp://x:1", [Path("a.dat")], Path("o"), _Opts(Path("r.pq")))
    assert paths == [tmp_path / "a.dat"] and out == tmp_path / "o"
    assert opts == _Opts(tmp_path / "r.pq", 1)
    same = for_scheduler(None, [Path("a.dat")], Path("o"), _Opts(Path("r.pq")))
    assert same == ([Path("a.dat")], Path("o"), _Opts(Path("r.pq")))


def test_relative_inputs_and_out_reach_workers_in_another_directory(tmp_path, monkeypatch):
    distributed = pytest.importorskip("distributed")
    workers_dir, here = tmp_path / "workers", tmp_path / "here"
    workers_dir.mkdir()
    here.mkdir()
    shutil.copy(SAMPLE, here / SAMPLE.name)
    monkeypatch.chdir(workers_dir)  # the workers start here
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        monkeypatch.chdir(here)  # the command is typed here
        res = CliRunner().invoke(
            main,
            ["grace-bias", SAMPLE.name, "--out", "out", "--scheduler", cluster.scheduler_address],
        )
    assert res.exit_code == 0, res.output
    assert (here / "out" / "bias_drift.parquet").exists()
    assert not (workers_dir / "out").exists()
