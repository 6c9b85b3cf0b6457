"""Monte-Carlo study of the honesty of the bias/drift sigmas (``make mc-sigma``, issue 20).

One-day records (1 Hz, 86,400 samples) of noise only (true bias = drift = 0), drawn by
the generators below (numpy/scipy.signal only, independent of ``accal.simulate``),
fitted by ``fit_trend`` with both methods.  Two σ per day: the day's own estimate
(``day``: the binned residual periodogram, what a single input gets) and the pooled one
(``pooled``: :func:`accal.estimators.lowfreq.pooled_covariance` over blocks of
``--pool`` consecutive days, each day with the others of its block, as
``accal grace-bias --pool-days`` does; a misfit keeps the day's σ).  For each case,
method and estimator it prints, for the bias and the drift:

* ``scatter/σ``: standard deviation of the estimates / RMS reported σ (target 0.8–1.25);
* ``|z|>3``: fraction of days with |estimate/σ| > 3 (target ≤ 1 %, Gaussian 0.27 %);
* ``σ scatter``: std(σ)/mean(σ) over the days (target ≤ 10 % for stationary noise).

Noise cases (σ per sample unless stated; "white" is 1e-10 m/s² per sample):

``white``                white only
``white + 1/f``          one-sided ASD 1.41e-10·sqrt(1 + 1 mHz/f) m/s²/√Hz (the
                         white part 1e-10 per sample), flat below 1/(2T)
``random walk``          2e-12 m/s²/√s random walk starting at 0 at the first sample
                         (its level at t0 is the instrument's bias at t0), + white
``AR(1) τ``              stationary AR(1), τ = 1, 3, 6 h, σ = 5e-10 m/s², + white
``1/rev band``           Gaussian band of 1/5600 Hz ± 10 %, σ = 3e-10 m/s², + white

It writes ``docs/figures/mc_sigma.png`` and prints the markdown table of
``docs/grace_bias.md``.  Run: ``python benchmarks/mc_sigma.py [--reps N] [--cases a,b]``
(default 200 days per case, pools of 8; ~1 minute on one core).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import scipy.signal

from accal.estimators.lowfreq import noise_spectra, pooled_covariance
from accal.estimators.trend import METHODS, fit_trend
from accal.pooling import DAY_EXCESS, day_excess

N = 86400
DT = 1.0
WHITE = 1e-10
ROOT = Path(__file__).resolve().parents[1]


def shaped(rng: np.random.Generator, psd_two_sided, pad: int = 4) -> np.ndarray:
    """Stationary Gaussian noise of two-sided PSD ``psd_two_sided(f)`` [per Hz], N samples.

    Spectral synthesis on ``pad·N`` points (complex Gaussian amplitudes with variance
    ``S(f)·fs·M``), a random window of N samples: the record is not periodic.
    """
    m = pad * N
    f = np.fft.rfftfreq(m, DT)
    amp = np.sqrt(psd_two_sided(f) * m / DT / 2.0)
    z = amp * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size))
    z[0] = amp[0] * rng.standard_normal() * np.sqrt(2.0)
    if m % 2 == 0:
        z[-1] = amp[-1] * rng.standard_normal() * np.sqrt(2.0)
    x = np.fft.irfft(z, m)
    a = rng.integers(0, m - N)
    return x[a : a + N]


def white(rng):
    return WHITE * rng.standard_normal(N)


def white_one_over_f(rng):
    fc, flat_below = 1e-3, 1.0 / (2 * N * DT)

    def psd(f):
        return WHITE**2 * DT * (1.0 + fc / np.maximum(f, flat_below))

    return shaped(rng, psd)


def random_walk(rng):
    return np.cumsum(2e-12 * np.sqrt(DT) * rng.standard_normal(N)) + white(rng)


def ar1(tau: float):
    phi = np.exp(-DT / tau)

    def gen(rng):
        w = rng.standard_normal(N) * 5e-10 * np.sqrt(1.0 - phi**2)
        x0 = 5e-10 * rng.standard_normal()  # stationary start
        x, _ = scipy.signal.lfilter([1.0], [1.0, -phi], w, zi=[phi * x0])
        return x + white(rng)

    return gen


def one_per_rev_band(rng):
    f0, width, sigma = 1.0 / 5600.0, 0.1 / 5600.0, 3e-10
    norm = sigma**2 / (2.0 * width * np.sqrt(2.0 * np.pi))  # two-sided: two bumps

    def psd(f):
        return norm * np.exp(-0.5 * ((f - f0) / width) ** 2)

    return shaped(rng, psd) + white(rng)


CASES = {
    "white": white,
    "white + 1/f": white_one_over_f,
    "random walk + white": random_walk,
    "AR(1) 1 h + white": ar1(3600.0),
    "AR(1) 3 h + white": ar1(10800.0),
    "AR(1) 6 h + white": ar1(21600.0),
    "1/rev band + white": one_per_rev_band,
}


def summarise(est: np.ndarray, sig: np.ndarray) -> tuple[float, float, float]:
    """``(scatter/σ, fraction |z| > 3, std(σ)/mean(σ))`` of one coefficient."""
    ratio = np.std(est) / np.sqrt(np.mean(sig**2))
    return float(ratio), float(np.mean(np.abs(est / sig) > 3)), float(np.std(sig) / np.mean(sig))


def study(name: str, gen, reps: int, seed: int, pool: int = 8) -> list[dict]:
    """Both methods on the same ``reps`` days of noise case ``name``, day and pooled σ."""
    rng = np.random.default_rng(seed)
    t = np.arange(N) * DT
    keys = ("est", "day", "pooled", "misfit")
    acc = {m: {k: [] for k in keys} for m in ("wavelet", "lsq")}
    done = 0
    while done < reps:
        days = [gen(rng) for _ in range(min(pool, reps - done))]
        done += len(days)
        for m, a in acc.items():
            fits = [fit_trend(t, e, method=m) for e in days]
            res = np.array([e - f.evaluate(t) for e, f in zip(days, fits, strict=True)])
            specs = noise_spectra(t, res, METHODS[m](t, 1), method=m)
            for i, fit in enumerate(fits):
                cov, _ = pooled_covariance(specs[i], specs[:i] + specs[i + 1 :])
                if cov is not None and day_excess(fit.cov, cov) > DAY_EXCESS:
                    cov = None  # as accal.pooling.pool_rows: the day keeps its own σ
                a["est"].append(fit.coef)
                a["day"].append(fit.sigma)
                a["misfit"].append(cov is None)
                a["pooled"].append(fit.sigma if cov is None else np.sqrt(np.diag(cov)))
    rows = []
    for m, a in acc.items():
        est = np.array(a["est"])
        for which in ("day", "pooled"):
            sig = np.array(a[which])
            row = {"case": name, "method": m, "sigma": which, "reps": reps, "pool": pool}
            row["misfit"] = float(np.mean(a["misfit"])) if which == "pooled" else 0.0
            for j, coef in enumerate(("bias", "drift")):
                row[coef] = summarise(est[:, j], sig[:, j])
            rows.append(row)
    return rows


def table(rows: list[dict]) -> str:
    """Markdown table of the study."""
    out = [
        "| noise | method | σ | bias scatter/σ | drift scatter/σ | bias \\|z\\|>3 "
        "| drift \\|z\\|>3 | σ_bias scatter | σ_drift scatter | misfit (day's σ kept) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        b, d = r["bias"], r["drift"]
        sig = r["sigma"] if r["sigma"] == "day" else f"pooled {r['pool']} d"
        mis = f"{100 * r['misfit']:.0f} %" if r["sigma"] == "pooled" else "–"
        out.append(
            f"| {r['case']} | {r['method']} | {sig} | {b[0]:.2f} | {d[0]:.2f} "
            f"| {100 * b[1]:.1f} % | {100 * d[1]:.1f} % | {100 * b[2]:.0f} % "
            f"| {100 * d[2]:.0f} % | {mis} |"
        )
    return "\n".join(out)


def figure(rows: list[dict], path: Path) -> None:
    """Scatter/σ per case and method against the target band."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.8), sharey=True)
    day = [r for r in rows if r["sigma"] == "day"]
    pooled = [r for r in rows if r["sigma"] == "pooled"]
    labels = [f"{r['case']} ({r['method'][:3]})" for r in day]
    y = np.arange(len(day))
    for ax, coef in zip(axes, ("bias", "drift"), strict=True):
        ax.axvspan(0.8, 1.25, color="0.9", label="target 0.8–1.25")
        ax.plot([r[coef][0] for r in day], y, "o", color="C0", label="the day's own σ")
        ax.plot(
            [r[coef][0] for r in pooled], y, "s", color="C3", mfc="none",
            label=f"pooled σ ({pooled[0]['pool']} days, --pool-days)",
        )  # fmt: skip
        ax.set_xscale("log")
        ax.set_xlabel(f"{coef}: scatter / RMS σ")
        ax.axvline(1.0, color="k", lw=0.5)
    axes[0].set_yticks(y, labels, fontsize=8)
    axes[0].invert_yaxis()
    axes[1].legend(fontsize=8, loc="lower right")
    fig.suptitle(f"grace-bias σ under coloured noise, 1 Hz days ({rows[0]['reps']} days per case)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=200)
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--pool", type=int, default=8, help="days per pool [8]")
    ap.add_argument("--figure", default=str(ROOT / "docs" / "figures" / "mc_sigma.png"))
    args = ap.parse_args()
    rows = []
    t0 = time.perf_counter()
    for i, name in enumerate(args.cases.split(",")):
        t1 = time.perf_counter()
        rows.extend(study(name, CASES[name], args.reps, seed=100 + i, pool=args.pool))
        print(f"# {name}: {time.perf_counter() - t1:.0f} s", flush=True)
    print(table(rows))
    print(f"\n# {time.perf_counter() - t0:.0f} s in all")
    if args.figure:
        figure(rows, Path(args.figure))
        print(f"# figure: {args.figure}")


if __name__ == "__main__":
    main()
