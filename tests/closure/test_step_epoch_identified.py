"""A bias step is removed only where its epoch is determined (closure.validation.
distant_epoch, issue 19 item 3).

The case that showed it: an `accal simulate` storm + thruster day with a lagged,
low-passed temperature coupling on z (the README's walk-through).  The coupling was found
with the right lag and time constant, then displaced by three z "steps" whose epochs
could have been anywhere in the day (profile within ΔW ≤ 3 over 85,000 s).  And a real
step, drawn here (numpy only), keeps a sharp epoch and is removed.
"""

from __future__ import annotations

import json

import numpy as np
from click.testing import CliRunner

from accal.cli import main
from accal.closure import close_loop

N = 40_000
SIGMA = 1e-10  # m/s² per sample


def test_a_real_step_keeps_a_sharp_epoch_and_is_removed():
    rng = np.random.default_rng(11)
    t = np.arange(N, dtype=float)
    y = 2e-7 + 3e-15 * t + SIGMA * rng.standard_normal(N) + np.where(t >= 22_000, 1e-10, 0.0)
    res = close_loop(t, y, candidates=("bias_step",), signal_model="none")
    steps = [e for e in res.effects if e.name == "bias_step"]
    assert len(steps) == 1, [(e.epoch, e.coefficient) for e in res.effects]
    s = steps[0]
    lo, hi = s.details["epoch_interval"]
    assert lo <= 22_000 <= hi and hi - lo < 0.02 * N
    assert abs(s.coefficient - 1e-10) < 3 * s.sigma


def test_steps_that_could_be_anywhere_do_not_displace_a_coupling(tmp_path):
    day = tmp_path / "day.asc"
    run = CliRunner()
    res = run.invoke(main, [
        "simulate", "grace", "--date", "2005-01-01", "--satellite", "A", "--storm",
        "--thrusters", "--effect", "coupling:axis=z,channel=temperature,coef=3e-9,lag=600,tau=300",
        "--out", str(day),
    ], catch_exceptions=False)  # fmt: skip
    assert res.exit_code == 0, res.output
    out = tmp_path / "o"
    res = run.invoke(main, [
        "grace-bias", str(day), "--aux", f"{day}.aux.parquet", "--close-loop", "--out",
        str(out), "-q", "--method", "wavelet",
    ], catch_exceptions=False)  # fmt: skip
    assert res.exit_code == 0, res.output
    z = json.loads((out / "closure.json").read_text())["sources"]["day.asc"]["z"]
    removed = [e for e in z["effects"] if e["instrument"]]
    assert not [e for e in removed if e["name"] == "bias_step"], removed
    # steps proposed there are reported, with the reason (three were before the orbit
    # period was weighted by each axis' noise; since, the period fits the eclipse edges
    # and none is proposed: the reason is tested on a drawn record below)
    why = [e["details"]["reason"] for e in z["rejected"] if e["name"] == "bias_step"]
    assert all("more than one step would there" in w for w in why), why
    # the coupling is the effect found, to 5 % of the truth.  With the day band-limited
    # like Level-1B data (CRN-like filter on signal and effects), 0.18 % of the channel's
    # variation lies outside the orbit-signal model, under the 0.2 % identifiability bound,
    # so it is reported, not removed (docs/closure.md)
    # (a rejected coupling has no σ: its coefficient, on the samples the spike screen
    # keeps, was 3.7 % off with the one-sided medians and 5.4 % with the sides' lines)
    (c,) = [e for e in z["effects"] + z["rejected"] if e["name"] == "auxiliary"]
    assert c["channel"] == "temperature" and abs(c["coefficient"] - 3e-9) < 0.06 * 3e-9
    if c in removed:
        assert abs(c["lag"] - 600.0) < 2 * c["details"]["lag_sigma"]
        # the coupling's c·T̄ (~8.8e-7 m/s²) leaves the bias: it is now the truth's
        truth = json.loads(day.with_name("day.asc.truth.json").read_text())
        b = z["estimates"]["wavelet"]["bias"]
        assert abs(b["after"] - truth["bias"][2]) < 2 * b["sigma_after"], (b, truth["bias"][2])
    else:
        assert c["details"]["reason"].startswith("not identifiable: only"), c["details"]
        assert c["details"]["cross_validation"]["ratio"] > 0.9  # confirmed out of sample


def test_a_lone_step_that_fits_as_well_at_the_other_end_is_not_identifiable():
    """A record whose first and last 600 s sit 1e-9 m/s² high (drawn here): one step
    at either end explains as much as at the other, 38,800 s away, so a lone step is
    reported with the reason; the two steps together are what the data show."""
    rng = np.random.default_rng(2)
    t = np.arange(N, dtype=float)
    ends = (t < 600) | (t >= N - 600)
    y = 2e-7 + 1e-9 * ends + SIGMA * rng.standard_normal(N)
    res = close_loop(t, y, candidates=("bias_step",), signal_model="none")
    why = [e.details["reason"] for e in res.rejected if e.name == "bias_step"]
    assert len(why) == 1 and "more than one step would there" in why[0], why
    steps = sorted((e for e in res.effects if e.name == "bias_step"), key=lambda e: e.epoch)
    assert [e.epoch for e in steps] == [600.0, N - 600.0]
    for e, size in zip(steps, (-1e-9, 1e-9), strict=True):
        assert abs(e.coefficient - size) < 3 * e.sigma
