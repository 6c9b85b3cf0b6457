"""The JSON summary of one demodulated run (``summary.json``).

Rd, σ(T), masking, drops, the rotation pattern, the noise (a-priori and from the
data), the consistency check, the signal leakage and the optional sinusoid fit
(eq. 24); and :func:`find_run`, which finds the run a summary names again.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from accal import __version__
from accal.demodjob.options import DemodOptions, RunInfo
from accal.errors import ValidationError
from accal.estimators.demod import fit_sinusoid, sigma_mean, signal_leakage

#: Measured masked time differing from --mask by more than this fraction is flagged.
MASK_RTOL = 0.1
#: A shift shorter than this fraction of τ gives the pattern's period (τ + shift);
#: a longer one only says that the pattern does not repeat every τ.
SHIFT_NEAR = 1 / 8


def summarise(
    path: Path, info: RunInfo, res: Any, opts: DemodOptions, *, out_dir: Path | None = None
) -> dict[str, Any]:
    """The run summary (JSON-ready): Rd, σ(T), leakage, masking, drops, sinusoid fit.

    ``source`` is the run's path as given; ``source_path`` the resolved absolute
    path and, with ``out_dir`` (where the summary goes), ``source_relpath`` the
    path relative to it, so that the run is found again from any working
    directory, and after the run and the output directory moved together
    (:func:`find_run`).
    """
    n = res.a_Y.size
    rd = np.asarray(res.Rd, float)
    n_std = max(1, int(round(opts.integration / res.tau)))
    # σ of the mean of the kept periods at their own lags (no lag that no pair has)
    sigma_run = sigma_mean(rd, n, index=res.period_index)
    sigma_std = sigma_mean(rd, n_std)
    unknown = [k for k in range(1, min(n_std, rd.size)) if not np.isfinite(rd[k])]
    std_note = None
    if unknown:
        std_note = (
            f"not computed: Rd[{unknown[0]}] is unknown because no two kept periods are "
            f"{unknown[0]} period(s) apart ({res.dropped} of {res.n_periods} periods dropped); "
            f"the mean over {opts.integration:g} s of consecutive periods needs it"
        )
    dropped = sorted(set(range(res.n_periods)) - set(res.period_index.tolist()))
    mt = res.masked_time
    measured = float(np.median(mt))
    mismatch = abs(measured - opts.mask) > MASK_RTOL * max(opts.mask, 1.0 / res.fs)
    out: dict[str, Any] = {
        "source": str(path),
        "source_path": str(Path(path).resolve()),
        "source_relpath": _relpath(path, out_dir) if out_dir is not None else None,
        "accal_version": __version__,
        "input": {
            "n_rows": info.n_input,
            "n_samples": info.n_samples,
            "fs": res.fs,
            "duration": info.n_samples / res.fs,
            "t_first": info.t_first,
            "resampled": info.resample is not None,
            "resample": info.resample,
            "axes": info.axes,
            "aux_channels": info.aux_channels,
            "chunk_rows": int(opts.chunk_rows),
            "warnings": list(info.warnings),
        },
        "options": {
            "tau": opts.tau,
            "mask": opts.mask,
            "method": opts.method,
            "psd": opts.psd,
            "signal_model": opts.signal_model,
            "bias_model": opts.bias_model,
            "rest_tol": opts.rest_tol,
        },
        "solver": res.solver,
        "n_periods": res.n_periods,
        "n_kept": n,
        "dropped": res.dropped,
        "dropped_periods": dropped,
        "masked_fraction": res.masked_fraction,
        "mask": {
            "nominal": opts.mask,
            "measured_median": measured,
            "measured_min": float(mt.min()),
            "measured_max": float(mt.max()),
            "mismatch": bool(mismatch),
            "tolerance": MASK_RTOL,
        },
        "leakage_max": res.max_leakage,
        "pattern": _pattern_summary(res),
        "Rd": rd.tolist(),
        "Rd_units": "m^2/s^4 (autocovariance of a_Y per period lag, eq. 23)",
        "sigma_T": {
            "run": {"T": n * res.tau, "n_periods": n, "sigma": sigma_run},
            "standard": {
                "T": n_std * res.tau,
                "n_periods": n_std,
                "sigma": float("nan") if std_note else sigma_std,
                "note": std_note,
            },
            "units": "m/s^2 (1 sigma of the mean over T, full Rd[k]; the run's at the lags "
            "of its kept periods)",
        },
        "mean": {
            "a_Y": float(np.mean(res.a_Y)),
            "a_Z": float(np.mean(res.a_Z)),
            "sigma": sigma_run,
            "units": "m/s^2 (plain mean of the kept periods; sigma at their own lags)",
        },
        "noise": noise_summary(res, opts),
        "consistency": consistency_summary(res),
        "signal_leakage": leakage_summary(res),
    }
    if opts.sinusoid_period is not None:
        out["sinusoid"] = _sinusoid_summary(res, rd, opts)
    return out


def _pattern_summary(res: Any) -> dict[str, Any]:
    """How the rotation pattern repeats: shift from one period to the next, its period."""
    shift = float(getattr(res, "rotation_shift", float("nan")))
    m_periods = int(getattr(res, "pattern_periods", 0))
    # a steady shift of a few samples: the pattern's period is tau + shift; layouts that
    # repeat every m periods: m·tau (QA: --tau 300 on a 600 s pattern was told "give
    # --tau 332" from the shift between its two halves); otherwise it does not repeat
    near = bool(
        np.isfinite(shift)
        and abs(shift) / res.fs < SHIFT_NEAR * res.tau
        and getattr(res, "rotation_shift_steady", True)
    )
    if m_periods >= 1:
        every = m_periods * res.tau
    elif near:
        every = res.tau + shift / res.fs
    else:
        every = None
    return {
        "rotation_shift": shift / res.fs if np.isfinite(shift) else None,
        "repeats_every": every,
        "pattern_periods": m_periods,
        "units": "s (median shift of the rotations from one period to the next: 0 when "
        "the rotation pattern repeats every tau; the period it repeats with); "
        "pattern_periods: the layout repeats every that many periods (0: not found)",
    }


def _sinusoid_summary(res: Any, rd: np.ndarray, opts: DemodOptions) -> dict[str, Any]:
    """Fit of ``α cos + β sin`` (``+ c``) of period ``opts.sinusoid_period`` (eq. 24), per axis."""
    fits = {}
    for ax in ("Y", "Z"):
        fit = fit_sinusoid(
            res.t_mid,
            getattr(res, f"a_{ax}"),
            1.0 / opts.sinusoid_period,
            rd=rd,
            index=res.period_index,
            constant=opts.sinusoid_constant,
        )
        fits[ax] = {
            "alpha": fit.alpha,
            "beta": fit.beta,
            "offset": fit.offset if fit.constant else None,
            "cov": fit.cov.tolist(),
            "sigma_alpha": fit.sigma_alpha,
            "sigma_beta": fit.sigma_beta,
            "sigma_offset": fit.sigma_offset if fit.constant else None,
        }
    model = "a(t) = alpha cos(2 pi f* t) + beta sin(2 pi f* t)"
    return {
        "period": opts.sinusoid_period,
        "f_star": 1.0 / opts.sinusoid_period,
        "t_origin": 0.0,
        "constant": opts.sinusoid_constant,
        "model": model + (" + offset" if opts.sinusoid_constant else "") + ", t = t_mid",
        "units": "m/s^2 (alpha, beta, offset), m^2/s^4 (cov, order alpha, beta[, offset])",
        **fits,
    }


def noise_summary(res: Any, opts: DemodOptions) -> dict[str, Any]:
    """The a-priori and the empirical noise of a run (JSON-ready; issue 20).

    Levels are ``sqrt(S(2/τ))`` [m s⁻² Hz⁻¹ᐟ²], where the per-period estimate takes
    its noise (eq. 26, Fig. 3); ``sigma_ratio`` is the σ the a-priori PSD gives over
    the σ the data's PSD gives, for the same estimator.
    """
    rep = getattr(res, "noise", None)
    if rep is None:
        return {"psd_used": "apriori", "apriori": opts.psd}
    f2 = 2.0 / res.tau
    fit = rep.fit
    apriori = "microstar" if str(opts.psd).lower() == "auto" else opts.psd
    return {
        "psd_used": rep.source,
        "apriori": apriori,
        "reason": rep.reason or None,
        "n_periods": rep.n_periods,
        "f_level": f2,
        "level_apriori": float(np.sqrt(rep.apriori(f2))),
        "level_data": float(np.sqrt(fit.psd(f2))) if fit is not None else None,
        "sigma_ratio": rep.sigma_ratio if fit is not None else None,
        "misfit_periods": {str(k): v for k, v in sorted(getattr(rep, "misfit", {}).items())},
        "level_spread": float(getattr(rep, "level_spread", 1.0)),
        "level_scaled": bool(getattr(rep, "level", {})),
        "psd_data": (
            {"f": fit.nodes.tolist(), "S": fit.values.tolist()} if fit is not None else None
        ),
        "units": "levels m/s^2/sqrt(Hz) at f_level [Hz] = 2/tau (two-sided PSD); sigma_ratio: "
        "sigma from the a-priori PSD / sigma from the data's PSD, same estimator; psd_data: "
        "the PSD estimated from the residual, f [Hz], S [m^2/s^4/Hz] (usable as --psd FILE); "
        "misfit_periods: period -> root of its residual power near 2/tau over the median "
        "period's, left out of the noise estimate, its sigma scaled by that factor; "
        "level_spread: highest over lowest noise power near 2/tau of blocks of 12 periods; "
        "level_scaled: the level changes over the run and each period's sigma is scaled by "
        "the root of its block's level over the run's",
    }


def consistency_summary(res: Any) -> dict[str, Any]:
    """χ² of the run's residual against the PSD behind σ (replaces the old scatter/σ).

    ``ratio`` = observed / expected periodogram of the per-period residual over
    ``1/τ … 4/τ`` (the band that sets σ), expected under the PSD used: 1 within
    ``scatter`` when that PSD describes the noise of the run.
    """
    rep = getattr(res, "noise", None)
    if rep is None or not np.isfinite(rep.check_ratio):
        return {"ratio": None}
    return {
        "test": "residual periodogram / its expectation under the PSD used (chi2/dof), "
        "band 1/tau-4/tau",
        "ratio": rep.check_ratio,
        "scatter": rep.check_scatter,
        "band": list(rep.band),
    }


def leakage_summary(res: Any) -> dict[str, Any]:
    """Signal leakage (:func:`accal.estimators.demod.signal_leakage`) as a JSON-ready dict."""
    lk = signal_leakage(res)
    out: dict[str, Any] = {"n_periods": lk.n, "signal_model": res.signal_model}
    for j, ax in enumerate(("Y", "Z")):
        out[ax] = {
            "rms": float(lk.rms[j]),
            "ratio": float(lk.ratio[j]),
            "ratio_slope": float(lk.ratio_slope[j]),
            "max": float(lk.max[j]),
        }
    out["units"] = (
        "m/s^2 (rms: RMS over periods of the estimated leakage of the signal's in-period "
        "slope and curvature into a_Y, a_Z, noise removed; ratio: rms / RMS sigma; "
        "ratio_slope: the slope's part (removed by --signal-model affine); max: "
        "largest |estimate|, noise included; in_sigma: how many periods have their "
        "significant leakage in sigma, those where it exceeds the noise sigma, and the "
        "largest leakage / noise sigma)"
    )
    out["in_sigma"] = _leak_in_sigma(res)
    return out


def _leak_in_sigma(res: Any) -> dict[str, Any]:
    """The periods whose σ includes their leakage (:func:`accal.estimators.demod.
    with_signal_leak`) and the largest leakage in noise σ of those."""
    big = np.asarray(getattr(res, "signal_leak_in_sigma", np.empty((0, 2))), dtype=bool)
    added = np.asarray(getattr(res, "signal_leak_added", np.empty((0, 2))), dtype=np.float64)
    n = np.asarray(res.a_Y).size
    if big.shape != (n, 2) or added.shape != (n, 2) or not big.any():
        return {"n_periods": 0, "periods_over_sigma": [], "max_z": 0.0}
    sig = np.column_stack([res.sigma_Y, res.sigma_Z]).astype(np.float64)
    noise = np.sqrt(np.maximum(sig**2 - added**2, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(big, added / noise, 0.0)
    rows = np.flatnonzero((z > 1.0).any(axis=1))
    return {
        "n_periods": int(big.any(axis=1).sum()),
        "periods_over_sigma": [int(k) for k in np.asarray(res.period_index)[rows]],
        "max_z": float(np.nanmax(z)),
    }


def summary_of_extended(summary: dict[str, Any], rows: Mapping[str, Any], model: str) -> None:
    """Point the summary's mean at the extended model's per-period values.

    The declared model's go to ``summary["declared"]`` (QA: after a closure the
    summary's mean a_Y was still the declared model's, 23σ off, while the periods
    held the corrected values).  ``Rd``, the σ over T and the noise report stay
    those of the declared demodulation; the mean's σ is the extended model's
    (:func:`_extended_mean_sigma`).
    """
    summary["declared"] = {"mean": dict(summary["mean"])}
    for ax in ("Y", "Z"):
        a = np.asarray(rows[f"a_{ax}"], dtype=np.float64)
        s = np.asarray(rows[f"sigma_{ax}"], dtype=np.float64)
        ok = np.isfinite(a) & np.isfinite(s)
        summary["mean"][f"a_{ax}"] = float(np.mean(a[ok])) if ok.any() else float("nan")
    summary["mean"]["model"] = model
    sigma = _extended_mean_sigma(summary, rows)
    if sigma is not None:
        summary["mean"]["sigma"] = sigma
        summary["mean"]["units"] = (
            "m/s^2 (plain mean of the kept periods of the extended model; sigma: the "
            "declared one scaled by the periods' sigma after/before the closure, with "
            "the effects' coefficient errors, common to every period, added)"
        )


def _extended_mean_sigma(summary: dict[str, Any], rows: Mapping[str, Any]) -> float | None:
    """σ of the mean of the extended model's per-period values (None: no change known).

    Two parts, added in quadrature:

    * the noise: the declared mean's σ (its own estimator weights and ``Rd``) times
      the ratio of the periods' median σ after and before the closure, which is what
      it becomes when the PSD changes by a constant factor (``--psd auto`` estimates it
      again without the effects; QA: the declared σ of the mean was 4.8e-12 m/s² for
      an error of 6.5e-14 after a temperature coupling was taken out);
    * the effects' coefficients: an error ``δc`` of an effect moves every period alike,
      by ``δc/c`` of the change the effect made (linear in ``c``); the mean change over
      the periods times the largest relative σ ``σ_c/|c|`` of the effects found
      (exact for one effect, an upper estimate for several).
    """
    declared = float(summary["declared"]["mean"].get("sigma", float("nan")))
    if not np.isfinite(declared) or "sigma_Y_before" not in rows:
        return None
    noise2, common2 = 0.0, 0.0
    effects = (summary.get("closure") or {}).get("effects") or []
    rel = [
        float(e["sigma"]) / abs(float(e["coefficient"]))
        for e in effects
        if e.get("coefficient") and np.isfinite(e.get("sigma", np.nan))
    ]
    for ax in ("Y", "Z"):
        after = np.asarray(rows[f"sigma_{ax}"], dtype=np.float64)
        before = np.asarray(rows[f"sigma_{ax}_before"], dtype=np.float64)
        change = np.asarray(rows[f"change_{ax}"], dtype=np.float64)
        ok = np.isfinite(after) & np.isfinite(before) & (before > 0)
        if not ok.any():
            return None
        noise2 = max(noise2, (declared * float(np.median(after[ok] / before[ok]))) ** 2)
        moved = change[ok & np.isfinite(change)]
        if rel and moved.size:
            common2 = max(common2, (float(np.mean(moved)) * max(rel)) ** 2)
    return float(np.sqrt(noise2 + common2))


def _relpath(path: Path, start: Path) -> str | None:
    """``path`` relative to the directory ``start`` (None if there is no such path)."""
    try:
        return os.path.relpath(Path(path).resolve(), Path(start).resolve())
    except ValueError:  # another drive (Windows)
        return None


def find_run(summary: dict[str, Any], summary_path: Path) -> Path:
    """The run file a demod summary names, wherever the current directory is.

    Tried in order: ``source_path`` (absolute), ``source_relpath`` relative to the
    summary's directory, ``source`` as given (relative to the current directory),
    ``source`` relative to the summary's directory (summaries of older versions
    only have ``source``).

    Parameters
    ----------
    summary : dict
        The parsed ``summary.json``.
    summary_path : Path
        Its file.

    Returns
    -------
    Path
        The first candidate that exists.

    Raises
    ------
    ValidationError
        None exists (the message lists the places tried).
    """
    here = Path(summary_path).parent
    source = Path(summary["source"])
    tried: list[Path] = []
    for key, base in (("source_path", None), ("source_relpath", here), ("source", None)):
        value = summary.get(key)
        if isinstance(value, str) and value:
            tried.append(Path(value) if base is None else base / value)
    if not source.is_absolute():
        tried.append(here / source)
    seen: list[Path] = []
    for cand in tried:
        if cand not in seen:
            seen.append(cand)
        if cand.is_file():
            return cand
    raise ValidationError(
        f"{source}: run file of {Path(summary_path).name} not found (moved?); "
        f"looked for {', '.join(map(str, seen))}"
    )
