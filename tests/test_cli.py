"""End-to-end tests of `accal grace-bias` and `accal simulate grace` (CliRunner and a real process)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner

from accal import __version__
from accal.cli import main

SAMPLES = Path(__file__).resolve().parents[1] / "data" / "samples"
GRACE_A = SAMPLES / "ACC1B_2003-09-14_A_00.asc"
GRACE_B = SAMPLES / "ACC1B_2003-09-14_B_00.asc"
FO_C = SAMPLES / "ACT1B_2023-06-01_C_04.txt"
FO_D = SAMPLES / "ACT1B_2023-06-01_D_04.txt"
SWARM = SAMPLES / "SW_A_ACCACAL_20240511_a_cal_x.csv.gz"


def invoke(*args: str) -> tuple[int, str, str]:
    runner = CliRunner()
    res = runner.invoke(main, [str(a) for a in args], catch_exceptions=False)
    return res.exit_code, res.stdout, res.stderr


def table(out: Path, fmt: str = "parquet") -> pd.DataFrame:
    from accal.pipeline import read_bias_drift

    return read_bias_drift(out / f"bias_drift.{fmt}")


def test_real_samples_end_to_end(tmp_path):
    code, _, err = invoke(
        "grace-bias", GRACE_A, GRACE_B, FO_C, FO_D, "--method", "both", "--out", tmp_path
    )
    assert code == 0, err
    df = table(tmp_path)
    assert len(df) == 4 * 3 * 2
    assert set(df["satellite"]) == {"GRACE-A", "GRACE-B", "GRACE-FO-C", "GRACE-FO-D"}
    assert not df.duplicated(["source", "axis", "method"]).any()
    a_y = df[(df.satellite == "GRACE-A") & (df.axis == "y") & (df.method == "wavelet")].iloc[0]
    # SOURCES.md: raw 60-s mean of GRACE-A y is -28.512 µm/s²; 60 s of data, drift tiny
    assert a_y["bias"] == pytest.approx(-28.512e-6, abs=0.01e-6)
    assert a_y["date"] == "2003-09-14"
    assert a_y["t0"] == 116769600.0
    assert a_y["n"] == 60
    c = df[(df.satellite == "GRACE-FO-C") & (df.method == "lsq")].set_index("axis")
    # SOURCES.md: 100-s means C ≈ (−0.278, −10.651, −0.182) µm/s²
    np.testing.assert_allclose(
        c.loc[["x", "y", "z"], "bias"] + c.loc[["x", "y", "z"], "drift"] * 49.5,
        [-0.278e-6, -10.651e-6, -0.182e-6],
        atol=0.002e-6,
    )
    assert (df["bias_sigma"] > 0).all() and (df["drift_sigma"] > 0).all()
    # units travel in the Parquet schema metadata
    md = pq.read_schema(tmp_path / "bias_drift.parquet").metadata
    units = json.loads(md[b"accal.units"])
    assert units["bias"].startswith("m/s^2") and units["drift"] == "m/s^3"
    # per-file report with the reader's findings (the GRACE-FO file is cut short)
    rep = json.loads((tmp_path / "ACT1B_2023-06-01_C_04.report.json").read_text())
    assert rep["read_report"]["n_records_header"] == 86400
    assert any("86400" in w for w in rep["read_report"]["warnings"])
    cal = pd.read_parquet(tmp_path / "ACC1B_2003-09-14_A_00.calibrated.parquet")
    assert list(cal.columns) == [
        "gps_time",
        "time_utc",
        "lin_accl_x",
        "lin_accl_y",
        "lin_accl_z",
        "valid",
        "qualflg",
    ]
    # trend removed: the calibrated series has (near) zero mean and no slope
    assert abs(cal["lin_accl_y"].mean()) < 1e-10


def test_calibrated_output_reads_back_through_the_table_reader(tmp_path):
    from accal.io import read

    assert invoke("grace-bias", GRACE_A, "--out", tmp_path)[0] == 0
    series = read(tmp_path / "ACC1B_2003-09-14_A_00.calibrated.parquet")
    assert len(series) == 60
    assert series.axes == ("x", "y", "z")
    import pyarrow.parquet as pq

    # never null: written REQUIRED (no definition levels)
    schema = pq.read_schema(tmp_path / "ACC1B_2003-09-14_A_00.calibrated.parquet")
    assert not any(f.nullable for f in schema)


@pytest.fixture(scope="module")
def simulated_day(tmp_path_factory):
    d = tmp_path_factory.mktemp("sim")
    out = d / "ACC1B_2005-01-01_A_sim.asc"
    code, _, err = invoke(
        "simulate",
        "grace",
        "--date",
        "2005-01-01",
        "--satellite",
        "A",
        "--seed",
        "3",
        "--gaps",
        "2",
        "--flagged",
        "0.02",
        "--out",
        out,
    )
    assert code == 0, err
    return out, json.loads(out.with_name(out.name + ".truth.json").read_text())


def test_simulated_day_recovers_truth_within_sigma(simulated_day, tmp_path):
    """LS estimate minus truth (instrument bias/drift + LS trend of the scaled true
    signal, which any trend estimator sees) within 4 reported sigmas."""
    day, truth = simulated_day
    code, _, err = invoke(
        "grace-bias", day, "--method", "lsq", "--format", "csv", "--out", tmp_path
    )
    assert code == 0, err
    df = table(tmp_path, "csv").set_index("axis")
    assert truth["n_flagged"] > 0
    for i, ax in enumerate("xyz"):
        row = df.loc[ax]
        expected_b = truth["bias"][i] + truth["signal_trend"]["bias"][i]
        expected_d = truth["drift"][i] + truth["signal_trend"]["drift"][i]
        assert abs(row["bias"] - expected_b) < 4 * row["bias_sigma"]
        assert abs(row["drift"] - expected_d) < 4 * row["drift_sigma"]
        assert row["n"] == truth["n_samples"] - truth["n_flagged"]
        assert row["n_gaps"] >= 1


def _true_reference(truth: dict) -> tuple[pd.DataFrame, object]:
    """The simulated day's true (scaled) signal as a reference table, and the simulation."""
    from accal.simulate.grace import simulate_grace_day

    sim = simulate_grace_day(
        date="2005-01-01", satellite="A", seed=3, n_gaps=2, flagged_fraction=0.02
    )
    s = np.array(truth["scale_s"])
    ref = pd.DataFrame(
        {
            "gps_time": sim.time,
            **{f"lin_accl_{ax}": s[i] * sim.true[:, i] for i, ax in enumerate("xyz")},
        }
    )
    return ref, sim


def test_reference_removes_the_signal(simulated_day, tmp_path):
    """--reference with the true (scaled) signal: the fit sees only bias + drift + noise."""
    from accal.io.writers import write_table

    day, truth = simulated_day
    ref, sim = _true_reference(truth)
    ref_path = write_table(ref, tmp_path / "ref.parquet")
    code, _, err = invoke(
        "grace-bias", day, "--method", "lsq", "--reference", ref_path, "--out", tmp_path / "o"
    )
    assert code == 0, err
    df = table(tmp_path / "o").set_index("axis")
    for i, ax in enumerate("xyz"):
        assert abs(df.loc[ax, "bias"] - truth["bias"][i]) < 4 * df.loc[ax, "bias_sigma"]
        assert abs(df.loc[ax, "drift"] - truth["drift"][i]) < 4 * df.loc[ax, "drift_sigma"]
        # and the noise-only fit is much tighter than the signal-laden one
        assert df.loc[ax, "rms"] < 1e-9
        # the table says what the bias holds, and how much signal a fit without the
        # reference would have put into it (the reference's mean over the used samples)
        assert df.loc[ax, "bias_includes"] == "instrument"
        used = np.isin(ref["gps_time"].to_numpy(), sim.time[sim.valid])
        expect = float(ref.loc[used, f"lin_accl_{ax}"].mean())
        assert df.loc[ax, "signal_mean"] == pytest.approx(expect, rel=1e-6, abs=1e-15)
    code, _, err = invoke("grace-bias", day, "--method", "lsq", "--out", tmp_path / "plain")
    assert code == 0, err
    plain = table(tmp_path / "plain").set_index("axis")
    assert (plain["bias_includes"] == "instrument+signal_mean").all()
    assert plain["signal_mean"].isna().all()
    # the drag axis: without the reference its day-mean signal goes into the bias
    assert abs(df.loc["x", "signal_mean"]) > 1e-8
    moved = plain.loc["x", "bias"] - df.loc["x", "bias"]
    assert abs(moved) > 10 * df.loc["x", "bias_sigma"]


def test_reference_holes_are_left_out_not_bridged(simulated_day, tmp_path):
    """A reference with a 600-sample hole: the data there leave the fit, with a warning.

    One missing reference sample is still bridged (spacing 2 s <= 2.5 nominal steps).
    QA: 96 missing samples were bridged by a straight line, silently (bias 2.5σ off).
    """
    from accal.io.writers import write_table

    day, truth = simulated_day
    ref, sim = _true_reference(truth)
    full = write_table(ref, tmp_path / "ref.parquet")
    keep = np.ones(len(ref), bool)
    keep[30_000:30_600] = False  # a hole: the data at 30,000-30,599 (+ its edges' partners)
    keep[50_000] = False  # one missing sample: bridged
    holed = write_table(ref[keep].reset_index(drop=True), tmp_path / "holed.parquet")
    for name, r in (("full", full), ("holed", holed)):
        code, _, err = invoke(
            "grace-bias", day, "--method", "lsq", "--reference", r, "--out", tmp_path / name
        )
        assert code == 0, err
    a, b = (table(tmp_path / n).set_index("axis") for n in ("full", "holed"))
    t = ref["gps_time"].to_numpy()
    in_hole = (t > t[29_999]) & (t < t[30_600])
    valid_there = int(np.count_nonzero(in_hole & sim.valid))
    assert valid_there > 500
    assert (a["n"] - b["n"]).tolist() == [valid_there] * 3
    rep = json.loads(next((tmp_path / "holed").glob("*.report.json")).read_text())
    msg = [w for w in rep["read_report"]["warnings"] if "holes" in w]
    assert len(msg) == 1 and f"{valid_there} sample(s)" in msg[0] and "holed.parquet" in msg[0]
    rep = json.loads(next((tmp_path / "full").glob("*.report.json")).read_text())
    assert not any("holes" in w for w in rep["read_report"]["warnings"])
    for ax in "xyz":
        assert abs(a.loc[ax, "bias"] - b.loc[ax, "bias"]) < 2 * b.loc[ax, "bias_sigma"]
    # a reference sampled every 10 s is interpolated (no hole), with a word
    t10 = np.arange(t[0], t[-1] + 10.0, 10.0)  # a regular 10 s grid over the data's span
    sparse = write_table(
        {"gps_time": t10, **{c: np.interp(t10, t, ref[c]) for c in ref.columns[1:]}},
        tmp_path / "sparse.parquet",
    )
    code, _, err = invoke(
        "grace-bias", day, "--method", "lsq", "--reference", sparse, "--out", tmp_path / "s"
    )
    assert code == 0, err
    assert (table(tmp_path / "s").set_index("axis")["n"] == a["n"]).all()
    rep = json.loads(next((tmp_path / "s").glob("*.report.json")).read_text())
    warns = rep["read_report"]["warnings"]
    assert not any("holes" in w for w in warns)
    assert any(
        "sparse.parquet is sampled every 10 s (median), the data every 1 s" in w for w in warns
    )


def test_scale_tn02_applied_to_calibrated_series(tmp_path):
    code, _, err = invoke("grace-bias", GRACE_A, "--scale", "tn02", "--out", tmp_path)
    assert code == 0, err
    df = table(tmp_path).set_index("axis")
    np.testing.assert_allclose(df.loc[["x", "y", "z"], "scale"], [0.9595, 0.9797, 0.9485])
    np.testing.assert_allclose(df["bias_correction"], -df["scale"] * df["bias"])


def test_scale_tn02_on_gracefo_is_a_clear_failure(tmp_path):
    code, _, err = invoke("grace-bias", FO_C, GRACE_A, "--scale", "tn02", "--out", tmp_path)
    assert code == 1
    lines = [x for x in err.splitlines() if x.startswith("accal:") and ": warning:" not in x]
    assert len(lines) == 1  # the GRACE-A sample's warning is its own (a short record)
    assert "ACT1B_2023-06-01_C_04.txt" in lines[0] and "no TN-02 scale preset" in lines[0]
    assert not any("ACT1B_2023-06-01_C_04.txt: warning" in x for x in err.splitlines())
    assert (tmp_path / "ACC1B_2003-09-14_A_00.calibrated.parquet").exists()
    assert not (tmp_path / "ACT1B_2023-06-01_C_04.calibrated.parquet").exists()


BAD_INPUTS = {
    "empty.asc": b"",
    "garbage.asc": bytes(range(256)) * 20,
    "nodata.asc": GRACE_A.read_bytes().split(b"END OF HEADER")[0] + b"END OF HEADER\n",
    "noend.asc": GRACE_A.read_bytes().split(b"END OF HEADER")[0],
    "nan.asc": GRACE_A.read_bytes().replace(b"1.211359188507761e-06", b"nan", 1),
    "corrupt.asc.gz": b"\x1f\x8b\x08\x00" + b"not really gzip" * 10,
}


def test_bad_inputs_fail_one_line_each_and_the_batch_goes_on(tmp_path):
    inputs = []
    for name, data in BAD_INPUTS.items():
        p = tmp_path / "in" / name
        p.parent.mkdir(exist_ok=True)
        p.write_bytes(data)
        inputs.append(p)
    (tmp_path / "in" / "adir").mkdir()
    inputs += [tmp_path / "in" / "adir", tmp_path / "in" / "missing.asc", GRACE_A]
    out = tmp_path / "out"
    code, _, err = invoke("grace-bias", *inputs, "--out", out, "-q")
    assert code == 1
    lines = err.strip().splitlines()
    assert len(lines) == len(inputs) - 1, err
    for p, line in zip(inputs[:-1], lines, strict=True):
        assert line.startswith(f"accal: {p}"), line
    assert "nan.asc:31" in err  # the offending line number
    # the good file is processed; nothing partial or temporary is left behind
    names = sorted(p.name for p in out.iterdir())
    assert names == [
        ".accal.lock",
        "ACC1B_2003-09-14_A_00.calibrated.parquet",
        "ACC1B_2003-09-14_A_00.report.json",
        "accal.log",
        "bias_drift.parquet",
        "manifest.json",
    ]
    # only the good input is recorded as done; the failures are retried next time
    manifest = json.loads((out / "manifest.json").read_text())["entries"]
    assert [Path(k).name for k in manifest] == [GRACE_A.name]
    assert len(table(out)) == 3


def test_fail_fast_stops_at_first_failure(tmp_path):
    bad = tmp_path / "empty.asc"
    bad.write_bytes(b"")
    code, _, err = invoke("grace-bias", bad, GRACE_A, "--fail-fast", "--out", tmp_path / "o")
    assert code == 1
    assert "not run" in err or not (tmp_path / "o" / "ACC1B_2003-09-14_A_00.report.json").exists()
    assert not (tmp_path / "o" / "ACC1B_2003-09-14_A_00.report.json").exists()


def test_table_is_cumulative_and_never_duplicates(tmp_path):
    assert invoke("grace-bias", GRACE_A, "--out", tmp_path)[0] == 0
    assert invoke("grace-bias", GRACE_B, "--out", tmp_path)[0] == 0
    assert invoke("grace-bias", GRACE_A, "--method", "both", "--out", tmp_path)[0] == 0
    df = table(tmp_path)
    assert len(df) == 3 + 3 + 3  # A wavelet (replaced), A lsq (new), B wavelet
    assert not df.duplicated(["source", "axis", "method"]).any()


def test_config_file_sets_defaults_and_flags_win(tmp_path):
    cfg = tmp_path / "c.toml"
    cfg.write_text('[grace-bias]\nmethod = "both"\nformat = "csv"\norder = 2\n')
    code, _, err = invoke("grace-bias", GRACE_A, "--config", cfg, "--out", tmp_path / "o")
    assert code == 0, err
    df = table(tmp_path / "o", "csv")
    assert set(df["method"]) == {"wavelet", "lsq"}
    assert (df["order"] == 2).all() and df["quadratic"].notna().all()
    code, _, _ = invoke(
        "grace-bias", GRACE_A, "--config", cfg, "--method", "lsq", "--out", tmp_path / "p"
    )
    assert set(table(tmp_path / "p", "csv")["method"]) == {"lsq"}
    cfg.write_text('[grace-bias]\nmethd = "both"\n')
    code, _, err = invoke("grace-bias", GRACE_A, "--config", cfg, "--out", tmp_path / "q")
    assert code == 2 and "unknown key 'methd'" in err


def test_config_sections_lists_and_messages(tmp_path):
    """Flat files apply to the command; other commands' tables set nothing; lists/strings fit."""
    cfg = tmp_path / "c.toml"
    # tables for another command only: grace-bias runs with its own defaults
    cfg.write_text('[table]\nsatellite = "GRACE-A"\n')
    code, _, err = invoke("grace-bias", GRACE_A, "--config", cfg, "--out", tmp_path / "a", "-q")
    assert code == 0, err
    assert set(table(tmp_path / "a")["method"]) == {"wavelet"}
    # a flat file (no tables) applies to the command; a list for --scale, a string for
    # the repeatable --include
    cfg.write_text('format = "csv"\nscale = [2.0, 2.0, 2.0]\ninclude = "*ACC1B_*.asc"\n')
    code, _, err = invoke(
        "grace-bias", GRACE_A.parent, "-r", "--config", cfg, "--out", tmp_path / "b", "-q"
    )
    assert code == 0, err
    df = table(tmp_path / "b", "csv")
    assert set(df["source"]) == {p.name for p in GRACE_A.parent.glob("*ACC1B_*.asc")}
    assert (df["scale"] == 2.0).all()
    # the message names the options as typed on the command line
    cfg.write_text("[grace-bias]\nkeep_goin = true\n")
    code, _, err = invoke("grace-bias", GRACE_A, "--config", cfg, "--out", tmp_path / "c")
    assert code == 2 and "unknown key 'keep_goin'" in err
    assert "keep-going" in err and "format" in err
    assert "fmt" not in err and "keep_going" not in err


def test_bundled_configs_are_valid(tmp_path):
    cfgs = sorted((SAMPLES.parents[1] / "configs").glob("*.toml"))
    assert cfgs
    for cfg in cfgs:
        res = CliRunner().invoke(main, ["grace-bias", "--config", str(cfg), "--help"])
        assert res.exit_code == 0, (cfg, res.output)


def test_swarm_single_axis_table_input(tmp_path):
    code, _, err = invoke(
        "grace-bias", SWARM, "--column", "x=a_cal_x", "--method", "both", "--out", tmp_path
    )
    assert code == 0, err
    df = table(tmp_path)
    assert list(df["axis"].unique()) == ["x"]
    assert (df["satellite"] == "Swarm-A").all()
    assert (df["date"] == "2024-05-11").all()
    row = df[df.method == "wavelet"].iloc[0]
    assert 0.85 * 86400 < row["n"] < 0.95 * 86400  # ~90 % valid (flag_val)
    assert row["n_flagged"] > 0


def test_usage_errors_exit_2(tmp_path):
    assert invoke("grace-bias", GRACE_A, "--out", tmp_path, "--method", "spline")[0] == 2
    assert invoke("grace-bias", GRACE_A)[0] == 2
    assert invoke("grace-bias", GRACE_A, "--column", "q=a", "--out", tmp_path)[0] == 2


def test_version_and_python_m_in_a_real_process(tmp_path):
    res = subprocess.run(
        [sys.executable, "-m", "accal", "--version"], capture_output=True, text=True, check=True
    )
    assert __version__ in res.stdout
    res = subprocess.run(
        [
            sys.executable,
            "-m",
            "accal",
            "grace-bias",
            str(GRACE_A),
            str(tmp_path / "nope.asc"),
            "--out",
            str(tmp_path / "o"),
            "--format",
            "csv",
        ],
        capture_output=True,
        text=True,
    )
    assert res.returncode == 1
    assert "Traceback" not in res.stderr
    assert f"accal: {tmp_path / 'nope.asc'}" in res.stderr
    assert (tmp_path / "o" / "bias_drift.csv").exists()


def test_column_option_applies_to_tables_and_leaves_l1b_files_alone(tmp_path):
    """--column maps table columns; a GRACE file in the same batch is read as usual."""
    code, _, err = invoke("grace-bias", GRACE_A, SWARM, "--column", "x=a_cal_x", "--out", tmp_path)
    assert code == 0, err
    assert set(table(tmp_path)["satellite"]) == {"GRACE-A", "Swarm-A"}


def test_inputs_writing_the_same_outputs_are_refused_not_mixed(tmp_path):
    """Two copies of a day, or x.asc and x.dat: the second fails, nothing is duplicated."""
    for d in ("a", "b"):
        (tmp_path / d).mkdir()
        (tmp_path / d / GRACE_A.name).write_bytes(GRACE_A.read_bytes())
    dat = GRACE_A.with_suffix(".dat")
    out = tmp_path / "out"
    code, _, err = invoke(
        "grace-bias", tmp_path / "a" / GRACE_A.name, tmp_path / "b" / GRACE_A.name, dat,
        "-j", "1", "--out", out,
    )  # fmt: skip
    assert code == 1
    lines = [ln for ln in err.splitlines() if "same outputs" in ln]
    assert len(lines) == 2 and all(str(tmp_path / "a" / GRACE_A.name) in ln for ln in lines)
    df = table(out)
    assert len(df) == 3 and not df.duplicated(["source", "axis", "method"]).any()
    assert "same outputs" in (out / "accal.log").read_text()


def test_reader_warnings_and_name_mismatch_reach_the_user(tmp_path):
    """A file named for another satellite and day: processed, one warning line, logged."""
    renamed = tmp_path / "ACC1B_2005-01-01_B_00.asc"
    renamed.write_bytes(GRACE_A.read_bytes())
    code, _, err = invoke("grace-bias", renamed, "--out", tmp_path / "out")
    assert code == 0
    warn = [ln for ln in err.splitlines() if ": warning:" in ln]
    assert len(warn) == 1
    assert "satellite B, the data are GRACE-A" in warn[0] and "2003-09-14" in warn[0]
    assert "file name says 2005-01-01" in (tmp_path / "out" / "accal.log").read_text()
    code, _, err = invoke("grace-bias", renamed, "--out", tmp_path / "out2", "-q")
    assert code == 0 and ": warning:" not in err
    # a correctly named file has nothing to say but that its 60 s are not a day
    code, _, err = invoke("grace-bias", GRACE_A, "--out", tmp_path / "out3")
    (warn,) = [ln for ln in err.splitlines() if ": warning:" in ln]
    assert code == 0 and ": warning: short record (60 used samples over 59 s" in warn


def test_output_directory_problems_are_one_line(tmp_path):
    out = tmp_path / "out"
    assert invoke("grace-bias", GRACE_A, "--out", out)[0] == 0
    code, _, err = invoke("grace-bias", GRACE_A, "--out", out, "--format", "csv")
    assert code == 1 and "holds bias_drift.parquet" in err and "Traceback" not in err
    assert not (out / "bias_drift.csv").exists()
    code, _, err = invoke("grace-bias", GRACE_A, "--out", out / "bias_drift.parquet" / "sub")
    assert code == 2 and "cannot write the output directory" in err
    assert len(err.strip().splitlines()) == 1


def test_bad_scale_is_a_usage_error_said_once(tmp_path):
    code, _, err = invoke("grace-bias", GRACE_A, GRACE_B, "--scale", "1,2", "--out", tmp_path)
    assert code == 2 and err.count("--scale expects") == 1
    assert not any(tmp_path.iterdir())


def test_table_filters_ignore_case_and_check_the_date_range(tmp_path):
    assert invoke("grace-bias", GRACE_A, "--method", "both", "--out", tmp_path)[0] == 0
    code, out, _ = invoke("table", tmp_path, "--method", "WAVELET", "--axis", "Y")
    assert code == 0 and len(out.strip().splitlines()) == 2  # header + one row
    code, _, err = invoke("table", tmp_path, "--start", "2004-01-01", "--end", "2003-01-01")
    assert code == 2 and "after --end" in err


@pytest.mark.skipif(sys.platform != "linux", reason="ru_maxrss units")
def test_summary_reports_the_workers_peak_memory(tmp_path):
    """The summary (stderr and accal.log) gives the peak RSS of the worker processes."""
    import re

    code, _, err = invoke("grace-bias", GRACE_A, GRACE_B, "-j", "2", "--out", tmp_path)
    assert code == 0
    for text in (err, (tmp_path / "accal.log").read_text()):
        m = re.search(r"peak RSS (\d+) MB per worker", text)
        assert m and 30 < int(m.group(1)) < 4000


@pytest.mark.skipif(not Path("/proc/self/clear_refs").exists(), reason="Linux /proc")
def test_an_inputs_peak_memory_is_its_own_not_the_workers_lifetime_one(tmp_path):
    """A worker that ran something big before (a Dask worker lives beyond the batch)
    reports, for the next input, the peak while that input ran."""
    code = (
        "import numpy as np, sys\n"
        "from pathlib import Path\n"
        "from accal.gracejob.process import process_one\n"
        "from accal.gracejob.options import GraceBiasOptions\n"
        "from accal.batch_summary import peak_rss_mb\n"
        "big = np.ones(100_000_000); del big  # 763 MiB, then freed\n"
        "lifetime = peak_rss_mb()\n"
        "o = process_one(Path(sys.argv[1]), Path(sys.argv[2]), GraceBiasOptions())\n"
        "print(lifetime, o.peak_rss, o.ok)\n"
    )
    res = subprocess.run(
        [sys.executable, "-c", code, str(GRACE_A), str(tmp_path)],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    lifetime, peak, ok = res.stdout.split()
    assert ok == "True"
    assert float(lifetime) > 700 and 30 < float(peak) < 400, res.stdout


def test_file_system_errors_of_any_command_are_one_line(tmp_path):
    """An OSError no command handled (here: demod's --out under a file) is one line, exit 2."""
    blocker = tmp_path / "afile"
    blocker.write_text("x")
    run = tmp_path / "run.parquet"
    assert invoke("simulate", "gap", "--out", run, "--days", "0.05")[0] == 0
    code, _, err = invoke("demod", run, "--tau", "600", "--mask", "200", "--out", blocker / "sub")
    assert code == 2
    assert err.strip() == f"accal: {blocker / 'sub'}: Not a directory"


def test_an_input_taking_over_outputs_displaces_the_earlier_one(tmp_path):
    """Across runs: the same name from another directory (different data), or x.dat after
    x.asc, replaces the earlier input's outputs, record and rows; re-running the earlier
    input then redoes it instead of calling stale outputs current."""
    e1, e2, out = tmp_path / "e1", tmp_path / "e2", tmp_path / "out"
    for d, src in ((e1, GRACE_A), (e2, GRACE_B)):
        d.mkdir()
        (d / "ACC1B_2003-09-14_X_00.asc").write_bytes(src.read_bytes())

    def bias_y():
        df = table(out)
        return df[(df.axis == "y")]["bias"].tolist()

    assert invoke("grace-bias", e1 / "ACC1B_2003-09-14_X_00.asc", "--out", out, "-q")[0] == 0
    first = bias_y()
    assert invoke("grace-bias", e2 / "ACC1B_2003-09-14_X_00.asc", "--out", out, "-q")[0] == 0
    second = bias_y()
    assert len(second) == 1 and second != first
    code, _, err = invoke("grace-bias", e1 / "ACC1B_2003-09-14_X_00.asc", "--out", out)
    assert code == 0 and "1 ok, 0 skipped" in err
    assert bias_y() == first
    manifest = json.loads((out / "manifest.json").read_text())["entries"]
    assert list(manifest) == [str((e1 / "ACC1B_2003-09-14_X_00.asc").resolve())]
    # x.asc, then x.dat of the same day: the .dat owns the outputs, the .asc rows go
    out2 = tmp_path / "out2"
    assert invoke("grace-bias", GRACE_A, "--out", out2, "-q")[0] == 0
    assert invoke("grace-bias", GRACE_A.with_suffix(".dat"), "--out", out2, "-q")[0] == 0
    assert set(table(out2)["source"]) == {GRACE_A.with_suffix(".dat").name}


def test_a_missing_or_empty_input_claims_no_outputs(tmp_path):
    """A missing X.asc, or an empty one, fails alone: the good X of the same day is done."""
    empty = tmp_path / "e" / GRACE_A.name
    empty.parent.mkdir()
    empty.write_bytes(b"")
    code, _, err = invoke(
        "grace-bias", tmp_path / "nothere" / GRACE_A.name, empty, GRACE_A, "--out", tmp_path / "o"
    )
    assert code == 1 and "same outputs" not in err
    assert "no such file" in err and "empty file" in err
    assert set(table(tmp_path / "o")["source"]) == {GRACE_A.name}


def test_diagnose_with_unwritable_outputs_is_one_clear_line(tmp_path, monkeypatch):
    import accal.pipeline_closure as pipeline_closure

    assert invoke("grace-bias", GRACE_A, "--out", tmp_path / "g", "-q")[0] == 0

    def refuse(*args, **kwargs):
        raise PermissionError(1, "Operation not permitted", str(tmp_path / "imm" / "x.png"))

    monkeypatch.setattr(pipeline_closure, "_plot_closure", refuse)
    code, _, err = invoke("diagnose", tmp_path / "g", "--out", tmp_path / "imm", "--plots")
    assert code == 1 and "internal error" not in err
    assert "cannot write outputs" in err and "Operation not permitted" in err


@pytest.mark.parametrize(
    "args",
    [
        ["--date", "2005-13-01"],
        ["--date", "abc"],
        ["--date", ""],
        ["--date", "1900-01-01"],
        ["--flagged", "-1"],
        ["--flagged", "2"],
        ["--noise", "-1"],
        ["--gaps", "-1"],
        ["--duration", "0"],
    ],
)
def test_simulate_grace_checks_its_options(tmp_path, args):
    code, _, err = invoke("simulate", "grace", "--out", tmp_path / "s.asc", *args)
    assert code == 2 and "Traceback" not in err and args[0] in err
    assert not any(tmp_path.iterdir())


def test_output_file_under_a_file_says_not_a_directory(tmp_path):
    (tmp_path / "afile").write_text("x")
    code, _, err = invoke(
        "design", "--tau", "600", "--mask", "200", "--out", tmp_path / "afile" / "x.csv"
    )
    assert code == 2 and err.strip() == f"accal: {tmp_path / 'afile'}: Not a directory"


@pytest.mark.parametrize(
    "text", ['[[period]]\nsatellite = "GRACE-B"\nstart = "2016-09-01"\nstatus = "weird"\n', "x [["]
)
def test_malformed_degraded_days_table_is_a_usage_error(tmp_path, text):
    table_file = tmp_path / "dd.toml"
    table_file.write_text(text)
    out = tmp_path / "out"
    code, _, err = invoke("grace-bias", GRACE_A, "--degraded-days", table_file, "--out", out)
    assert code == 2 and "dd.toml" in err and not out.exists()


def test_noise_free_simulation_has_no_warning_and_no_noise():
    """`simulate grace --noise 0` printed numpy's 'invalid value in multiply' (0 × inf at
    f = 0 of the 1/f shape); the noise is now exactly zero without it."""
    import warnings

    from accal.simulate.grace import coloured_noise

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        z = coloured_noise(1000, 1.0, 0.0, 1e-3, np.random.default_rng(1))
    assert z.shape == (1000,) and not z.any()


@pytest.mark.parametrize("seed", range(6))
def test_simulated_truth_counts_the_gaps_in_the_file(tmp_path, seed):
    """QA: gaps that overlap merge into one; the truth counted the gaps asked for."""
    import json

    from accal.io.grace_l1b import read_grace_acc1b
    from accal.simulate.grace import write_simulated_grace

    f = tmp_path / "ACC1B_2005-01-01_A_02.asc"
    truth = write_simulated_grace(f, seed=seed, duration=20000.0, n_gaps=8)
    t = json.loads(truth.read_text())
    assert t["n_gaps_requested"] == 8
    assert t["n_gaps"] == read_grace_acc1b(f).report.n_gaps


def test_day_with_every_sample_flagged_says_so(tmp_path):
    """QA: "only 0 usable samples; an order-1 trend needs at least 3" did not say why."""
    from accal.io.grace_l1b import read_grace_acc1b, write_grace_acc1b
    from accal.simulate.grace import write_simulated_grace

    f = tmp_path / "ACC1B_2005-01-01_A_02.asc"
    write_simulated_grace(f, seed=2, duration=600.0)
    s = read_grace_acc1b(f)
    write_grace_acc1b(
        s.replace(quality=np.ones(len(s), np.uint32), valid=np.zeros(len(s), bool)), f
    )
    code, _, err = invoke("grace-bias", f, "--out", tmp_path / "o")
    assert code == 1
    assert "only 0 usable samples of 600: 600 are flagged invalid" in err and f.name in err
    assert not list((tmp_path / "o").glob("*.calibrated.*"))
    code, _, err = invoke("grace-bias", f, "--keep-flagged", "--out", tmp_path / "k", "-q")
    assert code == 0, err
