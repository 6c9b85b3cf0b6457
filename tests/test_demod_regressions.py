"""Regressions of `accal demod` found by black-box QA (process exit, cwd, --resample, options).

Each test names the bug it pins down; the CLI is driven with CliRunner, except
where the bug only shows in a real process.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
from click.testing import CliRunner

from accal.cli import main as CLI
from accal.io.writers import write_table
from accal.pipeline_demod import write_simulated_gap

TAU, MASK = 60.0, 20.0


def invoke(*args) -> tuple[int, str, str]:
    res = CliRunner().invoke(CLI, [str(a) for a in args], catch_exceptions=False)
    return res.exit_code, res.stdout, res.stderr


@pytest.fixture(scope="module")
def run_csv(tmp_path_factory) -> Path:
    """One hour at 1 Hz (τ = 60 s, TM = 20 s) with a temperature-coupled bias, as CSV."""
    run = tmp_path_factory.mktemp("run") / "run.csv"
    write_simulated_gap(
        run, days=3600 / 86400, tau=TAU, mask=MASK, seed=3, temperature_coupling=1e-9
    )
    return run


def _rows(run: Path) -> pd.DataFrame:
    return pd.read_csv(run, comment="#")


# --- 1. a short plain CSV aborted the process (exit 134) at interpreter exit ---------


def test_short_csv_error_exits_1_never_aborts(run_csv, tmp_path):
    """The one-line error and exit 1, every time (24 processes, three at a time).

    pyarrow's threaded read_csv could finish its clean-up on a worker thread while
    the interpreter was shutting down (std::terminate, exit 134) in 5 of 7 runs of
    this test; accal.io._common.csv_read_options parses on the calling thread.
    """
    short = tmp_path / "short.csv"
    write_table(_rows(run_csv).iloc[:150], short, units={"theta": "rad"})
    cmd = [sys.executable, "-m", "accal", "demod", str(short), "--tau", "600", "--mask", "200"]
    env = {**os.environ, "PYTHONFAULTHANDLER": "1"}
    results = []
    for k in range(0, 24, 3):  # more processes than cores: the race needs busy cores
        procs = [
            subprocess.Popen(
                [*cmd, "--out", str(tmp_path / f"o{k + j}"), "-q"],
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
                env=env,
            )
            for j in range(3)
        ]
        results += [(p.wait(timeout=60), p.communicate()[1]) for p in procs]
    bad = [(code, err) for code, err in results if code != 1 or "Fatal Python error" in err]
    assert not bad, f"{len(bad)} of {len(results)} runs: {bad[0]}"
    for _, err in results:
        assert err.splitlines() == [
            f"accal: {short}: run lasts 150 s (150 samples), shorter than one modulation "
            "period (tau = 600 s)"
        ]


# --- 2. diagnose depended on the current directory -----------------------------------


def test_diagnose_finds_the_run_from_any_directory(run_csv, tmp_path, monkeypatch):
    data, res, elsewhere = tmp_path / "data", tmp_path / "res", tmp_path / "elsewhere"
    data.mkdir()
    elsewhere.mkdir()
    (data / "run.csv").write_bytes(run_csv.read_bytes())
    monkeypatch.chdir(data)
    code, _, err = invoke("demod", "run.csv", "--tau", TAU, "--mask", MASK, "--out", res, "-q")
    assert code == 0, err
    summary = json.loads((res / "summary.json").read_text())
    assert summary["source"] == "run.csv"  # as typed, for display
    assert summary["source_path"] == str((data / "run.csv").resolve())
    assert summary["source_relpath"] == os.path.join("..", "data", "run.csv")

    monkeypatch.chdir(elsewhere)
    code, text, err = invoke("diagnose", res, "-q")
    assert code == 0, err
    assert set(json.loads((res / "diagnose" / "closure.json").read_text())["sources"]) == {
        "run.csv"
    }

    # run and outputs moved together: found relative to the summary's directory
    moved = tmp_path / "moved"
    moved.mkdir()
    data.rename(moved / "data")
    res.rename(moved / "res")
    (moved / "res" / "diagnose" / "closure.json").unlink()
    code, _, err = invoke("diagnose", moved / "res", "-q")
    assert code == 0, err
    assert (moved / "res" / "diagnose" / "closure.json").exists()

    # a summary of an older accal: only the path as typed, relative to its directory
    legacy = tmp_path / "legacy"
    legacy.mkdir()
    (legacy / "run.csv").write_bytes(run_csv.read_bytes())
    (legacy / "periods.parquet").write_bytes((moved / "res" / "periods.parquet").read_bytes())
    old = {k: v for k, v in summary.items() if k not in ("source_path", "source_relpath")}
    (legacy / "summary.json").write_text(json.dumps(old))
    code, _, err = invoke("diagnose", legacy, "-q")
    assert code == 0, err


def test_diagnose_missing_run_is_one_line_and_writes_nothing(run_csv, tmp_path):
    run, res = tmp_path / "run.csv", tmp_path / "res"
    run.write_bytes(run_csv.read_bytes())
    assert invoke("demod", run, "--tau", TAU, "--mask", MASK, "--out", res, "-q")[0] == 0
    run.unlink()
    code, _, err = invoke("diagnose", res, "-q")
    assert code == 1
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "run file of summary.json not found (moved?)" in lines[0], err
    assert str(run) in lines[0]
    assert not (res / "diagnose").exists() and not (res / "closure.json").exists()
    code, _, err = invoke("diagnose", res)  # not quiet: no "reports:" line for nothing written
    assert code == 1 and "reports:" not in err


# --- 3. --close-loop ignored --resample ----------------------------------------------


@pytest.mark.parametrize("drop", [slice(1000, 1001), slice(2000, 2010)], ids=["row", "gap"])
def test_close_loop_resamples_like_the_demodulation(run_csv, tmp_path, drop):
    df = _rows(run_csv)
    run = tmp_path / "missing.csv"
    write_table(df.drop(index=df.index[drop]), run, units={"theta": "rad"})
    out = tmp_path / "out"
    args = ("demod", run, "--tau", TAU, "--mask", MASK, "--close-loop", "--out", out, "-q")
    code, _, err = invoke(*args)
    assert code == 1 and "irregular sampling" in err and "--resample" in err
    code, _, err = invoke(*args, "--resample")
    assert code == 0, err
    summary = json.loads((out / "summary.json").read_text())
    rs = summary["input"]["resample"]
    if drop.stop - drop.start == 1:
        assert (rs["n_interpolated"], rs["n_gaps"]) == (1, 0)
    else:
        assert rs["n_gaps"] == 1 and rs["n_gap"] == 10
    closure = json.loads((out / "closure.json").read_text())["sources"]["missing.csv"]
    assert closure["periods"]["n"] == summary["n_kept"]
    # diagnose re-reads the run resampled the same way, into DIR/diagnose: the run's own
    # closure report is kept
    own = (out / "closure.json").read_bytes()
    code, _, err = invoke("diagnose", out, "-q")
    assert code == 0, err
    again = json.loads((out / "diagnose" / "closure.json").read_text())["sources"]["missing.csv"]
    assert again["periods"] == closure["periods"]
    assert (out / "closure.json").read_bytes() == own
    assert [e["name"] for e in again["effects"]] == [e["name"] for e in closure["effects"]]


# --- 4. option validation: usage errors (exit 2), one line ---------------------------


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["--integration", "0"], "integration time must be positive and finite, got 0.0 s"),
        (["--integration", "-3600"], "integration time must be positive and finite, got -3600.0 s"),
        (["--integration", "inf"], "integration time must be positive and finite, got inf s"),
        (["--tau", "inf"], "tau must be positive and finite, got inf s"),
        (["--tau", "0"], "tau must be positive and finite, got 0.0 s"),
        (["--tau", "nan"], "tau must be positive and finite, got nan s"),
        (["--sinusoid-period", "inf"], "sinusoid period must be positive and finite, got inf s"),
    ],
)
def test_bad_option_is_a_usage_error(run_csv, tmp_path, options, message):
    out = tmp_path / "out"
    code, _, err = invoke("demod", run_csv, "--tau", TAU, "--mask", MASK, *options, "--out", out)
    assert code == 2, err
    assert [x for x in err.splitlines() if x.startswith("Error:")] == [f"Error: {message}"]
    assert not out.exists()


def test_same_run_twice_is_a_usage_error(run_csv, tmp_path, monkeypatch):
    monkeypatch.chdir(run_csv.parent)
    link = tmp_path / "link.csv"
    link.symlink_to(run_csv)
    out = tmp_path / "out"
    for runs, message in (
        (["run.csv", "run.csv"], "run run.csv is given twice; give each run once"),
        (["run.csv", "./run.csv"], "run run.csv is given twice; give each run once"),
        (["run.csv", str(link)], f"runs run.csv and {link} are the same file; give each run once"),
    ):
        code, _, err = invoke("demod", *runs, "--tau", TAU, "--mask", MASK, "--out", out)
        assert code == 2, err
        assert [x for x in err.splitlines() if x.startswith("Error:")] == [f"Error: {message}"]
        assert not out.exists()


def test_tau_not_matching_the_pattern_is_warned_not_hidden(run_csv, tmp_path):
    """--tau 59 on a 60 s pattern: estimates still fine (joint fit), one warning line."""
    code, _, err = invoke(
        "demod", run_csv, "--tau", TAU - 1, "--mask", MASK, "--out", tmp_path / "a"
    )
    assert code == 0 and err.count("eq. 16 leakage up to") == 1
    code, _, err = invoke("demod", run_csv, "--tau", TAU, "--mask", MASK, "--out", tmp_path / "b")
    assert code == 0 and "leakage" not in err


@pytest.mark.parametrize("mask", ["60", "70", "-1", "nan"])
def test_bad_mask_is_a_usage_error(run_csv, tmp_path, mask):
    code, _, err = invoke("demod", run_csv, "--tau", TAU, "--mask", mask, "--out", tmp_path)
    assert code == 2 and "must be in [0, tau) s" in err and "Traceback" not in err


def test_colliding_stems_are_a_usage_error_before_anything_runs(run_csv, tmp_path):
    for d in ("a", "b"):
        (tmp_path / d).mkdir()
        (tmp_path / d / "run.csv").write_bytes(run_csv.read_bytes())
    out = tmp_path / "out"
    code, _, err = invoke(
        "demod", tmp_path / "a" / "run.csv", tmp_path / "b" / "run.csv",
        "--tau", TAU, "--mask", MASK, "--out", out,
    )  # fmt: skip
    assert code == 2 and "would both write run.summary.json" in err
    assert not out.exists()
