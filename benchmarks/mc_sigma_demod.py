"""Monte-Carlo check of the per-period σ of ``accal demod`` (issue 20, make mc-sigma-demod).

For each noise case, runs of a rotating platform are generated here (not with
``accal simulate``): the Fig. 2 pattern of Lenoir et al. (2013) written out below,
an affine drifting bias per axis, a constant signal (plus a daily term in the leakage
case), and noise drawn by FFT shaping from a two-sided PSD.  Each run is demodulated
as ``accal demod`` does with no ``--psd`` (``noise="data"``: the PSD estimated from the
run's residual) and with the a-priori PSD (eq. 1), and the per-period errors against
the truth (the true mean of a_Y, a_Z over the whole period) are compared with the
reported σ:

* ``ratio`` = std of the errors / RMS of the reported σ (1 when σ is right; target
  0.8–1.25);
* ``|z|>3`` = fraction of the errors beyond 3 reported σ (Gaussian: 0.27 %);
* ``warn`` = fraction of runs whose a-priori/empirical σ ratio exceeds 2 (either way),
  the condition of the ``accal demod`` warning.

Prints a markdown table.  About 3 minutes on one core (``--quick``: a few seconds).

References
----------
B. Lenoir, B. Christophe, S. Reynaud, Adv. Space Res. 51 (2013) 188-197,
doi:10.1016/j.asr.2012.08.001 (eq. 1, Fig. 2, eq. 21).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np

from accal.estimators.demod import demodulate, signal_leakage
from accal.estimators.noise import MicroStarPSD

TAU, TM, FS = 600.0, 200.0, 1.0
DAY = 86400.0


def fig2_theta(tau: float, tm: float, fs: float) -> np.ndarray:
    """θ over one period: rests ``a | b | c | b | a`` at 0, π, 0, π, 0, four rotations.

    ``r = TM fs/4`` samples per rotation (quintic smooth step), ``b = (τ − TM) fs/4``,
    ``c = 2b − 2a`` (Σ cos θ = 0 over the rests), ``a`` the integer that makes the
    layout closest to rejecting a quadratic bias (|Σ c t²| smallest; Fig. 2).
    """
    q, r, b = int(tau * fs), int(tm * fs / 4), int((tau - tm) * fs / 4)
    x = (np.arange(r) + 1.0) / (r + 1.0)
    ramp = np.pi * x**3 * (10 - 15 * x + 6 * x**2)
    t = (np.arange(q) - (q - 1) / 2) / q
    best, best_val = None, np.inf
    for a in range(1, b):
        c = 2 * b - 2 * a
        th = np.concatenate(
            [np.zeros(a), ramp, np.full(b, np.pi), np.pi - ramp, np.zeros(c), ramp]
            + [np.full(b, np.pi), np.pi - ramp, np.zeros(a)]
        )
        rest = np.isin(th, (0.0, np.pi))
        val = abs(np.sum(np.cos(th) * rest * t**2))
        if val < best_val:
            best, best_val = th, val
    return best


def shaped_noise(n: int, psd: Callable[[np.ndarray], np.ndarray], rng, size: int = 2):
    """Gaussian noise with the two-sided PSD ``psd`` [m² s⁻⁴ Hz⁻¹] at 1/FS sampling."""
    nfft = 2 * n
    f = np.fft.rfftfreq(nfft, 1.0 / FS)
    f[0] = f[1]
    amp = np.sqrt(psd(f) * FS)
    w = rng.standard_normal((size, nfft))
    return np.fft.irfft(np.fft.rfft(w, axis=1) * amp, nfft, axis=1)[:, :n]


def make_run(days: float, psd, rng, daily: float = 0.0):
    """One run: (time, m_y, m_z, theta, true a_Y and a_Z per period)."""
    th1 = fig2_theta(TAU, TM, FS)
    q = th1.size
    n_per = int(days * DAY / TAU)
    n = n_per * q
    t = np.arange(n) / FS
    theta = np.tile(th1, n_per)
    a_y = 3e-7 + daily * np.sin(2 * np.pi * t / DAY + 0.3)
    a_z = -2e-7 + daily * np.cos(2 * np.pi * t / DAY + 0.3)
    noise = shaped_noise(n, psd, rng)
    by = 2e-6 + 1e-10 * t
    bz = -1e-6 - 5e-11 * t
    c, s = np.cos(theta), np.sin(theta)
    my = c * a_y + s * a_z + by + noise[0]
    mz = -s * a_y + c * a_z + bz + noise[1]
    truth = a_y.reshape(n_per, q).mean(axis=1), a_z.reshape(n_per, q).mean(axis=1)
    return t, my, mz, theta, truth


def white(level: float):
    """Two-sided PSD of white noise of ``level`` m/s² per sample at FS."""
    return lambda f: np.full_like(np.asarray(f, float), level**2 / FS)


CASES = {
    "white 1e-11 per sample": (white(1e-11), 0.0),
    "white 1e-9 per sample": (white(1e-9), 0.0),
    "MicroSTAR eq. 1": (MicroStarPSD(), 0.0),
    "10 × eq. 1 (PSD)": (lambda f: 10.0 * MicroStarPSD()(f), 0.0),
    "white 1e-11 + daily 1e-8 signal": (white(1e-11), 1e-8),
}


def run_case(name: str, runs: int, days: float, method: str, seed: int) -> dict:
    psd, daily = CASES[name]
    rng = np.random.default_rng(seed)
    err, sig, err_a, sig_a, warn, leak, secs = [], [], [], [], 0, [], []
    scaled = 0  # runs whose σ were scaled for a changing noise level (all cases stationary)
    for _ in range(runs):
        t, my, mz, th, (ty, tz) = make_run(days, psd, rng, daily)
        t0 = time.perf_counter()
        res = demodulate(t, my, mz, th, tau=TAU, mask=TM, method=method, noise="data")
        secs.append(time.perf_counter() - t0)
        apr = demodulate(t, my, mz, th, tau=TAU, mask=TM, method=method)
        k = res.period_index
        err.append(np.concatenate([res.a_Y - ty[k], res.a_Z - tz[k]]))
        sig.append(np.concatenate([res.sigma_Y, res.sigma_Z]))
        err_a.append(np.concatenate([apr.a_Y - ty[k], apr.a_Z - tz[k]]))
        sig_a.append(np.concatenate([apr.sigma_Y, apr.sigma_Z]))
        r = res.noise.sigma_ratio
        warn += bool(r > 2 or r < 0.5)
        scaled += bool(res.noise.level)
        leak.append(signal_leakage(res).ratio.max())
    e, s = np.concatenate(err), np.concatenate(sig)
    ea, sa = np.concatenate(err_a), np.concatenate(sig_a)
    per_run = [np.std(x) / np.sqrt(np.mean(y**2)) for x, y in zip(err, sig, strict=True)]
    return {
        "case": name,
        "method": method,
        "ratio": np.std(e) / np.sqrt(np.mean(s**2)),
        "ratio_run_scatter": float(np.std(per_run)),
        "z3": float(np.mean(np.abs(e / s) > 3)),
        "ratio_apriori": np.std(ea) / np.sqrt(np.mean(sa**2)),
        "warn": warn / runs,
        "leak": float(np.mean(leak)),
        "seconds": float(np.median(secs)),
        "n": e.size,
        "scaled": scaled / runs,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="2 runs of 0.5 day per case")
    ap.add_argument("--runs", type=int, default=6)
    ap.add_argument("--days", type=float, default=1.0)
    ap.add_argument("--seed", type=int, default=20)
    args = ap.parse_args()
    runs, days = (2, 0.5) if args.quick else (args.runs, args.days)
    print(
        f"{runs} runs of {days:g} day per case, tau = {TAU:g} s, TM = {TM:g} s, fs = {FS:g} Hz; "
        "errors against the true period means; no --psd (sigma from the data) vs eq. 1\n"
    )
    print(
        "| noise | method | σ ratio (data PSD) | run-to-run scatter | |z|>3 | σ ratio (eq. 1) "
        "| warns | leakage/σ | s per run | level-scaled runs |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for i, name in enumerate(CASES):
        for method in ("ls", "gls"):
            r = run_case(name, runs, days, method, args.seed + i)
            print(
                f"| {r['case']} | {r['method']} | {r['ratio']:.3f} | {r['ratio_run_scatter']:.3f} "
                f"| {100 * r['z3']:.2f} % | {r['ratio_apriori']:.3f} | {100 * r['warn']:.0f} % "
                f"| {r['leak']:.2f} | {r['seconds']:.2f} | {100 * r['scaled']:.0f} % |",
                flush=True,
            )


if __name__ == "__main__":
    main()
