"""Writing simulated GRACE days: ACC1B files, truths, side files, references, arcs.

Besides the ACC1B file and its truth (:func:`write_simulated_grace`): the couplings'
auxiliary channels (:func:`aux_path`), a reference table (``s·a_true`` plus a
POD-like reference noise, :func:`accal.simulate.grace_noise.reference_noise`) for
``accal grace-bias --reference``, with the scale matrix to expect in the truth; a
THR1B file of the thruster pulses (:func:`accal.simulate.thr1b.write_simulated_thr1b`);
and arcs of consecutive days with a continuous bias and one reference table
(:func:`write_simulated_arc`).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from accal.errors import ValidationError
from accal.io.grace_l1b import DEFAULT_INVALID_BITS, write_grace_acc1b
from accal.io.writers import atomic_path, write_table
from accal.series import AccSeries
from accal.simulate.effects import Effect, reference_scale
from accal.simulate.grace_effects import parsed_effects
from accal.simulate.grace_noise import (
    REFERENCE_BAND,
    REFERENCE_CORNER,
    REFERENCE_LIMIT,
    REFERENCE_NOISE,
    reference_noise,
)
from accal.simulate.grace_seeds import stream
from accal.simulate.grace_signal import SimulatedDay, simulate_grace_day
from accal.simulate.thr1b import thruster_path, write_simulated_thr1b
from accal.timescale import gps_day_start


def aux_path(out: str | Path) -> Path:
    """The auxiliary-channel table written beside a simulated file: ``<out>.aux.parquet``."""
    out = Path(out)
    return out.with_name(out.name + ".aux.parquet")


def _reference(
    day: SimulatedDay, level: float, dt: float, n: int, effects: Sequence[Effect]
) -> tuple[NDArray, dict[str, Any]]:
    """``s·a_true`` plus reference noise on the day's epochs, and its truth entry."""
    seed = int(day.truth["seed"])
    idx = np.rint((day.time - day.truth["t0"]) / dt).astype(np.int64)
    noise = reference_noise(n, dt, level, stream(seed, "reference"))[idx]
    ref = np.asarray(day.truth["scale_s"]) * day.true
    if level > 0:  # 0: exactly s·a_true (no −0.0 + 0.0 turned into +0.0)
        ref = ref + noise
    info = {
        "content": "s*a_true (nominal scale_s, thrusters included) + reference noise [m/s^2]",
        "scale": reference_scale(list(effects)).tolist(),
        "scale_meaning": "S of a_ref = S (a_raw - b(t) - other effects - instrument noise) + "
        "reference noise; row i = scale_x, scale_y, scale_z of the grace-bias row of axis i "
        "(identity without scale effects)",
        "noise": {
            "level": level,
            "level_meaning": "RMS of the noise below band_hz [m/s^2]",
            "band_hz": REFERENCE_BAND,
            "floor_asd": level / np.sqrt(REFERENCE_BAND),
            "corner_hz": REFERENCE_CORNER,
            "limit_hz": REFERENCE_LIMIT,
            "psd": "one-sided floor_asd^2 (1 + (f/corner_hz)^4 / (1 + (f/limit_hz)^4)) "
            "[m^2/s^4/Hz], axes independent",
            "stream": "reference",
            "rms": np.sqrt(np.mean(noise**2, axis=0)).tolist(),
        },
    }
    return ref, info


def _write_reference(path: str | Path, time: NDArray, ref: NDArray, meta: dict[str, Any]) -> None:
    write_table(
        {"gps_time": time, **{f"lin_accl_{a}": ref[:, i] for i, a in enumerate("xyz")}},
        path,
        units={"gps_time": "s", **{f"lin_accl_{a}": "m/s^2" for a in "xyz"}},
        meta=meta,
    )


def _write_day(out: Path, day: SimulatedDay, thrusters: bool) -> Path:
    """Write a simulated day's side files, then its ACC1B file and truth; the truth path."""
    sat = day.truth["satellite"]
    # flagged samples get the lowest bit that the reader treats as invalid (bit 0: Vp)
    flag = DEFAULT_INVALID_BITS & -DEFAULT_INVALID_BITS
    quality = np.where(day.valid, 0, flag).astype(np.uint32)
    series = AccSeries(
        time=day.time,
        acc=day.raw,
        valid=day.valid,
        quality=quality,
        aux=day.aux,
        satellite=f"GRACE-{sat}" if sat in "AB" else f"GRACE-FO-{sat}",
    )
    source = {"source": f"accal simulate grace ({out.name})", "seed": day.truth["seed"]}
    if day.channels:
        units = {"gps_time": "s", **{k: "K" for k in day.channels}}
        write_table(
            {"gps_time": day.channel_time, **day.channels},
            aux_path(out),
            fmt="parquet",
            units=units,
            meta={**source, "channels": day.truth["channels"]},
        )
    if thrusters:
        write_simulated_thr1b(
            thruster_path(out, sat),
            day.truth["thrusters"],
            sat,
            day.truth["t0"],
            stream(int(day.truth["seed"]), "thr1b"),
        )
    # the data file and its truth last: a side file that cannot be written leaves no day
    write_grace_acc1b(series, out, flavour="grace" if sat in "AB" else "gracefo")
    truth_path = out.with_name(out.name + ".truth.json")
    with atomic_path(truth_path) as tmp:
        tmp.write_text(json.dumps(day.truth, indent=2) + "\n")
    return truth_path


def write_simulated_grace(
    out: str | Path,
    *,
    reference_out: str | Path | None = None,
    reference_noise: float = REFERENCE_NOISE,
    **kwargs: Any,
) -> Path:
    """Simulate a day and write it as an ACC1B file plus ``<out>.truth.json``.

    Keyword arguments go to :func:`simulate_grace_day`.  GRACE A/B days are
    written in the GRACE RL02 ASCII layout, C/D in the GRACE-FO RL04 YAML layout,
    with all 12 columns.  A day with couplings also gets its channels in
    ``<out>.aux.parquet`` (:func:`aux_path`; columns ``gps_time`` [s] and one per
    channel, units in the Parquet metadata, readable by ``accal grace-bias --aux``).
    A day with ``thrusters=True`` also gets its pulses as a THR1B file
    (:func:`thruster_path`, :func:`accal.simulate.thr1b.write_simulated_thr1b`), which ``accal
    grace-bias`` finds beside the data and uses to leave the firings out.

    Parameters
    ----------
    out : str or Path
        The ACC1B file.
    reference_out : str or Path, optional
        Also write the reference acceleration: the true non-gravitational
        acceleration ``s·a_true`` (nominal scale, thrusters included, the scale
        errors of ``scale``/``scalematrix`` effects not) plus the reference noise
        of :func:`reference_noise`, at the data epochs, as a table (``gps_time``,
        ``lin_accl_x/y/z``; CSV for a ``.csv`` name, else Parquet) readable by
        ``accal grace-bias --reference``.  The truth gets ``reference``: ``scale``
        (the 3×3 ``S`` of ``a_ref = S·(a_raw − b(t))`` to compare with the fit,
        :func:`accal.simulate.effects.reference_scale`) and ``noise`` (model,
        level and the drawn RMS per axis).
    reference_noise : float
        Reference noise level [m/s²]: the RMS at orbit scales (below
        :data:`REFERENCE_BAND`); 0 writes ``s·a_true`` alone (the reference of
        earlier versions, same values and metadata).  Drawn from the day's
        ``"reference"`` stream: the other outputs of a seed do not change.

    Returns
    -------
    Path
        The truth file.
    """
    out = Path(out)
    day = simulate_grace_day(**kwargs)
    if reference_out is not None:
        dt = float(kwargs.get("dt", 1.0))
        n = int(round(float(kwargs.get("duration", 86400.0)) / dt))
        ref, info = _reference(day, reference_noise, dt, n, parsed_effects(kwargs))
        day.truth["reference"] = {"file": Path(reference_out).name, **info}
        source = {"source": f"accal simulate grace ({out.name})", "seed": day.truth["seed"]}
        content = "s * a_true (nominal scale_s of the truth)"
        if reference_noise > 0:
            content += f" + reference noise (truth['reference']['noise'] of {out.name})"
        _write_reference(reference_out, day.time, ref, {**source, "content": content})
    return _write_day(out, day, bool(kwargs.get("thrusters", False)))


def arc_paths(out: str | Path, date: str, days: int) -> list[Path]:
    """The data files of a multi-day simulation: ``out`` with ``date`` replaced by each day's.

    Raises
    ------
    ValidationError
        ``days > 1`` and the name of ``out`` does not contain ``date``.
    """
    out = Path(out)
    if days > 1 and date not in out.name:
        raise ValidationError(
            f"simulating {days} days needs the date {date} in the output name (it is replaced "
            f"by each day's date), got {out.name!r}"
        )
    start = np.datetime64(date, "D")
    return [out.with_name(out.name.replace(date, str(start + k))) for k in range(days)]


def arc_files(
    out: str | Path,
    date: str,
    days: int,
    satellite: str,
    *,
    coupling: bool = False,
    thrusters: bool = False,
    reference_out: str | Path | None = None,
) -> list[Path]:
    """The files a :func:`write_simulated_arc` call wrote, besides the truth files.

    Parameters
    ----------
    out, date, days
        As given to :func:`write_simulated_arc`.
    satellite : str
        ``A``, ``B``, ``C`` or ``D`` (names the THR1B files).
    coupling : bool
        A ``coupling`` effect was injected: each day's auxiliary table
        (:func:`aux_path`) is listed when it exists.
    thrusters : bool
        Thruster pulses were simulated: each day's THR1B file is listed.
    reference_out : str or Path, optional
        The reference table, listed last.

    Returns
    -------
    list of Path
        For each day its data file, then its auxiliary table and THR1B file; then
        the reference table.
    """
    written: list[Path] = []
    for path in arc_paths(out, date, days):
        written.append(path)
        if coupling and aux_path(path).exists():
            written.append(aux_path(path))
        if thrusters:
            written.append(thruster_path(path, satellite))
    if reference_out is not None:
        written.append(Path(reference_out))
    return written


def write_simulated_arc(
    out: str | Path,
    *,
    days: int,
    date: str = "2005-01-01",
    seed: int | None = None,
    reference_out: str | Path | None = None,
    reference_noise: float = REFERENCE_NOISE,
    **kwargs: Any,
) -> list[Path]:
    """Simulate ``days`` consecutive days as one arc: a data file per day, one reference.

    Each day is :func:`simulate_grace_day` of its date (seed: ``seed + k`` for day
    ``k``, or the day's :func:`default_seed`), written as by
    :func:`write_simulated_grace` to :func:`arc_paths` (``out`` with the date
    replaced); with ``days = 1`` it is exactly :func:`write_simulated_grace`.  What
    makes the days one arc:

    * the eq. 9 bias is continuous: day ``k`` starts at the bias of day ``k − 1``
      continued by its drift, ``b_k = b_{k−1} + d_{k−1}·(t0_k − t0_{k−1})`` (each day
      keeps its own random drift, so the bias is piecewise linear); the truth of
      every day has its ``bias`` at its ``t0``;
    * ``splinebias`` effects with random coefficients have their nodes in GPS time,
      so the spline is continuous across the days; ``scale`` and ``scalematrix``
      effects are the same every day.  The other effects restart each day (epochs
      from each day's start);
    * ``reference_out`` gets one table covering all days (concatenated), for
      ``accal grace-bias --reference REF --arc Nd``; the reference noise is drawn
      per day (POD arcs are usually daily).

    Every truth gets ``arc``: ``days``, ``index``, ``first_date`` and the data files.

    Parameters
    ----------
    out : str or Path
        The first day's ACC1B file; its name must contain ``date`` when ``days > 1``.
    days : int
        Number of days (>= 1).
    date : str
        First day, ``YYYY-MM-DD``.
    seed : int, optional
        Seed of the first day; day ``k`` uses ``seed + k``.
    reference_out, reference_noise
        As in :func:`write_simulated_grace`.
    **kwargs
        Passed to :func:`simulate_grace_day` for every day.

    Returns
    -------
    list of Path
        The truth files, one per day.
    """
    if days < 1:
        raise ValidationError(f"days must be >= 1, got {days}")
    if days == 1:
        truth = write_simulated_grace(
            out,
            reference_out=reference_out,
            reference_noise=reference_noise,
            date=date,
            seed=seed,
            **kwargs,
        )
        return [truth]
    paths = arc_paths(out, date, days)
    start = np.datetime64(date, "D")
    dt = float(kwargs.get("dt", 1.0))
    n = int(round(float(kwargs.get("duration", 86400.0)) / dt))
    effects = parsed_effects(kwargs)
    kwargs = {**kwargs, "effects": effects}
    times, refs, seeds, truths = [], [], [], []
    prev: dict[str, Any] | None = None
    for k, path in enumerate(paths):
        day_date = str(start + k)
        bias = None
        if prev is not None:
            step = gps_day_start(day_date) - prev["t0"]
            bias = np.asarray(prev["bias"]) + np.asarray(prev["drift"]) * step
        day = simulate_grace_day(
            date=day_date, seed=None if seed is None else seed + k, bias=bias, **kwargs
        )
        day.truth["arc"] = {
            "days": days,
            "index": k,
            "first_date": date,
            "files": [p.name for p in paths],
            "bias": "continued from the previous day: b_k = b_(k-1) + d_(k-1) (t0_k - t0_(k-1))",
        }
        if reference_out is not None:
            ref, info = _reference(day, reference_noise, dt, n, effects)
            day.truth["reference"] = {"file": Path(reference_out).name, **info}
            times.append(day.time)
            refs.append(ref)
        seeds.append(day.truth["seed"])
        truths.append(_write_day(path, day, bool(kwargs.get("thrusters", False))))
        prev = day.truth
    if reference_out is not None:
        content = "s * a_true (nominal scale_s of the truths)"
        if reference_noise > 0:
            content += " + reference noise (truth['reference']['noise'] of each day)"
        meta = {
            "source": f"accal simulate grace ({paths[0].name} .. {paths[-1].name})",
            "seed": seeds,
            "content": content,
        }
        _write_reference(reference_out, np.concatenate(times), np.concatenate(refs), meta)
    return truths
