"""Issue 19's acceptance cases on data accal did not generate (``tests/indep``).

Every day, run and table here comes from the independent generators (no import of
accal) or from the real Swarm-A day; accal sees them only through its readers and its
CLI or public API, as a user would.  The criteria are the issue's "done means":
nothing removed from a clean day and no estimate moved by more than its σ; an
injected effect found with the right name and its coefficient within 2σ; a table's
own channels considered without ``--aux``; the target never regressed on itself.
The Monte-Carlo rates behind these single cases are in ``make closure-detection``
(docs/closure.md).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from tests.indep import (
    grace_day,
    platform_run,
    swarm_day_with_channels,
    write_acc1b_grace,
    write_swarm_table,
    write_table,
)

from accal.cli import main
from accal.closure.demod import close_loop_demod


def invoke(*args):
    res = CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)
    return res.exit_code, res.stdout, res.stderr


def _closure(out, name):
    return json.loads((out / "closure.json").read_text())["sources"][name]


def _removed(entry, ax):
    return [e for e in entry[ax]["effects"] if e["instrument"]]


@pytest.fixture(scope="module")
def clean_day(tmp_path_factory):
    """A clean, real-like GRACE-A day (all 12 columns live, eclipses, thrusters) and a
    temperature table as --aux."""
    tmp = tmp_path_factory.mktemp("indep_clean")
    day = grace_day(31, "A", thrusters=True, gaps=1)
    path = write_acc1b_grace(day, tmp / day.l1b_name())
    aux = write_table(
        tmp / "temperature.parquet",
        {"time": day.time, "temperature": day.channels["temperature"]},
        units={"time": "s", "temperature": "K"},
    )
    return day, path, aux


def test_clean_day_nothing_removed_nothing_moved(clean_day, tmp_path):
    day, path, aux = clean_day
    code, _, err = invoke(
        "grace-bias", path, "--close-loop", "--aux", aux, "--method", "lsq", "--out", tmp_path, "-q"
    )
    assert code == 0, err
    entry = _closure(tmp_path, path.name)
    for ax in "xyz":
        assert not _removed(entry, ax), (ax, _removed(entry, ax))
        for q in ("bias", "drift"):
            assert entry[ax]["estimates"]["lsq"][q]["change_sigmas"] <= 1.0
        # the file's own angular accelerations were candidates beside the --aux channel
        tested = {c["channel"] for c in entry[ax]["considered"] if c["status"] == "considered"}
        assert {"temperature", "ang_accl_x", "ang_accl_y", "ang_accl_z"} <= tested, tested


def test_step_on_an_independent_day_is_found(tmp_path):
    """A 5e-9 m/s² step on y (cross-track: the drag is small there)."""
    epoch = 50_000.0
    day = grace_day(31, "A", thrusters=True, gaps=1, effects=[("step", "y", epoch, 5e-9)])
    path = write_acc1b_grace(day, tmp_path / day.l1b_name())
    out = tmp_path / "o"
    code, _, err = invoke("grace-bias", path, "--close-loop", "--method", "lsq", "--out", out, "-q")
    assert code == 0, err
    entry = _closure(out, path.name)
    removed = _removed(entry, "y")
    assert [e["name"] for e in removed] == ["bias_step"], removed
    assert abs(removed[0]["epoch"] - (day.truth["t0"] + epoch)) <= 60.0
    assert abs(removed[0]["coefficient"] - 5e-9) < 2 * removed[0]["sigma"]
    for ax in "xz":
        assert not _removed(entry, ax)


def test_scale_error_with_a_reference_is_found(tmp_path):
    """+2 % scale on x; the reference is the true non-gravitational acceleration."""
    day = grace_day(32, "A", effects=[("scale", "x", 0.02)])
    path = write_acc1b_grace(day, tmp_path / day.l1b_name())
    ref = write_table(
        tmp_path / "ref.parquet",
        {"gps_time": day.time, **{f"lin_accl_{a}": day.signal[:, i] for i, a in enumerate("xyz")}},
        units={"gps_time": "s", **{f"lin_accl_{a}": "m/s^2" for a in "xyz"}},
    )
    out = tmp_path / "o"
    code, _, err = invoke(
        "grace-bias", path, "--close-loop", "--reference", ref, "--method", "lsq",
        "--out", out, "-q",
    )  # fmt: skip
    assert code == 0, err
    entry = _closure(out, path.name)
    scale = [e for e in _removed(entry, "x") if e["name"] == "scale"]
    assert scale, entry["x"]["effects"]
    # raw − reference = (s·(1 + 0.02) − 1)·a + ...: the reported δs is relative to the
    # reference, i.e. the whole scale error of x
    s = day.truth["scale"][0] * 1.02
    assert abs(scale[0]["coefficient"] - (s - 1.0)) < 2 * scale[0]["sigma"] + 1e-6


def test_swarm_table_columns_are_candidates_and_never_the_target(tmp_path):
    """The real Swarm-A day as a table with a temperature column: without --aux the
    column is considered (also from a CSV without units); the table as its own --aux
    never regresses a_cal_x on itself."""
    day = swarm_day_with_channels(Path(__file__).resolve().parents[2] / "data" / "samples", 3)
    parquet = write_swarm_table(day, tmp_path / "swarm.parquet")
    plain = tmp_path / "swarm.csv"  # a plain CSV: no unit of any column
    day.table.to_csv(plain, index=False)
    for k, (path, extra) in enumerate(((parquet, []), (parquet, ["--aux", parquet]), (plain, []))):
        out = tmp_path / f"o{k}"
        code, _, err = invoke(
            "grace-bias", path, "--column", "x=a_cal_x", "--close-loop", "--out", out, "-q",
            "--force", *extra,
        )  # fmt: skip
        assert code == 0, err
        entry = _closure(out, path.name)["x"]
        status = {c["channel"]: c["status"] for c in entry["considered"]}
        assert status.get("temperature") == "considered", status
        assert status.get("a_cal_x", "left out") != "considered"
        assert not any(e.get("channel") == "a_cal_x" for e in entry["effects"])
        # the null: nothing removed from the ESA-calibrated series
        assert not _removed({"x": entry}, "x")


def _platform(run):
    tab = run.table
    return (
        tab["time"].to_numpy(),
        (tab["m_y"].to_numpy(), tab["m_z"].to_numpy()),
        tab["theta"].to_numpy(),
        {"temperature": tab["temperature"].to_numpy()},
    )


def _errors(per, truth_periods):
    tp = truth_periods.set_index("t_mid") if "t_mid" in truth_periods else truth_periods
    true_y = np.interp(per.t_mid, tp.index.to_numpy(), tp["a_Y"].to_numpy())
    return (
        float(np.sqrt(np.mean((per.a_Y_before - true_y) ** 2))),
        float(np.sqrt(np.mean((per.a_Y_after - true_y) ** 2))),
        float(np.median(per.sigma_Y_after)),
    )


def test_clean_platform_run_is_not_made_worse():
    run = platform_run(41, days=1.0)
    t, m, theta, aux = _platform(run)
    res, per = close_loop_demod(t, m, theta, tau=600.0, aux=aux)
    assert not res.effects, [e.name for e in res.effects]
    before, after, _ = _errors(per, run.periods)
    assert after <= 1.1 * before


def test_in_period_quadratic_on_the_platform_is_found():
    coef = 2.28e-13
    run = platform_run(42, days=1.0, effects=[("inperiod_quadratic", coef)])
    t, m, theta, aux = _platform(run)
    res, per = close_loop_demod(t, m, theta, tau=600.0, aux=aux)
    # demod's quadratic_drift is the in-period one, (t − t_k)² in every period k (one
    # column per axis); measured 2.2802e-13 ± 4.5e-16, a_Y error 3.7e-11 -> 4.4e-12
    names = [e.name for e in res.effects]
    assert names == ["quadratic_drift"], names
    e = res.effects[0]
    assert abs(e.coefficient - coef) < 2 * e.sigma
    before, after, sigma = _errors(per, run.periods)
    assert after <= max(before / 5.0, 2.0 * sigma), (before, after, sigma)


def test_platform_shape_that_stands_in_for_a_coupling_is_not_removed():
    """A lagged temperature coupling (3e-8 m/s²/K, lag 1466 s) on a platform run: a
    direction-dependent settling shape with 1.2 % of its variation outside the
    per-period signal took its place and moved every a_Z by 9.4σ (error 4.7e-12 ->
    1.8e-10 m/s², closure-detection seed 7301).  Such a shape is not identifiable
    (``kinds.SHAPE_IDENT_MIN``): reported, not removed; a_Y/a_Z no worse."""
    from accal.estimators.noise import as_psd

    run = platform_run(7301, days=1.0, effects=[("coupling", "temperature", 3e-8, 1465.83, "both")])
    t, m, theta, aux = _platform(run)
    res, per = close_loop_demod(
        t, m, theta, tau=600.0, aux=aux, rest_tol=1e-9, noise_psd=as_psd(None)
    )
    assert "intra_period_shape" not in [e.name for e in res.effects]
    shapes = [e for e in res.rejected if e.name == "intra_period_shape"]
    assert all("not identifiable" in e.details["reason"] for e in shapes)
    tp = run.periods.set_index("t_mid") if "t_mid" in run.periods else run.periods
    for ax in "YZ":
        true = np.interp(per.t_mid, tp.index.to_numpy(), tp[f"a_{ax}"].to_numpy())
        before = np.sqrt(np.mean((getattr(per, f"a_{ax}_before") - true) ** 2))
        after = np.sqrt(np.mean((getattr(per, f"a_{ax}_after") - true) ** 2))
        sigma = float(np.median(getattr(per, f"sigma_{ax}_after")))
        # issue 19's bound for an injected effect; measured a_Y 4.98e-12 -> 5.54e-12
        # (σ 4.9e-12): the coupling is kept at the alias 2666.5 s of 1465.8 s, whose
        # random walk moves a_Y (σ holds that spread, closure/aliasspread.py); with the
        # shape in its place the error had been 1.8e-10
        assert after <= max(before / 5.0, 2.0 * sigma), (ax, before, after, sigma)


def test_platform_coupling_at_an_alias_lag_keeps_honest_sigmas():
    """A 3e-8 m/s²/K coupling at 1543 s on a platform run whose temperature repeats with
    the rotation: the search keeps the alias 343 s (lags 943 and 1543 s listed as
    aliases).  Closure-detection seed 7307 had a_Y std z 3.19 after closure: the first
    period, 343 s of it left out, 52σ off; and the aliases move a_Y by ~0.9σ RMS, which
    σ did not hold.  Now that period is left out and σ holds the aliases' spread
    (measured: std z 1.18 -> 1.06, a_Z 1.14 -> 1.05; 1.33 without the spread), the
    coefficient's too."""
    from accal.estimators.noise import as_psd

    run = platform_run(
        7307, days=1.0, effects=[("coupling", "temperature", -3e-8, 1543.09, "both")]
    )
    t, m, theta, aux = _platform(run)
    res, per = close_loop_demod(
        t, m, theta, tau=600.0, aux=aux, rest_tol=1e-9, noise_psd=as_psd(None)
    )
    (e,) = [e for e in res.effects if e.name == "auxiliary"]
    # an alias's coefficient is biased (couplings._shortest_lag): −3.0264e-8 ± 1.1e-10,
    # 2.4σ, with the noise's σ; ± 1.9e-10, 1.4σ, with the aliases' spread
    assert e.details["coefficient_sigma_without_aliases"] < e.sigma
    assert abs(e.coefficient + 3e-8) < 2 * e.sigma
    aliases = e.details["base_sigma_aliases"]
    assert any(abs(a - 1543.09) < 10 for a in aliases), aliases
    assert 0 not in per.period_index
    tp = run.periods.set_index("period")
    for ax in "YZ":
        true = tp.loc[per.period_index, f"a_{ax}_rest"].to_numpy()
        z = (getattr(per, f"a_{ax}_after") - true) / getattr(per, f"sigma_{ax}_after")
        assert 0.8 < float(np.std(z)) < 1.25, ax
        assert float(np.max(np.abs(z))) < 4.5, ax


def test_platform_coupling_short_lag_no_low_pass_and_the_signal_models_leak():
    """A 3e-8 m/s²/K coupling at 23.3 s without a low-pass (closure-detection seed
    7304).  The refinement had stopped on the lag/low-pass ridge at 10.6 s with τ
    14.1 s (coefficient 3.67e-8, 2.2σ); polished, the lag is 23.2 s without a
    low-pass.  At the true lag the least squares are still 3.12e-8 (y) and 3.19e-8
    (z): the "mean" signal model's in-period leak, 5.6σ of the noise's σ; the σ now
    holds the change the signal's slope in the model makes (measured z 0.92)."""
    from accal.estimators.noise import as_psd

    run = platform_run(7304, days=1.0, effects=[("coupling", "temperature", 3e-8, 23.2977, "both")])
    t, m, theta, aux = _platform(run)
    res, _ = close_loop_demod(
        t, m, theta, tau=600.0, aux=aux, rest_tol=1e-9, noise_psd=as_psd(None)
    )
    (e,) = [e for e in res.effects if e.name == "auxiliary"]
    assert e.tau == 0.0 and abs(e.lag - 23.3) < 1.0, (e.lag, e.tau)
    for ax, d in e.details["axes"].items():
        z = (d["coefficient"] - 3e-8) / d["sigma"]
        z_noise = (d["coefficient"] - 3e-8) / d["sigma_without_signal_model"]
        assert abs(z) < 2.0, (ax, z)
        assert z_noise > 3.0, (ax, z_noise)  # measured 3.5 (y), 5.6 (z)


def test_platform_coupling_between_the_grid_lags_is_found():
    """A 3e-8 m/s²/K coupling at 1757.2 s (closure-detection seed 7309), missed by the
    31-lag grid (120 s apart: the temperature's part outside the per-period base
    decorrelates within ~35 s).  Scanned at every sample lag it is found at its lag
    (measured 1757.24 ± 1.05 s, coefficient −2.991e-8 ± 2.97e-10); with the grid
    (``lag_scan="grid"``) nothing is found."""
    from accal.estimators.noise import as_psd

    truth = 1757.1575520585868
    run = platform_run(7309, days=1.0, effects=[("coupling", "temperature", -3e-8, truth, "both")])
    t, m, theta, aux = _platform(run)
    kw = {"tau": 600.0, "aux": aux, "rest_tol": 1e-9, "noise_psd": as_psd(None)}
    res, _ = close_loop_demod(t, m, theta, **kw)
    (e,) = [e for e in res.effects if e.name == "auxiliary"]
    assert abs(e.coefficient + 3e-8) < 2 * e.sigma, (e.coefficient, e.sigma)
    assert abs(e.lag - truth) < 3 * e.details["lag_sigma"], (e.lag, e.details["lag_sigma"])
    grid, _ = close_loop_demod(t, m, theta, options={"lag_scan": "grid"}, **kw)
    assert not [e for e in grid.effects if e.name == "auxiliary"]


def test_a_later_coupling_is_searched_again_without_its_made_up_start():
    """A 3e-7 m/s²/K coupling through a 200 s low-pass at 400 s, added here to a clean
    run (half on z; the low-pass an exact first-order recursion from the first value,
    as accal assumes the channel's unknown history).  The search without the first
    ~1,300 s, where the lagged, filtered channel is made up, did not find it (p_adj
    0.024; 2e-5 with them): the first coupling stays, and the search went on to add the
    channel's square at a 3,173 s lag, made up over its first 3,173 s, never searched
    again without them (the code before: both in the model).  Now the square pauses
    the search too, and without every coupling's made-up samples it is not kept
    (measured: the coupling 3.12e-7 ± 3.6e-8 on y, 2.0e-8 ± 1.1e-7 on z; the square
    eliminated)."""
    from accal.estimators.noise import as_psd

    run = platform_run(11, days=1.0)
    t, (my, mz), theta, aux = _platform(run)
    temp = aux["temperature"]
    a = np.exp(-1.0 / 200.0)
    y = np.empty_like(temp)
    y[0] = temp[0]
    for k in range(1, temp.size):
        y[k] = a * y[k - 1] + (1 - a) * temp[k]
    x = np.interp(t - 400.0, t, y)
    res, _ = close_loop_demod(
        t, (my + 3e-7 * x, mz + 1.5e-7 * x), theta, tau=600.0, aux=aux, rest_tol=1e-9,
        noise_psd=as_psd(None),
    )  # fmt: skip
    assert [(e.name, e.channel) for e in res.effects] == [("auxiliary", "temperature")]
    (e,) = res.effects
    for ax, want in (("y", 3e-7), ("z", 1.5e-7)):
        d = e.details["axes"][ax]
        assert abs(d["coefficient"] - want) < 2 * d["sigma"], (ax, d["coefficient"], d["sigma"])
    assert abs(e.lag + e.tau - 600.0) < 100.0  # lag 398 s, τ 212 s: on the lag/τ ridge


def test_a_square_fitting_the_signals_in_period_leak_is_not_removed():
    """A clean run (`tests.indep` seed 9001): the temperature with its square had
    p_adj 7e-5 at the first step, the same under white noise of 1e-11 m/s² (so the
    signal, not the noise): the "mean" per-period signal leaves the signal's change
    within a period, with the rotation's rhythm, in the residual, and the square of a
    temperature kicked at every rotation fits it.  It was removed (at 174 s, and at
    466 s with the 31-lag grid); with the signal's slope in the model its p_adj is 1,
    so it is not identifiable, reported and not removed."""
    from accal.estimators.noise import as_psd

    run = platform_run(9001, days=1.0)
    t, m, theta, aux = _platform(run)
    res, per = close_loop_demod(
        t, m, theta, tau=600.0, aux=aux, rest_tol=1e-9, noise_psd=as_psd(None)
    )
    assert not res.effects, [(e.name, e.channel) for e in res.effects]
    (rej,) = [e for e in res.rejected if e.name == "auxiliary"]
    assert "signal's change within a modulation period" in rej.details["reason"]
    assert np.all(per.a_Y_after == per.a_Y_before)
