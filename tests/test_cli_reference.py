"""``accal grace-bias --reference REF --scale fit|fit-matrix --bias-basis ...`` end to end.

Days drawn here (CSV tables written with pandas, not ``accal simulate``); the real
THR1B and SCA1B samples of 2003-09-14 (GRACE-A) serve for the thruster screening and
the inertial-to-SRF rotation.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner
from scipy import signal

from accal.cli import main
from accal.io.attitude import read_attitude, rotate_to_inertial
from accal.io.thrusters import read_thrusters
from accal.pipeline import read_bias_drift
from accal.products.utc import utc_instants

SAMPLES = Path(__file__).resolve().parents[1] / "data" / "samples"
T_DAY = 116769600.0  # 2003-09-14 00:00:00 GPS


def _run(*args) -> tuple[int, str]:
    res = CliRunner().invoke(main, ["grace-bias", *map(str, args)], catch_exceptions=False)
    return res.exit_code, res.output


def _signal(t: np.ndarray, rng) -> np.ndarray:
    ph = 2 * np.pi * (t - T_DAY) / 5600.0
    b, a = signal.butter(2, 1 / 2000, fs=1.0)
    slow = signal.lfilter(b, a, rng.normal(size=t.size + 40_000))[40_000:]
    slow /= slow.std()
    drag = 2e-7 * (1 + 0.3 * np.sin(ph) + 0.2 * slow)
    return np.column_stack([-drag, 2e-8 * np.cos(ph) + 0.02 * drag, 3e-8 * np.sin(ph + 1)])


def _write(path: Path, t: np.ndarray, acc: np.ndarray) -> Path:
    pd.DataFrame(
        {"gps_time": t, "lin_accl_x": acc[:, 0], "lin_accl_y": acc[:, 1], "lin_accl_z": acc[:, 2]}
    ).to_csv(path, index=False, float_format="%.17g")
    return path


BIAS = np.array([-1.1e-6, 2.7e-5, -5.6e-7])
DRIFT = np.array([2e-13, -1e-13, 3e-13])
SCALE = np.array([0.96, 0.98, 0.95])


def _day(tmp_path: Path, n: int, seed: int, *, spikes=None):
    rng = np.random.default_rng(seed)
    t = T_DAY + np.arange(n, dtype=float)
    true = _signal(t, rng)
    raw = true / SCALE + BIAS + DRIFT * (t - t[0])[:, None] + 1e-10 * rng.normal(size=(n, 3))
    if spikes is not None:
        raw += spikes
    ref = true + signal.lfilter([1, -1], [1], 3e-9 * rng.normal(size=(n, 3)), axis=0)
    ref += 1e-10 * rng.normal(size=(n, 3))
    return t, true, _write(tmp_path / "day.csv", t, raw), _write(tmp_path / "ref.csv", t, ref)


def test_scale_fit_recovers_scales_and_bias_and_writes_every_product(tmp_path):
    t, true, day, ref = _day(tmp_path, 43_200, 1)
    out = tmp_path / "out"
    code, msg = _run(day, "--reference", ref, "--scale", "fit", "--out", out, "-q", "-j", "1")
    assert code == 0, msg
    tab = read_bias_drift(out / "bias_drift.parquet").set_index("axis")
    assert (tab["method"] == "reference").all() and (tab["bias_basis"] == "poly1").all()
    assert (tab["scale_mode"] == "fit").all()
    assert tab.loc["x", "scale_mode"] == "fit"  # the drag axis always has the signal
    for i, ax in enumerate("xyz"):
        if tab.loc[ax, "scale_mode"] != "fit":
            continue
        assert abs(tab.loc[ax, "scale"] - SCALE[i]) < 4 * tab.loc[ax, f"scale_{ax}_sigma"]
        assert abs(tab.loc[ax, "bias"] - BIAS[i]) < 4 * tab.loc[ax, "bias_sigma"]
        assert tab.loc[ax, "scale"] == tab.loc[ax, f"scale_{ax}"]
        off = [a for a in "xyz" if a != ax]
        assert all(tab.loc[ax, f"scale_{a}"] == 0 for a in off)
    cal = pd.read_parquet(out / "day.calibrated.parquet")
    err = cal[["lin_accl_x", "lin_accl_y", "lin_accl_z"]].to_numpy() - true
    assert np.sqrt(np.mean(err[:, 0] ** 2)) < 0.01 * np.sqrt(np.mean(true[:, 0] ** 2))
    par = pd.read_parquet(out / "day.bias_basis.parquet")
    assert len(par) == 3 * 2 and set(par["axis"]) == {"x", "y", "z"}
    assert par.columns.tolist() == [
        "axis", "index", "node_time", "node_time_utc", "coef", "coef_sigma",
    ]  # fmt: skip
    assert str(par["node_time_utc"].dtype) == "datetime64[ns, UTC]"
    assert par["node_time_utc"].dt.tz_convert(None).tolist() == list(
        utc_instants(par["node_time"].to_numpy())
    )
    rep = json.loads((out / "day.report.json").read_text())["reference_fit"]
    assert rep["crosstalk_test"]["dof"] == 6 and 0 <= rep["crosstalk_test"]["p"] <= 1
    assert rep["thrusters"]["file"] is None
    # the full covariance: its diagonal is the table's scale sigma
    with np.load(out / "day.reference_cov.npz") as npz:
        cov, scale = npz["cov"], npz["scale"]
        assert cov.shape == (9 + 3 * 2, 9 + 3 * 2) and str(npz["basis"]) == "poly1"
        # the file names its own rows: S row by row, then each axis' coefficients
        names, units = npz["names"].tolist(), npz["units"].tolist()
    assert names[:4] == ["scale_xx", "scale_xy", "scale_xz", "scale_yx"]
    assert names[9:] == [
        "bias_x[0]",
        "bias_x[1]",
        "bias_y[0]",
        "bias_y[1]",
        "bias_z[0]",
        "bias_z[1]",
    ]
    assert units == ["1"] * 9 + ["m/s^2"] * 6
    assert scale[0, 0] == tab.loc["x", "scale"]
    assert np.sqrt(cov[0, 0]) == pytest.approx(tab.loc["x", "scale_x_sigma"], rel=1e-12)
    np.testing.assert_allclose(cov, cov.T, rtol=0, atol=1e-12 * np.abs(cov).max())


def test_scale_matrix_and_spline_basis_through_the_cli(tmp_path):
    _, _, day, ref = _day(tmp_path, 43_200, 2)
    out = tmp_path / "out"
    code, msg = _run(
        day, "--reference", ref, "--scale", "fit-matrix", "--bias-basis", "spline:3h",
        "--out", out, "-q", "-j", "1", "--format", "csv",
    )  # fmt: skip
    assert code == 0, msg
    tab = pd.read_csv(out / "bias_drift.csv")  # readable with the defaults
    assert set(tab["bias_basis"]) == {"spline:10800s"}
    x = tab.set_index("axis").loc["x"]
    assert x["scale_mode"] == "fit-matrix" and x["scale_y_sigma"] > 0
    assert abs(x["scale_x"] - SCALE[0]) < 4 * x["scale_x_sigma"]
    par = pd.read_csv(out / "day.bias_basis.csv")
    assert len(par) == 3 * (4 + 3)  # 4 intervals of 3 h in 12 h, cubic: 7 coefficients
    utc = pd.to_datetime(par["node_time_utc"], utc=True).dt.tz_convert(None)
    assert utc.dt.as_unit("ns").tolist() == list(utc_instants(par["node_time"].to_numpy()))


def test_thruster_firings_of_the_real_thr1b_are_left_out(tmp_path):
    n = 7200
    t = T_DAY + np.arange(n, dtype=float)
    thr = read_thrusters(SAMPLES / "THR1B_2003-09-14_A_00.asc")
    spikes = np.zeros((n, 3))
    for start, dur in zip(thr.events.start, thr.events.duration, strict=True):
        spikes[(t >= start) & (t <= start + max(dur, 1.0)), 0] = 3e-7
    assert spikes[:, 0].any()
    _, _, day, ref = _day(tmp_path, n, 3, spikes=spikes)
    common = ("--reference", ref, "--scale", "1,1,1", "--bias-basis", "poly1", "-q", "-j", "1")
    res = {}
    for name, extra in (
        ("screened", ("--thrusters", SAMPLES / "THR1B_2003-09-14_A_00.asc")),
        (
            "off",
            ("--thrusters", SAMPLES / "THR1B_2003-09-14_A_00.asc", "--thruster-margins", "off"),
        ),
    ):
        out = tmp_path / name
        code, msg = _run(day, *common, *extra, "--out", out)
        assert code == 0, msg
        res[name] = read_bias_drift(out / "bias_drift.parquet").set_index("axis").loc["x"]
    # scale fixed at 1 while the data's is 0.96: compare against the fit's own truth
    truth_bias = res["screened"]["bias"]
    assert res["screened"]["n_thruster"] > 0 and res["off"]["n_thruster"] == 0
    # the spikes pull the unscreened bias by about their share of the samples
    share = spikes[:, 0].mean()
    assert abs(res["off"]["bias"] - truth_bias) > 0.3 * share
    rep = json.loads((tmp_path / "screened" / "day.report.json").read_text())
    assert rep["reference_fit"]["thrusters"]["firings"] == len(np.unique(thr.events.start))


def test_inertial_reference_is_rotated_with_the_real_sca1b(tmp_path):
    att = read_attitude(SAMPLES / "SCA1B_2003-09-14_A_00.asc")
    n = 290
    t = T_DAY + np.arange(n, dtype=float)
    rng = np.random.default_rng(4)
    true = np.column_stack([np.full(n, -2e-7), np.full(n, 3e-8), np.full(n, 5e-8)])
    true += 1e-9 * rng.normal(size=(n, 3))
    raw = true + BIAS
    day = _write(tmp_path / "day.csv", t, raw)
    inertial = rotate_to_inertial(t, true, att)
    assert np.abs(inertial - true).max() > 1e-8  # the frames differ
    ref = _write(tmp_path / "ref.csv", t, inertial)
    common = ("--reference", ref, "--scale", "1,1,1", "--bias-basis", "poly0", "-q", "-j", "1")
    res = {}
    for frame in ("inertial", "srf"):
        out = tmp_path / frame
        code, msg = _run(day, *common, "--reference-frame", frame, "--attitude",
                         SAMPLES / "SCA1B_2003-09-14_A_00.asc", "--out", out)  # fmt: skip
        if frame == "srf":  # --attitude is only for the inertial frame: said, exit 2
            assert code == 2 and "inertial" in msg
            continue
        assert code == 0, msg
        res[frame] = read_bias_drift(out / "bias_drift.parquet").set_index("axis")
    got = res["inertial"]["bias"].to_numpy()
    np.testing.assert_allclose(got, BIAS, atol=5e-10)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("--scale", "fit"), "give --reference"),
        (("--bias-basis", "spline:6h"), "give --reference"),
        (("--reference", "REF", "--bias-basis", "spline:0h"), "node step"),
        (("--reference", "REF", "--bias-basis", "poly7"), "expected poly0"),
        (("--reference", "REF", "--scale", "fit", "--pool-days", "4"), "pool-days"),
        (("--reference-frame", "inertial"), "add --bias-basis"),
        (("--reference", "REF", "--scale", "fit", "--thruster-margins", "1"), "BEFORE,AFTER"),
    ],
)
def test_usage_errors_are_one_line_exit_2(tmp_path, args, message):
    _, _, day, ref = _day(tmp_path, 2000, 5)
    args = [str(ref) if a == "REF" else a for a in args]
    out = tmp_path / "out"
    code, msg = _run(day, *args, "--out", out, "-q")
    assert code == 2 and message in msg, msg
    assert not out.exists()


def test_a_reference_that_does_not_cover_the_day_fails_that_input_only(tmp_path):
    t, _, day, ref = _day(tmp_path, 4000, 6)
    short = pd.read_csv(ref).iloc[:2000]
    short.to_csv(ref, index=False, float_format="%.17g")
    out = tmp_path / "out"
    code, msg = _run(day, "--reference", ref, "--scale", "fit", "--out", out, "-q")
    assert code == 1
    assert "reference covers" in msg and "day.csv" in msg
    assert not (out / "day.calibrated.parquet").exists()
    # one line naming the input and the reference, UTC times, what to do (QA: raw GPS
    # seconds "[116769600.0, 116771599.0] s" and no hint)
    (line,) = [ln for ln in msg.splitlines() if ln.startswith("accal: ")]
    assert line.startswith(f"accal: {day}: {ref}: the reference covers 2003-09-13 23:59:47 to ")
    assert (
        "2003-09-14 00:33:06 UTC, the data 2003-09-13 23:59:47 to 2003-09-14 01:06:26 UTC" in line
    )
    assert line.endswith("the reference must cover the data (give a reference for the whole day)")


@pytest.mark.parametrize("arc", [None, "3d"])
def test_a_truncated_reference_parquet_names_the_day_too(tmp_path, arc):
    """``accal: DAY: REF: corrupt Parquet file (...)``, as the reference's other errors
    (before: ``accal: REF: ...``, the day being processed not named)."""
    t, _, day, ref = _day(tmp_path, 2000, 6)
    pq = tmp_path / "ref.parquet"
    pd.read_csv(ref).to_parquet(pq)
    pq.write_bytes(pq.read_bytes()[: pq.stat().st_size // 2])
    extra = ("--arc", arc) if arc else ()
    code, msg = _run(
        day, "--reference", pq, "--scale", "fit", *extra, "--out", tmp_path / "o", "-q"
    )
    assert code == 1
    (line,) = [ln for ln in msg.splitlines() if ln.startswith("accal: ")]
    assert line.startswith(f"accal: {day}: {pq}: corrupt Parquet file ("), line


def test_no_sca1b_beside_a_table_input_is_a_clear_error(tmp_path):
    _, _, day, ref = _day(tmp_path, 2000, 7)
    out = tmp_path / "out"
    code, msg = _run(
        day, "--reference", ref, "--scale", "1,1,1", "--bias-basis", "poly0",
        "--reference-frame", "inertial", "--out", out, "-q",
    )  # fmt: skip
    assert code == 1 and "give --attitude" in msg


# ----------------------------------------------------------------------------- arcs


def _arc_days(tmp_path: Path, days=(0, 1, 2), hours: float = 24.0, seed: int = 8):
    """Days of 1 Hz data (tables) with one reference over all; bias: a slow sinusoid."""
    rng = np.random.default_rng(seed)
    n = int(max(days) + 1) * 86400
    t = T_DAY + np.arange(n, dtype=float)
    true = _signal(t, rng)
    bias = BIAS + 2e-8 * np.sin(2 * np.pi * (t - t[0]) / (3 * 86400))[:, None]
    raw = true / SCALE + bias + 1e-10 * rng.normal(size=(n, 3))
    ref = true + signal.lfilter([1, -1], [1], 3e-9 * rng.normal(size=(n, 3)), axis=0)
    paths = []
    for d in days:
        sl = slice(d * 86400, d * 86400 + int(hours * 3600))
        paths.append(_write(tmp_path / f"day{d}.csv", t[sl], raw[sl]))
    return t, bias, paths, _write(tmp_path / "ref.csv", t, ref)


def test_an_arc_of_three_days_has_one_scale_and_a_continuous_spline(tmp_path):
    t, bias, paths, ref = _arc_days(tmp_path)
    out = tmp_path / "out"
    args = ("--reference", ref, "--scale", "fit", "--bias-basis", "spline:6h", "-q")
    code, msg = _run(*paths, *args, "--arc", "3d", "--out", out)
    assert code == 0, msg
    tab = read_bias_drift(out / "bias_drift.parquet")
    assert len(tab) == 9
    x = tab[tab["axis"] == "x"]
    assert x["scale"].nunique() == 1  # one scale for the arc
    assert abs(x["scale"].iloc[0] - SCALE[0]) < 4 * x["scale_x_sigma"].iloc[0]
    for _, row in tab.iterrows():
        i = "xyz".index(row["axis"])
        k = int(row["t0"] - T_DAY)
        assert abs(row["bias"] - bias[k, i]) < 5 * row["bias_sigma"] + 1e-12
    par = pd.read_parquet(out / "arc_day0_2003-09-14_2003-09-16.bias_basis.parquet")
    assert len(par) == 3 * (12 + 3)  # 12 intervals of 6 h over 3 days, cubic
    rep = json.loads((out / "day1.report.json").read_text())["reference_fit"]
    assert rep["arc"]["sources"] == ["day0.csv", "day1.csv", "day2.csv"]
    with np.load(out / "arc_day0_2003-09-14_2003-09-16.reference_cov.npz") as npz:
        assert npz["cov"].shape == (9 + 3 * 15, 9 + 3 * 15)
    # a re-run skips all; a changed day redoes its whole arc
    before = (out / "day0.calibrated.parquet").stat().st_mtime_ns
    code, msg = _run(*paths, *args, "--arc", "3d", "--out", out)
    assert code == 0, msg
    assert (out / "day0.calibrated.parquet").stat().st_mtime_ns == before
    st = paths[2].stat()
    os.utime(paths[2], ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    code, msg = _run(*paths, *args, "--arc", "3d", "--out", out)
    assert code == 0, msg
    assert (out / "day0.calibrated.parquet").stat().st_mtime_ns > before
    assert len(read_bias_drift(out / "bias_drift.parquet")) == 9


def test_a_missing_day_starts_a_new_arc_and_a_bad_day_fails_alone(tmp_path):
    _, _, paths, ref = _arc_days(tmp_path, days=(0, 1, 3), hours=12.0, seed=9)
    bad = tmp_path / "bad.csv"
    bad.write_text("gps_time,lin_accl_x\n1,oops\n")
    out = tmp_path / "out"
    code, msg = _run(
        *paths, bad, "--reference", ref, "--scale", "fit", "--bias-basis", "poly1",
        "--arc", "30d", "--out", out, "-q",
    )  # fmt: skip
    assert code == 1 and "bad.csv" in msg
    tab = read_bias_drift(out / "bias_drift.parquet")
    assert sorted(set(tab["source"])) == ["day0.csv", "day1.csv", "day3.csv"]
    reps = {p.name: json.loads((out / f"{p.stem}.report.json").read_text()) for p in paths}
    assert reps["day0.csv"]["reference_fit"]["arc"]["sources"] == ["day0.csv", "day1.csv"]
    assert reps["day3.csv"]["reference_fit"]["arc"]["sources"] == ["day3.csv"]
    assert any("new arc" in w for w in reps["day3.csv"]["read_report"]["warnings"])


def test_group_arcs_by_satellite_length_and_month():
    from accal.pipeline_reference import group_arcs

    day = 86400.0
    t0 = 157809600.0  # 2005-01-01 00:00 GPS
    inputs = [("GRACE-A", t0 + d * day, t0 + d * day + day - 1) for d in range(5)]
    inputs += [("GRACE-B", t0 + d * day, t0 + d * day + day - 1) for d in range(2)]
    arcs, notes = group_arcs(inputs, "2d")
    assert arcs == [[0, 1], [2, 3], [4], [5, 6]] and not notes
    arcs, _ = group_arcs(inputs[::-1], "day")
    assert len(arcs) == 7
    # 2005-01-30 .. 2005-02-02 by month
    late = [("GRACE-A", t0 + d * day, t0 + d * day + day - 1) for d in range(29, 33)]
    arcs, _ = group_arcs(late, "month")
    assert arcs == [[0, 1], [2, 3]]  # January 30-31, February 1-2
    with pytest.raises(Exception, match="--arc"):
        group_arcs(late, "week")


def test_a_reference_in_another_unit_is_converted_or_refused(tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    _, _, day, ref = _day(tmp_path, 20_000, 10)
    base = pd.read_csv(ref)
    res = {}
    for unit in ("m/s^2", "nm/s^2", "furlong/fortnight^2"):
        scale = 1e9 if unit == "nm/s^2" else 1.0
        cols = {c: base[c].to_numpy() * (scale if c != "gps_time" else 1.0) for c in base}
        units = {"gps_time": "s", **{c: unit for c in base if c != "gps_time"}}
        table = pa.table(cols).replace_schema_metadata({"accal.units": json.dumps(units)})
        path = tmp_path / f"ref_{len(res)}.parquet"
        pq.write_table(table, path)
        out = tmp_path / f"out{len(res)}"
        code, msg = _run(day, "--reference", path, "--scale", "fit", "--out", out, "-q")
        res[unit] = (code, msg, out)
    assert res["m/s^2"][0] == 0 and res["nm/s^2"][0] == 0
    a, b = (read_bias_drift(res[u][2] / "bias_drift.parquet") for u in ("m/s^2", "nm/s^2"))
    np.testing.assert_allclose(b["bias"], a["bias"], rtol=1e-9)
    rep = json.loads((res["nm/s^2"][2] / "day.report.json").read_text())
    assert any("converted to m/s^2" in w for w in rep["read_report"]["warnings"])
    code, msg, _ = res["furlong/fortnight^2"]
    assert code == 1 and "not an acceleration unit" in msg and "ref_2.parquet" in msg


def test_a_sparser_reference_is_interpolated_and_said(tmp_path):
    t, _, day, ref = _day(tmp_path, 20_000, 11)
    full = pd.read_csv(ref)
    sparse = full.iloc[np.r_[0 : len(full) : 10, len(full) - 1]]
    sparse.to_csv(ref, index=False, float_format="%.17g")
    out = tmp_path / "out"
    code, msg = _run(day, "--reference", ref, "--scale", "fit", "--out", out, "-q")
    assert code == 0, msg
    rep = json.loads((out / "day.report.json").read_text())
    assert any("interpolated by a cubic spline" in w for w in rep["read_report"]["warnings"])
    x = read_bias_drift(out / "bias_drift.parquet").set_index("axis").loc["x"]
    assert abs(x["scale"] - SCALE[0]) < 5 * x["scale_x_sigma"] + 1e-3


def test_a_sparse_reference_ending_just_before_the_data_leaves_those_samples_out(tmp_path):
    """QA (2026-11-29): a 10 s reference whose last sample is 9 s before the day's last
    lost the whole day ("must cover the data").  Now those 9 samples are left out with
    a warning, and the fit is the same as with them."""
    t, true, day, ref = _day(tmp_path, 20_000, 7)
    full = pd.read_csv(ref)
    full.iloc[::10].to_csv(ref, index=False, float_format="%.17g")  # every 10 s, ends 9 s early
    out = tmp_path / "out"
    code, msg = _run(day, "--reference", ref, "--scale", "fit", "--out", out, "-j", "1")
    assert code == 0, msg
    assert "ends within 25 s of the data's end: 9 sample(s)" in msg
    cal = pd.read_parquet(out / "day.calibrated.parquet")
    assert not cal["valid"].to_numpy(bool)[-9:].any() and cal["valid"].to_numpy(bool)[-10]
    # an hour short is still an error
    full.iloc[:-3600].to_csv(ref, index=False, float_format="%.17g")
    code, msg = _run(day, "--reference", ref, "--scale", "fit", "--out", tmp_path / "o2", "-q")
    assert code == 1 and "the reference must cover the data" in msg


def test_a_reference_in_another_unit_is_an_error_not_a_scale_of_1e9(tmp_path):
    """QA: a reference in nm/s² (no unit metadata) gave scales of 9.6e8 and exit 0."""
    t, true, day, ref = _day(tmp_path, 20_000, 8)
    nm = pd.read_csv(ref)
    for ax in "xyz":
        nm[f"lin_accl_{ax}"] *= 1e9
    nm.to_csv(ref, index=False, float_format="%.17g")
    out = tmp_path / "out"
    code, msg = _run(day, "--reference", ref, "--scale", "fit", "--out", out, "-q", "-j", "1")
    assert code == 1, msg
    (line,) = [ln for ln in msg.splitlines() if ln.startswith("accal: ")]
    assert "the fitted scale on x is 9.6e+08" in line and "is the reference in m/s²" in line
    assert not (out / "day.calibrated.parquet").exists()


def test_a_reference_with_no_finite_sample_names_itself(tmp_path):
    """QA (2026-11-29): an all-NaN reference failed as "0 usable samples for 5
    parameters", without naming the reference."""
    t, true, day, ref = _day(tmp_path, 5_000, 9)
    nan = pd.read_csv(ref)
    nan[["lin_accl_x", "lin_accl_y", "lin_accl_z"]] = np.nan
    ref = tmp_path / "ref.parquet"  # (a CSV of empty fields is a column of no type)
    nan.to_parquet(ref, index=False)
    out = tmp_path / "out"
    code, msg = _run(day, "--reference", ref, "--scale", "fit", "--out", out, "-q", "-j", "1")
    assert code == 1, msg
    (line,) = [ln for ln in msg.splitlines() if ln.startswith("accal: ")]
    assert f"{ref}: the reference has no valid (finite) sample over the data's span" in line
    assert not (out / "day.calibrated.parquet").exists()


def test_column_maps_a_table_reference_beside_an_l1b_input_without_a_warning(tmp_path):
    """QA (2026-11-29): ``--column`` maps a table reference's columns, but an L1B input
    warned that the option "is for table inputs" as if it had been ignored."""
    day = tmp_path / "ACC1B_2005-01-01_A_00.asc"
    ref = tmp_path / "ref.parquet"
    res = CliRunner().invoke(
        main,
        ["simulate", "grace", "--date", "2005-01-01", "--duration", "7200", "--out", str(day),
         "--reference-out", str(ref)],
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    renamed = pd.read_parquet(ref).rename(columns={f"lin_accl_{a}": f"acc_{a}" for a in "xyz"})
    renamed.to_parquet(ref, index=False)
    cols = [f"--column={a}=acc_{a}" for a in "xyz"]
    code, msg = _run(day, "--reference", ref, *cols, "--scale", "fit", "--out", tmp_path / "o")
    assert code == 0, msg
    assert "is for table inputs" not in msg
    # without the mapping the reference's columns are not found
    code, msg = _run(day, "--reference", ref, "--scale", "fit", "--out", tmp_path / "o2", "-q")
    assert code == 1 and "lin_accl_x" in msg, msg


def test_a_thruster_file_of_another_day_is_said_and_not_used(tmp_path):
    """QA (2026-11-30): a THR1B whose records are of another day was used silently: no
    firing in the day, n_thruster 0, as if the day had none."""
    n = 7200
    _, _, day, ref = _day(tmp_path, n, 3)
    shifted = pd.read_csv(day)
    shifted["gps_time"] += 10 * 86400.0  # the same data ten days later
    shifted.to_csv(day, index=False, float_format="%.17g")
    moved = pd.read_csv(ref)
    moved["gps_time"] += 10 * 86400.0
    moved.to_csv(ref, index=False, float_format="%.17g")
    thr = SAMPLES / "THR1B_2003-09-14_A_00.asc"
    out = tmp_path / "out"
    code, msg = _run(day, "--reference", ref, "--scale", "1,1,1", "--bias-basis", "poly1",
                     "--thrusters", thr, "--out", out, "-j", "1")  # fmt: skip
    assert code == 0, msg
    assert (
        "THR1B_2003-09-14_A_00.asc: its records are of 2003-09-14 to 2003-09-14 (GPS), the "
        "data of 2003-09-24: another day's thruster file, not used" in msg
    )
    rep = json.loads((out / "day.report.json").read_text())["reference_fit"]["thrusters"]
    assert rep["firings"] == 0 and "another day's thruster file" in rep["why"]
