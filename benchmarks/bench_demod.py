"""Time `accal demod`'s work on a 1 Hz day against reading the run file with pyarrow.

Simulates an 86,400-sample day (τ = 600 s, TM = 200 s), writes it as Parquet in a
temporary directory and prints the best-of-N times of: a raw ``pyarrow.parquet``
read (baseline), ``read_rawlog``, one streamed pass of ``open_rawlog`` (in chunks of
2^18 rows: one chunk for a day), and the whole per-file pipeline (read twice →
validate → demodulate → merge into ``periods.parquet`` → write) with LS and GLS.
A year of data: ``benchmarks/bench_demod_year.py``.
Run: ``python benchmarks/bench_demod.py``.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import pyarrow.parquet as pq

from accal.io.rawlog import open_rawlog, read_rawlog
from accal.pipeline_demod import (
    DemodOptions,
    load_psd,
    output_paths,
    process_run,
    write_simulated_gap,
)


def best_of(fn, repeat: int = 7) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def main() -> None:
    with tempfile.TemporaryDirectory() as d:
        run = Path(d) / "run.parquet"
        write_simulated_gap(run, days=1.0, tau=600.0, mask=200.0, fs=1.0, seed=0)
        psd = load_psd("microstar")
        base = best_of(lambda: pq.read_table(run))
        read = best_of(lambda: read_rawlog(run))
        print(f"pyarrow read_table (baseline): {base:.4f} s")
        print(f"read_rawlog:                   {read:.4f} s  ({read / base:.1f}x)")
        stream = best_of(lambda: list(open_rawlog(run)))
        print(f"open_rawlog (one pass):        {stream:.4f} s  ({stream / base:.1f}x)")
        for method, model in (("ls", "mean"), ("ls", "affine"), ("gls", "mean")):
            opts = DemodOptions(tau=600.0, mask=200.0, method=method, signal_model=model)
            tgt = output_paths([run], Path(d) / f"out_{method}_{model}", "parquet")[0]
            tgt[0].parent.mkdir()
            t = best_of(lambda opts=opts, tgt=tgt: process_run(run, tgt, opts, psd))
            print(
                f"demod {method.upper():3s} {model:6s} (read..write):  {t:.4f} s  ({t / base:.0f}x)"
            )


if __name__ == "__main__":
    main()
