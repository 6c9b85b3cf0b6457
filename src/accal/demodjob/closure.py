"""Closing the loop on a demodulated run (``accal demod --close-loop``).

:func:`close_run` reads the run whole and runs
:func:`accal.closure.demod.close_loop_demod` with the declared demodulation
model as base; with ``--psd auto`` the PSD is estimated again without the
effects found, and with ``--method gls`` the per-period values are the GLS ones
(section 5.3).
"""

from __future__ import annotations

import contextlib
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from accal.demodjob.options import DemodOptions
from accal.demodjob.reading import estimate, load_psd
from accal.errors import ValidationError
from accal.estimators.demod import demodulate
from accal.estimators.resample import nominal_step, resample_uniform
from accal.io.rawlog import read_rawlog
from accal.io.writers import atomic_path


def close_run(
    path: Path, opts: DemodOptions, out_dir: Path, *, step: float | None = None, psd: Any = None
) -> tuple[dict[str, Any], Any, list[Path]]:
    """Close the loop on one run with the demodulation model as base.

    The run is read whole (:func:`accal.io.rawlog.read_rawlog`) and, with
    ``opts.resample``, resampled as the demodulation resampled it
    (:func:`accal.estimators.resample.resample_uniform` onto ``t0 + k·step``, gaps
    longer than ``opts.gap_factor`` steps kept as invalid samples, the grid point
    just after the last sample held); the declared
    model is the per-period signal (``--signal-model``) and affine bias (plus the
    ``--bias-model`` channels, eq. 18); every auxiliary channel (the declared ones
    for lagged couplings) is offered to the ``auxiliary`` candidate, with the platform candidates (angle offset,
    intra-period bias shape) and the generic ones (steps, periodic terms,
    polynomial drift).  Plots go to ``out_dir/<stem>.closure*.png``.

    Parameters
    ----------
    path : Path
        The run file.
    opts : DemodOptions
        Options of the demodulation (``tau``, models, ``resample``, ``gap_factor``, ``alpha``).
    out_dir : Path
        Where the plots go.
    step : float, optional
        With ``opts.resample``: the grid step the demodulation used [s]; default
        :func:`accal.estimators.resample.nominal_step` of the run.
    psd : PSD, optional
        The noise model of the demodulation (with ``--psd auto`` the PSD estimated
        from the run), for the per-period sigmas; made here when not given
        (``--psd auto``: by demodulating the run once).

    Returns
    -------
    closure : dict
        ``closure.json`` entry of the run (:meth:`ClosureResult.to_dict` plus
        ``model`` and per-period change statistics).
    periods : DemodPeriods
        Per-period values before/after.
    plots : list of Path
    """
    # here, not at the top: accal.closure takes ~1.2 s to import (pandas, scipy; measured
    # with python -X importtime), which a run without --close-loop does not need
    from accal.closure.demod import close_loop_demod
    from accal.closure.report import to_markdown

    if psd is None and str(opts.psd).lower() == "auto":  # the PSD from the data, as demod
        res0, _ = estimate(path, opts, load_psd(opts.psd))
        psd = res0.noise.used if res0.noise is not None else load_psd(opts.psd)
    elif psd is None:
        psd = load_psd(opts.psd)
    series = read_rawlog(path)
    time, valid = series.time, series.valid
    cols = {
        "m_y": series.acc[:, list(series.axes).index("y")],
        "m_z": series.acc[:, list(series.axes).index("z")],
        **{k: np.asarray(v, dtype=np.float64) for k, v in series.aux.items()},
    }
    if opts.resample:  # the grid of the demodulation (validated_chunks' UniformResampler)
        grid_step = step if step is not None else nominal_step(time, opts.tau)
        time, cols, valid, _ = resample_uniform(
            time, cols, grid_step, gap_factor=opts.gap_factor, hold_end=True
        )
    theta = cols["theta"]
    chans = {k: v for k, v in cols.items() if k not in ("m_y", "m_z", "theta")}
    bias_aux = {c: chans[c] for c in opts.aux_channels if c in chans}
    missing = [c for c in opts.aux_channels if c not in chans]
    if missing:
        raise ValidationError(f"bias-model channel(s) {missing} not in the run")
    # every varying channel, the declared ones too: at lag 0 they are in the base, but a
    # lagged coupling to one is not (QA: with temp2 declared, a 120 s coupling to it
    # went unreported and a_Y was off by up to 76σ)
    aux = {k: v for k, v in chans.items() if np.isfinite(v).any() and np.ptp(v[np.isfinite(v)]) > 0}

    psd_after = psd

    def without_effects(model: np.ndarray) -> Any:
        """With ``--psd auto``: the PSD estimated again without the effects found
        (``model``, interleaved y, z; the first estimate was made on the declared
        model's residual, which holds them; issue 20, QA: an undeclared 2e-8
        temperature coupling made sigma 16x the error); None otherwise."""
        nonlocal psd_after
        if str(opts.psd).lower() != "auto":
            return None
        psd_after = _psd_without_effects(
            (model[0::2], model[1::2]), time, cols, theta, valid, bias_aux, opts, psd
        )
        return psd_after

    res, periods = close_loop_demod(
        time,
        (cols["m_y"], cols["m_z"]),
        theta,
        valid,
        tau=opts.tau,
        signal_model=opts.signal_model,
        bias_model="affine",
        bias_aux=bias_aux or None,
        aux=aux or None,
        alpha=opts.alpha,
        rest_tol=opts.rest_tol,
        # sigmas before/after with the demodulation's own noise model (--psd)
        noise_psd=psd,
        psd_update=without_effects,  # the final fit again with it, not the search
    )
    if opts.method == "gls":  # also with no effect: "before" and "after" are GLS values
        periods = _gls_after(
            res, periods, time, cols, theta, valid, bias_aux, opts, psd, psd_after=psd_after
        )
    entry = res.to_dict()
    if psd_after is not psd:  # --psd auto, effects found: the noise without them
        f2 = 2.0 / opts.tau
        entry["noise_after"] = {
            "f_level": f2,
            "level_data": float(np.sqrt(psd_after(f2))),
            "units": "level m/s^2/sqrt(Hz) at f_level [Hz] = 2/tau (two-sided PSD), "
            "estimated with the closure's effects removed",
        }
    entry["method"] = opts.method
    entry["model"] = "+".join(["declared", *periods.effects])
    entry["periods"] = change_statistics(periods.to_table())
    entry["markdown"] = to_markdown(res, title=f"{path.name}: closing the loop")
    stem = path.name.split(".")[0]
    plots = _closure_plots(res, out_dir, stem) if opts.plots else []
    return entry, periods, plots


def closure_summary(entry: Mapping[str, Any]) -> dict[str, Any]:
    """The closure's part of a run's ``summary.json``: its effects, the residual RMS
    before and after, the model, and (``--psd auto``) the noise level without the
    effects (``noise_after``)."""
    keys = ("effects", "unexplained", "rms_before", "rms_after", "model", "noise_after")
    return {k: entry[k] for k in keys if k in entry}


def change_statistics(table: Mapping[str, Any]) -> dict[str, Any]:
    """RMS and median ``|change|/σ`` of the per-period change of ``a_Y``, ``a_Z``.

    ``table`` has ``period``, ``change_*``, ``sigma_change_*`` and ``sigma_*`` (after)
    columns: the periods rows, or :meth:`DemodPeriods.to_table`.

    Periods the closure left unchanged (change and its σ at rounding level, e.g.
    1e-22 ± 7e-27 m/s² beside a step in another period) count as 0 σ: their
    ratio of two rounding errors is meaningless (QA: "median |change|/σ 2.1e4").
    """
    out: dict[str, Any] = {"n": int(np.asarray(table["period"]).size)}
    for ax in ("Y", "Z"):
        change = np.asarray(table[f"change_{ax}"], dtype=np.float64)
        sig = np.asarray(table[f"sigma_change_{ax}"], dtype=np.float64)
        scale = np.asarray(table[f"sigma_{ax}"], dtype=np.float64)
        ok = np.isfinite(change)
        real = ok & (sig > 1e-6 * np.abs(scale))
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(real, np.abs(change) / sig, 0.0)[ok]
        out[f"median_abs_change_{ax}_sigmas"] = float(np.median(ratio)) if ratio.size else None
        out[f"n_changed_{ax}"] = int(np.count_nonzero(real))
        out[f"rms_change_{ax}"] = float(np.sqrt(np.mean(change[ok] ** 2))) if ok.any() else None
    return out


def _effects_model(res: Any) -> tuple[np.ndarray, np.ndarray]:
    """The closure's fitted effects on ``(m_y, m_z)`` [m s⁻²] (0 when none was found)."""
    k = res.effect_columns.shape[1]  # an effect may have a column per axis
    gamma = np.asarray(res.coef[res.coef.size - k :], dtype=np.float64)
    model = np.nan_to_num(res.effect_columns) @ gamma
    return model[0::2], model[1::2]


def _psd_without_effects(
    model: tuple[np.ndarray, np.ndarray],
    time: np.ndarray,
    cols: dict[str, np.ndarray],
    theta: np.ndarray,
    valid: Any,
    bias_aux: dict[str, np.ndarray],
    opts: DemodOptions,
    psd: Any,
) -> Any:
    """The PSD from the data (``--psd auto``) of the run with the closure's effects
    ``model = (m_y, m_z)`` [m s⁻²] removed.

    Samples where the model is NaN (those the closure left out: a lagged channel
    made up there) are left out of the estimate too: the misfit of the made-up
    regressor there is not noise (QA, data drawn outside accal: a 3e-8 m/s²/K
    coupling at 630 s left its first 630 s in the estimate, and every σ after the
    closure came out ~12 times the error).  ``psd`` itself when the run is too short
    for it.
    """
    my, mz = model
    gone = ~(np.isfinite(my) & np.isfinite(mz))
    if gone.any():
        kept = np.ones(my.size, dtype=bool) if valid is None else np.asarray(valid, dtype=bool)
        valid = kept & ~gone
        my, mz = np.nan_to_num(my), np.nan_to_num(mz)
    r = demodulate(
        time,
        cols["m_y"] - my,
        cols["m_z"] - mz,
        theta,
        tau=opts.tau,
        mask=opts.mask,
        signal_model=opts.signal_model,
        bias_aux=bias_aux or None,
        psd=load_psd(opts.psd),
        valid=valid,
        rest_tol=opts.rest_tol,
        noise="data",
    )
    return r.noise.used if r.noise is not None and r.noise.source == "data" else psd


def _gls_after(
    res: Any,
    periods: Any,
    time: np.ndarray,
    cols: dict[str, np.ndarray],
    theta: np.ndarray,
    valid: Any,
    bias_aux: dict[str, np.ndarray],
    opts: DemodOptions,
    psd: Any,
    *,
    psd_after: Any = None,
) -> Any:
    """The extended model's per-period values with the declared ``--method gls``.

    The closure fits its effects by least squares together with the declared
    model; with ``--method gls`` the user asked for the GLS estimator (section
    5.3), so the effects found are subtracted from ``m_y``, ``m_z`` and the run is
    demodulated again as declared (as ``grace-bias`` refits the calibrated series).
    The σ after adds to that GLS σ the variance the closure attributes to the
    effects' estimation, ``σ²_after,LS − σ²_before,LS`` (QA: with ``--method gls
    --close-loop`` the LS values were written, ``a_Y_before`` was GLS, and the
    change was an estimator difference).  "Before" is the declared GLS
    demodulation of the same samples, so the change and its statistics are those
    of the GLS values (the same from ``accal diagnose``).
    """
    k = res.effect_columns.shape[1]  # an effect may have a column per axis
    model_y, model_z = _effects_model(res)

    def gls(m_y: np.ndarray, m_z: np.ndarray, noise_psd: Any = psd) -> Any:
        return demodulate(
            time,
            m_y,
            m_z,
            theta,
            tau=opts.tau,
            mask=opts.mask,
            method="gls",
            signal_model=opts.signal_model,
            bias_aux=bias_aux or None,
            psd=noise_psd if noise_psd is not None else load_psd(opts.psd),
            valid=valid,
            rest_tol=opts.rest_tol,
        )

    # declared (as the periods rows have it) and with the effects subtracted (with
    # --psd auto: under the PSD of the run without the effects)
    before = gls(cols["m_y"], cols["m_z"])
    # nothing found: the declared GLS values (QA: the closure's LS values were written
    # as "after", 0.6σ from "before", with a change of σ 0)
    after = (
        gls(cols["m_y"] - model_y, cols["m_z"] - model_z, psd_after if psd_after else psd)
        if k
        else before
    )
    new: dict[str, np.ndarray] = {}
    for kind, r in (("before", before), ("after", after)):
        where = {int(p): i for i, p in enumerate(r.period_index)}
        pick = np.array([where.get(int(p), -1) for p in periods.period_index], dtype=np.int64)
        have = pick >= 0

        def take(x: np.ndarray, pick: np.ndarray = pick, have: np.ndarray = have) -> np.ndarray:
            out = np.full(pick.size, np.nan)
            out[have] = np.asarray(x)[pick[have]]
            return out

        for ax in ("Y", "Z"):
            new[f"a_{ax}_{kind}"] = take(getattr(r, f"a_{ax}"))
            sg = take(getattr(r, f"sigma_{ax}"))
            if kind == "after":
                extra = np.maximum(
                    getattr(periods, f"sigma_{ax}_after") ** 2
                    - getattr(periods, f"sigma_{ax}_before") ** 2,
                    0.0,
                )
                sg = np.sqrt(sg**2 + extra)
            new[f"sigma_{ax}_{kind}"] = sg
            if opts.signal_model == "affine":
                new[f"slope_{ax}_{kind}"] = take(getattr(r, f"slope_{ax}"))
                if kind == "after":
                    new[f"sigma_slope_{ax}_after"] = take(getattr(r, f"sigma_slope_{ax}"))
    for ax in ("Y", "Z"):
        new[f"change_{ax}"] = new[f"a_{ax}_after"] - new[f"a_{ax}_before"]
    return replace(periods, **new)


def _closure_plots(res: Any, out_dir: Path, stem: str) -> list[Path]:
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return []
    from accal.closure.report import plot_closure  # ~1.2 s to import: see close_run

    names = [out_dir / f"{stem}.closure{k}.png" for k in ("", "-psd", "-effects")]
    with contextlib.ExitStack() as stack:
        tmps = [stack.enter_context(atomic_path(p)) for p in names]
        pngs = [t.with_name(t.name + ".png") for t in tmps]
        plot_closure(res, *pngs, title=f"{stem} (accal demod)")
        for png, t in zip(pngs, tmps, strict=True):
            png.replace(t)
    return names
