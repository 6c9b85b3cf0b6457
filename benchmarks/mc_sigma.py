"""Monte-Carlo study of the honesty of the bias/drift sigmas (``make mc-sigma``, issue 20).

One-day records (1 Hz, 86,400 samples) of noise only (true bias = drift = 0), drawn by
the generators below (numpy/scipy.signal only, independent of ``accal.simulate``),
fitted by ``fit_trend`` with both methods.  For each case and method it prints, for the
σ of ``accal`` now ("new") and for the σ of the estimator before issue 20 ("old", the
binned-periodogram kernel copied below from ``trend.py`` at commit 2ce4c6f, evaluated
on the same residuals):

* ``scatter/σ``: standard deviation of the estimates / RMS reported σ (target 0.8–1.25);
* ``|z|>3``: fraction of days with |estimate/σ| > 3 (target ≤ 1 %, Gaussian 0.27 %);
* ``σ scatter``: std(σ)/mean(σ) over the days (target ≤ 10 %);

for the bias and the drift, and the fraction of days with the spectrum-misfit note
(the flag's false-alarm rate on the cases the model describes, its detection rate on
the band-limited case).  It writes ``docs/figures/mc_sigma.png`` and prints the
markdown table of ``docs/grace_bias.md``.

Noise cases (σ per sample unless stated; "white" is 1e-10 m/s² per sample):

``white``                white only
``white + 1/f``          one-sided ASD 1.41e-10·sqrt(1 + 1 mHz/f) m/s²/√Hz (the
                         white part 1e-10 per sample), flat below 1/(2T)
``random walk``          2e-12 m/s²/√s random walk starting at 0 at the first sample
                         (its level at t0 is the instrument's bias at t0), + white
``AR(1) τ``              stationary AR(1), τ = 1, 3, 6 h, σ = 5e-10 m/s², + white
``1/rev band``           Gaussian band of 1/5600 Hz ± 10 %, σ = 3e-10 m/s², + white
                         (not described by the noise model: the flag's detection rate)

Run: ``python benchmarks/mc_sigma.py [--reps N] [--cases a,b]`` (default 200 days per
case; ~2 minutes on one core).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import scipy.signal

from accal.estimators.trend import (
    _grid_index,
    _on_grid,
    _orthonormal_columns,
    _scaled_time,
    fit_trend,
    lsq_weights,
    wavelet_weights,
)

N = 86400
DT = 1.0
WHITE = 1e-10
ROOT = Path(__file__).resolve().parents[1]


# --------------------------------------------------------------------------------------
# independent noise generators
# --------------------------------------------------------------------------------------


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


# --------------------------------------------------------------------------------------
# the pre-issue-20 sigma (trend.py at 2ce4c6f, _CovarianceKernel), for before/after
# --------------------------------------------------------------------------------------


class OldKernel:
    """Binned residual periodogram with the white-noise projection correction."""

    def __init__(self, t, g, order, min_bin=3):
        t = np.asarray(t, dtype=np.float64)
        self.n = t.size
        self.idx, self.ngrid = _grid_index(t)
        u, _, _ = _scaled_time(t)
        q = _orthonormal_columns(np.vander(u, order + 1, increasing=True))
        rows = np.empty((order + 1 + g.shape[0], self.n))
        rows[: order + 1] = q.T
        rows[order + 1 :] = g
        spec = np.fft.rfft(_on_grid(rows, self.idx, self.ngrid), axis=1)
        nf = spec.shape[1]
        suppress = 1.0 - np.sum(np.abs(spec[: order + 1]) ** 2, axis=0) / self.n
        self.inv_suppress = 1.0 / np.clip(suppress, 0.2, None)
        edges = [1]
        while edges[-1] < nf:
            edges.append(edges[-1] + max(min_bin, int(0.25 * edges[-1])))
        edges[-1] = nf
        edges_arr = np.asarray(edges)
        self.nbins = edges_arr.size - 1
        self.counts = np.diff(edges_arr)
        self.starts = edges_arr[:-1] - 1
        two_sided = np.full(nf, 2.0)
        two_sided[0] = 1.0
        if self.ngrid % 2 == 0:
            two_sided[-1] = 1.0
        gs = spec[order + 1 :]
        p = gs.shape[0]
        self.p = p
        self.pair0 = np.empty((p, p))
        self.pair_bins = np.empty((p, p, self.nbins))
        for i in range(p):
            for j in range(i + 1):
                prod = (gs[i].real * gs[j].real + gs[i].imag * gs[j].imag) * two_sided
                self.pair0[i, j] = self.pair0[j, i] = prod[0]
                summed = np.add.reduceat(prod[1:], self.starts)
                self.pair_bins[i, j] = self.pair_bins[j, i] = summed

    def covariances(self, residuals):
        rspec = np.fft.rfft(_on_grid(residuals, self.idx, self.ngrid), axis=1)
        pgram = (rspec.real**2 + rspec.imag**2) * (self.inv_suppress / self.n)
        sbin = np.add.reduceat(pgram[:, 1:], self.starts, axis=1) / self.counts
        p = self.p
        cov = (sbin @ self.pair_bins.reshape(p * p, self.nbins).T).reshape(-1, p, p)
        cov += sbin[:, 0, None, None] * self.pair0
        return cov / self.ngrid


# --------------------------------------------------------------------------------------
# the study
# --------------------------------------------------------------------------------------


def summarise(est: np.ndarray, sig: np.ndarray) -> tuple[float, float, float]:
    """``(scatter/σ, fraction |z| > 3, std(σ)/mean(σ))`` of one coefficient."""
    ratio = np.std(est) / np.sqrt(np.mean(sig**2))
    return float(ratio), float(np.mean(np.abs(est / sig) > 3)), float(np.std(sig) / np.mean(sig))


def study(name: str, gen, reps: int, seed: int) -> list[dict]:
    rng = np.random.default_rng(seed)
    t = np.arange(N) * DT
    old = {
        m: OldKernel(t, w(t, 1), 1) for m, w in (("wavelet", wavelet_weights), ("lsq", lsq_weights))
    }
    acc = {m: {"est": [], "new": [], "old": [], "flag": []} for m in old}
    for _ in range(reps):
        e = gen(rng)
        for m in old:
            fit = fit_trend(t, e, method=m)
            resid = e - fit.evaluate(t)
            acc[m]["est"].append(fit.coef)
            acc[m]["new"].append(fit.sigma)
            acc[m]["old"].append(np.sqrt(np.diag(old[m].covariances(resid[None])[0])))
            acc[m]["flag"].append(any("misfit" in n for n in fit.notes))
    rows = []
    for m, a in acc.items():
        est = np.array(a["est"])
        row = {"case": name, "method": m, "flag": float(np.mean(a["flag"])), "reps": reps}
        for which in ("old", "new"):
            sig = np.array(a[which])
            for j, coef in enumerate(("bias", "drift")):
                row[(which, coef)] = summarise(est[:, j], sig[:, j])
        rows.append(row)
    return rows


def false_alarms(gen, days: int, seed: int) -> tuple[int, int]:
    """``(days, days flagged)``: the misfit note on noise the model describes."""
    rng = np.random.default_rng(seed)
    t = np.arange(N) * DT
    flagged = sum(any("misfit" in n for n in fit_trend(t, gen(rng)).notes) for _ in range(days))
    return days, flagged


def table(rows: list[dict]) -> str:
    """Markdown table: old → new for each statistic."""
    head = (
        "| noise | method | bias scatter/σ | drift scatter/σ | bias \\|z\\|>3 | drift \\|z\\|>3 "
        "| σ_bias scatter | σ_drift scatter | misfit flag |\n|---|---|---|---|---|---|---|---|---|"
    )
    out = [head]
    for r in rows:
        ob, od, nb, nd = (
            r[("old", "bias")],
            r[("old", "drift")],
            r[("new", "bias")],
            r[("new", "drift")],
        )
        out.append(
            f"| {r['case']} | {r['method']} | {ob[0]:.2f} → **{nb[0]:.2f}** | {od[0]:.2f} → **{nd[0]:.2f}** "
            f"| {100 * ob[1]:.1f} → **{100 * nb[1]:.1f} %** | {100 * od[1]:.1f} → **{100 * nd[1]:.1f} %** "
            f"| {100 * ob[2]:.0f} → **{100 * nb[2]:.0f} %** | {100 * od[2]:.0f} → **{100 * nd[2]:.0f} %** "
            f"| {100 * r['flag']:.1f} % |"
        )
    return "\n".join(out)


def figure(rows: list[dict], path: Path) -> None:
    import matplotlib
    import matplotlib.ticker

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.8), sharey=True)
    labels = [f"{r['case']} ({r['method'][:3]})" for r in rows]
    y = np.arange(len(rows))
    for ax, coef in zip(axes, ("bias", "drift"), strict=True):
        ax.axvspan(0.8, 1.25, color="0.9", label="target 0.8–1.25")
        ax.plot([r[("old", coef)][0] for r in rows], y, "o", mfc="none", color="C3", label="before")
        ax.plot([r[("new", coef)][0] for r in rows], y, "o", color="C0", label="after")
        ax.set_xscale("log")
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_xticks([0.1, 0.2, 0.5, 1.0, 2.0], ["0.1", "0.2", "0.5", "1", "2"])
        ax.set_xlabel(f"{coef}: scatter / RMS σ")
        ax.axvline(1.0, color="k", lw=0.5)
    axes[0].set_yticks(y, labels, fontsize=8)
    axes[0].invert_yaxis()
    axes[1].legend(fontsize=8, loc="lower right")
    fig.suptitle(
        f"grace-bias σ under coloured noise, 1 Hz days of {N} samples ({rows[0]['reps']} days per case)"
    )
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=200)
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--figure", default=str(ROOT / "docs" / "figures" / "mc_sigma.png"))
    ap.add_argument(
        "--far", type=int, default=1000, help="days per case for the flag's false-alarm rate"
    )
    args = ap.parse_args()
    if args.far:
        t0 = time.perf_counter()
        for i, name in enumerate(("white", "white + 1/f", "random walk + white")):
            n, k = false_alarms(CASES[name], args.far, seed=900 + i)
            print(f"# misfit flag on {name}: {k}/{n} days ({100 * k / n:.2f} %), wavelet")
        print(f"# {time.perf_counter() - t0:.0f} s", flush=True)
    rows = []
    t0 = time.perf_counter()
    for i, name in enumerate(args.cases.split(",")):
        t1 = time.perf_counter()
        rows.extend(study(name, CASES[name], args.reps, seed=100 + i))
        print(f"# {name}: {time.perf_counter() - t1:.0f} s", flush=True)
    print(table(rows))
    print(f"\n# {time.perf_counter() - t0:.0f} s in all")
    if args.figure:
        figure(rows, Path(args.figure))
        print(f"# figure: {args.figure}")


if __name__ == "__main__":
    main()
