"""Monte-Carlo study of the honesty of bias/drift sigmas (make mc-sigma).

Prints empirical scatter / RMS reported sigma for several noise colours.
"""

from __future__ import annotations

import numpy as np
import scipy.signal

from accal.estimators.trend import fit_trend
from accal.simulate.grace import coloured_noise


def study(make_noise, n, t, reps, method):
    eb, ed, sb, sd = [], [], [], []
    for _ in range(reps):
        e = make_noise()
        f = fit_trend(t, e, method=method)
        eb.append(f.bias)
        ed.append(f.drift)
        sb.append(f.sigma[0])
        sd.append(f.sigma[1])
    return np.std(eb) / np.sqrt(np.mean(np.square(sb))), np.std(ed) / np.sqrt(
        np.mean(np.square(sd))
    )


def main() -> None:
    rng = np.random.default_rng(0)
    n = 4320
    t = 10.0 * np.arange(n)
    cases = {}
    for phi in (0.0, 0.95, 0.99, 0.995, 0.999):
        corr = 0 if phi == 0 else round(-1 / np.log(phi))
        cases[f"AR(1)+white, corr {corr} samples, n={n}"] = (
            lambda phi=phi: (
                scipy.signal.lfilter([1], [1, -phi], rng.standard_normal(n + 5000))[5000:]
                + rng.standard_normal(n)
            ),
            n,
            t,
        )
    nd = 86400
    cases["white + 1/f below 1 mHz, 1 Hz day"] = (
        lambda: coloured_noise(nd, 1.0, 1e-10, 1e-3, rng),
        nd,
        np.arange(nd, dtype=float),
    )
    cases["white + 1/f below 10 mHz, 1 Hz day"] = (
        lambda: coloured_noise(nd, 1.0, 1e-10, 1e-2, rng),
        nd,
        np.arange(nd, dtype=float),
    )
    print(f"{'noise':45s} {'method':8s} {'bias':>6s} {'drift':>6s}   (scatter / sigma, 200 runs)")
    for name, (mk, nn, tt) in cases.items():
        for method in ("wavelet", "lsq"):
            rb, rd = study(mk, nn, tt, 200, method)
            print(f"{name:45s} {method:8s} {rb:6.2f} {rd:6.2f}")


if __name__ == "__main__":
    main()
