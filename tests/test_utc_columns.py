"""UTC columns beside the GPS seconds in every series and table accal writes (issue 21).

``gps_time`` → ``time_utc`` (calibrated series), ``t0`` → ``t0_utc`` (``bias_drift``),
``t_start``/``t_mid`` → ``t_start_utc``/``t_mid_utc`` (demod's ``periods``): ISO 8601
text in CSV, ``timestamp[ns, tz=UTC]`` in Parquet, equal to
:func:`accal.timescale.gps_to_utc` of the GPS column (to the microsecond).  An older
table without them gets them at the next merge; ``accal table --export FILE.nc``
writes CF netCDF; a calibrated file read back as an input keeps ``gps_time`` as its
time, exactly.
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner
from tests.indep import platform_run

from accal.cli import main
from accal.io import read
from accal.products.utc import utc_arrow
from accal.timescale import gps_to_utc, utc_to_gps

SAMPLES = Path(__file__).resolve().parents[1] / "data" / "samples"
DAY_A, DAY_B = "ACC1B_2003-09-14_A_00.asc", "ACC1B_2003-09-14_B_00.asc"
#: GPS-seconds column → its UTC column, in the files that have them.
UTC_COLUMNS = {
    "ACC1B_2003-09-14_A_00.calibrated": {"gps_time": "time_utc"},
    "bias_drift": {"t0": "t0_utc"},
    "periods": {"t_start": "t_start_utc", "t_mid": "t_mid_utc"},
}
ISO = re.compile(r"^\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{6}Z$")
#: 2003-09-14 00:00:00 GPS [s]: the demod run is moved there (its own times start at 0).
T0 = 116769600.0


def _invoke(*args: object) -> str:
    res = CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    return res.output


def _same(got: pd.Series, gps: pd.Series) -> bool:
    """Whether the UTC instants ``got`` (any resolution) are :func:`_expected` of ``gps``."""
    return got.dt.as_unit("ns").rename(None).equals(_expected(gps))


def _expected(gps: pd.Series) -> pd.Series:
    """gps_to_utc of the GPS seconds, rounded to the microsecond, time-zone aware."""
    ns = gps_to_utc(gps.to_numpy(dtype=float)).astype(np.int64)
    us = ((ns + 500) // 1000 * 1000).astype("datetime64[ns]")
    return pd.Series(pd.DatetimeIndex(us).tz_localize("UTC"), index=gps.index)


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Path, Path]]:
    """A grace-bias and a demod output directory per format."""
    root = tmp_path_factory.mktemp("utc")
    table = platform_run(1, days=0.05).table.copy()
    table["time"] += T0
    run = root / "run.parquet"
    table.to_parquet(run)
    out = {}
    for fmt in ("csv", "parquet"):
        g, d = root / f"g_{fmt}", root / f"d_{fmt}"
        _invoke("grace-bias", SAMPLES / DAY_A, "--method", "both", "--format", fmt,
                "--out", g, "-q")  # fmt: skip
        _invoke("demod", run, "--tau", 600, "--mask", 200, "--format", fmt, "--out", d, "-q")
        out[fmt] = (g, d)
    return out


def test_every_csv_opens_with_pandas_defaults_with_its_utc_column(runs):
    seen = set()
    for directory in runs["csv"]:
        for csv in sorted(directory.glob("*.csv")):
            df = pd.read_csv(csv)  # no options
            pairs = UTC_COLUMNS[csv.name.removesuffix(".csv")]
            units = json.loads(csv.with_name(csv.name + "-metadata.json").read_text())
            for gps, utc in pairs.items():
                cols = df.columns.tolist()
                assert cols[cols.index(gps) + 1] == utc  # right after its GPS column
                assert df[utc].map(lambda s: bool(ISO.match(s))).all(), df[utc].head()
                got = pd.to_datetime(df[utc], utc=True)
                assert _same(got, df[gps]), (csv.name, utc)
                assert units["accal:units"][utc].startswith("UTC (ISO 8601 instant of " + gps)
                seen.add(utc)
    assert seen == {"time_utc", "t0_utc", "t_start_utc", "t_mid_utc"}
    # the run was moved to 2003-09-14 00:00 GPS: its first period starts 13 s before in UTC
    per = pd.read_csv(runs["csv"][1] / "periods.csv")
    assert per["t_start_utc"].iloc[0] == "2003-09-13T23:59:47.000000Z"


def test_parquet_utc_columns_are_timezone_aware_timestamps(runs):
    seen = set()
    for directory in runs["parquet"]:
        for path in sorted(directory.glob("*.parquet")):
            schema = pq.read_schema(path)
            df = pd.read_parquet(path)
            for gps, utc in UTC_COLUMNS[path.name.removesuffix(".parquet")].items():
                assert schema.field(utc).type == pa.timestamp("ns", tz="UTC")
                assert schema.field(utc).metadata[b"unit"].startswith(b"UTC (ISO 8601")
                assert str(df[utc].dtype) == "datetime64[ns, UTC]"
                assert _same(df[utc], df[gps]), (path.name, utc)
                seen.add(utc)
    assert seen == {"time_utc", "t0_utc", "t_start_utc", "t_mid_utc"}


def _drop_t0_utc(table_path: Path) -> None:
    """Make ``table_path`` a table of the previous version: no ``t0_utc`` column."""
    if table_path.suffix == ".parquet":
        pq.write_table(pq.read_table(table_path).drop_columns(["t0_utc"]), table_path)
        return
    old = pacsv.read_csv(table_path).drop_columns(["t0_utc"])
    pacsv.write_csv(old, table_path)
    side = table_path.with_name(table_path.name + "-metadata.json")
    doc = json.loads(side.read_text())
    doc["tableSchema"]["columns"] = [
        c for c in doc["tableSchema"]["columns"] if c["name"] != "t0_utc"
    ]
    del doc["accal:units"]["t0_utc"]
    side.write_text(json.dumps(doc))


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_a_table_without_t0_utc_merges_with_new_rows_and_gets_it(runs, tmp_path, fmt):
    out = tmp_path / "o"
    shutil.copytree(runs[fmt][0], out)
    table = out / f"bias_drift.{fmt}"
    _drop_t0_utc(table)
    before = pd.read_csv(table) if fmt == "csv" else pd.read_parquet(table)
    assert "t0_utc" not in before.columns and len(before) == 6
    # the old table is read as it is (accal table), with t0_utc from t0
    assert "2003-09-13 23:59:47" in _invoke("table", out, "--columns", "source,t0_utc")
    _invoke("grace-bias", SAMPLES / DAY_A, SAMPLES / DAY_B, "--method", "both",
            "--format", fmt, "--out", out, "-q")  # fmt: skip
    after = pd.read_csv(table) if fmt == "csv" else pd.read_parquet(table)
    assert len(after) == 12 and set(after["source"]) == {DAY_A, DAY_B}
    utc = pd.to_datetime(after["t0_utc"], utc=True)
    assert utc.notna().all() and _same(utc, after["t0"])
    # the old rows are the old rows, with t0_utc added
    old = after[after["source"] == DAY_A].drop(columns="t0_utc").reset_index(drop=True)
    pd.testing.assert_frame_equal(old, before.reset_index(drop=True))


def test_netcdf_export_has_cf_units_and_a_utc_time_coordinate(runs, tmp_path):
    xr = pytest.importorskip("xarray")
    g = runs["parquet"][0]
    nc = tmp_path / "bias.nc"
    _invoke("table", g, "--export", nc)
    table = pd.read_parquet(g / "bias_drift.parquet")
    with xr.open_dataset(nc) as ds:
        assert "t0_utc" in ds.coords and ds["t0_utc"].attrs["standard_name"] == "time"
        want = table["t0_utc"].dt.tz_convert(None).to_numpy(dtype="datetime64[ns]")
        assert np.array_equal(ds["t0_utc"].to_numpy(), want)
        assert ds["bias"].attrs["units"] == "m s-2" and ds["drift"].attrs["units"] == "m s-3"
        assert ds["t0"].attrs["units"] == "s" and ds["bias_sigma"].attrs["units"] == "m s-2"
        assert ds["bias"].attrs["long_name"].startswith("m/s^2 (trend value at t0")
        assert np.array_equal(ds["bias"].to_numpy(), table["bias"].to_numpy())
        assert np.array_equal(ds["t0"].to_numpy(), table["t0"].to_numpy())
        assert [str(s) for s in ds["source"].to_numpy()] == table["source"].tolist()
        assert ds.attrs["Conventions"] == "CF-1.8" and ds.attrs["accal_version"]
        assert ds.attrs["exported_from"] == str(g / "bias_drift.parquet")
    # the CSV and Parquet exports carry t0_utc as the table does
    _invoke("table", g, "--export", tmp_path / "x.csv", "--columns", "source,t0,t0_utc")
    got = pd.read_csv(tmp_path / "x.csv")
    assert got["t0_utc"].map(lambda s: bool(ISO.match(s))).all()
    assert _same(pd.to_datetime(got["t0_utc"], utc=True), got["t0"])
    _invoke("table", g, "--export", tmp_path / "x.parquet")
    assert pd.read_parquet(tmp_path / "x.parquet")["t0_utc"].equals(table["t0_utc"])
    res = CliRunner().invoke(main, ["table", str(g), "--export", str(tmp_path / "x.txt")])
    assert res.exit_code == 2 and "must end in .csv, .parquet or .nc" in res.output


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_a_calibrated_file_read_as_input_takes_gps_time_exactly(tmp_path, fmt):
    """Sub-microsecond GPS seconds: time_utc (rounded to the µs) would differ from them."""
    rng = np.random.default_rng(3)
    gps = 7.0e8 + np.arange(600.0) + 0.1234567
    src = tmp_path / "day.parquet"
    pd.DataFrame(
        {"gps_time": gps, "lin_accl_x": 1e-7 + 1e-10 * rng.normal(size=gps.size)}
    ).to_parquet(src)
    _invoke("grace-bias", src, "--format", fmt, "--out", tmp_path / "o", "-q")
    cal = tmp_path / "o" / f"day.calibrated.{fmt}"
    series = read(cal)
    assert series.time.view(np.int64).tolist() == gps.view(np.int64).tolist()
    assert series.meta["table"]["time_column"] == "gps_time" and "time_utc" not in series.aux
    # the same instants, not a column "ignored" with a warning on every re-read
    assert not [w for w in series.report.warnings if "time_utc" in w], series.report.warnings
    written = pd.read_csv(cal) if fmt == "csv" else pd.read_parquet(cal)
    utc = pd.to_datetime(written["time_utc"], utc=True)
    assert _same(utc, written["gps_time"])
    # the UTC column is rounded to the microsecond: taken as the time it would move it
    back = utc_to_gps(utc.dt.tz_convert(None).to_numpy(dtype="datetime64[ns]"))
    assert np.abs(back - gps).max() > 2e-7


def test_utc_columns_are_total_and_follow_the_leap_seconds():
    # 2016-12-31T23:59:60 UTC (the last leap second) is GPS 536500817; NaN and before
    # 1972 (no leap-second table) are empty/null, not an error
    gps = np.array([536500816.0, 536500818.0, np.nan, -1e10, 116769600.9999996])
    text = utc_arrow(gps, "csv").to_pylist()
    assert text == [
        "2016-12-31T23:59:59.000000Z",
        "2017-01-01T00:00:00.000000Z",
        "",
        "",
        "2003-09-13T23:59:48.000000Z",
    ]
    stamps = utc_arrow(gps, "parquet")
    assert stamps.type == pa.timestamp("ns", tz="UTC") and stamps.null_count == 2
    assert [str(s) for s in stamps.to_pylist()[:2]] == [
        "2016-12-31 23:59:59+00:00",
        "2017-01-01 00:00:00+00:00",
    ]


def test_accal_table_reads_a_demod_directory(runs, tmp_path):
    xr = pytest.importorskip("xarray")
    d = runs["csv"][1]
    text = _invoke("table", d)
    assert text.split()[:3] == ["source", "period", "t_mid_utc"]
    assert "2003-09-14 00:04:46.500+00:00" in text  # t_mid 299.5 s after 00:00 GPS
    _invoke("table", d, "--export", tmp_path / "p.nc")
    per = pd.read_csv(d / "periods.csv")
    with xr.open_dataset(tmp_path / "p.nc") as ds:
        assert {"t_start_utc", "t_mid_utc"} <= set(ds.coords)
        want = _expected(per["t_mid"]).dt.tz_convert(None).to_numpy(dtype="datetime64[ns]")
        assert np.array_equal(ds["t_mid_utc"].to_numpy(), want)
        assert ds["a_Y"].attrs["units"] == "m s-2" and ds["t_mid"].attrs["units"] == "s"
        assert np.array_equal(ds["a_Y"].to_numpy(), per["a_Y"].to_numpy())
    _invoke("table", d, "--export", tmp_path / "p.csv", "--columns", "source,t_mid,t_mid_utc")
    got = pd.read_csv(tmp_path / "p.csv")
    assert _same(pd.to_datetime(got["t_mid_utc"], utc=True), got["t_mid"])
    # the bias/drift filters do not apply: a usage error, not a traceback
    res = CliRunner().invoke(main, ["table", str(d), "--method", "lsq"])
    assert res.exit_code == 2 and "periods table of accal demod" in res.output
