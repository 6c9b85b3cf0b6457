"""The library side of ``accal simulate gap``: a simulated run and its truth, written."""

from __future__ import annotations

import contextlib
from pathlib import Path
from typing import Any

import numpy as np

from accal import __version__
from accal.errors import ValidationError
from accal.estimators.design import design_pattern
from accal.io.chunked import chunked_table_writer
from accal.simulate.gap import simulate_gap_chunks

#: Simulations longer than this are generated and written in blocks of this length [day].
SIMULATE_CHUNK_DAYS = 10.0


def write_simulated_gap(out: Path, **params: Any) -> tuple[Path, Path]:
    """Simulate a run (:func:`accal.simulate.gap.simulate_gap`) and write it with its truth.

    The run goes to ``out`` (``.csv`` → CSV, else Parquet) and the per-period true
    means to ``<stem>.truth.<ext>`` next to it; both or neither are written.  Runs
    longer than ``SIMULATE_CHUNK_DAYS`` are simulated and written in blocks of that
    length (:func:`accal.simulate.gap.simulate_gap_chunks`), so a simulated year
    needs a few hundred MB; shorter ones are one block, identical to
    :func:`~accal.simulate.gap.simulate_gap`'s record.
    """
    out = Path(out)
    if out.name.lower().endswith(".gz"):
        raise ValidationError(f"{out}: compressed output is not supported; use .parquet or .csv")
    # option errors name the options (design_pattern's own messages say tm, tau)
    tau, mask, fs = (float(params.get(k, d)) for k, d in (("tau", 600), ("mask", 200), ("fs", 1)))
    if not 0 < fs < np.inf or not 0 < tau < np.inf:
        raise ValidationError(
            f"--tau and --fs must be positive and finite, got --tau {tau:g} s, --fs {fs:g} Hz"
        )
    if not 0 < mask < tau:
        raise ValidationError(
            f"--mask (masking time TM) must be in (0, --tau) s for a calibration pattern, got "
            f"--mask {mask:g} s for --tau {tau:g} s"
        )
    try:
        design_pattern(tau, mask, fs, kind=params.get("kind", "fig2"))
    except ValidationError as exc:
        raise ValidationError(
            f"no calibration pattern for --tau {tau:g} s, --mask {mask:g} s, --fs {fs:g} Hz: {exc}"
        ) from None
    fmt = "csv" if out.suffix.lower() == ".csv" else "parquet"
    truth_path = out.with_name(f"{out.stem}.truth{out.suffix or '.parquet'}")
    run_units = {
        "time": "s (from the start of the run)",
        "m_y": "m/s^2",
        "m_z": "m/s^2",
        "m_x": "m/s^2",
        "theta": "rad",
        "temperature": "K",
    }
    truth_units = {
        "period": "index of the modulation period",
        "t_start": "s",
        "t_mid": "s",
        "a_Y": "m/s^2 (true period mean)",
        "a_Z": "m/s^2 (true period mean)",
        "bias_y": "m/s^2 (true period-mean bias of m_y)",
        "bias_z": "m/s^2 (true period-mean bias of m_z)",
    }
    meta = {"simulate_gap": params, "accal_version": __version__}
    blocks = simulate_gap_chunks(**params, chunk_days=SIMULATE_CHUNK_DAYS)
    with contextlib.ExitStack() as stack:
        w_run = stack.enter_context(chunked_table_writer(out, fmt=fmt, units=run_units, meta=meta))
        w_truth = stack.enter_context(
            chunked_table_writer(truth_path, fmt=fmt, units=truth_units, meta=meta)
        )
        for data, truth in blocks:
            w_run.write(data)
            w_truth.write(truth)
    return out, truth_path
