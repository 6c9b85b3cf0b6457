"""Markdown, JSON and plots of a closure result (files only where the caller says)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from accal.closure import close_loop
from accal.closure.demod import close_loop_demod
from accal.closure.report import plot_closure, result_to_dict, to_markdown, write_json


def test_markdown_json_and_plots(sim, tmp_path):
    d = sim(3, step=(0.4, 2e-9), n=43200, dt=2.0)
    res = close_loop(d["t"], d["y"], candidates=("bias_step",))
    md = to_markdown(res, truth=d["truth"])
    assert "bias_step" in md and "true error" in md
    epoch = res.effects[0].epoch
    assert f"epoch {epoch:.10g} s" in md  # absolute epochs are not rounded to 3 digits
    assert write_json(res, tmp_path / "closure.json").stat().st_size > 0
    a, b = plot_closure(res, tmp_path / "res.png", tmp_path / "psd.png")
    assert a.stat().st_size > 0 and b.stat().st_size > 0
    files = plot_closure(res, tmp_path / "r2.png", tmp_path / "p2.png", tmp_path / "e.png")
    assert len(files) == 3 and files[2].stat().st_size > 0
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "closure.json",
        "e.png",
        "p2.png",
        "psd.png",
        "r2.png",
        "res.png",
    ]


def test_demod_report_has_axes_notes_and_a_psd(platform, tmp_path):
    d = platform(4, settle=(2e-10, -1e-10, 20.0, "direction"))
    res, _ = close_loop_demod(d["t"], d["m"], d["theta"], tau=600.0)
    out = json.loads(json.dumps(result_to_dict(res)))
    assert out["channels"] == ["y", "z"]
    e = out["effects"][0]
    assert e["name"] == "intra_period_shape" and e["axis"] in ("y", "z")
    assert set(e["details"]["axes"]) == {"y", "z"}
    assert {"common", "rest@3.142"} <= {n["channel"] for n in out["notes"]}
    assert len(out["base"]) == 36 * 6  # a_Y, a_Z, bias and drift of both axes per period
    md = to_markdown(res)
    assert "not identifiable" in md and "more (closure.json)" in md
    assert md.count("\n| a_Y[") <= 30
    # rests of ≤ 132 s: no Welch segment, the binned gapped periodogram is used
    assert res.stats_after.freq.size > 10 and np.all(np.isfinite(res.stats_after.psd))
    paths = plot_closure(res, tmp_path / "r.png", tmp_path / "p.png", tmp_path / "e.png")
    assert all(p.stat().st_size > 10_000 for p in paths)


def test_eliminated_effects_say_which_member(sim):
    """An effect added then eliminated names its epoch/frequency/lag and its p at admission."""
    import dataclasses

    from accal.closure.select import Effect

    d = sim(3, step=(0.4, 2e-9), n=43200, dt=2.0)
    res = close_loop(d["t"], d["y"], candidates=("bias_step",))
    gone = Effect("bias_step", None, float("nan"), float("nan"), 1e-5, epoch=1.5e8)
    line = Effect("periodic", "line", float("nan"), float("nan"), 2e-3, frequency=1e-3)
    out = result_to_dict(dataclasses.replace(res, eliminated=(gone, line)))
    # "eliminated", not "removed": these were not removed from the data (QA, 2026-11-29:
    # a key "removed" that was always empty read as "nothing removed")
    assert "removed" not in out
    assert out["eliminated"] == [
        {"name": "bias_step", "channel": None, "p_accept": 1e-5, "epoch": 1.5e8},
        {"name": "periodic", "channel": "line", "p_accept": 2e-3, "frequency": 1e-3},
    ]
    md = to_markdown(dataclasses.replace(res, eliminated=(gone, line)))
    # the Markdown names the step by its epoch, not "bias_step (None)" (QA)
    assert "eliminated (stood in for another effect): bias_step@2004-10-02T14:40:00GPS, " in md
    assert "periodic(0.001 Hz)" in md and "(None)" not in md


def test_exponential_time_constant_reported_with_its_sigma():
    """closure.json carries details.tau_sigma and the Markdown prints τ ± σ(τ)."""
    rng = np.random.default_rng(4)
    t = np.arange(0.0, 86400.0, 2.0)
    y = 1e-7 + 1e-12 * t + 3e-9 * np.exp(-t / 5000.0) + 1e-11 * rng.standard_normal(t.size)
    res = close_loop(t, y, candidates=("exponential_drift",))
    e = res.effects[0]
    assert e.name == "exponential_drift"
    sig = e.details["tau_sigma"]
    assert 0 < sig < 0.05 * e.tau and abs(e.tau - 5000.0) < 4 * sig
    out = json.loads(json.dumps(result_to_dict(res)))
    assert out["effects"][0]["details"]["tau_sigma"] == sig
    assert "± " in to_markdown(res).split("exponential_drift", 1)[1].splitlines()[0]


def test_the_old_name_of_eliminated_still_works_and_warns(sim):
    """``ClosureResult.removed`` was the eliminated effects: it stays, deprecated."""
    import dataclasses

    from accal.closure.select import Effect

    d = sim(3, n=4320, dt=20.0)
    res = close_loop(d["t"], d["y"], candidates=("bias_step",))
    gone = Effect("bias_step", None, float("nan"), float("nan"), 1e-5, epoch=1.5e8)
    res = dataclasses.replace(res, eliminated=(gone,))
    with pytest.warns(DeprecationWarning, match="eliminated"):
        assert res.removed == (gone,)
