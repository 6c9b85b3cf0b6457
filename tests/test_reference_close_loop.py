"""``grace-bias --reference REF --scale fit --bias-basis ... --close-loop`` (issue 22).

The closure runs on the residual of the reference fit, with the fit's model (bias
basis, reference columns of the fitted scales) as its null model.  Days drawn here
with numpy (not ``accal simulate``): 1 Hz, a drag-like along-track reference of
~2e-7 m/s² with once- and twice-per-revolution and slow (6-17 h) parts, smaller
cross-track and radial signals, raw = signal / S + bias + drift·t + noise, the
reference = signal + its own white noise.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from accal.cli import main
from accal.estimators.refbasis import parse_bias_basis
from accal.estimators.reference import fit_reference
from accal.gracejob.reference_closure import null_design
from accal.pipeline import read_bias_drift

T_DAY = 158976000.0  # 2005-01-14 12:00:00 GPS
N_DAY = 86_400
BIAS = np.array([-1.1e-6, 2.7e-5, -5.6e-7])  # m/s²
DRIFT = np.array([2e-13, -1e-13, 3e-13])  # m/s³
SCALE = np.array([0.96, 0.98, 0.95])
ORBIT = 5600.0  # s
STEP = ("y", 0.4, 1e-8)  # axis, fraction of the day, size [m/s²]


def _signal(t: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A non-gravitational acceleration in the SRF (x along track) [m/s²]."""
    ph = 2 * np.pi * (t - t[0]) / ORBIT
    slow = sum(
        np.sin(2 * np.pi * (t - t[0]) / p + rng.uniform(0, 2 * np.pi))
        for p in (6 * 3600.0, 9 * 3600.0, 17 * 3600.0)
    )
    slow /= slow.std()
    drag = 2e-7 * (1 + 0.3 * np.sin(ph) + 0.1 * np.sin(2 * ph + 0.4) + 0.2 * slow)
    return np.column_stack(
        [-drag, 2e-8 * np.cos(ph) + 0.02 * drag, 3e-8 * np.sin(ph + 1) + 5e-9 * slow]
    )


def _pod_noise(n: int, rng: np.random.Generator) -> np.ndarray:
    """Noise of a POD-derived reference [m/s²], shape (n, 3): white (2.3e-8 per sample,
    the ASD of ``accal simulate``'s default up to 0.1 Hz), a differenced-white (blue)
    part of 2e-8 and a red AR(1) part (τ = 1 h) of 1e-9 RMS: 3.9e-8 m/s² RMS at 1 Hz,
    twice the cross-track signal."""
    white = 2.3e-8 * rng.normal(size=(n, 3))
    blue = 2e-8 / np.sqrt(2) * np.diff(rng.normal(size=(n + 1, 3)), axis=0)
    a = np.exp(-1.0 / 3600.0)
    red = np.empty((n, 3))
    red[0] = rng.normal(size=3)
    drive = np.sqrt(1 - a * a) * rng.normal(size=(n, 3))
    for k in range(1, n):  # AR(1), unit variance
        red[k] = a * red[k - 1] + drive[k]
    return white + blue + 1e-9 * red


def _draw(n: int, seed: int, step: tuple[str, float, float] | None = None, noisy: bool = False):
    """(t, true signal, raw, reference); ``step`` adds a bias step to the raw data,
    ``noisy`` gives the reference a POD-like noise (:func:`_pod_noise`) instead of 3e-10
    of white noise."""
    rng = np.random.default_rng(seed)
    t = T_DAY + np.arange(n, dtype=float)
    true = _signal(t, rng)
    raw = true / SCALE + BIAS + DRIFT * (t - t[0])[:, None] + 1e-10 * rng.normal(size=(n, 3))
    if step is not None:
        ax, frac, size = step
        raw[int(frac * n) :, "xyz".index(ax)] += size
    ref = true + (_pod_noise(n, rng) if noisy else 3e-10 * rng.normal(size=(n, 3)))
    return t, true, raw, ref


def _write(path: Path, t: np.ndarray, acc: np.ndarray) -> Path:
    pd.DataFrame(
        {"gps_time": t, "lin_accl_x": acc[:, 0], "lin_accl_y": acc[:, 1], "lin_accl_z": acc[:, 2]}
    ).to_csv(path, index=False, float_format="%.17g")
    return path


def _run(*args) -> tuple[int, str]:
    res = CliRunner().invoke(main, ["grace-bias", *map(str, args)], catch_exceptions=False)
    return res.exit_code, res.output


COMMON = ("--scale", "fit", "--bias-basis", "poly1", "-q", "-j", "1")


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, dict]:
    """A clean day and one with a bias step, each run without and with --close-loop."""
    base = tmp_path_factory.mktemp("refcl")
    out: dict[str, dict] = {}
    for name, step in (("clean", None), ("step", STEP)):
        t, true, raw, ref = _draw(N_DAY, 1, step)
        day = _write(base / f"{name}.csv", t, raw)
        ref_path = _write(base / f"{name}_ref.csv", t, ref)
        res = {"t": t, "true": true}
        for key, extra in (("plain", ()), ("closed", ("--close-loop",))):
            o = base / f"{name}_{key}"
            code, msg = _run(day, "--reference", ref_path, *COMMON, *extra, "--out", o)
            assert code == 0, msg
            res[key] = o
        out[name] = res
    return out


def _table(out: Path) -> pd.DataFrame:
    return read_bias_drift(out / "bias_drift.parquet").set_index("axis")


def _calibrated_error(out: Path, stem: str, true: np.ndarray, axis: str) -> float:
    cal = pd.read_parquet(out / f"{stem}.calibrated.parquet")
    ok = cal["valid"].to_numpy(bool)
    err = cal[f"lin_accl_{axis}"].to_numpy()[ok] - true[ok, "xyz".index(axis)]
    return float(np.sqrt(np.mean(err**2)))


def test_clean_day_nothing_removed_estimates_unchanged(runs):
    r = runs["clean"]
    plain, closed = _table(r["plain"]), _table(r["closed"])
    summary = json.loads((r["closed"] / "closure.json").read_text())["sources"]["clean.csv"]
    for ax in "xyz":
        assert summary[ax]["removed_from_calibrated"] == []
        assert closed.loc[ax, "model"] == "poly1"
        sigma = {"bias": "bias_sigma", "drift": "drift_sigma", "scale": f"scale_{ax}_sigma"}
        for q, sig in sigma.items():
            assert abs(closed.loc[ax, q] - plain.loc[ax, q]) <= closed.loc[ax, sig]
            assert closed.loc[ax, sig] == plain.loc[ax, sig]
            est = summary[ax]["estimates"]["reference"][q]
            assert est["change_sigmas"] == 0.0
    # σ unchanged: nothing was removed, the fit is the same
    np.testing.assert_array_equal(closed["bias_sigma"], plain["bias_sigma"])
    assert (closed["scale_mode"] == "fit").all()


def test_injected_step_found_and_removed(runs):
    r = runs["step"]
    entry = json.loads((r["closed"] / "closure.json").read_text())["sources"]["step.csv"]
    ax, frac, size = STEP
    steps = [e for e in entry[ax]["effects"] if e["name"] == "bias_step"]
    assert len(steps) == 1
    e = steps[0]
    assert abs(e["epoch"] - r["t"][int(frac * N_DAY)]) <= 3.0
    assert abs(e["coefficient"] - size) <= 2 * e["sigma"]
    assert entry[ax]["removed_from_calibrated"] == entry[ax]["model"].split("+")[1:]
    for other in "xz":  # nothing removed where nothing was injected
        assert entry[other]["removed_from_calibrated"] == []
    tab = _table(r["closed"])
    assert tab.loc[ax, "model"].startswith("poly1+bias_step@2005-01-14T21:36:00")
    # the refit: bias back at the truth within its σ (the plain fit took the step in)
    assert abs(tab.loc[ax, "bias"] - BIAS[1]) < 3 * tab.loc[ax, "bias_sigma"]
    before = _calibrated_error(r["plain"], "step", r["true"], ax)
    after = _calibrated_error(r["closed"], "step", r["true"], ax)
    assert after <= before / 5, (before, after)
    # the outputs of --close-loop: report entry, closure.md, history of the calibrated file
    report = json.loads((r["closed"] / "step.report.json").read_text())
    assert report["closure"][ax]["model"] == tab.loc[ax, "model"]
    assert "bias_step" in (r["closed"] / "closure.md").read_text()
    assert any("close_loop" in h for h in report["history"])


def test_rerun_without_close_loop_drops_the_closure(runs, tmp_path):
    r = runs["clean"]
    src = r["closed"].parent / "clean.csv"
    ref = r["closed"].parent / "clean_ref.csv"
    out = tmp_path / "o"
    assert _run(src, "--reference", ref, *COMMON[:4], "--close-loop", "--out", out, "-q")[0] == 0
    assert (out / "closure.json").exists()
    code, msg = _run(src, "--reference", ref, *COMMON[:4], "--out", out, "-q")
    assert code == 0, msg
    assert not (out / "closure.json").exists()


def _arc_days(base: Path, n: int = 21_600, seed: int = 6) -> tuple[list[Path], Path, list]:
    """Three 6-hour files on consecutive days (a gap of 18 h between them), a 1e-8 m/s²
    bias step on y in the middle of the second; one reference table over the three."""
    rng = np.random.default_rng(seed)
    days, refs, trues = [], [], []
    for d in range(3):
        t = T_DAY - 43_200.0 + d * 86_400.0 + np.arange(n, dtype=float)
        true = _signal(t, rng)
        raw = true / SCALE + BIAS + DRIFT * (t - T_DAY)[:, None] + 1e-10 * rng.normal(size=(n, 3))
        if d == 1:
            raw[n // 2 :, 1] += 1e-8
        refs.append(
            pd.DataFrame(
                {
                    "gps_time": t,
                    **{
                        f"lin_accl_{a}": true[:, i] + 3e-10 * rng.normal(size=n)
                        for i, a in enumerate("xyz")
                    },
                }
            )
        )
        days.append(_write(base / f"d{d}.csv", t, raw))
        trues.append(true)
    ref = base / "ref.csv"
    pd.concat(refs).to_csv(ref, index=False, float_format="%.17g")
    return days, ref, trues


def test_close_loop_over_a_multi_day_arc(tmp_path):
    """``--arc 3d --close-loop``: each day's closure on its share of the arc's fit (a
    spline over the three days), the step found on its day only, the arc fitted again
    without it (before the closure the spline bent to the step on all three days).
    Seed 5 of this generator draws a 6.3e-11 ± 9.8e-12 m/s² "step" on the first day's z
    at p 0.0016, one of the false alarms the level α = 0.01 per axis allows (nine axes
    here); seed 6 has none."""
    days, ref, trues = _arc_days(tmp_path)
    common = ("--reference", ref, "--scale", "fit", "--bias-basis", "spline:6h", "--arc", "3d")
    out, plain = tmp_path / "closed", tmp_path / "plain"
    code, msg = _run(*days, *common, "--close-loop", "-q", "-j", "1", "--out", out)
    assert code == 0, msg
    assert _run(*days, *common, "-q", "-j", "1", "--out", plain)[0] == 0
    sources = json.loads((out / "closure.json").read_text())["sources"]
    assert set(sources) == {"d0.csv", "d1.csv", "d2.csv"}
    for name, entry in sources.items():
        for ax in "xyz":
            removed = entry[ax]["removed_from_calibrated"]
            if (name, ax) != ("d1.csv", "y"):
                assert removed == [], (name, ax, removed)
    (step,) = [e for e in sources["d1.csv"]["y"]["effects"] if e["name"] == "bias_step"]
    t_step = T_DAY - 43_200.0 + 86_400.0 + 10_800.0
    assert abs(step["epoch"] - t_step) <= 3.0
    assert abs(step["coefficient"] - 1e-8) < 2 * step["sigma"]
    tab = read_bias_drift(out / "bias_drift.parquet").set_index(["source", "axis"])
    assert "bias_step@" in tab.loc[("d1.csv", "y"), "model"]
    assert list(out.glob("arc_*.bias_basis.parquet"))
    for k, true in enumerate(trues):  # the calibrated y against the truth, every day
        before = _calibrated_error(plain, f"d{k}", true, "y")
        after = _calibrated_error(out, f"d{k}", true, "y")
        assert after <= (before / 5 if k == 1 else before), (k, before, after)
        assert after < 1.5e-10  # the raw noise (1e-10) times the scale


def test_arc_day_is_the_per_day_closure(tmp_path):
    t, _, raw, ref = _draw(6000, 4)
    day, ref = _write(tmp_path / "d.csv", t, raw), _write(tmp_path / "r.csv", t, ref)
    out = tmp_path / "out"
    code, msg = _run(day, "--reference", ref, *COMMON, "--arc", "day", "--close-loop", "--out", out)
    assert code == 0, msg
    assert set(json.loads((out / "closure.json").read_text())["sources"]["d.csv"]) == set("xyz")


@pytest.fixture(scope="module")
def noisy_runs(tmp_path_factory) -> dict[str, dict]:
    """A clean day and one with a bias step against a POD-like noisy reference
    (:func:`_pod_noise`): the clean day without and with --close-loop, the step day
    with it."""
    base = tmp_path_factory.mktemp("refcl_noisy")
    out: dict[str, dict] = {}
    for name, step, keys in (("clean", None, ("plain", "closed")), ("step", STEP, ("closed",))):
        t, true, raw, ref = _draw(N_DAY, 7, step, noisy=True)
        day = _write(base / f"{name}.csv", t, raw)
        ref_path = _write(base / f"{name}_ref.csv", t, ref)
        res = {"t": t, "true": true}
        for key in keys:
            o = base / f"{name}_{key}"
            extra = ("--close-loop",) if key == "closed" else ()
            code, msg = _run(day, "--reference", ref_path, *COMMON, *extra, "--out", o)
            assert code == 0, msg
            res[key] = o
        out[name] = res
    return out


def test_noisy_reference_clean_day_has_no_artefacts(noisy_runs):
    """A reference 2× noisier than the cross-track signal: no orbit-periodic or
    unexplained structure, nothing removed, the table the plain run's.  (Before: the
    closure regressed on the noisy reference, whose coefficient came out near −1
    (errors in variables), and periodic terms of 1e-8 m/s² were reported.)"""
    r = noisy_runs["clean"]
    summary = json.loads((r["closed"] / "closure.json").read_text())["sources"]["clean.csv"]
    for ax in "xyz":
        assert summary[ax]["removed_from_calibrated"] == []
        assert summary[ax]["effects"] == [], summary[ax]["effects"]
        assert not summary[ax].get("unexplained"), summary[ax].get("unexplained")
        assert [b["name"] for b in summary[ax]["base"]] == ["bias[0]", "bias[1]"]
    plain, closed = _table(r["plain"]), _table(r["closed"])
    pd.testing.assert_frame_equal(closed, plain)
    # the scales the closure holds fixed are the reference fit's, not attenuated
    np.testing.assert_allclose(closed["scale"].to_numpy(), SCALE, rtol=0.03)


def test_noisy_reference_step_day_finds_the_step_only(noisy_runs):
    r = noisy_runs["step"]
    entry = json.loads((r["closed"] / "closure.json").read_text())["sources"]["step.csv"]
    ax, frac, size = STEP
    removed = entry[ax]["removed_from_calibrated"]
    assert len(removed) == 1 and removed[0].startswith("bias_step@"), removed
    (e,) = [e for e in entry[ax]["effects"] if e["name"] == "bias_step"]
    assert abs(e["epoch"] - r["t"][int(frac * N_DAY)]) <= 60.0
    assert abs(e["coefficient"] - size) <= 3 * e["sigma"]
    for other in "xz":
        assert entry[other]["removed_from_calibrated"] == []
    tab = _table(r["closed"])
    # the bias (at the first sample, in raw units) within 2σ of the truth after the refit
    assert abs(tab.loc[ax, "bias"] - BIAS[1]) < 2 * tab.loc[ax, "bias_sigma"]


@pytest.mark.parametrize(("mode", "spec"), [("fit", "poly1"), ("fit-matrix", "spline:2h")])
def test_null_design_is_the_calibrated_residual(mode, spec):
    """Noise-free data: the closure's data are the fit's bias exactly (eq. 3: a_raw −
    S⁻¹a_ref with the fitted S), its base the bias basis alone, and its ``reference``
    (the scale candidate's regressor) the raw data less the fitted bias."""
    n = 20_000
    rng = np.random.default_rng(5)
    t = T_DAY + np.arange(n, dtype=float)
    true = _signal(t, rng)
    s = np.diag(SCALE)
    if mode == "fit-matrix":
        s = s + np.array([[0, 1e-3, -2e-3], [5e-4, 0, 1e-3], [-1e-3, 2e-3, 0]])
    raw = true @ np.linalg.inv(s).T + BIAS + DRIFT * (t - t[0])[:, None]
    basis = parse_bias_basis(spec, float(t[0]), float(t[-1]))
    fit = fit_reference(t, raw, true, np.ones(n, bool), basis, scale=mode)
    for i in range(3):
        y, base, signal = null_design(fit, i, t, raw, true)
        coef, *_ = np.linalg.lstsq(base.columns, y, rcond=None)
        resid = y - base.columns @ coef
        assert np.sqrt(np.mean(resid**2)) < 1e-6 * np.sqrt(np.mean(y**2))
        np.testing.assert_allclose(coef * base.scale, fit.bias_coef[i], rtol=1e-6, atol=1e-14)
        assert base.signal == () and base.columns.shape[1] == fit.basis.size
        np.testing.assert_allclose(signal, (true @ np.linalg.inv(s).T)[:, i], atol=1e-13)


def test_truth_and_a_coupling_to_a_table_channel(tmp_path):
    """A 5e-9 m/s² step on y and a 2e-9 m/s²/K coupling of z to a temperature column:
    both found and removed; with ``--truth`` (no reference scale in it) the estimates
    carry the true errors of bias and drift and closure.md is written.  (On x, where the
    drag's 6-17 h parts look like a step over 30,000 s, the plain fit's scale takes the
    step in: the closure, which holds that scale, sees only what is left.)"""
    n = 30_000
    t, _, raw, ref = _draw(n, 2, ("y", 0.5, 5e-9))
    temp = 20 + 0.5 * np.sin(2 * np.pi * (t - t[0]) / ORBIT + 0.3)
    temp += 0.3 * np.sin(2 * np.pi * (t - t[0]) / 20_000.0)
    raw[:, 2] += 2e-9 * (temp - temp.mean())
    day = tmp_path / "d.csv"
    pd.DataFrame(
        {"gps_time": t, **{f"lin_accl_{a}": raw[:, i] for i, a in enumerate("xyz")}, "temp": temp}
    ).to_csv(day, index=False, float_format="%.17g")
    ref = _write(tmp_path / "r.csv", t, ref)
    truth = tmp_path / "truth.json"
    truth.write_text(json.dumps({"t0": t[0], "bias": BIAS.tolist(), "drift": DRIFT.tolist()}))
    out = tmp_path / "out"
    code, msg = _run(day, "--reference", ref, *COMMON, "--truth", truth, "--out", out)
    assert code == 0, msg
    entry = json.loads((out / "closure.json").read_text())["sources"]["d.csv"]
    (step,) = [e for e in entry["y"]["effects"] if e["name"] == "bias_step"]
    assert (
        abs(step["epoch"] - t[n // 2]) <= 3 and abs(step["coefficient"] - 5e-9) < 2 * step["sigma"]
    )
    (cpl,) = [e for e in entry["z"]["effects"] if e["name"] == "auxiliary"]
    assert cpl["channel"] == "temp" and abs(cpl["coefficient"] - 2e-9) < 2 * cpl["sigma"]
    assert entry["x"]["removed_from_calibrated"] == []
    est = entry["y"]["estimates"]["reference"]
    assert set(est) == {"bias", "drift"}  # the truth has no reference scale
    assert abs(est["bias"]["true_error_after"]) < 3 * est["bias"]["sigma_after"]
    assert abs(est["bias"]["true_error_before"]) > 20 * abs(est["bias"]["true_error_after"])
    assert "true error after" in (out / "closure.md").read_text()


def test_fixed_scales_the_scale_candidate_is_not_attenuated_by_a_noisy_reference(tmp_path):
    """``--scale 1,1,1`` against a POD-like noisy reference: the ``scale`` candidate's
    regressor is the raw data less the bias, not the reference, so its coefficient is
    ``1 − s`` for a raw gain ``1/s`` (truth 0.04, 0.02, 0.05), not pulled towards −1."""
    t, _, raw, ref = _draw(N_DAY, 1, noisy=True)
    day, ref = _write(tmp_path / "d.csv", t, raw), _write(tmp_path / "r.csv", t, ref)
    out = tmp_path / "out"
    args = ("--scale", "1,1,1", "--bias-basis", "poly1", "-q", "-j", "1", "--close-loop")
    code, msg = _run(day, "--reference", ref, *args, "--out", out)
    assert code == 0, msg
    entry = json.loads((out / "closure.json").read_text())["sources"]["d.csv"]
    for i, ax in enumerate("xyz"):
        assert entry[ax]["removed_from_calibrated"] == ["scale"], entry[ax]["effects"]
        (e,) = [e for e in entry[ax]["effects"] if e["name"] == "scale"]
        assert abs(e["coefficient"] - (1 - SCALE[i])) < 3 * e["sigma"] < 0.03, e
