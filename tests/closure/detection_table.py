"""Detection rate vs effect size for close_loop (run: python tests/closure/detection_table.py).

One day at 2 s, 1e-10 m/s²/√Hz white + 1/f below 1 mHz, two gaps, all candidates,
temperature channel given, orbit_period given; 10 seeds per size.  Prints a
Markdown table (docs/closure.md).
"""

from __future__ import annotations

import importlib.util
import sys
import time
from pathlib import Path

spec = importlib.util.spec_from_file_location("cf", Path(__file__).with_name("conftest.py"))
cf = importlib.util.module_from_spec(spec)
spec.loader.exec_module(cf)

from accal.closure import close_loop  # noqa: E402

CASES = {
    "bias_step": [("step", (0.4, v)) for v in (1e-10, 2e-10, 4e-10, 8e-10)],
    "quadratic_drift": [("quadratic", v) for v in (2.5e-21, 5e-21, 1e-20, 2e-20)],
    "auxiliary": [("temp_coupling", v) for v in (2.5e-11, 5e-11, 1e-10, 2e-10)],
}


def main(seeds: int = 10) -> None:
    print("| effect | size | detected (right kind) | any report |")
    print("|---|---|---|---|")
    t0 = time.time()
    for kind, sizes in CASES.items():
        for key, val in sizes:
            hit = anyf = 0
            for s in range(seeds):
                d = cf.make_day(500 + s, n=43200, dt=2.0, n_gaps=2, **{key: val})
                r = close_loop(
                    d["t"], d["y"], valid=d["valid"], aux={"temp": d["temp"]}, orbit_period=cf.ORBIT
                )
                hit += any(e.name == kind for e in r.effects)
                anyf += r.found
            size = val[1] if isinstance(val, tuple) else val
            print(f"| {kind} | {size:.2g} | {hit}/{seeds} | {anyf}/{seeds} |", flush=True)
    print(f"\n{time.time() - t0:.0f} s", file=sys.stderr)


if __name__ == "__main__":
    main()
