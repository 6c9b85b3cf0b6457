"""Bias/drift σ on realistic days with a reference (``make mc-sigma-indep``, issue 20).

The days come from the independent generator of the tests (``tests.indep.grace_day``:
every L1B channel live, eclipses, real-L1B high-frequency content, gaps and micro-gaps
flagged), not from accal's simulator.  Each day is fitted as ``accal grace-bias
--reference`` fits it: ``raw − s·a_true`` on the samples the quality flags keep, so the
residual is the instrument noise of the generator's noise model.  The truth is the
generator's bias and drift at the fit's ``t0``.  Per noise model and method it prints
scatter/σ of the errors, the fraction |z| > 3 and the day-to-day scatter of σ, for the
day's own σ and the pooled σ of ``--pool-days`` (blocks of consecutive days).

Run: ``python benchmarks/mc_sigma_indep.py [--days N] [--pool P]`` (default 48 days per
noise model, pools of 8; ~3 minutes on one core).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.indep.grace import grace_day  # noqa: E402

from accal.estimators.lowfreq import noise_spectra, pooled_covariance  # noqa: E402
from accal.estimators.trend import METHODS, fit_trend  # noqa: E402

#: Noise models of the generator (``tests.indep._common.noise_psd``) and their options.
CASES = {
    "white+1/f (1 mHz corner)": {"noise": "white+1/f"},
    "random walk": {"noise": "randomwalk"},
    "AR(1) 3 h": {"noise": "ar1", "noise_tau": 10800.0},
    "1/rev band": {"noise": "bandlimited-1rev"},
}
#: Quality bits the reader drops by default (interpolated samples near gaps).
FLAG_BITS = 0b11100000


def day_fit(seed: int, kw: dict, method: str):
    """(t, residual, fit, true bias/drift at the fit's t0) of one generated day."""
    d = grace_day(seed, "A", **kw)
    keep = (d.qualflg & FLAG_BITS) == 0
    t = d.time[keep]
    y = (d.lin_accl - d.signal * np.asarray(d.truth["scale"]))[keep, 0]
    fit = fit_trend(t, y, method=method)
    b, dr = d.truth["bias"][0], d.truth["drift"][0]
    truth = np.array([b + dr * (fit.t0 - d.truth["t0"]), dr])
    return t, y - fit.evaluate(t), fit, truth


def study(name: str, kw: dict, n_days: int, pool: int, method: str) -> dict:
    errs, day_sig, pooled_sig, misfit = [], [], [], 0
    for b0 in range(0, n_days, pool):
        block = [day_fit(1000 + s, kw, method) for s in range(b0, min(b0 + pool, n_days))]
        specs = [
            noise_spectra(t, r[None, :], METHODS[method](t, 1), method=method)[0]
            for t, r, _, _ in block
        ]
        for i, (_, _, fit, truth) in enumerate(block):
            errs.append(fit.coef - truth)
            day_sig.append(fit.sigma)
            others = [s for j, s in enumerate(specs) if j != i and s is not None]
            cov = pooled_covariance(specs[i], others)[0] if specs[i] is not None else None
            misfit += cov is None
            pooled_sig.append(fit.sigma if cov is None else np.sqrt(np.diag(cov)))
    errs = np.array(errs)
    out = {"case": name, "method": method, "days": n_days, "misfit": misfit / n_days}
    for key, sig in (("day", np.array(day_sig)), ("pooled", np.array(pooled_sig))):
        out[key] = [
            (
                float(np.std(errs[:, j]) / np.sqrt(np.mean(sig[:, j] ** 2))),
                float(np.mean(np.abs(errs[:, j] / sig[:, j]) > 3)),
                float(np.std(sig[:, j]) / np.mean(sig[:, j])),
            )
            for j in range(2)
        ]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--days", type=int, default=48)
    ap.add_argument("--pool", type=int, default=8)
    ap.add_argument("--method", default="wavelet", choices=tuple(METHODS))
    args = ap.parse_args()
    print(
        "| noise (tests.indep) | σ | bias scatter/σ | drift scatter/σ | bias \\|z\\|>3 "
        "| drift \\|z\\|>3 | σ_bias scatter | σ_drift scatter |"
    )
    print("|---|---|---|---|---|---|---|---|")
    t_all = time.perf_counter()
    for name, kw in CASES.items():
        r = study(name, kw, args.days, args.pool, args.method)
        for key in ("day", "pooled"):
            (rb, zb, sb), (rd, zd, sd) = r[key]
            label = "day" if key == "day" else f"pooled {args.pool} d (misfit {r['misfit']:.0%})"
            print(
                f"| {name} | {label} | {rb:.2f} | {rd:.2f} | {zb:.1%} | {zd:.1%} "
                f"| {sb:.0%} | {sd:.0%} |",
                flush=True,
            )
    print(f"\n# {args.days} days per case, {args.method}, {time.perf_counter() - t_all:.0f} s")


if __name__ == "__main__":
    main()
