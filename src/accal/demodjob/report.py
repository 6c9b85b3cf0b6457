"""What a demod summary tells a person: warnings for stderr and ``summary.md``."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from accal.estimators.demod import LAYOUT_LAGS

#: A-priori and empirical σ differing by more than this factor (either way) is a warning.
NOISE_RATIO_WARN = 2.0
#: Signal leakage (RMS over periods, in σ) above which ``summary_warnings`` tells.
LEAKAGE_WARN = 0.3
#: Shift of the rotations from one period to the next above which --tau is taken not
#: to match the pattern [samples]: 0 for a pattern that repeats every τ (also with a
#: four-angle pattern, an affine signal model, or jittered and resampled timing), 1
#: for a 600 s pattern demodulated with --tau 599 at 1 Hz.
SHIFT_WARN = 0.5


def tau_of(summary: dict[str, Any]) -> float:
    """The modulation period ``--tau`` a summary was made with [s]."""
    return float(summary["options"]["tau"])


def summary_warnings(summary: dict[str, Any]) -> tuple[str, ...]:
    """Findings of a summary worth a line on stderr."""
    w = list(summary["input"].get("warnings") or [])
    m = summary["mask"]
    if m["mismatch"]:
        w.append(
            f"measured masked time {m['measured_median']:g} s per period differs from "
            f"--mask {m['nominal']:g} s by more than {100 * m['tolerance']:g} %"
        )
    misfit = (summary.get("noise") or {}).get("misfit_periods") or {}
    if misfit:
        which = _ranges([int(k) for k in misfit], limit=8)
        top = max(misfit.values())
        w.append(
            f"{len(misfit)} period(s) ({which}) have a residual up to {top:.0f}x the others' "
            "(a feature of the data the model lacks): left out of the noise estimate, their "
            "sigma scaled by it"
        )
    if summary["dropped"]:
        which = _ranges(summary.get("dropped_periods") or [], limit=8)
        w.append(
            f"{summary['dropped']} of {summary['n_periods']} periods dropped"
            + (f" ({which})" if which else "")
        )
    # samples after the last whole period are not used (QA: a 900 s run said "1/1
    # periods" with its last 300 s silently left out)
    fs = summary["input"]["fs"]
    tail = int(summary["input"]["n_samples"]) - int(
        round(summary["n_periods"] * tau_of(summary) * fs)
    )
    if tail > 0:
        w.append(
            f"the last {tail / fs:g} s ({tail} samples) are less than one period "
            f"(--tau {tau_of(summary):g} s) and are not used"
        )
    # eq. 16 leakage alone is no fault: the joint fit of eq. 17 (chosen whenever it is not
    # ~0) removes the bias whatever the pattern (four angles, an affine signal model, jitter
    # give some).  What is wrong is a --tau that is not the pattern's period: then the
    # rotations move from one period to the next.
    pat = summary.get("pattern") or {}
    shift, tau = pat.get("rotation_shift"), tau_of(summary)
    m_periods = int(pat.get("pattern_periods") or 0)
    if m_periods > 1:
        w.append(
            f"the rotations differ from one period to the next and repeat every {m_periods} "
            f"periods: the pattern's period is {m_periods * tau:.9g} s, not --tau {tau:g} s; "
            f"give --tau {m_periods * tau:.9g}"
        )
    elif (
        m_periods == 0
        and pat.get("repeats_every") is None
        and "pattern_periods" in pat
        and shift is not None
        and np.isfinite(shift)  # at least two periods to compare
    ):
        w.append(
            f"the rotations differ from one period to the next and do not repeat within "
            f"{LAYOUT_LAGS} periods: the pattern does not repeat every --tau {tau:g} s; give "
            "--tau its period (or fix the time column)"
        )
    elif (
        m_periods != 1 and shift is not None and np.isfinite(shift) and abs(shift) * fs > SHIFT_WARN
    ):
        leak = summary.get("leakage_max")
        leak_text = (
            f"; eq. 16 leakage up to {leak:.2g}, removed by the joint fit of eq. 17"
            if leak is not None and np.isfinite(leak) and leak > 1e-9
            else ""
        )
        every = pat.get("repeats_every")
        if every is not None:
            what = f"the pattern repeats every {every:.9g} s, not --tau {tau:g} s; give --tau {every:.9g}"
        else:
            what = f"the pattern does not repeat every --tau {tau:g} s; give --tau its period"
        w.append(
            f"the rotations move by {shift:+.9g} s from one period to the next: {what} "
            f"(or fix the time column){leak_text}"
        )
    w += _noise_warnings(summary)
    rs = summary["input"].get("resample")
    if rs:
        held = rs.get("n_end_held", 0)
        w.append(
            f"resampled onto a {rs['step']:.9g} s grid: {rs['n_interpolated']} samples "
            f"interpolated, {rs['n_gap']} in {rs['n_gaps']} gap(s) marked invalid "
            f"(largest gap {rs['largest_gap']:.9g} s)"
            + (f", {held} grid point after the last sample took its value" if held else "")
        )
    return tuple(w)


def _noise_warnings(summary: dict[str, Any]) -> list[str]:
    """Warnings on the noise (a-priori vs data, fall-back) and on the signal leakage."""
    w: list[str] = []
    nz = summary.get("noise") or {}
    auto = str(summary["options"].get("psd")).lower() == "auto"
    ratio = nz.get("sigma_ratio")
    if auto and nz.get("psd_used") == "apriori" and nz.get("reason"):
        w.append(
            f"sigma from the a-priori PSD ({nz['apriori']}), not from the data: "
            f"{nz['reason']}; check it against the instrument's noise"
        )
    if nz.get("level_scaled"):
        w.append(
            f"the noise level near 2/tau changes over the run (blocks of 12 periods span "
            f"{nz['level_spread']:.3g} x in power): each period's sigma is scaled by its "
            "block's level (the PSD's shape is the run's)"
        )
    if ratio is not None and not 1 / NOISE_RATIO_WARN <= ratio <= NOISE_RATIO_WARN:
        what = (
            "sigma, Rd and GLS use the PSD from the data"
            if nz.get("psd_used") == "data"
            else f"sigma uses --psd {nz['apriori']} as asked: it is {ratio:.3g} x what the "
            "run's noise gives (drop --psd to use the data's)"
        )
        after = (summary.get("closure") or {}).get("noise_after")
        closed = (
            f"; without the closure's effects the data give {after['level_data']:.3g}, "
            "the sigma after the closure use that"
            if after
            else ""
        )
        w.append(
            f"the noise of this run differs from the a-priori PSD ({nz['apriori']}) by more "
            f"than a factor {NOISE_RATIO_WARN:g}: sigma a-priori / sigma data = {ratio:.3g} "
            f"(noise at 2/tau: {nz['level_apriori']:.3g} a-priori, {nz['level_data']:.3g} "
            f"data, m/s^2/sqrt(Hz){closed}); {what}"
        )
    lk = summary.get("signal_leakage") or {}
    worst = max((lk[ax]["ratio"] for ax in ("Y", "Z") if ax in lk), default=float("nan"))
    if np.isfinite(worst) and worst > LEAKAGE_WARN:
        slope = max(lk[ax].get("ratio_slope", 0.0) for ax in ("Y", "Z") if ax in lk)
        hint = (
            "use --signal-model affine"
            if lk.get("signal_model") == "mean" and slope > 0.5 * worst
            else "it is the signal's curvature: a shorter --tau reduces it"
        )
        cut = lk.get("in_sigma") or {}
        held = (
            f"each period's sigma holds its own where significant ({cut['n_periods']} "
            "periods, columns signal_leak_Y/Z)"
            if cut.get("n_periods")
            else "not in sigma"
        )
        w.append(
            f"the signal's variation within a period leaks into a_Y/a_Z at {worst:.2g} sigma "
            f"(RMS over periods, --signal-model {lk.get('signal_model')}); {held}; {hint}"
        )
    cut = lk.get("in_sigma") or {}
    over = cut.get("periods_over_sigma") or []
    if over and not (np.isfinite(worst) and worst > LEAKAGE_WARN and len(over) > 8):
        some = ", ".join(str(k) for k in over[:8])
        more = f" and {len(over) - 8} more" if len(over) > 8 else ""
        hint = (
            "; --signal-model affine removes the slope's part"
            if lk.get("signal_model") == "mean"
            else ""
        )
        w.append(
            f"period(s) {some}{more}: the signal's change within the period leaks into "
            f"a_Y/a_Z by up to {cut['max_z']:.3g} sigma of the noise (a rest layout lopsided "
            "about t_mid: a period cut by a gap or the run's end, or a run that does not "
            "start where its pattern does); their sigma_Y/sigma_Z include it (columns "
            f"signal_leak_Y/Z){hint}"
        )
    return w


def summary_markdown(s: dict[str, Any]) -> str:
    """Human-readable version of the summary."""

    def e(x: Any) -> str:
        return "n/a" if x is None or (isinstance(x, float) and not np.isfinite(x)) else f"{x:.4g}"

    o = s["options"]
    rs = s["input"].get("resample")
    resampled = ""
    if rs:
        resampled = (
            f" (resampled to {rs['step']:.9g} s: {rs['n_interpolated']} interpolated, "
            f"{rs['n_gap']} in {rs['n_gaps']} gap(s) masked)"
        )
    lines = [
        f"# accal demod: {Path(s['source']).name}",
        "",
        f"accal {s['accal_version']}; tau = {o['tau']:g} s, mask = {o['mask']:g} s, "
        f"method = {o['method']} ({s['solver']}), signal model = {o['signal_model']}, "
        f"bias model = {o['bias_model']}, PSD = {o['psd']}.",
        "",
        "| quantity | value |",
        "| --- | --- |",
        f"| samples, fs | {s['input']['n_samples']}, {s['input']['fs']:g} Hz{resampled} |",
        f"| periods kept / whole | {s['n_kept']} / {s['n_periods']} |",
        f"| dropped periods | {_ranges(s['dropped_periods']) or 'none'} |",
        f"| masked fraction | {s['masked_fraction']:.4f} |",
        f"| masked time per period (median, min–max) | {s['mask']['measured_median']:g} s "
        f"({s['mask']['measured_min']:g}–{s['mask']['measured_max']:g}); --mask {o['mask']:g} s"
        f"{' **MISMATCH**' if s['mask']['mismatch'] else ''} |",
        f"| max eq. 16 leakage | {e(s['leakage_max'])} |",
        f"| Rd[0..{len(s['Rd']) - 1}] [m²/s⁴] | {', '.join(e(x) for x in s['Rd'])} |",
        f"| σ of the mean over the run ({s['sigma_T']['run']['T']:g} s) | "
        f"{e(s['sigma_T']['run']['sigma'])} m/s² |",
        f"| σ of the mean over {s['sigma_T']['standard']['T']:g} s | "
        + (
            f"n/a ({s['sigma_T']['standard']['note']}) |"
            if s["sigma_T"]["standard"].get("note")
            else f"{e(s['sigma_T']['standard']['sigma'])} m/s² |"
        ),
        f"| mean a_Y, a_Z{_of_model(s)} | {e(s['mean']['a_Y'])}, {e(s['mean']['a_Z'])} m/s² |",
        *_noise_markdown(s, e),
    ]
    if "declared" in s:
        d = s["declared"]
        lines += [
            f"| mean a_Y, a_Z (declared model) | {e(d['mean']['a_Y'])}, {e(d['mean']['a_Z'])} "
            "m/s² |",
        ]
    if "sinusoid" in s:
        sn = s["sinusoid"]
        for ax in ("Y", "Z"):
            f = sn[ax]
            off = f", c = {e(f['offset'])} ± {e(f['sigma_offset'])}" if sn.get("constant") else ""
            lines.append(
                f"| sinusoid {ax} (P = {sn['period']:g} s): α, β ± σ | "
                f"{e(f['alpha'])} ± {e(f['sigma_alpha'])}, {e(f['beta'])} ± {e(f['sigma_beta'])}"
                f" m/s², cov(α,β) = {e(f['cov'][0][1])}{off} |"
            )
    return "\n".join(lines) + "\n"


def _noise_markdown(s: dict[str, Any], e: Callable[[Any], str]) -> list[str]:
    """Rows of the summary table on the noise, the consistency check and the leakage."""
    nz = s.get("noise") or {}
    rows = []
    if "level_apriori" in nz:
        used = "the run's residual (data)" if nz["psd_used"] == "data" else nz["apriori"]
        why = f" ({nz['reason']})" if nz.get("reason") and nz["psd_used"] != "data" else ""
        rows += [
            f"| σ, Rd, GLS from the PSD of | {used}{why} |",
            f"| noise at 2/τ: a-priori ({nz['apriori']}), data [m/s²/√Hz] | "
            f"{e(nz['level_apriori'])}, {e(nz['level_data'])} |",
            f"| σ a-priori / σ data (same estimator) | {e(nz['sigma_ratio'])} |",
        ]
    after = (s.get("closure") or {}).get("noise_after")
    if after:
        rows.append(
            f"| noise at 2/τ without the closure's effects (σ after it) [m/s²/√Hz] | "
            f"{e(after['level_data'])} |"
        )
    c = s.get("consistency") or {}
    if c.get("ratio") is not None:
        rows.append(
            f"| residual power / expected under the PSD used, {e(c['band'][0])}–"
            f"{e(c['band'][1])} Hz (χ²/dof; 1 ± {e(c['scatter'])}) | {e(c['ratio'])} |"
        )
    lk = s.get("signal_leakage") or {}
    if "Y" in lk:
        rows.append(
            f"| in-period signal leakage, RMS/σ (Y, Z; `{lk['signal_model']}` model) | "
            f"{e(lk['Y']['ratio'])}, {e(lk['Z']['ratio'])} |"
        )
    return rows


def _of_model(s: dict[str, Any]) -> str:
    model = s["mean"].get("model")
    return f" (`{model}`)" if model else ""


def _ranges(index: Sequence[int], limit: int = 40) -> str:
    """``[1, 2, 3, 7]`` → ``"1–3, 7"`` (at most ``limit`` ranges shown)."""
    out: list[str] = []
    idx = list(index)
    i = 0
    while i < len(idx):
        j = i
        while j + 1 < len(idx) and idx[j + 1] == idx[j] + 1:
            j += 1
        out.append(str(idx[i]) if i == j else f"{idx[i]}–{idx[j]}")
        i = j + 1
    more = len(out) - limit
    return ", ".join(out[:limit]) + (f", ... ({more} more ranges)" if more > 0 else "")
