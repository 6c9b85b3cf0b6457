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

import numpy as np
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
    this test; accal.io.common.csv_read_options parses on the calling thread.
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
    assert err.splitlines() == [f"accal: {message} (see 'accal demod --help')"]
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
        assert err.splitlines() == [f"accal: {message} (see 'accal demod --help')"]
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


def test_colliding_stems_fail_the_second_input_alone(run_csv, tmp_path):
    """As grace-bias: the first input of a stem runs, the others fail with one line each
    (QA, 2026-11-30: two runs of one stem in two directories stopped the whole call)."""
    for d in ("a", "b", "c"):
        (tmp_path / d).mkdir()
    a = tmp_path / "a" / "run.csv"
    b = tmp_path / "b" / "run.csv"
    other = tmp_path / "c" / "other.csv"
    for p in (a, b, other):
        p.write_bytes(run_csv.read_bytes())
    out = tmp_path / "out"
    code, _, err = invoke("demod", a, b, other, "--tau", TAU, "--mask", MASK, "--out", out)
    assert code == 1, err
    (line,) = [ln for ln in err.splitlines() if "would write the same outputs" in ln]
    assert str(b) in line and str(a) in line and "run.summary.*" in line
    assert (out / "run.summary.json").exists() and (out / "other.summary.json").exists()
    summary = json.loads((out / "run.summary.json").read_text())
    assert Path(summary["source"]) == a  # the first of the stem
    manifest = json.loads((out / "manifest.json").read_text())
    assert len(manifest["entries"]) == 2


# --- 5. second QA pass: cumulative --out, formats, σ, jitter, warnings, messages ----------


def _copy(run: Path, dest: Path) -> Path:
    dest.parent.mkdir(parents=True, exist_ok=True)
    dest.write_bytes(run.read_bytes())
    return dest


def test_rerun_into_the_same_out_leaves_no_stale_summary_for_diagnose(run_csv, tmp_path):
    """A run alone (summary.json), then with another run (a.summary.json): one summary each.

    The first summary.json (method ls) used to stay, and diagnose analysed run a twice,
    once with the stale options; a summary planted from an earlier run is ignored too.
    """
    a, b = _copy(run_csv, tmp_path / "in" / "a.csv"), _copy(run_csv, tmp_path / "in" / "b.csv")
    out = tmp_path / "out"
    common = ("--tau", TAU, "--mask", MASK, "--out", out, "-q")
    assert invoke("demod", a, *common)[0] == 0
    stale = json.loads((out / "summary.json").read_text())
    code, _, err = invoke("demod", a, b, *common, "--method", "gls")
    assert code == 0, err
    assert sorted(p.name for p in out.glob("*summary*")) == [
        "a.summary.json", "a.summary.md", "b.summary.json", "b.summary.md",
    ]  # fmt: skip
    # an earlier run's summary of a (another name, other options): not current
    (out / "old.summary.json").write_text(json.dumps(stale))
    code, text, err = invoke("diagnose", out)
    assert code == 0, err
    assert [ln.split(":")[0] for ln in text.splitlines()] == ["a.csv", "b.csv"]
    assert set(json.loads((out / "diagnose" / "closure.json").read_text())["sources"]) == {
        "a.csv",
        "b.csv",
    }


def test_another_format_into_the_same_out_is_refused(run_csv, tmp_path):
    out = tmp_path / "out"
    assert invoke("demod", run_csv, "--tau", TAU, "--mask", MASK, "--out", out, "-q")[0] == 0
    code, _, err = invoke(
        "demod", run_csv, "--tau", TAU, "--mask", MASK, "--out", out, "--format", "csv", "-q"
    )
    assert code == 2
    assert err.splitlines() == [
        f"accal: {out / 'periods.parquet'}: the periods table of this --out is in --format "
        "parquet; use --format parquet there, or another --out for --format csv"
    ]
    assert not (out / "periods.csv").exists()


def test_sigma_of_the_mean_with_every_other_period_dropped(run_csv, tmp_path):
    """Odd periods at π/2 and 3π/2 only (dropped): no kept pair is 1 period apart.

    Rd[1] is then unknown and σ of the mean was null; it needs only the lags the kept
    periods have (0, 2, 4, ...).  The standard σ over --integration (consecutive
    periods) cannot be computed: null, with the reason.
    """
    df = _rows(run_csv)
    odd = (df["time"] // TAU).astype(int) % 2 == 1
    df.loc[odd, "theta"] += np.pi / 2
    run = tmp_path / "alt.csv"
    write_table(df, run, units={"theta": "rad"})
    out = tmp_path / "out"
    code, _, err = invoke("demod", run, "--tau", TAU, "--mask", MASK, "--out", out, "-q")
    assert code == 0, err
    s = json.loads((out / "summary.json").read_text())
    assert s["n_kept"] == 30 and s["dropped_periods"] == list(range(1, 60, 2))
    assert s["Rd"][1] is None and s["Rd"][2] is not None
    n, rd = s["n_kept"], s["Rd"]
    expected = np.sqrt((n * rd[0] + 2 * sum((n - k) * rd[2 * k] for k in (1, 2))) / n**2)
    assert s["mean"]["sigma"] == pytest.approx(expected, rel=1e-12)
    assert s["sigma_T"]["run"]["sigma"] == s["mean"]["sigma"]
    std = s["sigma_T"]["standard"]
    assert std["sigma"] is None and "Rd[1] is unknown" in std["note"]
    assert "n/a (not computed: Rd[1] is unknown" in (out / "summary.md").read_text()


def _jittered(run_csv: Path, path: Path) -> Path:
    """The run with ±1 ms timing jitter, the last sample early, the first one late."""
    df = _rows(run_csv)
    rng = np.random.default_rng(1)
    t = df["time"].to_numpy() + rng.uniform(-1e-3, 1e-3, len(df))
    t[0], t[-1] = df["time"].iloc[0] + 5e-4, df["time"].iloc[-1] - 5e-4
    df["time"] = t
    write_table(df, path, units={"theta": "rad"})
    return path


def test_jitter_with_resample_keeps_the_last_period(run_csv, tmp_path):
    """The grid ended one point short of the jittered last sample: period 59 vanished."""
    run = _jittered(run_csv, tmp_path / "jit.csv")
    out = tmp_path / "out"
    args = ("demod", run, "--tau", TAU, "--mask", MASK, "--resample", "--out", out)
    code, _, err = invoke(*args)  # no -q: -q is errors only
    assert code == 0, err
    s = json.loads((out / "summary.json").read_text())
    assert (s["n_periods"], s["n_kept"]) == (60, 60)
    rs = s["input"]["resample"]
    assert rs["n_grid"] == 3600 and rs["n_end_held"] == 1
    assert "1 grid point after the last sample took its value" in err


@pytest.mark.parametrize("case", ["affine", "jitter"])
def test_leakage_of_a_valid_pattern_is_no_warning(run_csv, tmp_path, case):
    """Eq. 16 leakage 0.09 (affine signal) or 0.13 (jitter + resample): the joint fit
    removes the bias, --tau is the pattern's period: no misleading '--tau?' warning."""
    run, extra = run_csv, ["--signal-model", "affine"]
    if case == "jitter":
        run, extra = _jittered(run_csv, tmp_path / "jit.csv"), ["--resample"]
    out = tmp_path / "out"
    code, _, err = invoke("demod", run, "--tau", TAU, "--mask", MASK, *extra, "--out", out, "-q")
    assert code == 0, err
    s = json.loads((out / "summary.json").read_text())
    assert s["leakage_max"] > 1e-2 and s["pattern"]["rotation_shift"] == 0.0
    assert "eq. 16" not in err and "--tau" not in err and "rotations move" not in err


def test_tau_not_matching_the_pattern_says_which_tau(run_csv, tmp_path):
    out = tmp_path / "out"
    code, _, err = invoke("demod", run_csv, "--tau", TAU - 1, "--mask", MASK, "--out", out)
    assert code == 0, err
    assert (
        "the rotations move by +1 s from one period to the next: the pattern repeats every "
        "60 s, not --tau 59 s; give --tau 60 (or fix the time column); eq. 16 leakage up to"
    ) in err
    assert json.loads((out / "summary.json").read_text())["pattern"]["repeats_every"] == 60.0


@pytest.mark.parametrize("command", ["demod", "budget"])
def test_missing_psd_file_is_a_usage_error(run_csv, tmp_path, command):
    missing = tmp_path / "nope.csv"
    out = tmp_path / "out"
    if command == "demod":
        args = ("demod", run_csv, "--tau", TAU, "--mask", MASK, "--out", out)
    else:
        args = ("budget", "--tau", 600, "--mask", 200)
    code, _, err = invoke(*args, "--psd", missing)
    assert code == 2
    assert err.splitlines() == [f"accal: {missing}: no such file"]
    assert not out.exists()


def test_diagnose_on_a_directory_with_nothing_usable_names_both_kinds(run_csv, tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    code, _, err = invoke("diagnose", empty)
    assert code == 1
    assert err.splitlines() == [
        f"accal: {empty}: no *.calibrated.parquet or *.calibrated.csv file (accal grace-bias "
        "output) and no periods.parquet or periods.csv with summary.json or "
        "<stem>.summary.json (accal demod output) to diagnose"
    ]
    # a periods table whose summaries are gone: what is missing, and for which run
    out = tmp_path / "out"
    assert invoke("demod", run_csv, "--tau", TAU, "--mask", MASK, "--out", out, "-q")[0] == 0
    (out / "summary.json").unlink()
    code, _, err = invoke("diagnose", out)
    assert code == 1
    assert err.splitlines() == [
        f"accal: {out}: warning: run.csv: rows in periods.parquet but no current summary "
        f"(summary.json now belongs to another run); re-run accal demod on it into {out} to "
        "diagnose it",
        f"accal: {out}: no accal demod summary (summary.json or <stem>.summary.json) naming a "
        "run of its periods table to diagnose",
    ]


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["--mask", "0"], "--mask (masking time TM) must be in (0, --tau) s"),
        (["--mask", "700"], "--mask (masking time TM) must be in (0, --tau) s"),
        (["--mask", "201"], "no calibration pattern for --tau 600 s, --mask 201 s, --fs 1 Hz"),
    ],
)
def test_simulate_gap_bad_mask_names_the_option(tmp_path, options, message):
    code, _, err = invoke("simulate", "gap", *options, "--out", tmp_path / "r.parquet")
    assert code == 2, err
    assert len(err.splitlines()) == 1 and err.startswith(f"accal: {message}")
    assert not list(tmp_path.iterdir())


def test_text_run_named_parquet_is_read_with_a_warning(run_csv, tmp_path):
    run = _copy(run_csv, tmp_path / "run.parquet")
    out = tmp_path / "out"
    code, _, err = invoke("demod", run, "--tau", TAU, "--mask", MASK, "--out", out)
    assert code == 0, err  # no -q: -q is errors only (the warning is then in accal.log)
    assert f"accal: {run}: warning: named .parquet but is text: read as CSV" in err.splitlines()
    s = json.loads((out / "summary.json").read_text())
    assert s["input"]["warnings"] == ["named .parquet but is text: read as CSV"]


# --- absolute times: a regular 10 Hz run in GPS seconds was refused as irregular -----


@pytest.mark.parametrize("offset", [1.4e9, 1e8])
@pytest.mark.parametrize("extra", [[], ["--chunk-size", "16"], ["--resample"]])
def test_10hz_run_in_gps_seconds_is_regular(tmp_path, offset, extra):
    """QA: times of 1.4e9 s are stored to 2.4e-7 s, 2.4e-6 of a 10 Hz step.

    The run was refused ("irregular sampling", or ``tau·fs = 6000.000358 is not an
    integer``), also with --resample.  The step tolerance now includes the times' own
    rounding, and the step is the mean one snapped to τ/q: the same periods as with
    times from 0, to the rounding of the times.
    """
    run = tmp_path / "run.parquet"
    write_simulated_gap(run, days=1300 / 86400, tau=TAU, mask=MASK, fs=10.0, seed=5)
    rows = pd.read_parquet(run)
    shifted = tmp_path / "gps.parquet"
    write_table(rows.assign(time=rows["time"] + offset), shifted, units={"theta": "rad"})
    out = {}
    for name, f in (("plain", run), ("gps", shifted)):
        code, _, err = invoke(
            "demod", f, "--tau", TAU, "--mask", MASK, *extra, "--out", tmp_path / name, "-q"
        )
        assert code == 0, err
        out[name] = pd.read_parquet(tmp_path / name / "periods.parquet")
    assert len(out["plain"]) == len(out["gps"]) == 21
    np.testing.assert_allclose(out["gps"]["a_Y"], out["plain"]["a_Y"], rtol=0, atol=1e-15)
    np.testing.assert_allclose(out["gps"]["sigma_Y"], out["plain"]["sigma_Y"], rtol=1e-9)
    np.testing.assert_allclose(out["gps"]["t_mid"] - offset, out["plain"]["t_mid"], atol=1e-6)


def test_irregular_10hz_in_gps_seconds_is_still_refused(tmp_path):
    """The tolerance is the times' rounding, not more: a 1e-5 s slip is irregular."""
    run = tmp_path / "run.parquet"
    write_simulated_gap(run, days=1300 / 86400, tau=TAU, mask=MASK, fs=10.0, seed=5)
    rows = pd.read_parquet(run)
    t = rows["time"].to_numpy() + 1.4e9
    t[500:] += 1e-5
    bad = tmp_path / "gps.parquet"
    write_table(rows.assign(time=t), bad, units={"theta": "rad"})
    code, _, err = invoke("demod", bad, "--tau", TAU, "--mask", MASK, "--out", tmp_path / "o")
    assert code == 1
    assert "irregular sampling: 1 of" in err and "gps.parquet" in err
    # the place, readable at GPS times (QA: "at t = 1.4000005e+09 s", no row)
    assert "after t = 1400000049.9000 s, before row 501)" in err
    code, _, err = invoke(
        "demod", bad, "--tau", TAU, "--mask", MASK, "--chunk-size", "16", "--out", tmp_path / "p"
    )
    assert code == 1 and "after t = 1400000049.9000 s, before row 501)" in err


# --- θ noisy at rest: no usable period, and no way to say so -----------------------


def test_theta_noisy_at_rest_needs_and_takes_rest_tol(run_csv, tmp_path):
    """QA: N(0, 1e-8 rad) on θ left no period at rest (tolerance 1e-9 rad, not settable)."""
    rows = _rows(run_csv)
    rng = np.random.default_rng(1)
    noisy = tmp_path / "noisy.csv"
    theta = rows["theta"] + 1e-8 * rng.standard_normal(len(rows))
    write_table(rows.assign(theta=theta), noisy, units={"theta": "rad"})
    code, _, err = invoke("demod", noisy, "--tau", TAU, "--mask", MASK, "--out", tmp_path / "a")
    assert code == 1 and "--rest-tol" in err and "no period has enough" in err
    code, _, err = invoke(
        "demod", noisy, "--tau", TAU, "--mask", MASK, "--rest-tol", "1e-6", "--out", tmp_path / "b"
    )
    assert code == 0, err
    assert invoke("demod", run_csv, "--tau", TAU, "--mask", MASK, "--out", tmp_path / "c")[0] == 0
    got, ref = (pd.read_parquet(tmp_path / d / "periods.parquet") for d in ("b", "c"))
    assert len(got) == len(ref) == 60
    np.testing.assert_allclose(got["a_Y"], ref["a_Y"], rtol=0, atol=1e-13)
    summary = json.loads((tmp_path / "b" / "summary.json").read_text())
    assert summary["options"]["rest_tol"] == 1e-6
    code, _, err = invoke(
        "demod", run_csv, "--tau", TAU, "--mask", MASK, "--rest-tol", "0", "--out", tmp_path / "d"
    )
    assert code == 2 and "rest tolerance" in err


@pytest.mark.parametrize(
    ("tau", "says"),
    [
        (
            TAU / 2,
            "repeat every 2 periods: the pattern's period is 60 s, not --tau 30 s; give --tau 60",
        ),
        (TAU + 7, "move by -7 s from one period to the next: the pattern repeats every 60 s"),
        (TAU * 2, None),  # two patterns per period: it repeats every --tau
    ],
)
def test_tau_a_fraction_of_the_pattern_says_the_pattern_period(run_csv, tmp_path, tau, says):
    """QA: --tau 300 on a 600 s pattern was told "give --tau 332" (the shift between the
    pattern's two halves), and --tau 332 then passed without a word."""
    out = tmp_path / "o"
    code, _, err = invoke("demod", run_csv, "--tau", tau, "--mask", MASK, "--out", out)
    assert code == 0, err
    pattern = json.loads((out / "summary.json").read_text())["pattern"]
    if says is None:
        assert "rotations" not in err and pattern["pattern_periods"] == 1
    else:
        assert says in err and "give --tau 3" not in err


# --- θ in another radian convention ----------------------------------------------------


@pytest.mark.parametrize(
    "convert",
    [
        pytest.param(lambda th: np.where(th > np.pi - 1e-9, th - 2 * np.pi, th), id="atan2"),
        pytest.param(lambda th: th + 2 * np.pi * 7, id="offset-7-turns"),
        pytest.param(  # always rotating forward: 0, π, 2π, 3π, ...
            lambda th: th[0] + np.concatenate([[0.0], np.cumsum(np.abs(np.diff(th)))]),
            id="unwrapped",
        ),
    ],
)
def test_theta_in_another_radian_convention_is_wrapped(run_csv, tmp_path, convert):
    """QA: θ of [−π, π) was refused ("must lie in [0, 2π]") and unwrapped radians were
    "degrees"; rests at multiples of π/2 tell radians, so they are wrapped into [0, 2π)."""
    rows = _rows(run_csv)
    other = tmp_path / "other.csv"
    write_table(rows.assign(theta=convert(rows["theta"].to_numpy())), other, units={"theta": "rad"})
    for name, f in (("a", run_csv), ("b", other)):
        code, _, err = invoke("demod", f, "--tau", TAU, "--mask", MASK, "--out", tmp_path / name)
        assert code == 0, err
    ref, got = (pd.read_parquet(tmp_path / d / "periods.parquet") for d in "ab")
    assert len(got) == len(ref) == 60
    np.testing.assert_allclose(got["a_Y"], ref["a_Y"], rtol=0, atol=1e-16)
    np.testing.assert_allclose(got["a_Z"], ref["a_Z"], rtol=0, atol=1e-16)


def test_theta_in_degrees_is_still_refused(run_csv, tmp_path):
    rows = _rows(run_csv)
    deg = tmp_path / "deg.csv"
    write_table(rows.assign(theta=np.degrees(rows["theta"]) - 90.0), deg, units={})
    code, _, err = invoke("demod", deg, "--tau", TAU, "--mask", MASK, "--out", tmp_path / "o")
    assert code == 1 and "deg.csv" in err
    assert "must lie in [0, 2π]" in err or "looks like degrees" in err


def test_a_run_of_one_period_has_no_pattern_warning(tmp_path):
    """A single period has nothing to compare its rotations with: no "do not repeat"."""
    run = tmp_path / "one.parquet"
    write_simulated_gap(run, days=600 / 86400, tau=600.0, mask=200.0, seed=2)
    code, _, err = invoke("demod", run, "--tau", 600, "--mask", 200, "--out", tmp_path / "o")
    assert code == 0, err
    assert "rotations" not in err and "1/1 periods" in err


def test_theta_in_range_with_noise_at_the_zero_rest(run_csv, tmp_path):
    """QA: θ mod 2π with N(0, 1e-8 rad) at rest flipped between ~0 and ~2π − ε: 352 s
    masked per period instead of ~208 s, a_Y off by 5σ, exit 0.  Values just under 2π
    are the rest at 0."""
    rows = _rows(run_csv)
    rng = np.random.default_rng(0)
    th = np.mod(rows["theta"].to_numpy() + 1e-8 * rng.standard_normal(len(rows)), 2 * np.pi)
    noisy = tmp_path / "noisy.csv"
    write_table(rows.assign(theta=th), noisy, units={"theta": "rad"})
    for name, f in (("a", run_csv), ("b", noisy)):
        code, _, err = invoke(
            "demod", f, "--tau", TAU, "--mask", MASK, "--rest-tol", "1e-6", "--out", tmp_path / name
        )
        assert code == 0 and "rotations" not in err, err
    ref, got = (pd.read_parquet(tmp_path / d / "periods.parquet") for d in "ab")
    # the θ noise itself enters cos θ, sin θ: ~1e-15 m/s², against 2.1e-11 (5σ) before
    np.testing.assert_allclose(got["a_Y"], ref["a_Y"], rtol=0, atol=1e-13)
    np.testing.assert_allclose(got["a_Z"], ref["a_Z"], rtol=0, atol=1e-13)


def test_theta_declared_deg_but_in_radians_says_so(run_csv, tmp_path):
    """QA: radians declared 'deg' failed with "theta never reaches π (range 0 to 0.0548
    rad)", not a word about the declaration."""
    rows = _rows(run_csv)
    wrong = tmp_path / "wrong.csv"
    write_table(rows, wrong, units={"theta": "deg"})
    code, _, err = invoke("demod", wrong, "--tau", TAU, "--mask", MASK, "--out", tmp_path / "o")
    assert code == 1 and "wrong.csv" in err
    assert "theta is declared in 'deg' and was converted to rad" in err
