"""Time read_grace_acc1b against a raw pyarrow.csv.read_csv of the same bytes.

Generates a synthetic 86,400-record ACC1B ASCII day (the real layout: 12 fields,
two spaces before qualflg) in a temporary directory and prints the median times
and their ratio.  Run: ``python benchmarks/bench_readers.py``.
"""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv

from accal.io.grace_l1b import read_grace_acc1b, write_grace_acc1b
from accal.series import AccSeries


def make_day(path: Path, n: int = 86_400) -> None:
    rng = np.random.default_rng(0)
    t0 = 116769600.0
    acc = np.array([1.2e-6, -2.85e-5, 5.3e-7]) + 1e-8 * rng.standard_normal((n, 3))
    aux = {c: 1e-4 * rng.standard_normal(n) for c in ("ang_accl_x", "ang_accl_y", "ang_accl_z")}
    aux |= {c: 1e-9 * rng.standard_normal(n) for c in ("acl_x_res", "acl_y_res", "acl_z_res")}
    quality = np.where(rng.random(n) < 0.5, 32, 0).astype(np.uint32)
    s = AccSeries(time=t0 + np.arange(n), acc=acc, quality=quality, aux=aux, satellite="GRACE-A")
    write_grace_acc1b(s, path)


def raw_pyarrow(path: Path) -> pa.Table:
    data = path.read_bytes()
    start = data.index(b"END OF HEADER")
    start = data.index(b"\n", start) + 1
    return pacsv.read_csv(
        pa.py_buffer(data[start:]),
        read_options=pacsv.ReadOptions(autogenerate_column_names=True),
        parse_options=pacsv.ParseOptions(delimiter=" "),
    )


def best_of(fn, path: Path, repeat: int = 15) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn(path)
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "ACC1B_2003-09-14_A_02.asc"
        make_day(path)
        size = path.stat().st_size / 1e6
        read_grace_acc1b(path), raw_pyarrow(path)  # warm up
        t_raw = best_of(raw_pyarrow, path)
        t_acc = best_of(read_grace_acc1b, path)
    print(f"file: 86400 records, {size:.1f} MB")
    print(f"raw pyarrow.csv.read_csv: {t_raw * 1e3:7.1f} ms (median)")
    print(f"read_grace_acc1b:         {t_acc * 1e3:7.1f} ms (median)")
    print(f"ratio: {t_acc / t_raw:.2f}")


if __name__ == "__main__":
    main()
