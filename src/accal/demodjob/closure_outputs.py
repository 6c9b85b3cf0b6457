"""What a closure of the loop writes: extended periods rows, ``closure.json``/``.md``."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from accal import __version__
from accal.closure_reports import read_sources
from accal.demodjob.outputs import json_text
from accal.estimators.demod import sigma_factor
from accal.io.writers import atomic_path


def leak_of(res: Any, opts: Any) -> Any:
    """The signal's leakage in the σ of the declared demodulation ``res``
    (``signal_leak_added``) for :func:`apply_closure`, or None with ``--method gls``,
    whose values after the closure come from a demodulation again (with its own)."""
    if str(getattr(opts, "method", "")).lower() == "gls":
        return None
    return getattr(res, "signal_leak_added", None)


def misfit_of(res: Any) -> Any:
    """Per row of the declared demodulation ``res``: the factor its σ was scaled by for
    its misfit (``NoiseReport.misfit``, 1 elsewhere), for :func:`apply_closure`; None
    without one."""
    rep = getattr(res, "noise", None)
    if rep is None or not (rep.misfit or rep.level) or getattr(rep, "source", "") != "data":
        return None
    return np.array([sigma_factor(rep, int(k)) for k in res.period_index], dtype=np.float64)


def apply_closure(
    rows: dict[str, Any],
    units: dict[str, str],
    periods: Any,
    leak_added: Any = None,
    misfit: Any = None,
) -> tuple[dict[str, Any], dict[str, str]]:
    """Periods rows with the extended model's ``a_Y``/``a_Z`` (declared ones as ``*_before``).

    Periods the closure could not determine keep NaN in the extended columns.
    ``leak_added`` (n, 2), the signal's leakage the declared demodulation put into
    each row's σ (``DemodResult.signal_leak_added``,
    :func:`accal.estimators.demod.with_signal_leak`): the closure's own σ are the
    noise's, and its instrument effects do not change the signal's leakage, so it is
    added to them in quadrature too (QA, 2026-11-29: a period cut by a gap had σ_Y
    8.96e-12 before the closure and 7.24e-13 after with nothing removed, its error
    −9.6e-12 going from −1.1σ to −13.2σ).  ``misfit`` (n,): the factor each row's σ
    was scaled by in the declared demodulation for its misfit (:func:`misfit_of`):
    where over 1, the σ after the closure is at least the declared one (its noise
    model is the run's PSD without those periods), unless the closure moved the
    period's value by more than the declared σ.
    """
    idx = {int(k): i for i, k in enumerate(periods.period_index)}
    where = np.array([idx.get(int(k), -1) for k in rows["period"]], dtype=np.int64)
    have = where >= 0

    def take(values: np.ndarray) -> np.ndarray:
        out = np.full(where.size, np.nan)
        out[have] = np.asarray(values, dtype=np.float64)[where[have]]
        return out

    rows = dict(rows)
    for ax in ("Y", "Z"):
        rows[f"a_{ax}_before"] = rows[f"a_{ax}"]
        rows[f"sigma_{ax}_before"] = rows[f"sigma_{ax}"]
        rows[f"a_{ax}"] = take(getattr(periods, f"a_{ax}_after"))
        rows[f"sigma_{ax}"] = take(getattr(periods, f"sigma_{ax}_after"))
        if misfit is not None and np.shape(misfit) == (where.size,):
            # not below the declared σ, which holds the misfit, unless the closure moved
            # the period's value by more than it (an effect it removed explains the
            # misfit); the closure's own σ may hold it already (a signal step it reports)
            moved = np.abs(rows[f"a_{ax}"] - rows[f"a_{ax}_before"]) > rows[f"sigma_{ax}_before"]
            big = (np.asarray(misfit, dtype=np.float64) > 1.0) & ~moved
            rows[f"sigma_{ax}"] = np.where(
                big, np.fmax(rows[f"sigma_{ax}"], rows[f"sigma_{ax}_before"]), rows[f"sigma_{ax}"]
            )
        if leak_added is not None and np.shape(leak_added) == (where.size, 2):
            add = np.asarray(leak_added, dtype=np.float64)[:, "YZ".index(ax)]
            rows[f"sigma_{ax}"] = np.hypot(rows[f"sigma_{ax}"], add)
        rows[f"change_{ax}"] = rows[f"a_{ax}"] - rows[f"a_{ax}_before"]
        sc = take(getattr(periods, f"sigma_change_{ax}"))
        # the closure analysed these periods on fewer samples than the declared fit (a
        # lagged coupling's unknown start is left out): its change σ is not that of
        # this difference (QA: period 0, change_Z -2.6e-11 ± 1.3e-12 on an axis with
        # nothing injected); σ_after ⊕ σ_before bounds it (the two correlate positively)
        other = np.abs(take(getattr(periods, f"a_{ax}_before")) - rows[f"a_{ax}_before"]) > (
            1e-3 * np.abs(rows[f"sigma_{ax}_before"])
        )
        rows[f"sigma_change_{ax}"] = np.where(
            other, np.hypot(rows[f"sigma_{ax}"], rows[f"sigma_{ax}_before"]), sc
        )
    n = where.size
    model = "+".join(["declared", *periods.effects])
    rows["model"] = np.array([model] * n, dtype=object)
    units = dict(units)
    for ax in ("Y", "Z"):
        units[f"a_{ax}"] = f"m/s^2 (mean a_{ax} over the period, extended model of --close-loop)"
        units[f"sigma_{ax}"] = "m/s^2 (1 sigma, extended model, coloured-noise sandwich)"
        units[f"a_{ax}_before"] = "m/s^2 (declared demodulation model, --method)"
        units[f"sigma_{ax}_before"] = "m/s^2 (1 sigma, declared model)"
        units[f"change_{ax}"] = "m/s^2 (extended - declared)"
        units[f"sigma_change_{ax}"] = (
            "m/s^2 (1 sigma of the change, closure's covariance; periods the closure "
            "analysed on fewer samples (a lagged coupling's unknown start): sigma_after "
            "(+) sigma_before, an upper bound)"
        )
    units["model"] = "declared model plus the effects --close-loop added"
    return rows, units


def write_demod_closure(
    out_dir: Path, source: str, entry: dict[str, Any] | None
) -> tuple[Path, Path]:
    """Merge one run's closure into ``OUT/closure.json`` / ``closure.md`` (layout: ``sources``).

    ``entry=None`` (the source redone without ``--close-loop``) removes the source's
    entry and plots; with no source left the two files are removed.
    """
    jpath, mpath = out_dir / "closure.json", out_dir / "closure.md"
    sources = read_sources(jpath)
    if entry is None:
        if sources.pop(source, None) is None:
            return jpath, mpath
        stem = source.split(".")[0]
        for k in ("", "-psd", "-effects"):
            (out_dir / f"{stem}.closure{k}.png").unlink(missing_ok=True)
        if not sources:
            for f in (jpath, mpath):
                f.unlink(missing_ok=True)
            return jpath, mpath
    else:
        sources[source] = entry
    sources = dict(sorted(sources.items()))
    with atomic_path(jpath) as tmp:
        tmp.write_text(json_text({"accal_version": __version__, "sources": sources}))
    lines = ["# accal demod: closing the loop", ""]
    for src, e in sources.items():
        lines.append(e.get("markdown", f"## {src}").rstrip())
        per = e.get("periods") or {}
        lines += [
            "",
            f"Model: `{e.get('model')}`"
            + (f", per-period values by `--method {e['method']}`" if e.get("method") else "")
            + ". Per-period change of a_Y/a_Z (extended - declared): "
            f"RMS {_g(per.get('rms_change_Y'))} / {_g(per.get('rms_change_Z'))} m/s², median "
            f"|change|/σ {_g(per.get('median_abs_change_Y_sigmas'))} / "
            f"{_g(per.get('median_abs_change_Z_sigmas'))} over {per.get('n', 0)} periods"
            + (
                f" ({per['n_changed_Y']} / {per['n_changed_Z']} changed beyond rounding)."
                if "n_changed_Y" in per
                else "."
            ),
            "",
        ]
    with atomic_path(mpath) as tmp:
        tmp.write_text("\n".join(lines) + "\n")
    return jpath, mpath


def _g(x: Any) -> str:
    return "–" if x is None else f"{x:.3g}"
