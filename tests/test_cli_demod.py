"""End-to-end tests of `accal demod`, `design`, `budget` and `simulate gap` (CliRunner + a process).

The commands are not registered in accal.cli yet: the tests build the group the
way cli.py will (``main.add_command``), see ``make_cli``.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import click
import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from accal.estimators.design import rest_mask
from accal.io.writers import read_table_metadata, write_table
from accal.simulate.gap import simulate_gap

REGISTER = """
import click
from accal.cli import main, simulate
from accal.cli_demod import budget, demod, design, simulate_gap
for cmd in (demod, design, budget):
    if cmd.name not in main.commands:
        main.add_command(cmd)
if "gap" not in simulate.commands:
    simulate.add_command(simulate_gap, name="gap")
"""


def make_cli() -> click.Group:
    ns: dict = {}
    exec(REGISTER, ns)
    return ns["main"]


CLI = make_cli()


def invoke(*args) -> tuple[int, str, str]:
    res = CliRunner().invoke(CLI, [str(a) for a in args], catch_exceptions=False)
    return res.exit_code, res.stdout, res.stderr


@pytest.fixture(scope="module")
def day(tmp_path_factory) -> Path:
    """A simulated 1 Hz day (τ = 600 s, TM = 200 s) written by `accal simulate gap`."""
    d = tmp_path_factory.mktemp("gap")
    code, _, err = invoke(
        "simulate", "gap", "--days", 1, "--tau", 600, "--mask", 200, "--seed", 7,
        "--temperature-coupling", 2e-9, "--out", d / "run.parquet",
    )  # fmt: skip
    assert code == 0, err
    return d / "run.parquet"


def test_simulate_then_demod_recovers_truth(day, tmp_path):
    truth = pd.read_parquet(day.with_name("run.truth.parquet"))
    assert len(truth) == 144
    units, meta = read_table_metadata(day)
    assert units["theta"] == "rad" and meta["simulate_gap"]["seed"] == 7
    for method in ("ls", "gls"):
        out = tmp_path / method
        code, _, err = invoke(
            "demod", day, "--tau", 600, "--mask", 200, "--out", out, "--method", method,
            "--bias-model", "affine+temperature", "--sinusoid-period", 43200, "--quiet",
            "--psd", "microstar",  # the paper's numbers below (issue 20: auto is the default)
        )  # fmt: skip
        assert code == 0, err
        assert sorted(p.name for p in out.iterdir()) == [
            ".accal.lock",
            "accal.log",
            "manifest.json",
            "periods.parquet",
            "summary.json",
            "summary.md",
        ]
        df = pd.read_parquet(out / "periods.parquet").merge(
            truth, on="period", suffixes=("", "_true")
        )
        assert len(df) == 144
        for ax in ("Y", "Z"):
            z = (df[f"a_{ax}"] - df[f"a_{ax}_true"]) / df[f"sigma_{ax}"]
            # within 4 sigma per period, and sigma right on average (rms z ~ 1)
            assert np.abs(z).max() < 4.0, (method, ax)
            assert 0.75 < np.sqrt(np.mean(z**2)) < 1.3, (method, ax)
        units, meta = read_table_metadata(out / "periods.parquet")
        assert units["a_Y"].startswith("m/s^2") and units["drift_y"].startswith("m/s^3")
        assert "bias_y_temperature" in df and set(df["source"]) == {"run.parquet"}
        assert meta["sources"]["run.parquet"]["method"] == method
        assert meta["sources"]["run.parquet"]["Rd"][0] == pytest.approx(
            df.sigma_Y.median() ** 2, rel=0.01
        )
        s = json.loads((out / "summary.json").read_text())
        # paper: Rd[0] = 1.84e-23 (LS), per-period GLS on data 1.77e-23 (docs/demod.md)
        assert s["Rd"][0] == pytest.approx(1.84e-23 if method == "ls" else 1.77e-23, rel=0.05)
        assert s["n_kept"] == 144 and s["dropped"] == 0 and s["dropped_periods"] == []
        assert s["mask"]["measured_median"] == 208.0 and not s["mask"]["mismatch"]
        assert s["sigma_T"]["standard"]["T"] == 10800.0
        assert s["sigma_T"]["standard"]["sigma"] == pytest.approx(1.0e-12, rel=0.05)
        # the noise is eq. 1's: the residual agrees with it (chi2/dof ~ 1), and the PSD
        # estimated from the data gives the a-priori sigma within its ~5 % scatter
        assert 0.85 < s["consistency"]["ratio"] < 1.15
        assert 0.85 < s["noise"]["sigma_ratio"] < 1.18 and s["noise"]["psd_used"] == "apriori"
        assert {"alpha", "beta", "cov"} <= set(s["sinusoid"]["Y"])
        assert "| periods kept / whole | 144 / 144 |" in (out / "summary.md").read_text()


# --- bad inputs: one-line message naming the file, exit 1, no output -------------


def small_run(**change) -> pd.DataFrame:
    data, _ = simulate_gap(days=1200 / 86400, tau=60, mask=20, seed=1)
    for k, v in change.items():
        data[k] = v(data) if callable(v) else v
    return data


def _time_back(d):
    t = d["time"].to_numpy().copy()
    t[100], t[101] = t[101], t[100]
    return t


def _time_jitter(d):
    t = d["time"].to_numpy().copy()
    t[100] += 0.3
    return t


def _nan(d):
    y = d["m_y"].to_numpy().copy()
    y[10] = np.nan
    return y


BAD = {
    "not_monotonic": ({"time": _time_back}, [], r"bad\.csv:\d+: time is not strictly increasing"),
    "irregular": ({"time": _time_jitter}, [], r"bad\.csv: irregular sampling: 2 of 1199 steps .*--resample"),
    "degrees": ({"theta": lambda d: np.degrees(d["theta"])}, [], r"bad\.csv: theta reaches 180 > 2π and its rests are not at multiples of π/2 rad: it looks like degrees"),
    "short": ({}, ["--tau", 1800, "--mask", 600], r"bad\.csv: run lasts 1200 s .* shorter than one modulation period"),
    "tau_not_integer": ({}, ["--tau", 60.5], r"bad\.csv: tau·fs = 60.5 is not an integer .* use tau = 60 s or 61 s"),
    "nan": ({"m_y": _nan}, [], r"bad\.csv: m_y has 1 NaN/inf value\(s\), first at t = 10 s \(row 11\)"),
    "never_pi": ({"theta": lambda d: np.where(d["theta"] > 0, 1.0, 0.0)}, [], r"bad\.csv: theta never reaches π"),
    "no_usable_period": ({"theta": lambda d: np.pi * (d["time"] % 60) / 59}, [], r"bad\.csv: no period has enough unmasked samples"),
    "missing_columns": ({"m_z": None}, [], r"bad\.csv: missing column\(s\) m_z"),
    "no_channel": ({}, ["--bias-model", "affine+heater"], r"bad\.csv: .*no auxiliary channel 'heater' \(channels: temperature\)"),
}  # fmt: skip


@pytest.mark.parametrize("case", list(BAD))
def test_bad_input(case, tmp_path):
    change, extra, pattern = BAD[case]
    data = small_run(**{k: v for k, v in change.items() if v is not None})
    data = data.drop(columns=[k for k, v in change.items() if v is None])
    bad = tmp_path / "bad.csv"
    write_table(data, bad, units={"theta": "rad"})
    out = tmp_path / "out"
    args = {"--tau": 60, "--mask": 20}
    for k, v in zip(extra[::2], extra[1::2], strict=True):
        args[k] = v
    flat = [x for kv in args.items() for x in kv]
    code, _, err = invoke("demod", bad, *flat, "--out", out, "--quiet")
    assert code == 1
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"accal: {bad}")
    assert __import__("re").search(pattern, lines[0]), lines[0]
    # nothing but the run's bookkeeping (lock, log)
    assert not out.exists() or {p.name for p in out.iterdir()} <= {".accal.lock", "accal.log"}


def test_resample_jitter_and_gaps(tmp_path):
    """--resample: jittered time is interpolated onto the grid; a 7 s hole stays a hole
    (its grid points are masked, never interpolated) and its period is still used."""
    data = small_run()
    t = data["time"].to_numpy() + np.random.default_rng(3).uniform(-0.02, 0.02, len(data))
    data["time"] = t
    data = data.drop(index=range(146, 152)).reset_index(drop=True)  # rest at θ = 0, period 2
    bad = tmp_path / "jit.csv"
    write_table(data, bad)
    code, _, err = invoke("demod", bad, "--tau", 60, "--mask", 20, "--out", tmp_path / "x", "-q")
    assert code == 1 and "irregular sampling" in err and "use --resample" in err
    code, _, err = invoke(
        "demod", bad, "--tau", 60, "--mask", 20, "--out", tmp_path / "o", "--resample"
    )
    assert code == 0, err
    # 146..152 s: the grid point at 152 s precedes the jittered sample after the hole
    assert "1192 samples interpolated, 7 in 1 gap(s) marked invalid" in err
    s = json.loads((tmp_path / "o" / "summary.json").read_text())
    rs = s["input"]["resample"]
    assert s["input"]["resampled"] and rs["step"] == 1.0 and rs["n_grid"] == 1200
    assert rs["n_gap"] == 7 and rs["n_gaps"] == 1 and rs["n_exact"] == 1
    assert rs["n_input"] == 1194 and rs["largest_gap"] == pytest.approx(7.0, abs=0.05)
    df = pd.read_parquet(tmp_path / "o" / "periods.parquet").set_index("period")
    assert len(df) == 20 and s["dropped"] == 0
    # the hole and the sample on each side of it are masked in period 2
    assert df.n_used.loc[2] < df.n_used.drop(2).min() - 5
    # interpolating θ next to the rotations masks a few more samples than --mask says
    assert s["mask"]["mismatch"] and "measured masked time" in err


def test_batch_one_bad_one_good(tmp_path):
    good, bad = tmp_path / "good.csv.gz", tmp_path / "bad.csv"
    write_table(small_run(), tmp_path / "good.csv")
    good.write_bytes(__import__("gzip").compress((tmp_path / "good.csv").read_bytes()))
    write_table(small_run(m_y=_nan), bad)
    out = tmp_path / "out"
    code, _, err = invoke(
        "demod", bad, good, "--tau", 60, "--mask", 20, "--out", out, "--format", "csv"
    )
    assert code == 1
    assert f"accal: {bad}: m_y has 1 NaN" in err
    assert "1 ok, 0 skipped (current), 1 failed" in err
    assert sorted(p.name for p in out.iterdir()) == [
        ".accal.lock",
        "accal.log",
        "good.summary.json",
        "good.summary.md",
        "manifest.json",  # what was processed with which options (re-runs skip it)
        "periods.csv",
        "periods.csv-metadata.json",  # its units (CSVW sidecar)
    ]
    df = pd.read_csv(out / "periods.csv", comment="#")
    assert len(df) == 20 and {"a_Y", "sigma_Z", "bias_y", "drift_z", "leakage"} <= set(df)
    assert set(df.source) == {"good.csv.gz"}


def test_psd_file_and_bad_psd(tmp_path):
    run = tmp_path / "r.csv"
    write_table(small_run(), run)
    f = np.logspace(-5, np.log10(0.5), 50)
    psd = tmp_path / "psd.csv"
    pd.DataFrame({"f": f, "S": (5.7e-11) ** 2 * (1 + 4.2e-3 / f)}).to_csv(psd, index=False)
    code, _, err = invoke(
        "demod", run, "--tau", 60, "--mask", 20, "--out", tmp_path / "o", "--psd", psd, "-q"
    )
    assert code == 0, err
    psd.write_text("f,S\n1,-1\n2,1\n")
    code, _, err = invoke(
        "demod", run, "--tau", 60, "--mask", 20, "--out", tmp_path / "p", "--psd", psd
    )
    # a bad --psd table is a bad option value: exit 2 (as a missing one), one line
    assert code == 2 and err.splitlines() == [f"accal: {psd}: PSD table values must be positive"]
    assert not (tmp_path / "p").exists()


def test_config_file(tmp_path):
    run = tmp_path / "r.parquet"
    write_table(small_run(), run)
    cfg = tmp_path / "c.toml"
    cfg.write_text('[demod]\ntau = 60\nmask = 20\nformat = "csv"\n')
    code, _, err = invoke("demod", run, "--config", cfg, "--out", tmp_path / "o", "-q")
    assert code == 0, err
    assert (tmp_path / "o" / "periods.csv").exists()


# --- design -----------------------------------------------------------------


@pytest.mark.parametrize("kind", ["fig2", "fig1"])
def test_design_mean_model_conditions(kind, tmp_path):
    out = tmp_path / "theta.csv"
    code, stdout, err = invoke(
        "design",
        "--tau",
        600,
        "--mask",
        200,
        "--fs",
        1,
        "--kind",
        kind,
        "--periods",
        3,
        "--out",
        out,
    )
    assert code == 0, err
    assert "sum_c" in stdout and "sum_ct2" in stdout and "NOT ZERO" not in stdout
    df = pd.read_csv(out, comment="#")
    assert len(df) == 1800
    theta = df["theta"].to_numpy().reshape(3, 600)
    for th in theta:
        # the mask demod will find on the file (discrete θ̇ = θ̈ = 0)
        c = np.cos(th) * rest_mask(th, periodic=True)
        t = np.arange(600) - 299.5
        assert abs(c.sum()) < 1e-9 and abs((c * t).sum()) < 1e-6
    np.testing.assert_array_equal(df["rest"].to_numpy()[:600], rest_mask(theta[0], periodic=True))


def test_design_bad_options_usage_error(tmp_path):
    code, _, err = invoke("design", "--tau", 600, "--mask", 201, "--out", tmp_path / "x.csv")
    assert code == 2 and "divisible" in err
    assert not (tmp_path / "x.csv").exists()


# --- budget -----------------------------------------------------------------


def test_budget_json_ls_and_gls():
    code, stdout, err = invoke(
        "budget", "--mask", 200, "--tau", 600, "--integration", 10800, "--json"
    )
    assert code == 0, err
    rep = json.loads(stdout)  # exactly one JSON object
    # paper (section 5.1): Rd[0] = 1.84e-23 m²s⁻⁴ (LS), σ over 3 h ≈ 1 pm s⁻²
    assert rep["Rd"][0] == pytest.approx(1.84e-23, rel=0.1)
    assert rep["sigma_T"] == pytest.approx(1.0e-12, rel=0.1)
    assert "tau_opt" not in rep
    code, stdout, _ = invoke("budget", "--mask", 200, "--tau", 600, "--method", "gls", "--json")
    assert json.loads(stdout)["Rd"][0] == pytest.approx(1.71e-23, rel=0.1)  # paper: GLS 1.71e-23


def test_budget_scan_and_plot(tmp_path):
    png = tmp_path / "scan.png"
    code, stdout, err = invoke(
        "budget", "--mask", 200, "--taus", "400:1000:200", "--json", "--plot", png
    )
    assert code == 0, err
    rep = json.loads(stdout)
    assert rep["tau"] == [400.0, 600.0, 800.0, 1000.0]
    assert len(rep["sigma"]) == 4 and rep["tau_opt"] in rep["tau"]
    assert rep["tau_budget"] == rep["tau_opt"] and len(rep["Rd"]) >= 1
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    code, stdout, _ = invoke("budget", "--mask", 200, "--tau", 600)
    assert code == 0 and "Rd[0] = 1.838" in stdout and "sigma over T = 3600 s" in stdout


def test_budget_real_process():
    """One real process: stdout is exactly one JSON object, nothing else."""
    code = REGISTER + "main(['budget', '--mask', '200', '--tau', '600', '--json'])\n"
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    rep = json.loads(res.stdout)
    assert rep["Rd"][0] == pytest.approx(1.84e-23, rel=0.1) and rep["sigma_T"] > 0


# --- chunked reading, cumulative table, eq. 24 constant ---------------------------


def _outputs(out: Path):
    df = (
        pd.read_parquet(out / "periods.parquet")
        if (out / "periods.parquet").exists()
        else (pd.read_csv(out / "periods.csv", comment="#"))
    )
    return df, json.loads((out / "summary.json").read_text())


@pytest.mark.parametrize("method", ["ls", "gls"])
def test_chunked_run_equals_whole_file(day, tmp_path, method):
    """A day read 1000 rows at a time (87 chunks, chunk borders inside periods) gives the
    whole-file results to rounding: every column of every period, Rd and the eq. 24 fit."""
    common = ("--tau", 600, "--mask", 200, "--method", method, "--bias-model",
              "affine+temperature", "--sinusoid-period", 43200, "-q")  # fmt: skip
    assert invoke("demod", day, *common, "--out", tmp_path / "whole")[0] == 0
    code, _, err = invoke("demod", day, *common, "--chunk-size", 1000, "--out", tmp_path / "ch")
    assert code == 0, err
    (a, sa), (b, sb) = _outputs(tmp_path / "whole"), _outputs(tmp_path / "ch")
    assert list(a.columns) == list(b.columns) and len(a) == len(b) == 144
    pd.testing.assert_frame_equal(a, b, check_exact=False, rtol=1e-9, atol=0)
    np.testing.assert_allclose(sb["Rd"], sa["Rd"], rtol=1e-9)
    assert sb["input"]["chunk_rows"] == 1000 and sa["input"]["n_samples"] == 86400
    for k in ("alpha", "beta"):
        assert sb["sinusoid"]["Y"][k] == pytest.approx(sa["sinusoid"]["Y"][k], rel=1e-9)


def test_tiny_chunks_csv_gz_and_resample(tmp_path):
    """16-row chunks of a gzipped CSV, with jitter and a hole resampled on the way."""
    data = small_run()
    data["time"] = data["time"] + np.where(np.arange(len(data)) % 7 == 3, 0.01, 0.0)
    data = data.drop(index=range(700, 704)).reset_index(drop=True)
    write_table(data, tmp_path / "r.csv", units={"theta": "rad"})
    run = tmp_path / "r.csv.gz"
    run.write_bytes(__import__("gzip").compress((tmp_path / "r.csv").read_bytes()))
    args = ("--tau", 60, "--mask", 20, "--resample", "--format", "csv", "-q")
    assert invoke("demod", run, *args, "--out", tmp_path / "whole")[0] == 0
    assert invoke("demod", run, *args, "--chunk-size", 16, "--out", tmp_path / "ch")[0] == 0
    (a, sa), (b, sb) = _outputs(tmp_path / "whole"), _outputs(tmp_path / "ch")
    assert sa["input"]["resample"] == sb["input"]["resample"]
    assert sa["input"]["resample"]["n_gap"] == 4
    pd.testing.assert_frame_equal(a, b, check_exact=False, rtol=1e-9, atol=0)


def test_cumulative_periods_table(tmp_path):
    """Several runs share periods.<fmt> (a source column); a re-run replaces its rows,
    never duplicates them; a failed run leaves the table untouched."""
    r1, r2, bad = tmp_path / "r1.parquet", tmp_path / "r2.csv", tmp_path / "bad.csv"
    write_table(small_run(), r1)
    write_table(small_run(m_y=lambda d: d["m_y"] + 1e-9), r2)
    write_table(small_run(m_y=_nan), bad)
    out = tmp_path / "out"
    args = ("--tau", 60, "--mask", 20, "--out", out, "-q")
    assert invoke("demod", r1, r2, *args)[0] == 0
    assert sorted(p.name for p in out.iterdir()) == [
        ".accal.lock", "accal.log", "manifest.json", "periods.parquet", "r1.summary.json", "r1.summary.md", "r2.summary.json", "r2.summary.md",
    ]  # fmt: skip
    df = pd.read_parquet(out / "periods.parquet")
    assert df.groupby("source").size().to_dict() == {"r1.parquet": 20, "r2.csv": 20}
    assert df[["source", "period"]].equals(
        df[["source", "period"]].sort_values(["source", "period"])
    )
    # a constant added to m_y is a bias: rejected, same a_Y
    np.testing.assert_allclose(
        df[df.source == "r2.csv"].a_Y.to_numpy(), df[df.source == "r1.parquet"].a_Y.to_numpy(),
        rtol=0, atol=1e-15,
    )  # fmt: skip
    # re-run r2 alone with GLS and the affine signal model: its rows are replaced
    assert invoke("demod", r2, *args, "--method", "gls", "--signal-model", "affine")[0] == 0
    df2 = pd.read_parquet(out / "periods.parquet")
    assert df2.groupby("source").size().to_dict() == {"r1.parquet": 20, "r2.csv": 20}
    assert df2.slope_Y.isna().sum() == 20 and df2[df2.source == "r2.csv"].slope_Y.notna().all()
    pd.testing.assert_frame_equal(
        df2[df2.source == "r1.parquet"].dropna(axis=1), df[df.source == "r1.parquet"]
    )
    _, meta = read_table_metadata(out / "periods.parquet")
    assert meta["sources"]["r1.parquet"]["method"] == "ls"
    assert meta["sources"]["r2.csv"]["method"] == "gls"
    assert meta["sources"]["r2.csv"]["solver"] == "gls-eq17"
    before = (out / "periods.parquet").read_bytes()
    code, _, err = invoke("demod", bad, *args)
    assert code == 1 and "m_y has 1 NaN" in err
    assert (out / "periods.parquet").read_bytes() == before
    assert not list(out.glob(".*.tmp"))  # no temporary files left


def test_one_run_per_call_keeps_every_summary(tmp_path):
    """QA: one run per call into the same --out (a cron job) overwrote summary.json, so
    the first run's summary was gone while its rows stayed in the periods table.  A run
    alone into a directory with another run's summary is named after its stem."""
    r1, r2 = tmp_path / "r1.parquet", tmp_path / "r2.parquet"
    write_table(small_run(), r1)
    write_table(small_run(m_y=lambda d: d["m_y"] + 1e-9), r2)
    out = tmp_path / "out"
    args = ("--tau", 60, "--mask", 20, "--out", out, "-q")

    def summaries() -> dict[str, str]:
        return {
            p.name: json.loads(p.read_text())["source"].rsplit("/", 1)[-1]
            for p in sorted(out.glob("*summary.json"))
        }

    assert invoke("demod", r1, *args)[0] == 0
    assert summaries() == {"summary.json": "r1.parquet"}  # alone in its directory
    assert invoke("demod", r2, *args)[0] == 0
    assert summaries() == {"summary.json": "r1.parquet", "r2.summary.json": "r2.parquet"}
    assert invoke("demod", r1, *args)[0] == 0  # r1 again: one summary each, none stale
    assert summaries() == {"r1.summary.json": "r1.parquet", "r2.summary.json": "r2.parquet"}
    assert sorted(p.name for p in out.glob("*summary.md")) == ["r1.summary.md", "r2.summary.md"]
    df = pd.read_parquet(out / "periods.parquet")
    assert df.groupby("source").size().to_dict() == {"r1.parquet": 20, "r2.parquet": 20}


def test_sinusoid_constant_term(day, tmp_path):
    """Eq. 24 without a constant: the 4.6e-7 m/s² mean leaks into α, β over a day that is
    not a whole number of sinusoid periods; --sinusoid-constant absorbs it (as c)."""
    args = ("--tau", 600, "--mask", 200, "--sinusoid-period", 200000, "-q")
    assert invoke("demod", day, *args, "--out", tmp_path / "a")[0] == 0
    assert invoke("demod", day, *args, "--sinusoid-constant", "--out", tmp_path / "b")[0] == 0
    sa, sb = _outputs(tmp_path / "a")[1]["sinusoid"], _outputs(tmp_path / "b")[1]["sinusoid"]
    assert not sa["constant"] and sa["Y"]["offset"] is None
    assert abs(sa["Y"]["alpha"]) > 1e-8  # the leak: thousands of sigma
    y = sb["Y"]
    assert sb["constant"] and len(y["cov"]) == 3
    assert abs(y["alpha"]) < 4 * y["sigma_alpha"] and abs(y["beta"]) < 4 * y["sigma_beta"]
    assert y["offset"] == pytest.approx(4.6e-7, abs=4 * y["sigma_offset"])
    assert "c = " in (tmp_path / "b" / "summary.md").read_text()


def test_demod_output_directory_is_locked_and_logged(tmp_path):
    """A second demod (or grace-bias) on a directory in use refuses; the log records runs."""
    from accal.batch import OutputLock
    from accal.pipeline_demod import write_simulated_gap

    run = tmp_path / "run.parquet"
    write_simulated_gap(run, days=0.02, tau=60.0, mask=20.0, seed=1)
    out = tmp_path / "out"
    with OutputLock(out, "test"):
        code, _, err = invoke("demod", run, "--tau", 60, "--mask", 20, "--out", out, "-q")
    assert code == 1
    assert "output directory is in use by another accal run" in err
    assert len(err.strip().splitlines()) == 1
    assert invoke("demod", run, "--tau", 60, "--mask", 20, "--out", out, "-q")[0] == 0
    log = (out / "accal.log").read_text()
    assert "start accal demod: 1 runs" in log and f"ok {run}" in log


# ---------------------------------------------------------------- --close-loop


@pytest.fixture(scope="module")
def undeclared_run(tmp_path_factory):
    """Half a day with a temperature-driven bias the declared model does not have, and a
    bias step of 5e-10 m/s^2 on m_y in the middle of a period."""
    from accal.pipeline_demod import write_simulated_gap

    tmp = tmp_path_factory.mktemp("undeclared_run")
    run = tmp / "run.parquet"
    _, truth = write_simulated_gap(
        run, days=0.5, tau=600.0, mask=200.0, seed=4, temperature_coupling=1e-9
    )
    df = pd.read_parquet(run)
    step_at = df["time"].iloc[0] + 30 * 600.0 + 250.0  # inside period 30
    df.loc[df["time"] >= step_at, "m_y"] += 5e-10
    df.to_parquet(run)
    return run, pd.read_parquet(truth), step_at


def test_demod_close_loop_finds_undeclared_effects_and_refits(undeclared_run, tmp_path):
    run, truth, step_at = undeclared_run
    out = tmp_path / "out"
    code, _, err = invoke(
        "demod", run, "--tau", 600, "--mask", 200, "--close-loop", "--plots", "--out", out
    )  # fmt: skip
    assert code == 0, err
    assert "closure:" in err
    closure = json.loads((out / "closure.json").read_text())["sources"]["run.parquet"]
    found = {e["name"]: e for e in closure["effects"]}
    assert "bias_step" in found, closure["effects"]
    assert abs(found["bias_step"]["epoch"] - step_at) <= 60.0
    assert abs(found["bias_step"]["coefficient"] - 5e-10) < 3 * found["bias_step"]["sigma"]
    assert "auxiliary" in found and found["auxiliary"]["channel"] == "temperature"
    # periods: the extended model's values, the declared ones kept as *_before
    df = pd.read_parquet(out / "periods.parquet").merge(truth, on="period", suffixes=("", "_true"))
    assert {"a_Y_before", "change_Y", "sigma_change_Y", "model"} <= set(df.columns)
    assert df["model"].iloc[0].startswith("declared+")
    err_before = np.abs(df["a_Y_before"] - df["a_Y_true"])
    err_after = np.abs(df["a_Y"] - df["a_Y_true"])
    # the period with the step was biased by it; the extended model removes that
    hit = df["period"] == 30
    assert float(err_after[hit].iloc[0]) < 0.5 * float(err_before[hit].iloc[0])
    # and overall the error does not grow, scatter/sigma stays sane
    assert np.sqrt(np.mean(err_after**2)) <= 1.05 * np.sqrt(np.mean(err_before**2))
    z = (df["a_Y"] - df["a_Y_true"]) / df["sigma_Y"]
    assert 0.7 < float(np.std(z)) < 1.4
    for name in ("run.closure.png", "run.closure-psd.png", "run.closure-effects.png"):
        assert (out / name).stat().st_size > 5000
    md = (out / "closure.md").read_text()
    assert "bias_step" in md and "declared+" in md


def test_demod_close_loop_on_clean_run_adds_nothing(tmp_path):
    from accal.pipeline_demod import write_simulated_gap

    run = tmp_path / "clean.parquet"
    write_simulated_gap(run, days=0.25, tau=600.0, mask=200.0, seed=9)
    out = tmp_path / "out"
    code, _, err = invoke(
        "demod", run, "--tau", 600, "--mask", 200, "--close-loop", "--out", out, "-q"
    )
    assert code == 0, err
    closure = json.loads((out / "closure.json").read_text())["sources"]["clean.parquet"]
    assert closure["effects"] == []
    df = pd.read_parquet(out / "periods.parquet")
    assert (df["model"] == "declared").all()
    np.testing.assert_allclose(df["a_Y"], df["a_Y_before"], rtol=0, atol=3 * df["sigma_Y"].max())


def test_diagnose_demod_directory(undeclared_run, tmp_path):
    run, _, step_at = undeclared_run
    out = tmp_path / "out"
    assert invoke("demod", run, "--tau", 600, "--mask", 200, "--out", out, "-q")[0] == 0
    before = (out / "periods.parquet").read_bytes()
    code, text, err = invoke("diagnose", out)
    assert code == 0, err
    assert "bias_step" in text and "auxiliary" in text
    assert (out / "periods.parquet").read_bytes() == before  # diagnose reports only
    closure = json.loads((out / "diagnose" / "closure.json").read_text())["sources"]["run.parquet"]
    assert any(
        abs(e["epoch"] - step_at) <= 60 for e in closure["effects"] if e["name"] == "bias_step"
    )


def test_demod_close_loop_sigmas_stay_honest(tmp_path):
    """QA case: with a found coupling the per-period sigmas came out 27 % low (std z 1.46).

    The closure estimated the noise PSD of a residual left by the per-period base; the
    sigmas now use the demodulation's own noise model (--psd), before and after.
    """
    from accal.pipeline_demod import write_simulated_gap

    run = tmp_path / "temp.parquet"
    _, truth = write_simulated_gap(
        run, days=1.0, tau=600.0, mask=200.0, seed=1, temperature_coupling=2e-8
    )
    out = tmp_path / "out"
    code, _, err = invoke(
        "demod", run, "--tau", 600, "--mask", 200, "--close-loop", "--out", out, "-q"
    )
    assert code == 0, err
    closure = json.loads((out / "closure.json").read_text())["sources"]["temp.parquet"]
    assert "auxiliary" in {e["name"] for e in closure["effects"]}
    df = pd.read_parquet(out / "periods.parquet").merge(
        pd.read_parquet(truth), on="period", suffixes=("", "_true")
    )
    for ax in "YZ":
        z = (df[f"a_{ax}"] - df[f"a_{ax}_true"]) / df[f"sigma_{ax}"]
        assert 0.85 < float(np.std(z)) < 1.2, (ax, float(np.std(z)))
        # --psd auto (issue 20): "before" is the declared model, whose residual holds the
        # undeclared coupling, so its PSD from the data (and sigma) is far larger; "after"
        # uses the PSD of the run without the effects found
        assert float((df[f"sigma_{ax}"] / df[f"sigma_{ax}_before"]).median()) < 0.2
    # under one fixed PSD the closure only adds estimation variance: sigma after >= before
    code, _, err = invoke(
        "demod", run, "--tau", 600, "--mask", 200, "--close-loop", "--out", out / "m", "-q",
        "--psd", "microstar",
    )  # fmt: skip
    assert code == 0, err
    df = pd.read_parquet(out / "m" / "periods.parquet")
    for ax in "YZ":
        assert float((df[f"sigma_{ax}"] / df[f"sigma_{ax}_before"]).median()) >= 0.98


def test_demod_close_loop_gls_summary_and_rerun_without_it(undeclared_run, tmp_path):
    """QA: with ``--method gls --close-loop`` the periods held the closure's LS values
    (a_Y bit-identical to LS) while a_Y_before was GLS; the summary's mean and
    scatter/σ were the declared model's (23σ off, 31.7); "median |change|/σ" was
    2e4 from periods that had not changed (a rounding-level change over a
    rounding-level σ); and a re-run without --close-loop left the old closure."""
    run, truth, _ = undeclared_run
    out = tmp_path / "out"
    rows = {}
    for method in ("ls", "gls"):
        code, _, err = invoke(
            "demod", run, "--tau", 600, "--mask", 200, "--method", method, "--close-loop",
            "--out", out / method, "-q",
        )  # fmt: skip
        assert code == 0, err
        rows[method] = pd.read_parquet(out / method / "periods.parquet").merge(
            truth, on="period", suffixes=("", "_true")
        )
    ls, gls = rows["ls"], rows["gls"]
    assert not np.allclose(gls["a_Y"], ls["a_Y"], rtol=0, atol=1e-16)
    plain = tmp_path / "plain"
    assert invoke("demod", run, "--tau", 600, "--mask", 200, "--method", "gls",
                  "--out", plain, "-q")[0] == 0  # fmt: skip
    declared = pd.read_parquet(plain / "periods.parquet")
    np.testing.assert_array_equal(gls["a_Y_before"], declared["a_Y"])
    for ax in "YZ":
        z = (gls[f"a_{ax}"] - gls[f"a_{ax}_true"]) / gls[f"sigma_{ax}"]
        assert 0.8 < float(np.std(z)) < 1.25, (ax, float(np.std(z)))
    summary = json.loads((out / "gls" / "summary.json").read_text())
    assert summary["mean"]["model"].startswith("declared+")
    assert summary["mean"]["a_Y"] == pytest.approx(float(gls["a_Y"].mean()), rel=1e-12)
    assert summary["declared"]["mean"]["a_Y"] == pytest.approx(
        float(gls["a_Y_before"].mean()), rel=1e-12
    )
    assert "(declared model)" in (out / "gls" / "summary.md").read_text()
    closure = json.loads((out / "gls" / "closure.json").read_text())["sources"]["run.parquet"]
    assert closure["method"] == "gls"
    per = closure["periods"]
    # measured 10.4: the coupling changed every period; no longer ~2e4 from rounding
    assert per["median_abs_change_Y_sigmas"] < 100 and 0 < per["n_changed_Y"] <= per["n"]
    # the same source again without --close-loop: its closure report and plots go
    code, _, err = invoke("demod", run, "--tau", 600, "--mask", 200, "--out", out / "ls", "-q")
    assert code == 0, err
    assert not (out / "ls" / "closure.json").exists() and not (out / "ls" / "closure.md").exists()
    assert not list((out / "ls").glob("run.closure*.png"))
    assert "model" not in pd.read_parquet(out / "ls" / "periods.parquet").columns


def test_demod_gls_close_loop_with_nothing_found_keeps_the_gls_values(tmp_path):
    """QA: with ``--method gls --close-loop`` and no effect found, the closure's LS
    values were written as ``a_Y`` (0.6σ from the GLS ``a_Y_before``), with a change
    whose σ was 0."""
    from accal.pipeline_demod import write_simulated_gap

    run = tmp_path / "clean.parquet"
    write_simulated_gap(run, days=0.25, tau=600.0, mask=200.0, seed=3)
    out = tmp_path / "o"
    args = ("demod", run, "--tau", 600, "--mask", 200, "--method", "gls", "--out")
    code, _, err = invoke(*args, out, "--close-loop", "-q")
    assert code == 0, err
    closure = json.loads((out / "closure.json").read_text())["sources"]["clean.parquet"]
    assert closure["effects"] == [] and closure["method"] == "gls"
    per = pd.read_parquet(out / "periods.parquet")
    assert invoke(*args, tmp_path / "plain", "-q")[0] == 0
    plain = pd.read_parquet(tmp_path / "plain" / "periods.parquet")
    for ax in "YZ":
        np.testing.assert_array_equal(per[f"a_{ax}"], plain[f"a_{ax}"])
        np.testing.assert_array_equal(per[f"a_{ax}"], per[f"a_{ax}_before"])
        np.testing.assert_array_equal(per[f"sigma_{ax}"], plain[f"sigma_{ax}"])
        assert (per[f"change_{ax}"] == 0).all()


def test_demod_change_sigma_of_periods_in_a_lagged_couplings_start(tmp_path):
    """QA: with a 500 s lagged coupling the closure analyses period 0 without its first
    500 s, but its change was written against the declared value of all its samples
    with the closure's σ of another difference: change_Z -2.6e-11 ± 1.3e-12 (20σ) on
    an axis where nothing was injected."""
    from accal.pipeline_demod import write_simulated_gap

    run = tmp_path / "lag.parquet"
    write_simulated_gap(run, days=0.25, tau=600.0, mask=200.0, seed=5)
    df = pd.read_parquet(run)
    t, temp = df["time"].to_numpy(), df["temperature"].to_numpy()
    df["m_y"] += 2e-8 * (np.interp(t - 500.0, t, temp) - temp.mean())
    df.to_parquet(run)
    out = tmp_path / "o"
    code, _, err = invoke("demod", run, "--tau", 600, "--mask", 200, "--close-loop", "--out", out)
    assert code == 0, err
    closure = json.loads((out / "closure.json").read_text())["sources"]["lag.parquet"]
    lags = [e["lag"] for e in closure["effects"] if e["name"] == "auxiliary"]
    assert len(lags) == 1 and abs(lags[0] - 500.0) < 5.0
    per = pd.read_parquet(out / "periods.parquet")
    ratio = (per["change_Z"] / per["sigma_change_Z"]).abs()
    # measured: max 1.25 over the periods, period 0 0.94 (19 before)
    assert float(ratio.max()) < 4.5, per.loc[ratio.idxmax(), ["period", "change_Z"]].tolist()
    np.testing.assert_allclose(per["change_Z"], per["a_Z"] - per["a_Z_before"], rtol=0, atol=0)


def test_tail_shorter_than_a_period_is_a_warning(tmp_path):
    """QA: a 900 s run with --tau 600 said "1/1 periods" and left its last 300 s out
    without a word."""
    from accal.pipeline_demod import write_simulated_gap

    full = tmp_path / "full.parquet"
    write_simulated_gap(full, days=0.25, tau=600.0, mask=200.0, seed=2)
    run = tmp_path / "run.parquet"
    pd.read_parquet(full).iloc[:900].to_parquet(run)
    code, _, err = invoke("demod", run, "--tau", 600, "--mask", 200, "--out", tmp_path / "o")
    assert code == 0, err
    assert "warning: the last 300 s (300 samples) are less than one period" in err
    code, _, err = invoke("demod", full, "--tau", 600, "--mask", 200, "--out", tmp_path / "p")
    assert code == 0 and "less than one period" not in err
    # -q is errors only, as in grace-bias (the fuzzer found demod printing warnings
    # under -q); the warning is in the run's log
    code, _, err = invoke("demod", run, "--tau", 600, "--mask", 200, "--out", tmp_path / "q", "-q")
    assert code == 0 and err == "", err
    assert "less than one period" in (tmp_path / "q" / "accal.log").read_text()


def test_lagged_coupling_to_a_declared_channel_is_searched(tmp_path):
    """QA: with the channel declared in --bias-model (per-period coefficient, lag 0) a
    lagged coupling to it was not searched: "no effect", a_Y max |z| 76.  The declared
    channels are offered to the coupling search too (at lag 0 they are in the base)."""
    from accal.pipeline_demod import write_simulated_gap

    run = tmp_path / "run.parquet"
    _, truth = write_simulated_gap(run, days=0.5, tau=600.0, mask=200.0, seed=6)
    df = pd.read_parquet(run)
    t = df["time"].to_numpy()
    walk = np.cumsum(np.random.default_rng(6).standard_normal(t.size))
    slow = 0.3 * np.sin(2 * np.pi * t / 5400.0) + 0.002 * walk
    df["temp2"] = slow
    df["m_y"] += 2e-8 * np.interp(t - 120.0, t, slow)
    df.to_parquet(run)
    out = tmp_path / "out"
    code, _, err = invoke(
        "demod", run, "--tau", 600, "--mask", 200, "--bias-model", "affine+temp2",
        "--close-loop", "--out", out, "-q",
    )  # fmt: skip
    assert code == 0, err
    closure = json.loads((out / "closure.json").read_text())["sources"]["run.parquet"]
    found = [e for e in closure["effects"] if e["name"] == "auxiliary"]
    assert len(found) == 1 and found[0]["channel"] == "temp2"
    assert abs(found[0]["lag"] - 120.0) < 5.0
    rows = pd.read_parquet(out / "periods.parquet").merge(
        pd.read_parquet(truth), on="period", suffixes=("", "_true")
    )
    z = (rows["a_Y"] - rows["a_Y_true"]) / rows["sigma_Y"]
    assert float(np.std(z)) < 1.5


def test_dropped_periods_are_named(tmp_path):
    """A hole of two and a half periods drops them, and the warning says which (QA: the
    count alone, the list only in summary.json)."""
    data = small_run()
    data = data.drop(index=range(300, 450)).reset_index(drop=True)  # 300 .. 449 s
    bad = tmp_path / "hole.csv"
    write_table(data, bad)
    code, _, err = invoke(
        "demod", bad, "--tau", 60, "--mask", 20, "--out", tmp_path / "o", "--resample"
    )
    assert code == 0, err
    s = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert s["dropped"] >= 2
    first, last = s["dropped_periods"][0], s["dropped_periods"][-1]
    assert f"periods dropped ({first}–{last})" in err, err
