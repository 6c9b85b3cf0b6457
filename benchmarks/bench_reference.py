"""``make bench-reference``: a 30-day arc at 1 Hz through the CLI, time and peak memory.

Writes 30 one-day Parquet tables (2.6 M samples × 3 axes) and one reference table
covering them, then runs, each in its own process (peak RSS of that process):

* ``accal grace-bias DAYS --reference REF --scale fit-matrix --bias-basis spline:6h
  --arc 30d`` (the issue-22 target: ≤ 60 s and ≤ 2 GB on the 2-core CI machine);
* the same days with the plain wavelet fit (``-j 1``), the baseline of the same run.

Usage: ``python benchmarks/bench_reference.py [--days 30] [--repeats 1] [--out DIR]``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from scipy import signal

T0 = 157809600.0  # 2005-01-01 00:00:00 GPS
S_TRUE = np.array([[0.96, 1e-3, 0.0], [0.0, 0.98, -1e-3], [1e-3, 0.0, 0.95]])


def write_arc(folder: Path, days: int, seed: int = 0) -> tuple[list[Path], Path]:
    """Day tables and one reference (drag-like signal, spline-like bias, blue ref noise)."""
    rng = np.random.default_rng(seed)
    n = days * 86400
    t = T0 + np.arange(n, dtype=float)
    ph = 2 * np.pi * (t - T0) / 5600.0
    b, a = signal.butter(2, 1 / 3000, fs=1.0)
    slow = signal.lfilter(b, a, rng.normal(size=n))
    slow /= slow.std()
    drag = 2e-7 * (1 + 0.3 * np.sin(ph) + 0.2 * slow)
    true = np.column_stack([-drag, 2e-8 * np.cos(ph) + 0.02 * drag, 3e-8 * np.sin(ph + 1)])
    bias = np.array([-1.1e-6, 2.7e-5, -5.6e-7]) + 2e-8 * np.sin(
        2 * np.pi * (t - T0)[:, None] / np.array([5, 7, 3]) / 86400
    )
    raw = true @ np.linalg.inv(S_TRUE).T + bias + 1e-10 * rng.normal(size=(n, 3))
    ref = true + signal.lfilter([1, -1], [1], 3e-9 * rng.normal(size=(n, 3)), axis=0)
    paths = []
    for d in range(days):
        sl = slice(d * 86400, (d + 1) * 86400)
        p = folder / f"day{d:02d}.parquet"
        _table(p, t[sl], raw[sl])
        paths.append(p)
    ref_path = folder / "reference.parquet"
    _table(ref_path, t, ref)
    return paths, ref_path


def _table(path: Path, t: np.ndarray, acc: np.ndarray) -> None:
    cols = {"gps_time": t, **{f"lin_accl_{a}": acc[:, i] for i, a in enumerate("xyz")}}
    table = pa.table(cols).replace_schema_metadata(
        {"units": json.dumps({"gps_time": "s", **{f"lin_accl_{a}": "m/s^2" for a in "xyz"}})}
    )
    pq.write_table(table, path)


def run(args: list[str]) -> tuple[float, float, str]:
    """Run ``accal ARGS`` in a child process: wall time [s], peak RSS [MB], output."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    start = time.perf_counter()
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    res = subprocess.run(
        [sys.executable, "-m", "accal", *args], capture_output=True, text=True, env=env
    )
    wall = time.perf_counter() - start
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    if res.returncode != 0:
        raise SystemExit(f"accal {' '.join(args)} failed:\n{res.stdout}\n{res.stderr}")
    # ru_maxrss of the children is the largest child so far: run the big one first
    return wall, max(peak, before) / 1024.0, res.stdout + res.stderr


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--days", type=int, default=30)
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--out", type=Path, default=Path(tempfile.gettempdir()) / "accal_bench_ref")
    opts = ap.parse_args()
    opts.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        start = time.perf_counter()
        days, ref = write_arc(folder, opts.days)
        print(f"wrote {opts.days} days + reference in {time.perf_counter() - start:.1f} s")
        rows = []
        for rep in range(opts.repeats):
            arc_args = [
                "grace-bias", *map(str, days), "--reference", str(ref), "--scale", "fit-matrix",
                "--bias-basis", "spline:6h", "--arc", f"{opts.days}d", "-q", "--force",
                "--out", str(folder / f"arc{rep}"),
            ]  # fmt: skip
            wall, rss, _ = run(arc_args)
            rows.append({"case": "reference arc", "repeat": rep, "wall_s": wall, "peak_mb": rss})
            print(
                f"reference arc ({opts.days} d, fit-matrix, spline:6h): {wall:.1f} s, {rss:.0f} MB"
            )
            base_args = ["grace-bias", *map(str, days), "-j", "1", "-q", "--force",
                         "--out", str(folder / f"plain{rep}")]  # fmt: skip
            wall_b, _, _ = run(base_args)
            rows.append({"case": "wavelet per day", "repeat": rep, "wall_s": wall_b})
            print(f"baseline (wavelet per day, -j 1): {wall_b:.1f} s; ratio {wall / wall_b:.2f}")
        import pyarrow.parquet as pqr

        tab = pqr.read_table(folder / "arc0" / "bias_drift.parquet").to_pandas()
        x = tab[tab["axis"] == "x"].iloc[0]
        check = {
            "scale_xx": [float(x["scale_x"]), float(x["scale_x_sigma"]), S_TRUE[0, 0]],
            "scale_xy": [float(x["scale_y"]), float(x["scale_y_sigma"]), S_TRUE[0, 1]],
        }
        print("check (estimate, sigma, truth):", check)
    (opts.out / "bench_reference.json").write_text(
        json.dumps({"days": opts.days, "runs": rows, "check": check}, indent=2) + "\n"
    )
    print(f"results: {opts.out / 'bench_reference.json'}")


if __name__ == "__main__":
    main()
