"""Bias/drift σ pooled over adjacent days of an archive (``accal grace-bias --pool-days``).

Each input's trend residual spectrum (:class:`~accal.estimators.lowfreq.NoiseSpectrum`
of every axis and method) is saved next to its outputs as ``<stem>.noise.npz``.
After a batch, every row of the ``bias_drift`` table whose input has one gets the
covariance of :func:`accal.estimators.lowfreq.pooled_covariance` fitted to its day and
the ``pool_days − 1`` nearest other days of the same satellite, axis, method and
order (within ``pool_days`` calendar days); ``sigma_model`` says which model (or
``day`` when the day's own estimate stays: no neighbours, too short a record, or a
spectrum the model does not fit).  The model is of noise: a residual that holds the
orbit's non-gravitational signal (no ``--reference``) has spectral lines, and its
day keeps its own σ, which counts the signal as noise.  Days processed by earlier
runs in the same output directory take part, so a daily cron job pools with the days
before.
"""

from __future__ import annotations

import datetime as _dt
import zipfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from accal.estimators.lowfreq import NoiseSpectrum, noise_spectra, pooled_covariance
from accal.estimators.trend import METHODS
from accal.io.writers import atomic_path

__all__ = [
    "DAY_EXCESS",
    "DAY_MODEL",
    "day_excess",
    "day_spectra",
    "pool_rows",
    "spectra_path",
    "write_spectra",
]

#: ``sigma_model`` of a row whose σ is the day's own binned-periodogram estimate.
DAY_MODEL = "day"


def spectra_path(out_dir: Path, stem: str) -> Path:
    """Where an input's noise spectra are saved."""
    return Path(out_dir) / f"{stem}.noise.npz"


def day_spectra(
    time: np.ndarray,
    acc: np.ndarray,
    axes: Sequence[str],
    masks: dict[str, np.ndarray],
    fits: dict[tuple[str, str], Any],
) -> dict[tuple[str, str], NoiseSpectrum]:
    """The residual spectrum of every fit ``(axis, method)``.

    ``masks``: the samples each axis' fit used; ``fits``: :class:`TrendFit` per
    (axis, method).  Axes with the same samples share the layout's expectations.
    Fits on records too short for the model are left out.
    """
    groups: dict[tuple[bytes, str, int], list[str]] = {}
    for ax, method in fits:
        key = (np.packbits(masks[ax]).tobytes(), method, fits[(ax, method)].order)
        groups.setdefault(key, []).append(ax)
    out = {}
    for (_, method, order), group in groups.items():
        use = masks[group[0]]
        t = time[use]
        res = np.stack(
            [acc[use, list(axes).index(ax)] - fits[(ax, method)].evaluate(t) for ax in group]
        )
        specs = noise_spectra(t, res, METHODS[method](t, order), order=order, method=method)
        out.update({(ax, method): s for ax, s in zip(group, specs, strict=True) if s is not None})
    return out


def write_spectra(
    path: Path,
    spectra: dict[tuple[str, str], NoiseSpectrum],
    fits: dict[tuple[str, str], Any],
) -> Path:
    """Save ``spectra`` with each fit's own covariance (atomically; durable with the
    batch's commit)."""
    arrays: dict[str, np.ndarray] = {}
    stored: dict[int, str] = {}  # axes on the same samples share their expectations
    for (ax, method), spec in spectra.items():
        prefix = f"{ax}.{method}."
        fields = spec.to_arrays(prefix)
        if id(spec.shapes) in stored:
            fields[prefix + "shapes"] = np.array(stored[id(spec.shapes)])
        else:
            stored[id(spec.shapes)] = prefix + "shapes"
        arrays.update(fields)
        arrays[f"{ax}.{method}.day_cov"] = np.asarray(fits[(ax, method)].cov, float)
    with atomic_path(path, sync=False) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, **arrays)
    return path


def read_spectra(path: Path) -> dict[tuple[str, str], tuple[NoiseSpectrum, np.ndarray]]:
    """Inverse of :func:`write_spectra`: ``(spectrum, the day's own covariance)`` per
    (axis, method); a missing or unreadable file gives ``{}``."""
    try:
        with np.load(path, allow_pickle=False) as z:
            keys = {tuple(k.split(".")[:2]) for k in z.files}
            arrays = {k: z[k] for k in z.files}
            for k, v in arrays.items():  # a shared array is stored once, named elsewhere
                if v.dtype.kind == "U" and v.ndim == 0:
                    arrays[k] = arrays[str(v)]
            return {
                (ax, m): (
                    NoiseSpectrum.from_arrays(arrays, f"{ax}.{m}."),
                    np.asarray(arrays[f"{ax}.{m}.day_cov"], float),
                )
                for ax, m in keys
            }
    except (OSError, ValueError, KeyError, zipfile.BadZipFile):
        return {}


def pool_rows(
    rows: list[dict[str, Any]], out_dir: Path, stems: dict[str, str], pool_days: int
) -> int:
    """Replace the σ of ``rows`` (``bias_drift`` rows, modified in place) by pooled ones.

    Parameters
    ----------
    rows : list of dict
        Table rows with ``source``, ``satellite``, ``axis``, ``method``, ``order``,
        ``date``.
    out_dir : Path
        Where the ``<stem>.noise.npz`` files are.
    stems : dict
        ``source`` → output stem.
    pool_days : int
        Days per pool, the row's own included.

    Returns
    -------
    int
        Rows given a pooled σ.
    """
    cache: dict[str, dict] = {}

    def spectrum(row):
        src = row["source"]
        if src not in cache:
            stem = stems.get(src)
            cache[src] = read_spectra(spectra_path(out_dir, stem)) if stem else {}
        return cache[src].get((row["axis"], row["method"]), (None, None))[0]

    def own_cov(row):  # the day's own covariance, saved beside its spectrum
        return cache[row["source"]][(row["axis"], row["method"])][1]

    groups: dict[tuple, list[int]] = {}
    for i, r in enumerate(rows):
        r["sigma_model"], r["sigma_days"] = DAY_MODEL, 1
        if spectrum(r) is not None:  # back to the day's own σ (an earlier run pooled it)
            _set_sigmas(r, own_cov(r))
        groups.setdefault((r["satellite"], r["axis"], r["method"], r["order"]), []).append(i)
    n_pooled = 0
    for members in groups.values():
        days = {i: _ordinal(rows[i]["date"]) for i in members}
        have = [i for i in members if days[i] is not None and spectrum(rows[i]) is not None]
        for i in have:
            near = sorted(
                (j for j in have if j != i and abs(days[j] - days[i]) <= pool_days),
                key=lambda j: (abs(days[j] - days[i]), days[j]),
            )[: pool_days - 1]
            if not near:
                continue
            cov, info = pooled_covariance(spectrum(rows[i]), [spectrum(rows[j]) for j in near])
            if cov is None:
                if info.get("day_differs"):
                    why = (
                        f"this day's spectrum differs from the pool's {info['model']}, "
                        f"p {info['p_day']:.1g}"
                    )
                elif info["lines"]:
                    why = (
                        f"{info['lines']} bins of spectral lines (an orbit signal: use --reference)"
                    )
                else:
                    why = f"misfit of {info['model']}, p {info['p_misfit']:.1g}"
                rows[i]["sigma_model"] = f"{DAY_MODEL} (not pooled: {why})"
                continue
            excess = day_excess(own_cov(rows[i]), cov)
            if excess > DAY_EXCESS:
                rows[i]["sigma_model"] = (
                    f"{DAY_MODEL} (not pooled: its own σ is {excess:.1f}x the pool's "
                    f"{info['model']}: low-frequency power the other days lack)"
                )
                continue
            _set_sigmas(rows[i], cov)
            rows[i]["sigma_model"] = f"pooled: {info['model']}"
            rows[i]["sigma_days"] = int(info["days"])
            n_pooled += 1
    return n_pooled


#: A day whose own bias or drift σ exceeds the pooled one by this factor keeps its own.
#: Under a stationary noise the day's σ rests on ~6 degrees of freedom at the lowest
#: bins and is, if anything, too small under red noise: 2.5× the pool's happens with
#: p ~ 1e-5.  QA (2026-11-30): a day with a slow bump of ~1e-9 m/s² got the pool's
#: 2.1e-11 m/s² for its own 6.0e-11 and was 7.8σ off.
DAY_EXCESS = 2.5


def day_excess(day_cov: np.ndarray, pooled: np.ndarray) -> float:
    """Largest ratio of the day's own bias/drift σ to the pooled one."""
    d = np.sqrt(np.clip(np.diag(day_cov)[:2], 0.0, None))
    p = np.sqrt(np.clip(np.diag(pooled)[:2], 0.0, None))
    ok = p > 0
    return float(np.max(d[ok] / p[ok])) if ok.any() else 0.0


def _set_sigmas(row: dict[str, Any], cov: np.ndarray) -> None:
    sig = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    row["bias_sigma"], row["drift_sigma"] = float(sig[0]), float(sig[1])
    if cov.shape[0] > 2:
        row["quadratic_sigma"] = float(sig[2])
    denom = sig[0] * sig[1]
    row["bias_drift_corr"] = float(cov[0, 1] / denom) if denom > 0 else float("nan")


def _ordinal(date: str) -> int | None:
    try:
        return _dt.date.fromisoformat(str(date)).toordinal()
    except ValueError:
        return None
