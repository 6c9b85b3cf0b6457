"""Benchmarks of `accal grace-bias` on a synthetic 1 Hz, 86,400-row ACC1B day.

(a) End-to-end wall time of the CLI (fresh Python process: import, read, fit 3 axes
    with sigmas, write calibrated Parquet + report + table) against a minimal
    pipeline in a fresh process: Python start + pyarrow CSV read of the same file +
    Parquet write.  Target ratio ≤ 1.2.
(b) The wavelet estimator against the lsq estimator on the same arrays, both for
    the coefficients alone and for the full fit with coloured-noise sigmas.

Run with ``make bench``; prints a table, asserts nothing.
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPEAT = 5


def wall(cmd: list[str]) -> float:
    """Median wall time of a command over REPEAT runs [s]."""
    times = []
    for _ in range(REPEAT):
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def best(fn, n: int = 20) -> float:
    """Best-of-n time of a call [s]."""
    out = []
    for _ in range(n):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return min(out)


def main() -> None:
    from accal.simulate.grace import write_simulated_grace

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        day = tmp / "ACC1B_2005-01-01_A_sim.asc"
        write_simulated_grace(day, date="2005-01-01", satellite="A", seed=1)
        size_mb = day.stat().st_size / 1e6
        accal = [
            sys.executable,
            "-m",
            "accal",
            "grace-bias",
            str(day),
            "--out",
            str(tmp / "o"),
            "-q",
        ]
        minimal = [
            sys.executable,
            "-c",
            "import sys, pyarrow.csv as c, pyarrow.parquet as pq\n"
            "lines = open(sys.argv[1], 'rb').read()\n"
            "start = lines.index(b'END OF HEADER')\n"
            "start = lines.index(b'\\n', start) + 1\n"
            "import io\n"
            "t = c.read_csv(io.BytesIO(lines[start:]), read_options=c.ReadOptions(autogenerate_column_names=True),"
            " parse_options=c.ParseOptions(delimiter=' '))\n"
            "pq.write_table(t, sys.argv[2])\n",
            str(day),
            str(tmp / "minimal.parquet"),
        ]
        t_accal = wall(accal)
        t_min = wall(minimal)
        t_py = wall([sys.executable, "-c", "pass"])
        print(f"file: {size_mb:.1f} MB, 86,400 rows; median of {REPEAT} runs")
        print(f"(a) accal grace-bias end to end : {t_accal:6.3f} s")
        print(f"    minimal pyarrow read+write  : {t_min:6.3f} s")
        print(f"    python start alone          : {t_py:6.3f} s")
        print(f"    ratio accal / minimal       : {t_accal / t_min:6.2f}  (target <= 1.2)")

        from accal.io import read

        series = read(day)
        t = series.time
        a = series.axis("x")
        from accal.estimators.trend import fit_trend, lsq_weights, wavelet_weights

        wc = best(lambda: wavelet_weights(t, 1) @ a)
        lc = best(lambda: lsq_weights(t, 1) @ a)
        wf = best(lambda: fit_trend(t, a, method="wavelet"), 10)
        lf = best(lambda: fit_trend(t, a, method="lsq"), 10)
        ref = best(lambda: np.polynomial.polynomial.polyfit(t - t[0], a, 1))
        print("(b) estimators on one axis (best of 20/10):")
        print(
            f"    coefficients only: wavelet {wc * 1e3:7.2f} ms, lsq {lc * 1e3:7.2f} ms, "
            f"lsq/wavelet = {lc / wc:4.2f}  (numpy polyfit: {ref * 1e3:.2f} ms)"
        )
        print(
            f"    full fit + sigmas: wavelet {wf * 1e3:7.2f} ms, lsq {lf * 1e3:7.2f} ms, "
            f"lsq/wavelet = {lf / wf:4.2f}"
        )


if __name__ == "__main__":
    main()
