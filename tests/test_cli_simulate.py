"""`accal simulate grace`: the real-like file, --storm, --thrusters, --effect, --reference-out."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from accal.cli import main
from accal.crn import crn_smooth
from accal.io.grace_l1b import read_grace_acc1b


def invoke(*args):
    res = CliRunner().invoke(main, [str(a) for a in args])
    assert not isinstance(res.exception, Exception) or isinstance(res.exception, SystemExit), (
        res.exception
    )
    return res.exit_code, res.stdout, res.stderr


def _truth(path):
    return json.loads(path.with_name(path.name + ".truth.json").read_text())


def test_default_file_has_all_twelve_columns_at_real_magnitudes(tmp_path):
    out = tmp_path / "ACC1B_2003-09-14_A_02.asc"
    code, _, err = invoke("simulate", "grace", "--date", "2003-09-14", "--duration", 3600,
                          "--out", out)  # fmt: skip
    assert code == 0, err
    s = read_grace_acc1b(out)
    truth = _truth(out)
    assert len(s) == 3600 and s.valid.all()
    # ang_accl at the real sample's offsets, full precision (not rounded), with noise
    for ax, real in zip("xyz", (3.3220e-4, -3.9353e-5, -2.9153e-4), strict=True):
        v = s.aux[f"ang_accl_{ax}"]
        assert v.mean() == pytest.approx(real, rel=0.02) and np.unique(v).size == v.size
    for ax in "xyz":
        assert 1e-10 < np.median(np.abs(s.aux[f"acl_{ax}_res"])) < 1e-7
    assert 5550 <= truth["orbit_period"] <= 5700
    assert truth["storm"] is None and truth["thrusters"] == [] and truth["effects"] == []
    assert all(e["exit"] > e["entry"] for e in truth["eclipses"])
    # GRACE-FO keeps the ACT1B convention: angular columns 0
    out_c = tmp_path / "ACT1B_2023-06-01_C_04.txt"
    code, _, err = invoke("simulate", "grace", "--date", "2023-06-01", "--satellite", "C",
                          "--duration", 600, "--out", out_c)  # fmt: skip
    assert code == 0, err
    c = read_grace_acc1b(out_c)
    assert not any(c.aux[f"ang_accl_{ax}"].any() for ax in "xyz")
    assert all(c.aux[f"acl_{ax}_res"].any() for ax in "xyz")


def test_storm_and_thrusters_are_signal_with_their_truth(tmp_path):
    """raw(--storm --thrusters) − raw(plain) is s × (the storm's extra drag + the pulses
    listed in the truth); nothing else of the day changes."""
    plain, both = tmp_path / "p.asc", tmp_path / "b.asc"
    common = ("--date", "2005-01-01", "--seed", 3, "--duration", 43200)
    assert invoke("simulate", "grace", *common, "--out", plain)[0] == 0
    code, _, err = invoke("simulate", "grace", *common, "--storm", "--thrusters", "--out", both)
    assert code == 0, err
    tp, tb = _truth(plain), _truth(both)
    storm = tb["storm"]
    assert 2 <= storm["factor"] <= 4 and 2 * 3600 <= storm["rise_s"] <= 5 * 3600
    assert storm["onset"] == tb["t0"] + storm["onset_s"] and storm["onset_s"] <= 0.5 * 43200
    pulses = tb["thrusters"]
    assert 2 <= len(pulses) <= 100  # a few per hour over 12 h
    assert all(1e-8 <= abs(p["amplitude"]) <= 1e-7 and 2 <= p["length"] <= 5 for p in pulses)
    for k in ("bias", "drift", "orbit_period", "eclipses", "drag", "seed"):
        assert tb[k] == tp[k]
    a, b = read_grace_acc1b(plain), read_grace_acc1b(both)
    s = np.asarray(tp["scale_s"])
    tau = a.time - tp["t0"]
    pulse = np.zeros_like(a.acc)
    for p in pulses:  # half sines, zero at both ends
        on = (tau >= p["epoch_s"]) & (tau <= p["epoch_s"] + p["length"])
        pulse[on, "xyz".index(p["axis"])] += p["amplitude"] * np.sin(
            np.pi * (tau[on] - p["epoch_s"]) / p["length"]
        )
    # the file holds them through the Level-1B CRN-like filter (no gaps: the 1 s grid)
    assert np.all(np.diff(tau) == 1.0)
    extra = (b.acc - a.acc) / s - crn_smooth(pulse, 1.0)
    before = tau < storm["onset_s"] - 40.0
    assert np.abs(extra[before]).max() < 1e-19  # rounding of the raw values only
    assert np.abs(extra[:, 1:]).max() < 1e-8  # the storm is drag: along-track (x) mostly
    peak = np.abs(tau - storm["onset_s"] - storm["rise_s"]) < 1800
    # A flies +x forward: drag along −x, up by (factor − 1) × its quiet level (~1 ± 0.4)
    assert extra[peak, 0].mean() < -0.5 * (storm["factor"] - 1) * tp["drag"]["level"]


def test_effects_aux_and_reference_files(tmp_path):
    """A coupling writes <out>.aux.parquet (gps_time + channel, unit K), readable as
    --aux; --reference-out is s·a_true, readable as --reference: grace-bias on
    raw − reference finds the bias plus the injected effects' LS trend."""
    from accal.io.housekeeping import read_housekeeping
    from accal.io.writers import read_table_metadata

    try:  # where grace-bias --aux reads its channels (moving with the closure rewrite)
        from accal.pipeline_closure import load_aux
    except ImportError:
        from accal.pipeline import load_aux

    out = tmp_path / "ACC1B_2005-01-01_B_02.asc"
    ref = tmp_path / "ref.parquet"
    code, _, err = invoke(
        "simulate", "grace", "--date", "2005-01-01", "--satellite", "B", "--duration", 20000,
        "--gaps", 2, "--flagged", 0.01, "--out", out, "--reference-out", ref,
        "--effect", "coupling:axis=y,channel=temperature,coef=2e-9,lag=300,tau=200",
        "--effect", "scale:axis=x,factor=1.03", "--effect", "quadratic:axis=z,coef=3e-18",
    )  # fmt: skip
    assert code == 0, err
    aux = out.with_name(out.name + ".aux.parquet")
    assert f"wrote {out}, {aux}, {ref} and " in err
    truth = _truth(out)
    assert [e["name"] for e in truth["effects"]] == ["coupling", "scale", "quadratic"]
    hk = read_housekeeping(aux)
    assert set(hk.channels) == {"temperature"} and hk.units["temperature"] == "K"
    assert hk.time[0] == truth["t0"] - 14400.0  # the channel's history before the day
    _, meta = read_table_metadata(aux)
    assert meta["channels"]["temperature"]["unit"] == "K"
    series = read_grace_acc1b(out)
    channels, notes = load_aux(aux, series.time, series.satellite)
    assert set(channels) == {"temperature"} and notes == []
    assert np.isfinite(channels["temperature"]).all()
    r = pd.read_parquet(ref)
    assert list(r.columns) == ["gps_time", "lin_accl_x", "lin_accl_y", "lin_accl_z"]
    assert np.array_equal(r["gps_time"].to_numpy(), series.time)
    code, _, err = invoke("grace-bias", out, "--reference", ref, "--method", "lsq",
                          "--out", tmp_path / "o", "-q")  # fmt: skip
    assert code == 0, err
    from accal.pipeline import read_bias_drift

    df = read_bias_drift(tmp_path / "o" / "bias_drift.parquet").set_index("axis")
    for i, ax in enumerate("xyz"):
        expected = truth["bias"][i] + truth["effects_trend"]["bias"][i]
        assert abs(df.loc[ax, "bias"] - expected) < 4 * df.loc[ax, "bias_sigma"], ax
        expected_d = truth["drift"][i] + truth["effects_trend"]["drift"][i]
        assert abs(df.loc[ax, "drift"] - expected_d) < 4 * df.loc[ax, "drift_sigma"], ax
    # the scale error is in raw − reference: (factor − 1)·s·a_true, mostly drag on x
    assert abs(truth["effects_trend"]["bias"][0]) > 1e-9


def test_reference_out_as_csv(tmp_path):
    out, ref = tmp_path / "d.asc", tmp_path / "ref.csv"
    code, _, err = invoke("simulate", "grace", "--duration", 600, "--out", out,
                          "--reference-out", ref)  # fmt: skip
    assert code == 0, err
    # pandas reads it with its defaults; the units are in the CSVW sidecar
    df = pd.read_csv(ref)
    assert list(df.columns) == ["gps_time", "lin_accl_x", "lin_accl_y", "lin_accl_z"]
    side = json.loads((tmp_path / "ref.csv-metadata.json").read_text())
    assert side["accal:units"]["lin_accl_x"] == "m/s^2"
    assert not out.with_name(out.name + ".aux.parquet").exists()  # no coupling, no channel


@pytest.mark.parametrize(
    ("spec", "says"),
    [
        ("step:axis=x,epoch=600,size=1e-9", "epoch must be in [0, 600)"),
        ("step:axis=x,epoch=10", "step needs size"),
        ("wobble:axis=x", "unknown effect 'wobble'"),
        ("coupling:axis=y,channel=pressure,coef=1e-9", "channel must be 'temperature'"),
        ("scale:axis=x,factor=abc", "factor must be a number, got 'abc'"),
        ("growing:axis=y,period=100,amp0=1e-9", "growing needs amp1"),
        ("sawtooth:axis=y,period=100,amp=1e-9,shape=up", "sawtooth has no key 'shape'"),
    ],
)
def test_bad_effect_is_a_one_line_usage_error(tmp_path, spec, says):
    code, _, err = invoke("simulate", "grace", "--duration", 600, "--effect", spec,
                          "--out", tmp_path / "d.asc")  # fmt: skip
    assert code == 2 and len(err.splitlines()) == 1, err
    assert err.startswith(f"accal: --effect '{spec}': ") and says in err
    assert not any(tmp_path.iterdir())


def test_same_day_same_file_and_effects_change_only_their_axis(tmp_path):
    a, b, c = tmp_path / "a.asc", tmp_path / "b.asc", tmp_path / "c.asc"
    args = ("simulate", "grace", "--date", "2012-05-05", "--satellite", "D", "--duration", 3000)
    assert invoke(*args, "--out", a)[0] == 0
    assert invoke(*args, "--out", b)[0] == 0
    assert a.read_bytes().replace(b"a.asc", b"") == b.read_bytes().replace(b"b.asc", b"")
    assert invoke(*args, "--effect", "step:axis=z,epoch=1000,size=4e-9", "--out", c)[0] == 0
    sa, sc = read_grace_acc1b(a), read_grace_acc1b(c)
    d = sc.acc - sa.acc
    tau = sa.time - sa.time[0]
    assert not d[:, :2].any()
    assert np.all(np.diff(tau) == 1.0)
    assert np.allclose(d[:, 2], crn_smooth(4e-9 * (tau >= 1000), 1.0), rtol=0, atol=1e-20)
    assert d[tau < 980, 2].max() < 1e-20 and np.all(np.abs(d[tau > 1020, 2] - 4e-9) < 1e-20)
    assert _truth(c)["effects"][0]["epoch_gps"] == sa.time[0] + 1000
