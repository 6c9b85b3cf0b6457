"""Time ``close_loop`` on a 1 Hz day: 86,400 samples × 3 axes, all candidates (issue 4: ≤ 5 s).

A simulated GRACE-A day (:func:`accal.simulate.grace.simulate_grace_day`, real-like
non-gravitational signal, 1e-10 m/s²/√Hz noise, two gaps) with a temperature channel
and a lagged coupling on x; per axis ``close_loop(..., base="poly1", aux={"temp": T},
orbit_period=5600)`` with the default candidates (quadratic, cubic, step, periodic,
auxiliary).  Also times the rotating-platform adapter ``close_loop_demod`` on a 1 Hz
day (τ = 600 s, 144 periods as a block base, all candidates incl. the platform ones).

Prints the one-off import time of scipy/the closure and the best of ``--repeat``
wall-clock times.  Run: ``python benchmarks/bench_closure.py [--repeat 3]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)

    t = time.perf_counter()
    import scipy.linalg  # noqa: F401
    import scipy.optimize  # noqa: F401
    import scipy.signal  # noqa: F401
    import scipy.stats  # noqa: F401

    from accal.closure import close_loop
    from accal.closure.demod import close_loop_demod

    print(f"imports (scipy, accal.closure): {time.perf_counter() - t:.2f} s (once per process)")

    from accal.simulate.grace import simulate_grace_day

    day = simulate_grace_day(seed=3, n_gaps=2)
    tt = day.time
    tau = tt - tt[0]
    rng = np.random.default_rng(0)
    temp = 20 + 1.5 * np.sin(2 * np.pi * tau / 86400) + 0.4 * np.sin(2 * np.pi * tau / 5600)
    temp += 0.3 * np.cumsum(rng.standard_normal(tt.size)) / np.sqrt(tt.size)
    raw = day.raw.copy()
    raw[:, 0] += 3e-9 * np.interp(tau - 600.0, tau, temp)

    def grace() -> list:
        return [
            close_loop(tt, raw[:, k], valid=day.valid, aux={"temp": temp}, orbit_period=5600.0)
            for k in range(3)
        ]

    times = []
    for _ in range(args.repeat):
        t = time.perf_counter()
        res = grace()
        times.append(time.perf_counter() - t)
    found = [[e.name for e in r.effects] for r in res]
    print(
        f"close_loop, 86,400 samples x 3 axes, all candidates: best {min(times):.2f} s "
        f"(runs: {', '.join(f'{x:.2f}' for x in times)}); effects per axis: {found}"
    )

    from accal.simulate.gap import simulate_gap

    d, _ = simulate_gap(days=1.0, seed=3)
    args_d = (d.time.to_numpy(), d[["m_y", "m_z"]].to_numpy(), d.theta.to_numpy())
    times = []
    for _ in range(args.repeat):
        t = time.perf_counter()
        res_d, per = close_loop_demod(*args_d, tau=600.0, aux={"temp": d.temperature.to_numpy()})
        times.append(time.perf_counter() - t)
    print(
        f"close_loop_demod, 86,400 samples x 2 axes (144 periods x 8 base columns): "
        f"best {min(times):.2f} s; effects: {[e.name for e in res_d.effects]}; "
        f"periods: {per.period_index.size}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
