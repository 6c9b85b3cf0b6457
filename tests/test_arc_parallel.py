"""``grace-bias --arc`` on the batch's workers (issue 22): each arc is one task.

Two arcs of three 6-hour days (1 Hz tables and one reference over all, drawn as in
``tests/test_cli_reference.py``), fitted with a 6-hour bias spline and one scale per
arc: ``-j 2`` and a dask scheduler must write, byte for byte, what ``-j 1`` writes
(the log, the manifest and the lock aside), and the arcs must run on the workers.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner
from tests.test_cli_reference import _arc_days

from accal.cli import main

#: Bookkeeping of a run: differs between runs (times, pids, the lock's token).
BOOKKEEPING = {".accal.lock", "accal.log", "manifest.json"}


def _run(*args: object) -> tuple[int, str]:
    res = CliRunner().invoke(main, ["grace-bias", *map(str, args)], catch_exceptions=False)
    return res.exit_code, res.output


def _outputs(out: Path) -> dict[str, bytes]:
    """Every output file's bytes, the bookkeeping left out."""
    return {p.name: p.read_bytes() for p in sorted(out.iterdir()) if p.name not in BOOKKEEPING}


@pytest.fixture(scope="module")
def arcs(tmp_path_factory) -> tuple[list[Path], tuple[object, ...], Path]:
    """The six days, the options, and the ``-j 1`` output directory."""
    tmp = tmp_path_factory.mktemp("arcs")
    _, _, days, ref = _arc_days(tmp, days=(0, 1, 2, 3, 4, 5), hours=6.0, seed=11)
    args = ("--reference", ref, "--scale", "fit", "--bias-basis", "spline:6h", "--arc", "3d")
    serial = tmp / "j1"
    code, msg = _run(*days, *args, "--out", serial, "-j", 1, "-q")
    assert code == 0, msg
    return days, args, serial


def test_two_workers_fit_the_arcs_and_write_what_one_writes(arcs, tmp_path):
    days, args, serial = arcs
    out = tmp_path / "j2"
    code, msg = _run(*days, *args, "--out", out, "-j", 2)
    assert code == 0, msg
    assert "6 ok, 0 skipped (current), 0 failed" in msg and "2 workers" in msg
    names = set(_outputs(serial))
    assert {
        "arc_day0_2003-09-14_2003-09-16.bias_basis.parquet",
        "arc_day3_2003-09-17_2003-09-19.bias_basis.parquet",
        "arc_day0_2003-09-14_2003-09-16.reference_cov.npz",
        "arc_day3_2003-09-17_2003-09-19.reference_cov.npz",
        "bias_drift.parquet",
    } <= names
    assert len(names) == 5 + 2 * 6  # and each day's calibrated file and report
    assert _outputs(out) == _outputs(serial)
    log = (out / "accal.log").read_text()
    assert "inputs read for the arcs in 2 worker processes" in log
    assert "2 arcs run in 2 worker processes" in log  # one arc per worker
    assert "arcs run in 2 worker processes" not in (serial / "accal.log").read_text()


def test_dask_scheduler_fits_the_arcs_and_writes_what_one_worker_writes(arcs, tmp_path):
    distributed = pytest.importorskip("distributed")
    days, args, serial = arcs
    out = tmp_path / "dask"
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None
    ) as cluster:
        code, msg = _run(*days, *args, "--out", out, "--scheduler", cluster.scheduler_address)
    assert code == 0, msg
    assert _outputs(out) == _outputs(serial)
    assert "2 arcs run on dask scheduler" in (out / "accal.log").read_text()
