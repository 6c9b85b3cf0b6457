"""The Python API as a notebook user runs it (issue 21), against the CLI on the same input.

Every number the API returns is compared with what ``accal grace-bias`` /
``accal demod`` write for the same input, to the last bit (the API wraps the
functions the CLI runs: :func:`accal.pipeline.fit_input`, :mod:`accal.pipeline_demod`).
"""

from __future__ import annotations

import doctest
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

import accal
from accal.cli import main

REPO = Path(__file__).resolve().parents[1]
SAMPLES = REPO / "data" / "samples"
L1B = [
    "ACC1B_2003-09-14_A_00.asc",
    "ACC1B_2003-09-14_B_00.asc",
    "ACT1B_2023-06-01_C_04.txt",
    "ACT1B_2023-06-01_D_04.txt",
]
SWARM = "SW_A_ACCACAL_20240511_a_cal_x.csv.gz"
#: Numeric columns of ``bias_drift`` compared bit for bit.
NUMBERS = ["bias", "drift", "bias_sigma", "drift_sigma", "bias_drift_corr", "t0", "rms"]
NUMBERS += ["scale", "bias_correction", "signal_mean", "n", "n_total", "n_flagged"]
#: Identifying / descriptive columns compared as text.
LABELS = ["source", "satellite", "date", "axis", "frame", "method", "model", "day_status"]


def cli(*args: object) -> None:
    """Run ``accal ARGS`` in this process (exit status 0 required)."""
    res = CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)
    assert res.exit_code == 0, res.output


def max_difference(api: pd.DataFrame, out: Path) -> float:
    """Largest |API − CLI| over the numeric bias_drift columns; the labels must agree."""
    table = pd.read_parquet(out / "bias_drift.parquet")
    key = ["source", "axis", "method"]
    merged = api.merge(table, on=key, suffixes=("_api", "_cli"), validate="one_to_one")
    assert len(merged) == len(api) == len(table[table["source"].isin(api["source"])])
    worst = 0.0
    for c in NUMBERS:
        a = merged[f"{c}_api"].to_numpy(dtype=float)
        b = merged[f"{c}_cli"].to_numpy(dtype=float)
        assert np.array_equal(np.isnan(a), np.isnan(b)), c
        ok = ~np.isnan(a)
        worst = max(worst, float(np.max(np.abs(a[ok] - b[ok]), initial=0.0)))
    for c in set(LABELS) - set(key):
        assert merged[f"{c}_api"].astype(str).tolist() == merged[f"{c}_cli"].astype(str).tolist()
    return worst


@pytest.fixture(scope="module")
def grace_cli(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``accal grace-bias`` on the four real L1B samples and the Swarm day, both methods."""
    out = tmp_path_factory.mktemp("grace-cli")
    inputs = [SAMPLES / n for n in (*L1B, SWARM)]
    cli("grace-bias", *inputs, "--column", "x=a_cal_x", "--method", "both", "-j", "1", "-q",
        "--out", out)  # fmt: skip
    return out


@pytest.fixture(scope="module")
def swarm_closure(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, accal.Closure]:
    """The real Swarm day closed by the CLI and by the API (no reference: orbit model)."""
    out = tmp_path_factory.mktemp("swarm-closure")
    cli("grace-bias", SAMPLES / SWARM, "--column", "x=a_cal_x", "--close-loop", "-q",
        "--out", out)  # fmt: skip
    day = accal.read(SAMPLES / SWARM, columns={"x": "a_cal_x"})
    return out, accal.close_loop(accal.fit_bias(day))


def test_fit_bias_equals_the_cli_on_the_five_real_samples(grace_cli: Path) -> None:
    worst = 0.0
    for name in (*L1B, SWARM):
        columns = {"x": "a_cal_x"} if name == SWARM else None
        fit = accal.fit_bias(accal.read(SAMPLES / name, columns=columns), method="both")
        assert fit.source == name and fit.methods == ("wavelet", "lsq")
        worst = max(worst, max_difference(fit.table(), grace_cli))
        # the per-axis accessors are the table's values
        t = fit.table().set_index(["method", "axis"])
        for ax, v in fit.bias("lsq").items():
            assert v == t.loc[("lsq", ax), "bias"]
        assert fit.drift_sigma() == t.loc["wavelet", "drift_sigma"].to_dict()
        # the calibrated series is the CLI's calibrated file
        stem = name.split(".")[0]
        cal = pd.read_parquet(grace_cli / f"{stem}.calibrated.parquet")
        df = fit.to_dataframe()
        # the file has time_utc beside gps_time: the frame's UTC index
        assert ["gps_time", "time_utc", *df.columns[1:]] == cal.columns.tolist()
        assert cal["time_utc"].tolist() == df.index.tolist()
        for c in df.columns:
            assert np.array_equal(df[c].to_numpy(), cal[c].to_numpy()), (name, c)
    assert worst == 0.0  # bit for bit


def test_a_notebook_gets_utc_indexed_frames_and_xarray_with_units() -> None:
    day = accal.read(SAMPLES / SWARM, columns={"x": "a_cal_x"})
    fit = accal.fit_bias(day, method="lsq")
    df = fit.to_dataframe()
    # the UTC index is the file's own UTC time column (GPS seconds converted back)
    raw = pd.read_csv(SAMPLES / SWARM, usecols=["time_utc"])
    utc = pd.to_datetime(raw["time_utc"], utc=True)
    assert isinstance(df.index, pd.DatetimeIndex) and str(df.index.tz) == "UTC"
    assert (df.index == pd.DatetimeIndex(utc)).all()
    assert np.array_equal(df["gps_time"].to_numpy(), day.time)
    assert df.attrs["units"]["lin_accl_x"].startswith("m/s^2")
    assert df.attrs["units"]["gps_time"].startswith("s (GPS seconds")
    assert df.attrs["source"] == SWARM and df.attrs["method"] == "lsq"
    table = fit.table()
    assert table.attrs["units"]["drift"] == "m/s^3"
    ds = fit.to_xarray()
    assert ds["lin_accl_x"].attrs["units"] == "m s-2" and ds["lin_accl_x"].attrs["long_name"]
    assert ds["gps_time"].attrs["units"] == "s"
    assert ds["bias"].attrs["units"] == "m s-2" and ds["drift_sigma"].attrs["units"] == "m s-3"
    assert float(ds["bias"].sel(estimator="lsq", axis="x")) == fit.bias()["x"]
    assert ds.attrs["source"] == SWARM and ds.attrs["accal_version"] == accal.__version__
    assert "read(" in ds.attrs["history"] and ds.attrs["Conventions"].startswith("CF")
    assert np.array_equal(ds["time"].to_numpy(), df.index.tz_localize(None).to_numpy())


def test_close_loop_finds_the_cli_orbit_period_and_numbers(swarm_closure) -> None:
    out, closure = swarm_closure
    assert max_difference(closure.fit.table(), out) == 0.0
    entry = json.loads((out / "closure.json").read_text())["sources"][SWARM]["x"]
    # the orbit period estimated from the data (nominal 5600 s), as the CLI found it
    assert closure.orbit_period == entry["signal_model"]["period"]
    assert 5500 < closure.orbit_period < 5700
    assert closure.model == {"x": entry["model"]}
    df = closure.to_dataframe()
    assert len(df) == len(entry["effects"]) + len(entry["unexplained"])
    assert df["coefficient"].tolist() == [e["coefficient"] for e in entry["unexplained"]]
    assert "orbit-phase template" in closure.markdown


def test_close_loop_with_a_reference_finds_the_cli_step(tmp_path: Path) -> None:
    day_path = tmp_path / "ACC1B_2005-01-01_A_02.asc"
    ref = tmp_path / "ref.parquet"
    cli("simulate", "grace", "--duration", "10800", "--out", day_path, "--reference-out", ref,
        "--effect", "step:axis=x,epoch=5000,size=5e-9")  # fmt: skip
    out = tmp_path / "out"
    cli("grace-bias", day_path, "--reference", ref, "--close-loop", "-q", "--out", out)
    day = accal.read(day_path)
    closure = accal.close_loop(day, reference=ref)
    assert max_difference(closure.fit.table(), out) == 0.0
    assert closure.model["x"].startswith("poly1+bias_step@")
    assert closure.orbit_period is None  # with a reference, no orbit-signal model
    df = closure.to_dataframe()
    step = df[(df["axis"] == "x") & (df["kind"] == "effect")].iloc[0]
    assert step["name"] == "bias_step" and bool(step["instrument"])
    entry = json.loads((out / "closure.json").read_text())["sources"][day_path.name]["x"]
    assert [step["epoch"], step["coefficient"], step["sigma"]] == [
        entry["effects"][0][k] for k in ("epoch", "coefficient", "sigma")
    ]
    assert abs(step["epoch"] - (day.time[0] + 5000)) < 600  # the injected step
    assert step["epoch_utc"].tzname() == "UTC"
    assert abs(abs(step["coefficient"]) - 5e-9) < 5 * step["sigma"]
    # the epoch's σ (accal.closure.epochprofile), as closure.json's details have it
    assert step["epoch_sigma"] == entry["effects"][0]["details"]["epoch_sigma"] >= 1.0
    assert df.attrs["units"]["epoch_sigma"] == "s" and "lag_sigma" in df.columns


def test_demodulate_equals_the_cli(tmp_path: Path) -> None:
    from accal.pipeline_demod import write_simulated_gap

    run, _ = write_simulated_gap(
        tmp_path / "run.parquet", days=0.2, tau=600, mask=200, temperature_coupling=2e-8
    )
    out = tmp_path / "res"
    cli("demod", run, "--tau", 600, "--mask", 200, "--close-loop", "-q", "--out", out)
    table = pd.read_parquet(out / "periods.parquet").set_index("period")
    plain = accal.demodulate(run, tau=600, mask=200)
    closed = accal.close_loop(plain).fit  # = accal.demodulate(..., close_loop=True)
    df = closed.to_dataframe()
    assert df.index.tolist() == table.index.tolist()
    worst = 0.0
    for c in df.columns:
        if df[c].dtype.kind == "f":
            a, b = df[c].to_numpy(), table[c].to_numpy(dtype=float)
            assert np.array_equal(np.isnan(a), np.isnan(b)), c
            worst = max(worst, float(np.nanmax(np.abs(a - b), initial=0.0)))
    assert worst == 0.0
    # the declared model's values are those of a demodulation without closure
    assert np.array_equal(plain.a_Y, table["a_Y_before"].to_numpy())
    assert np.array_equal(plain.to_dataframe()["sigma_Z"], table["sigma_Z_before"])
    assert closed.closure is not None and closed.closure.fit is closed
    summary = json.loads((out / "summary.json").read_text())  # the extended model's mean
    assert [closed.summary["mean"][k] for k in ("a_Y", "a_Z", "model")] == [
        summary["mean"][k] for k in ("a_Y", "a_Z", "model")
    ]
    assert closed.summary["declared"]["mean"]["a_Y"] == plain.summary["mean"]["a_Y"]
    assert closed.closure.model == {"run.parquet": table["model"].iloc[0]}
    effects = closed.closure.to_dataframe()
    assert "auxiliary" in set(effects["name"])  # the temperature coupling
    assert effects["epoch_utc"].isna().all()  # run times are not GPS seconds
    assert df.attrs["units"]["a_Y"].startswith("m/s^2") and df.attrs["tau"] == 600
    ds = plain.to_xarray()
    assert ds["a_Y"].attrs["units"] == "m s-2" and ds["sigma_Y"].attrs["units"] == "m s-2"
    assert ds["t_mid"].attrs["units"] == "s" and ds.attrs["method"] == "ls"
    assert np.array_equal(ds["a_Z"].to_numpy(), plain.a_Z)


def test_import_accal_stays_lazy() -> None:
    code = (
        "import sys, accal; assert 'accal.api' not in sys.modules and 'numpy' not in sys.modules;"
        " f = accal.fit_bias; assert 'accal.api' in sys.modules and f is accal.api.fit_bias"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=60)
    with pytest.raises(AttributeError, match="no attribute 'fit_biass'"):
        accal.fit_biass  # noqa: B018


def test_api_docstring_examples_run(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    import importlib
    import tempfile

    monkeypatch.chdir(REPO)  # the examples read data/samples/ relative to the repository
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))  # their simulated runs go here
    attempted = 0
    for name in ("", ".common", ".bias", ".closure_result", ".demod", ".loop"):
        module = importlib.import_module(f"accal.api{name}")
        result = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE)
        assert result.failed == 0, name
        attempted += result.attempted
    assert attempted >= 20
