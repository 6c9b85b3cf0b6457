"""`accal simulate grace --reference-out`: reference noise, scale matrix, spline bias, THR1B, arcs.

The simulated reference is checked against its documented model (Welch PSD, level,
reproducibility by seed), the raw/reference relation ``a_ref = S (a_raw − b)`` is
checked exactly on a noise-free day, the THR1B file is read back with
:func:`accal.io.thrusters.read_thrusters`, and ``accal grace-bias --reference`` is
run end to end on simulated days (one day with ``--scale fit-matrix``, a two-day
``--days`` arc with ``--arc 2d``).
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner
from scipy import signal

from accal.cli import main
from accal.crn import crn_smooth
from accal.io.grace_l1b import read_grace_acc1b
from accal.io.thrusters import THRUSTERS, find_thruster_file, read_thrusters
from accal.pipeline import read_bias_drift
from accal.simulate.effects import parse_effect, spline_bias
from accal.simulate.grace import (
    REFERENCE_BAND,
    reference_noise,
    reference_noise_psd,
    simulate_grace_day,
    stream,
)
from accal.simulate.thr1b import thruster_path


def invoke(*args):
    res = CliRunner().invoke(main, [str(a) for a in args])
    assert not isinstance(res.exception, Exception) or isinstance(res.exception, SystemExit), (
        res.exception
    )
    return res.exit_code, res.stderr


def _truth(path):
    return json.loads(path.with_name(path.name + ".truth.json").read_text())


def _simulate(out, *args):
    code, err = invoke("simulate", "grace", "--out", out, *args)
    assert code == 0, err
    return _truth(out)


def test_reference_noise_has_the_documented_psd_and_level():
    level, dt, n = 1e-9, 1.0, 86400
    x = reference_noise(n, dt, level, np.random.default_rng(7))
    assert x.shape == (n, 3)
    f, p = signal.welch(x, fs=1 / dt, nperseg=8192, axis=0)  # one-sided, per axis
    p = p.mean(axis=1)
    model = reference_noise_psd(f, level)
    low = (f > 2e-4) & (f < REFERENCE_BAND)  # orbit scales: the white floor
    high = (f > 0.3) & (f < 0.48)  # the f⁴ rise
    assert np.mean(p[low] / model[low]) == pytest.approx(1.0, rel=0.3)
    assert np.mean(p[high] / model[high]) == pytest.approx(1.0, rel=0.1)
    assert model[high].min() > 5 * model[low].max()  # noisy at high frequency
    # the level is the RMS at orbit scales (below 1 mHz): an ideal low-pass of the draw
    spec = np.fft.rfft(x, axis=0)
    spec[np.fft.rfftfreq(n, dt) > REFERENCE_BAND] = 0
    assert np.sqrt(np.mean(np.fft.irfft(spec, n, axis=0) ** 2)) == pytest.approx(level, rel=0.3)
    # per 1 Hz sample, as documented (5.6e-8 m/s^2 at 1e-9)
    assert x.std() == pytest.approx(5.6e-8, rel=0.05)
    assert not reference_noise(100, dt, 0.0, np.random.default_rng(7)).any()


def test_reference_noise_is_reproducible_and_leaves_the_rest_of_the_day_alone(tmp_path):
    common = ("--satellite", "C", "--date", "2023-06-01", "--duration", 7200, "--seed", 11)
    a, b, c = tmp_path / "a.txt", tmp_path / "b.txt", tmp_path / "c.txt"
    ta = _simulate(a, *common, "--reference-out", tmp_path / "a.parquet")
    tb = _simulate(b, *common, "--reference-out", tmp_path / "b.parquet")
    tc = _simulate(c, *common, "--reference-out", tmp_path / "c.parquet", "--reference-noise", 0)
    ra, rb, rc = (pd.read_parquet(tmp_path / f"{k}.parquet") for k in "abc")
    pd.testing.assert_frame_equal(ra, rb)  # same seed, same reference
    assert tb["reference"]["noise"] == ta["reference"]["noise"]
    assert a.read_bytes() == b.read_bytes() == c.read_bytes()  # the data file does not change
    assert {k: v for k, v in ta.items() if k != "reference"} == {
        k: v for k, v in tc.items() if k != "reference"
    }
    noise = (ra - rc)[["lin_accl_x", "lin_accl_y", "lin_accl_z"]].to_numpy()
    # the noise in the file is the documented model drawn from the day's "reference" stream
    expected = reference_noise(7200, 1.0, 1e-9, stream(11, "reference"))
    np.testing.assert_allclose(noise, expected, rtol=1e-6, atol=1e-22)
    assert ta["reference"]["noise"]["level"] == 1e-9 and tc["reference"]["noise"]["level"] == 0
    assert ta["reference"]["noise"]["rms"] == pytest.approx(np.sqrt((noise**2).mean(0)))
    # another seed, another reference noise
    other = tmp_path / "d.txt"
    _simulate(other, *common[:-1], 12, "--reference-out", tmp_path / "d.parquet")
    assert not np.allclose(pd.read_parquet(tmp_path / "d.parquet")["lin_accl_x"], ra["lin_accl_x"])


def test_noise_free_reference_is_s_times_a_true(tmp_path):
    out, ref = tmp_path / "ACC1B_2005-01-01_A_02.asc", tmp_path / "ref.csv"
    truth = _simulate(out, "--duration", 3000, "--reference-out", ref, "--reference-noise", 0)
    day = simulate_grace_day(date="2005-01-01", satellite="A", duration=3000)
    r = pd.read_csv(ref)
    np.testing.assert_array_equal(r["gps_time"], day.time)
    s = np.asarray(truth["scale_s"])
    for i, a in enumerate("xyz"):
        np.testing.assert_array_equal(r[f"lin_accl_{a}"], s[i] * day.true[:, i])


def test_scale_matrix_and_spline_bias_relate_raw_and_reference_exactly(tmp_path):
    """Without noise: a_ref = S (a_raw − b − d·(t − t0) − spline), S from the truth."""
    out, ref = tmp_path / "ACT1B_2023-06-01_D_04.txt", tmp_path / "ref.parquet"
    truth = _simulate(
        out, "--satellite", "D", "--date", "2023-06-01", "--duration", 20000, "--noise", 0,
        "--reference-out", ref, "--reference-noise", 0,
        "--effect", "scalematrix:xx=0.97,xy=2e-3,yz=-1e-3,zx=-3e-3,zz=1.01",
        "--effect", "scale:axis=y,factor=1.02",
        "--effect", "splinebias:axis=z,step=10800,amp=2e-9",
    )  # fmt: skip
    s_ref = np.array(truth["reference"]["scale"])
    s_mat = np.array(truth["effects"][0]["matrix"])
    assert truth["effects"][0]["axis"] == "xyz"
    np.testing.assert_allclose(np.linalg.inv(s_mat), truth["effects"][0]["inverse"])
    # scale:axis=y,factor=f adds diag(f − 1) to the raw signal's matrix S⁻¹
    m = np.linalg.inv(s_mat) + np.diag([0.0, 0.02, 0.0])
    np.testing.assert_allclose(s_ref, np.linalg.inv(m), rtol=1e-12)
    series = read_grace_acc1b(out)
    r = pd.read_parquet(ref)[["lin_accl_x", "lin_accl_y", "lin_accl_z"]].to_numpy()
    spl = truth["effects"][2]
    nodes = np.array(spl["node_epochs"])
    assert np.all(np.diff(nodes) == 10800) and nodes[0] <= truth["t0"] - 10800
    bias = np.zeros_like(r)
    # the simulator band-limits the effects like the data (Level-1B CRN-like filter)
    t_full = truth["t0"] + np.arange(20000.0)
    full = crn_smooth(spline_bias(t_full, nodes, np.array(spl["coefficients"]), 10800), 1.0)
    bias[:, 2] = full[np.searchsorted(t_full, series.time)]
    assert spl["bias_t0"] == pytest.approx(bias[0, 2], rel=1e-9)
    tau = (series.time - truth["t0"])[:, None]
    raw = series.acc - np.asarray(truth["bias"]) - np.asarray(truth["drift"]) * tau - bias
    assert np.abs(r).max() > 1e-8
    np.testing.assert_allclose(raw @ s_ref.T, r, rtol=0, atol=1e-13 * np.abs(r).max())


def test_spline_bias_is_continuous_across_days_simulated_one_by_one():
    spec = "splinebias:axis=x,step=21600,amp=1e-9,seed=4"
    days = [
        simulate_grace_day(date=d, satellite="C", duration=86400.0, dt=10.0, effects=[spec])
        for d in ("2023-06-01", "2023-06-02")
    ]
    e0, e1 = (d.truth["effects"][0] for d in days)
    n0 = dict(zip(e0["node_epochs"], e0["coefficients"], strict=True))
    n1 = dict(zip(e1["node_epochs"], e1["coefficients"], strict=True))
    shared = sorted(set(n0) & set(n1))
    assert len(shared) >= 3 and all(n0[k] == n1[k] for k in shared)
    boundary = np.array([days[1].truth["t0"]])
    b0 = spline_bias(boundary, np.array(list(n0)), np.array(list(n0.values())), 21600)
    assert b0[0] == pytest.approx(e1["bias_t0"], rel=1e-12)


@pytest.mark.parametrize(
    ("sat", "date", "name"),
    [
        ("A", "2005-01-01", "ACC1B_2005-01-01_A_02.asc"),
        ("C", "2023-06-01", "ACT1B_2023-06-01_C_04.txt"),
    ],
)
def test_thr1b_file_round_trips_through_read_thrusters(tmp_path, sat, date, name):
    out = tmp_path / name
    truth = _simulate(out, "--satellite", sat, "--date", date, "--duration", 10800,
                      "--thrusters", "--seed", 5)  # fmt: skip
    pulses = truth["thrusters"]
    assert len(pulses) >= 3
    thr = find_thruster_file(out)
    assert thr == thruster_path(out, sat) and thr.name.startswith(f"THR1B_{date}_{sat}_")
    firings = read_thrusters(thr)
    assert firings.warnings == () and firings.satellite.endswith(sat)
    ev = firings.events
    np.testing.assert_array_equal(np.unique(ev.start), sorted({p["epoch"] for p in pulses}))
    # every pulse fires an attitude pair (branch 1 and 2, same thruster, same on-time)
    assert len(ev) == 2 * len(pulses)
    for p in pulses:
        at = ev.start == p["epoch"]
        fired = {THRUSTERS[k] for k in ev.thruster[at]}
        assert all(n.startswith("att_ctrl_") for n in fired)
        assert {n.replace("_1_", "_2_") for n in fired if "_1_" in n} == {
            n for n in fired if "_2_" in n
        }
        assert p["length"] in ev.duration[at]


def test_fit_matrix_recovers_the_injected_scales_end_to_end(tmp_path):
    out, ref = tmp_path / "ACT1B_2023-06-01_C_04.txt", tmp_path / "ref.parquet"
    truth = _simulate(
        out, "--satellite", "C", "--date", "2023-06-01", "--duration", 21600, "--seed", 3,
        "--thrusters", "--reference-out", ref,
        "--effect", "scalematrix:xx=0.95,yy=1.04,zz=0.97,xy=2e-3,zx=-3e-3",
    )  # fmt: skip
    code, err = invoke("grace-bias", out, "--reference", ref, "--scale", "fit-matrix",
                       "--bias-basis", "poly1", "--out", tmp_path / "o", "-q", "-j", 1)  # fmt: skip
    assert code == 0, err
    tab = read_bias_drift(tmp_path / "o" / "bias_drift.parquet").set_index("axis")
    s_true = np.array(truth["reference"]["scale"])
    assert tab.loc["x", "scale_mode"] == "fit-matrix"
    assert (tab["n_thruster"] > 0).all()  # the THR1B beside the data was found and used
    for i, ax in enumerate("xyz"):
        if tab.loc[ax, "scale_mode"] != "fit-matrix":
            continue
        for j, b in enumerate("xyz"):
            err_ij = abs(tab.loc[ax, f"scale_{b}"] - s_true[i, j])
            assert err_ij < 4 * tab.loc[ax, f"scale_{b}_sigma"], (ax, b)
    assert abs(tab.loc["x", "scale"] - 1) > 2 * tab.loc["x", "scale_x_sigma"]  # 0.95 is seen


def test_days_writes_an_arc_that_grace_bias_fits_as_one(tmp_path):
    out, ref = tmp_path / "ACT1B_2023-06-01_D_04.txt", tmp_path / "ref.parquet"
    code, err = invoke(
        "simulate", "grace", "--satellite", "D", "--date", "2023-06-01", "--days", 2,
        "--seed", 8, "--out", out, "--reference-out", ref,
        "--effect", "scale:axis=x,factor=1.03",
        "--effect", "splinebias:axis=y,step=21600,amp=2e-9",
    )  # fmt: skip
    assert code == 0, err
    day2 = tmp_path / "ACT1B_2023-06-02_D_04.txt"
    t1, t2 = _truth(out), _truth(day2)
    assert (t1["seed"], t2["seed"]) == (8, 9) and t2["arc"]["index"] == 1
    # the eq. 9 bias continues across midnight with the first day's drift
    step = t2["t0"] - t1["t0"]
    np.testing.assert_allclose(
        t2["bias"], np.add(t1["bias"], np.multiply(t1["drift"], step)), rtol=1e-12
    )
    r = pd.read_parquet(ref)
    times = np.concatenate([read_grace_acc1b(p).time for p in (out, day2)])
    np.testing.assert_array_equal(r["gps_time"], times)
    code, err = invoke("grace-bias", out, day2, "--reference", ref, "--scale", "fit",
                       "--bias-basis", "spline:6h", "--arc", "2d", "--out", tmp_path / "o",
                       "-q", "-j", 1)  # fmt: skip
    assert code == 0, err
    tab = read_bias_drift(tmp_path / "o" / "bias_drift.parquet")
    x = tab[tab["axis"] == "x"]
    assert len(x) == 2 and x["scale"].nunique() == 1  # one scale for the arc
    s_true = t1["reference"]["scale"][0][0]
    assert s_true == pytest.approx(1 / 1.03)
    assert abs(x["scale"].iloc[0] - s_true) < 4 * x["scale_x_sigma"].iloc[0]


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (("--effect", "scalematrix:axis=x,xx=1"), "scalematrix has no key 'axis'"),
        (("--effect", "scalematrix:xx=1,xy=1,yx=1,yy=1"), "well conditioned"),
        (("--effect", "splinebias:axis=x,step=600"), "either amp"),
        (("--effect", "splinebias:axis=x,step=600,amp=1e-9,coefs=1e-9"), "either amp"),
        (("--effect", "splinebias:axis=x,step=600,coefs=1e-9;2e-9"), "coefs: 4 values needed"),
        (("--reference-noise", -1), "--reference-noise"),
        (("--days", 2), "must contain the date"),
    ],
)
def test_bad_options_are_usage_errors(tmp_path, args, says):
    code, err = invoke("simulate", "grace", "--duration", 600, "--out", tmp_path / "d.asc", *args)
    assert code == 2 and says in err, err


def test_given_spline_coefficients_sit_on_nodes_from_the_start_of_the_record():
    e = parse_effect("splinebias:axis=y,step=600,coefs=1e-9;2e-9;3e-9;4e-9", duration=600)
    day = simulate_grace_day(date="2023-06-01", satellite="C", duration=600, noise=0,
                             effects=[e])  # fmt: skip
    tr = day.truth["effects"][0]
    t0 = day.truth["t0"]
    assert tr["node_epochs"] == [t0 - 600, t0, t0 + 600, t0 + 1200]
    # at t0 the nodes t0 − step, t0, t0 + step weigh 1/6, 2/3, 1/6
    assert tr["bias_t0"] == pytest.approx((1e-9 + 4 * 2e-9 + 3e-9) / 6, rel=1e-12)
    np.testing.assert_allclose(day.instrument[0, 1], tr["bias_t0"], rtol=1e-12)
