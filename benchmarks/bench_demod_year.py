"""A year of 1 Hz rotating-platform data through ``accal demod``: wall time and peak memory.

Simulates a run with :func:`accal.pipeline_demod.write_simulated_gap` (MicroSTAR
noise of eq. 1, τ = 600 s, TM = 200 s, drifting bias and a temperature-coupled
bias; generated and written to Parquet in 10-day blocks), then runs
``python -m accal demod`` on it in a separate process for each method and reports
the wall time and the peak resident memory of that process (``ru_maxrss`` from
``os.wait4``, so the numbers are the child's own).

On the 30-day run it also runs the demodulation with the whole file as one chunk
(``--chunk-size`` larger than the file) and checks that the chunked and whole-file
periods tables agree (largest difference relative to each column's scale).

Run: ``python benchmarks/bench_demod_year.py`` (365 and 30 days, LS and GLS;
several minutes, ~1 GB of temporary files) or e.g. ``--days 30 --methods ls``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SIMULATE = """
import sys
from accal.pipeline_demod import write_simulated_gap
write_simulated_gap(sys.argv[1], days=float(sys.argv[2]), tau=600.0, mask=200.0, seed=1,
                    temperature_coupling=2e-9, signal_amplitude=5e-9, signal_period=86400.0)
"""


def run(cmd: list[str], log: Path) -> tuple[float, float]:
    """Run ``cmd``; return (wall time [s], peak RSS of the child [MB]); raise on failure."""
    with open(log, "wb") as err:
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise SystemExit(f"failed ({proc.returncode}): {' '.join(cmd)}\n{log.read_text()}")
    return wall, usage.ru_maxrss / 1024.0  # Linux: KB


def compare(a: Path, b: Path) -> tuple[int, float]:
    """Rows and the largest column-scaled difference between two periods tables."""
    import numpy as np
    import pandas as pd

    x, y = pd.read_parquet(a), pd.read_parquet(b)
    assert list(x.columns) == list(y.columns) and len(x) == len(y)
    worst = 0.0
    for c in x.columns:
        if x[c].dtype.kind in "fi":
            u, v = x[c].to_numpy(float), y[c].to_numpy(float)
            scale = np.nanmax(np.abs(u)) or 1.0
            worst = max(worst, float(np.nanmax(np.abs(u - v)) / scale))
        else:
            assert (x[c] == y[c]).all(), c
    return len(x), worst


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--days", type=float, action="append", help="run length(s) [day]")
    ap.add_argument("--methods", default="ls,gls")
    ap.add_argument("--dir", type=Path, default=None, help="work directory (kept)")
    args = ap.parse_args()
    days_list = args.days or [30.0, 365.0]
    work = args.dir or Path(tempfile.mkdtemp(prefix="accal-year-"))
    work.mkdir(parents=True, exist_ok=True)
    py = sys.executable
    rows = []
    try:
        for days in days_list:
            run_file = work / f"run{days:g}d.parquet"
            wall, rss = run([py, "-c", SIMULATE, str(run_file), str(days)], work / "sim.log")
            size = run_file.stat().st_size / 1e6
            rows.append((f"simulate {days:g} d", wall, rss, f"{size:.0f} MB Parquet"))
            print(f"{rows[-1][0]:<28} {wall:8.1f} s {rss:8.0f} MB  {rows[-1][3]}", flush=True)
            for method in args.methods.split(","):
                out = work / f"out{days:g}d_{method}"
                cmd = [py, "-m", "accal", "demod", str(run_file), "--tau", "600", "--mask",
                       "200", "--method", method, "--bias-model", "affine+temperature",
                       "--out", str(out), "-q"]  # fmt: skip
                wall, rss = run(cmd, work / "demod.log")
                rows.append((f"demod {method.upper()} {days:g} d (chunked)", wall, rss, ""))
                print(f"{rows[-1][0]:<28} {wall:8.1f} s {rss:8.0f} MB", flush=True)
                if days <= 31:
                    whole = work / f"out{days:g}d_{method}_whole"
                    cmd_w = [*cmd[:-3], "--chunk-size", str(10**9), "--out", str(whole), "-q"]
                    wall, rss = run(cmd_w, work / "demod.log")
                    n, worst = compare(out / "periods.parquet", whole / "periods.parquet")
                    note = f"{n} periods, max rel. diff vs chunked {worst:.1e}"
                    rows.append((f"demod {method.upper()} {days:g} d (whole)", wall, rss, note))
                    print(f"{rows[-1][0]:<28} {wall:8.1f} s {rss:8.0f} MB  {note}", flush=True)
    finally:
        if args.dir is None:
            shutil.rmtree(work, ignore_errors=True)
    print("\n| step | wall [s] | peak RSS [MB] | note |\n| --- | --- | --- | --- |")
    for name, wall, rss, note in rows:
        print(f"| {name} | {wall:.1f} | {rss:.0f} | {note} |")


if __name__ == "__main__":
    main()
