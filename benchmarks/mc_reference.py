"""Monte-Carlo benchmark of the reference calibration ``fit_reference`` (``make mc-reference``, issue 22).

Arcs of 1 Hz data are drawn by the small generator below (numpy/scipy only, independent
of ``accal.simulate`` and of the tests' generators) and fitted by
:func:`accal.estimators.reference.fit_reference` as ``accal grace-bias --reference``
fits them: ``a_ref = S·(a_raw − b(t)) + e``.

Generator (SRF: x along-track, y cross-track, z radial; all numbers in m/s²)

* signal ``a_true``: drag ``−2e-7·ρ(t)·(1 + 0.3 cos u + 0.08 cos 2u)·(1 + 0.03 w(t))``
  with ``ρ = exp(0.25 g(t))`` (g a smooth unit process, correlation ~1.5 d: slow density
  changes of tens of %) and ``w`` a sub-orbital wave (~300 s); cross-track
  ``1e-8 cos(u + 1)·(0.5 + 0.5 ρ)`` plus 2 % of the drag times a wind process (~900 s);
  radial ``3e-8·(0.7 sin(u + 0.3) + 0.3 h(t))`` (~1200 s); solar radiation pressure
  ``1e-8`` along the sun direction, switched off in a cylindrical Earth shadow with a
  ~10 s penumbra (the β angle moves by 50° over 30 days, so eclipse seasons end);
* ``raw = S⁻¹·a_true + b(t) + n(t) + spikes``: ``S = diag(0.96, 0.98, 0.95)`` (TN-02-like)
  plus, in the ``cross`` truth, off-diagonal terms ±1e-3 (:data:`CROSS`); ``b(t)`` a
  clamped cubic B-spline with 6 h nodes whose coefficients are TN-02-like constants
  (−1.1e-6, 2.7e-5, −5.6e-7) plus N(0, (3e-9, 1e-8, 2e-9)) perturbations; ``n`` the
  accelerometer noise, ASD 1e-10·√(1 + 1 mHz/f) m/s²/√Hz on every axis; spikes: thruster
  firings (Poisson, 3 per hour, 0.2–1.2 s, 1e-7–1e-6 m/s² along a random direction), on
  the samples inside the firing, masked with GROOPS's margins (0.1 s before, 0.7 s after);
* reference ``a_ref = a_true + e``, the same kind of ``e`` on every axis (:data:`NOISES`):
  ``blue`` positions with white noise differentiated twice (rms 3e-8 per 1 Hz sample,
  PSD ∝ f⁴); ``white`` 3e-9 per sample; ``red+blue`` AR(1) τ = 1 h, σ = 2e-9 plus a
  once-differenced white noise of 1e-8 per sample; ``1/rev line`` (a model the estimator
  was not designed for: an AR model cannot whiten a line) white 3e-9 plus a once-per-rev
  sinusoid of 5e-10 whose phase random-walks by 1 rad per √day.

Truths and fits (:data:`TRUTHS`, :data:`CONFIGS`; the same signal, accelerometer noise
and reference noise for every truth of a replicate): ``cross``/``diag`` (S with/without
cross-talk, spline bias) fitted with ``spline:6h`` over the arc (``scale="fit"`` and
``"fit-matrix"``; on ``cross`` also ``poly1`` per day, a bias model that cannot follow
the 6 h spline, to show what that costs); ``cross/lin``/``diag/lin`` (a bias that is a
line per day) fitted with ``poly1`` per day, each day its own fit.  The days are
noise-model segments (``breaks``) as ``grace-bias --arc`` sets them.  Without a
reference, each day of raw x is also fitted by the wavelet trend
(``fit_trends(method="wavelet", order=1)``): its day mean against the true day mean of b
is the reference-free error.

Reported per case: scatter/σ (std of z) and mean z of each scale entry and of the bias
at every day start, the fractions |z| > 2 and > 3, the cross-talk test's p-values
(false alarms at 0.05/0.01 on the ``diag`` truth, power on ``cross``), fall-backs of a
scale (``fit.modes``/``fit.notes``), the RMS day-mean bias error on x against the
wavelet's, the run time per fit and the peak RSS of the fitting process during a fit
(``VmHWM`` after resetting it, Linux).  Writes ``results.json`` and ``summary.md`` to
``--out`` and ``docs/figures/reference_mc.png``.

Run: ``python benchmarks/mc_reference.py [--quick] [--days D] [--reps R] [--workers W]``
(default: the 30-day arcs of issue 22 at 1 Hz, 5 replicates of every case, 2
processes: 17 min, 23 min with the data-domain σ of the fit; ``--quick``: 2-day arcs,
5 replicates, ~2 min).  The estimator is the one importable as ``accal`` (e.g.
``PYTHONPATH=/path/to/snapshot/src`` to measure a frozen tree): its file hashes are in
``results.json``.  ``--replot`` redraws the tables and the figure from
``OUT/results.json``.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy import signal, stats  # noqa: E402
from scipy.interpolate import BSpline  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DAY = 86400.0
T0 = 7.0e8  # GPS seconds of the arc's first sample (2022)
ORBIT = 5640.0  # [s]
S_DIAG = np.diag([0.96, 0.98, 0.95])
#: Cross-talk of the ``cross`` truth (added to S_DIAG).
CROSS = 1e-3 * np.array([[0.0, 1.0, -1.0], [-1.0, 0.0, 1.0], [1.0, -1.0, 0.0]])
#: Truths: scale matrix and kind of bias (``spline``: cubic, 6 h nodes; ``linear``: a line
#: per day, continuous at midnight: the model of ``poly1`` per day).
TRUTHS = {
    "cross": (S_DIAG + CROSS, "spline"),
    "diag": (S_DIAG, "spline"),
    "cross/lin": (S_DIAG + CROSS, "linear"),
    "diag/lin": (S_DIAG, "linear"),
}
B0 = np.array([-1.1e-6, 2.7e-5, -5.6e-7])  # TN-02-like biases [m/s²]
B_PERT = np.array([3e-9, 1e-8, 2e-9])  # σ of the spline coefficients around B0 [m/s²]
NODE = 6 * 3600.0  # spline node step of the true bias [s]
ACC_ASD, ACC_CORNER = 1e-10, 1e-3  # [m/s²/√Hz], [Hz]
RHO = 6371.0 / (6371.0 + 450.0)  # Earth radius / orbit radius
THR_RATE, THR_BEFORE, THR_AFTER = 3 / 3600.0, 0.1, 0.7  # [1/s], [s], [s]
NOISES = ("blue", "white", "red+blue", "1/rev line")
#: (bias basis, scale mode) per truth; ``poly1/day`` fits each day on its own.  On the
#: ``spline`` truths ``poly1/day`` is a misspecified bias model (shown once, on ``cross``).
CONFIGS = {
    "cross": (("spline:6h", "fit-matrix"), ("spline:6h", "fit"), ("poly1/day", "fit-matrix")),
    "diag": (("spline:6h", "fit"),),
    "cross/lin": (("poly1/day", "fit-matrix"), ("poly1/day", "fit")),
    "diag/lin": (("poly1/day", "fit"),),
}


# ------------------------------------------------------------------------- generator
def colored(rng: np.random.Generator, n: int, asd, pad: int = 2) -> np.ndarray:
    """Gaussian noise of one-sided ASD ``asd(f)`` [unit/√Hz] at 1 Hz, ``n`` samples.

    Spectral synthesis on ``pad·n`` points and a random window of ``n``: not periodic.
    """
    m = pad * n
    f = np.fft.rfftfreq(m, 1.0)
    f[0] = f[1]
    amp = asd(f) * np.sqrt(m) / 2.0
    z = amp * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size))
    z[0] = 0.0
    x = np.fft.irfft(z, m)
    a = int(rng.integers(0, m - n))
    return x[a : a + n]


def markov(rng: np.random.Generator, n: int, tau: float) -> np.ndarray:
    """Stationary first-order Markov process, unit variance, correlation time ``tau`` [s]."""
    phi = np.exp(-1.0 / tau)
    w = rng.standard_normal(n) * np.sqrt(1.0 - phi**2)
    x, _ = signal.lfilter([1.0], [1.0, -phi], w, zi=[phi * rng.standard_normal()])
    return x


def smooth(rng: np.random.Generator, n: int, tau: float) -> np.ndarray:
    """A smooth stationary unit-variance process: white noise through two first-order
    low-passes of time ``tau`` [s] (a burn-in of 12 τ, then the exact variance
    (1 − φ)²(1 + φ²)/(1 − φ²)³ of ``1/(1 − φB)²`` divided out: no per-arc normalisation,
    which would inflate a process slower than the arc)."""
    phi = np.exp(-1.0 / tau)
    burn = int(12 * tau)
    x = signal.lfilter([1.0 - phi], [1.0, -phi], rng.standard_normal(n + burn))
    x = signal.lfilter([1.0], [1.0, -phi], x)[burn:]
    return x / np.sqrt((1 - phi) ** 2 * (1 + phi**2) / (1 - phi**2) ** 3)


def signal_arc(rng: np.random.Generator, n: int) -> np.ndarray:
    """True non-gravitational acceleration, shape (n, 3) [m/s²] (module docstring)."""
    s = np.arange(n, dtype=float)
    # argument of latitude from the sun's direction (slow drift: the sun moves)
    u = 2 * np.pi * s / ORBIT + rng.uniform(0, 2 * np.pi) - 2 * np.pi * s / (365.25 * DAY)
    beta = np.deg2rad(rng.uniform(0.0, 30.0) + 50.0 * s / (30 * DAY))
    dens = np.exp(0.25 * smooth(rng, n, 1.5 * DAY))
    orb = 1 + 0.3 * np.cos(u - 0.5) + 0.08 * np.cos(2 * u + rng.uniform(0, 2 * np.pi))
    drag = 2e-7 * dens * orb * (1 + 0.03 * smooth(rng, n, 300.0))
    cpsi = np.cos(beta) * np.cos(u)  # cos of the satellite-sun angle seen from the Earth
    spsi = np.sqrt(np.clip(1 - cpsi**2, 0, None))
    lit = np.where(cpsi < 0, np.clip(0.5 + (spsi - RHO) / 4e-3, 0, 1), 1.0)
    sun = np.column_stack([-np.cos(beta) * np.sin(u), np.sin(beta), np.cos(beta) * np.cos(u)])
    a = np.column_stack(
        [
            -drag,
            1e-8 * np.cos(u + 1.0) * (0.5 + 0.5 * dens) + 0.02 * drag * smooth(rng, n, 900.0),
            3e-8 * (0.7 * np.sin(u + 0.3) + 0.3 * smooth(rng, n, 1200.0)),
        ]
    )
    return a - 1e-8 * lit[:, None] * sun


def true_bias(rng: np.random.Generator, n: int, kind: str) -> np.ndarray:
    """b(t), shape (n, 3): a clamped cubic B-spline with 6 h nodes from the first sample
    (``spline``) or a line per day, continuous at midnight (``linear``)."""
    step, k = (NODE, 3) if kind == "spline" else (DAY, 1)
    n_int = max(1, int(np.ceil((n - 1) / step - 1e-9)))
    inner = step * np.arange(n_int + 1)
    knots = np.concatenate([[0.0] * k, inner, [inner[-1]] * k])
    coef = B0 + B_PERT * rng.standard_normal((knots.size - k - 1, 3))
    return BSpline(knots, coef, k)(np.arange(n, dtype=float))


def thrusters(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Spikes on the raw data (n, 3) [m/s²] and the valid mask (firings with margins out)."""
    k = rng.poisson(THR_RATE * n)
    start = np.sort(rng.uniform(0, n - 2, k))
    end = start + rng.uniform(0.2, 1.2, k)
    amp = np.exp(rng.uniform(np.log(1e-7), np.log(1e-6), k))
    direc = rng.standard_normal((k, 3))
    direc /= np.linalg.norm(direc, axis=1)[:, None]
    spikes = np.zeros((n, 3))
    valid = np.ones(n, bool)
    for ts, te, a, d in zip(start, end, amp, direc, strict=True):
        spikes[int(np.ceil(ts)) : int(np.floor(te)) + 1] += a * d
        valid[int(np.ceil(ts - THR_BEFORE)) : int(np.floor(te + THR_AFTER)) + 1] = False
    return spikes, valid


def reference_noise(rng: np.random.Generator, n: int, kind: str) -> np.ndarray:
    """Reference error e, shape (n, 3) [m/s²] (module docstring)."""
    if kind == "blue":
        return np.diff(rng.standard_normal((n + 2, 3)), 2, axis=0) * (3e-8 / np.sqrt(6.0))
    if kind == "white":
        return rng.standard_normal((n, 3)) * 3e-9
    if kind == "red+blue":
        red = np.column_stack([markov(rng, n, 3600.0) for _ in range(3)]) * 2e-9
        return red + np.diff(rng.standard_normal((n + 1, 3)), axis=0) * 1e-8
    if kind == "1/rev line":
        s = np.arange(n, dtype=float)
        steps = rng.standard_normal((n, 3)) / np.sqrt(DAY)
        phase = rng.uniform(0, 2 * np.pi, 3) + np.cumsum(steps, axis=0)
        line = 5e-10 * np.cos(2 * np.pi * s[:, None] / ORBIT + phase)
        return line + rng.standard_normal((n, 3)) * 3e-9
    raise ValueError(f"unknown reference noise {kind!r}")


def draw_arc(seed: int, days: float, truth: str) -> dict:
    """One arc: time, raw, valid, true signal and bias (the same for both truths of a seed)."""
    rng = np.random.default_rng([seed, 0])
    n = int(round(days * DAY))
    a = signal_arc(rng, n)
    s_mat, kind = TRUTHS[truth]
    b = true_bias(np.random.default_rng([seed, 9]), n, kind)
    flat_below = 1.0 / (2.0 * n)
    noise = np.column_stack(
        [
            colored(rng, n, lambda f: ACC_ASD * np.sqrt(1 + ACC_CORNER / np.maximum(f, flat_below)))
            for _ in range(3)
        ]
    )
    spikes, valid = thrusters(rng, n)
    raw = a @ np.linalg.inv(s_mat).T + b + noise + spikes
    return {"t": T0 + np.arange(n, dtype=float), "a": a, "b": b, "raw": raw, "valid": valid}


# ------------------------------------------------------------------------- one task
def _peak_rss_reset() -> None:
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
    except OSError:
        pass


def _peak_rss_mb() -> float:
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmHWM"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _fit_record(fit, s_true, day_t, day_b, day_grid, wall, cpu, rss) -> dict:
    """What one fit gives against the truth (bias at day starts, day means, scales)."""
    sig = fit.scale_sigma
    with np.errstate(divide="ignore", invalid="ignore"):
        z_s = np.where(sig > 0, (fit.scale - s_true) / sig, np.nan)
    val, sb = fit.bias(day_t)
    means = []
    for tg, bg in day_grid:
        means.append(fit.bias(tg)[0].mean(0) - bg.mean(0))
    return {
        "scale": fit.scale.tolist(),
        "scale_sigma": sig.tolist(),
        "z_scale": z_s.tolist(),
        "bias_err": (val - day_b).tolist(),
        "bias_sigma": sb.tolist(),
        "daymean_err": np.array(means).tolist(),
        "p": fit.crosstalk_test.get("p", float("nan")),
        "chi2": fit.crosstalk_test.get("chi2", float("nan")),
        "dof": fit.crosstalk_test.get("dof", 0),
        "modes": list(fit.modes),
        "notes": list(fit.notes),
        "ar_order": [m.order for m in fit.noise],
        "sigma0": fit.sigma0.tolist(),
        "wall_s": wall,
        "cpu_s": cpu,
        "rss_mb": rss,
    }


def run_task(task: dict) -> list[dict]:
    """Every configured fit of one arc, truth and reference noise (+ the wavelet if asked)."""
    from accal.estimators.refbasis import parse_bias_basis
    from accal.estimators.reference import fit_reference
    from accal.estimators.trend import fit_trends

    arc = draw_arc(task["seed"], task["days"], task["truth"])
    t, raw, valid, b = arc["t"], arc["raw"], arc["valid"], arc["b"]
    n = t.size
    nd = int(round(n / DAY))
    starts = np.arange(nd) * int(DAY)
    stops = np.minimum(starts + int(DAY), n)
    grid = [(t[a:z:10], b[a:z:10]) for a, z in zip(starts, stops, strict=True)]
    rng = np.random.default_rng([task["seed"], 1 + NOISES.index(task["noise"])])
    ref = arc["a"] + reference_noise(rng, n, task["noise"])
    del arc
    breaks = np.zeros(n, bool)
    breaks[starts] = True
    s_true = TRUTHS[task["truth"]][0]
    head = {k: task[k] for k in ("seed", "truth", "noise", "days")}
    out = []
    for spec, mode in task["configs"]:
        pieces = [(0, n)] if spec.startswith("spline") else list(zip(starts, stops, strict=True))
        for day0, (a, z) in enumerate(pieces):
            basis = parse_bias_basis(spec.removesuffix("/day"), float(t[a]), float(t[z - 1]))
            _peak_rss_reset()
            w0, c0 = time.perf_counter(), time.process_time()
            rec = dict(head, basis=spec, mode=mode, day0=day0 if len(pieces) > 1 else 0)
            try:
                fit = fit_reference(
                    t[a:z], raw[a:z], ref[a:z], valid[a:z], basis,
                    scale=mode, apriori=tuple(np.diag(S_DIAG)), breaks=breaks[a:z],
                )  # fmt: skip
            except Exception as exc:  # noqa: BLE001 - reported, not hidden
                rec.update(error=f"{type(exc).__name__}: {exc}")
                out.append(rec)
                continue
            wall, cpu = time.perf_counter() - w0, time.process_time() - c0
            inside = (starts >= a) & (starts < z)
            rec.update(
                _fit_record(
                    fit, s_true, t[starts[inside]], b[starts[inside]],
                    [g for g, k in zip(grid, inside, strict=True) if k], wall, cpu,
                    _peak_rss_mb(),
                )
            )  # fmt: skip
            out.append(rec)
    if task["wavelet"]:
        errs, sigs, walls = [], [], []
        for (tg, bg), a, z in zip(grid, starts, stops, strict=True):
            w0 = time.perf_counter()
            tf = fit_trends(t[a:z], raw[a:z, :1], method="wavelet", order=1, valid=valid[a:z])[0]
            walls.append(time.perf_counter() - w0)
            mean_t = float(np.mean(t[a:z]))
            errs.append(tf.bias + tf.drift * (mean_t - tf.t0) - float(np.mean(b[a:z, 0])))
            sigs.append(float(tf.sigma[0]))
            del tg, bg
        out.append(
            dict(head, basis="wavelet (no reference)", mode="-", daymean_err_x=errs,
                 bias_sigma_x=sigs, wall_s=float(np.sum(walls)))
        )  # fmt: skip
    return out


# ------------------------------------------------------------------------- running
def make_tasks(args: argparse.Namespace) -> list[dict]:
    tasks = []
    for rep in range(args.reps):
        for truth in args.truths:
            for k, noise in enumerate(args.noises):
                tasks.append(
                    {
                        "seed": args.seed + rep,
                        "truth": truth,
                        "noise": noise,
                        "days": args.days,
                        "configs": CONFIGS[truth],
                        "wavelet": k == 0,
                    }
                )
    return tasks


def run_all(tasks: list[dict], workers: int) -> list[dict]:
    """Run the tasks on ``workers`` forked processes; all records, in task order."""
    import multiprocessing as mp

    import accal.estimators.refbasis  # noqa: F401 - imported once, before the fork
    import accal.estimators.reference  # noqa: F401
    import accal.estimators.trend  # noqa: F401

    t_start = time.perf_counter()
    results: list[list[dict]] = [[] for _ in tasks]
    if workers <= 1:
        it = ((i, run_task(task)) for i, task in enumerate(tasks))
        return _collect(it, results, tasks, t_start)
    with mp.get_context("fork").Pool(workers, maxtasksperchild=4) as pool:
        it = pool.imap_unordered(_indexed, list(enumerate(tasks)), chunksize=1)
        out = _collect(it, results, tasks, t_start)
        pool.close()
        pool.join()
    return out


def _indexed(item: tuple[int, dict]) -> tuple[int, list[dict]]:
    return item[0], run_task(item[1])


def _collect(it, results, tasks, t_start) -> list[dict]:
    for k, (i, recs) in enumerate(it, 1):
        results[i] = recs
        task = tasks[i]
        bad = sum("error" in r for r in recs)
        print(
            f"[{k}/{len(tasks)} {time.perf_counter() - t_start:6.0f} s] seed {task['seed']} "
            f"{task['truth']} {task['noise']}: {len(recs)} fits"
            + (f", {bad} FAILED" if bad else ""),
            file=sys.stderr,
            flush=True,
        )
    return [r for recs in results for r in recs]


# ------------------------------------------------------------------------- aggregation
def _zstats(z: np.ndarray) -> dict:
    z = np.asarray(z, dtype=float).ravel()
    z = z[np.isfinite(z)]
    if z.size == 0:
        return {"n": 0}
    return {
        "n": int(z.size),
        "std": float(np.std(z, ddof=1)) if z.size > 1 else float("nan"),
        "mean": float(np.mean(z)),
        "gt2": float(np.mean(np.abs(z) > 2)),
        "gt3": float(np.mean(np.abs(z) > 3)),
    }


def summarise(records: list[dict]) -> list[dict]:
    """One row per (truth, noise, basis, mode): the statistics of the module docstring."""
    wav: dict[str, list[dict]] = {}  # the wavelet does not see the reference: per truth
    for r in records:
        if r["basis"].startswith("wavelet"):
            wav.setdefault(r["truth"], []).append(r)
    keys = []
    for r in records:
        k = (r["truth"], r["noise"], r["basis"], r["mode"])
        if not r["basis"].startswith("wavelet") and k not in keys:
            keys.append(k)
    rows = []
    for truth, noise, basis, mode in keys:
        recs = [
            r
            for r in records
            if (r["truth"], r["noise"], r["basis"], r["mode"]) == (truth, noise, basis, mode)
        ]
        ok = [r for r in recs if "error" not in r]
        row = {
            "truth": truth,
            "noise": noise,
            "basis": basis,
            "mode": mode,
            "fits": len(recs),
            "errors": sorted({r["error"] for r in recs if "error" in r}),
        }
        if not ok:
            rows.append(row)
            continue
        zs = np.array([r["z_scale"] for r in ok], dtype=float)  # (fits, 3, 3)
        want = np.eye(3, dtype=bool) if mode == "fit" else np.ones((3, 3), bool)
        row["scale_entries"] = {
            f"S{'xyz'[i]}{'xyz'[j]}": _zstats(zs[:, i, j])
            for i in range(3)
            for j in range(3)
            if want[i, j]
        }
        row["scale"] = _zstats(zs[:, want])
        row["scale_diag"] = _zstats(zs[:, np.eye(3, dtype=bool)])
        err = np.array([r["scale"] for r in ok], float) - TRUTHS[truth][0]
        eye = np.eye(3, dtype=bool)
        row["scale_rms_err"] = [
            float(np.sqrt(np.mean(err[:, eye] ** 2))),
            float(np.sqrt(np.mean(err[:, ~eye] ** 2))) if mode != "fit" else float("nan"),
        ]
        row["scale_offdiag"] = _zstats(zs[:, ~np.eye(3, dtype=bool)]) if mode != "fit" else {}
        # within 2σ, per fit: all requested entries
        row["scale_all_within_2sigma"] = float(
            np.mean([np.all(np.abs(z[want][np.isfinite(z[want])]) < 2) for z in zs])
        )
        be = np.concatenate([np.array(r["bias_err"], float).reshape(-1, 3) for r in ok])
        bs = np.concatenate([np.array(r["bias_sigma"], float).reshape(-1, 3) for r in ok])
        zb = be / bs
        row["bias"] = _zstats(zb)
        row["bias_axes"] = {ax: _zstats(zb[:, i]) for i, ax in enumerate("xyz")}
        row["bias_rms_err"] = np.sqrt(np.mean(be**2, axis=0)).tolist()
        row["bias_rms_sigma"] = np.sqrt(np.mean(bs**2, axis=0)).tolist()
        dm = np.concatenate([np.array(r["daymean_err"], float).reshape(-1, 3) for r in ok])
        row["daymean_rms_err"] = np.sqrt(np.mean(dm**2, axis=0)).tolist()
        p = np.array([r["p"] for r in ok], float)
        p = p[np.isfinite(p)]
        row["p"] = {
            "n": int(p.size),
            "lt05": float(np.mean(p < 0.05)) if p.size else float("nan"),
            "lt01": float(np.mean(p < 0.01)) if p.size else float("nan"),
            "median": float(np.median(p)) if p.size else float("nan"),
            "ks_uniform": float(stats.kstest(p, "uniform").pvalue) if p.size > 2 else float("nan"),
        }
        row["fallback_fits"] = int(sum(any(m != mode for m in r["modes"]) for r in ok))
        row["fixed_axes"] = int(sum(m == "fixed" for r in ok for m in r["modes"]))
        row["notes"] = sorted({n.split(" (")[0] for r in ok for n in r["notes"]})
        row["ar_order"] = [float(np.mean([r["ar_order"][i] for r in ok])) for i in range(3)]
        row["wall_s"] = float(np.mean([r["wall_s"] for r in ok]))
        row["cpu_s"] = float(np.mean([r.get("cpu_s", np.nan) for r in ok]))
        row["rss_mb"] = float(np.max([r["rss_mb"] for r in ok]))
        w = wav.get(truth)
        if w:
            e = np.concatenate([r["daymean_err_x"] for r in w])
            row["wavelet_daymean_rms_x"] = float(np.sqrt(np.mean(e**2)))
            row["ratio_x"] = row["wavelet_daymean_rms_x"] / row["daymean_rms_err"][0]
        rows.append(row)
    return rows


def _f(x, fmt=".2f") -> str:
    return "–" if x is None or not np.isfinite(x) else format(x, fmt)


def _zcell(s: dict) -> str:
    if not s or not s.get("n"):
        return "–"
    return f"{_f(s['std'])} ({_f(s['mean'], '+.2f')})"


def _tail(s: dict) -> str:
    if not s or not s.get("n"):
        return "–"
    return f"{100 * s['gt2']:.0f}/{100 * s['gt3']:.1f} %"


def markdown(rows: list[dict], meta: dict) -> str:
    """The summary tables (one row per case, then the scale entries of the main case)."""
    lines = [
        f"Monte-Carlo of `fit_reference`: {meta['days']:g}-day arcs at 1 Hz, {meta['reps']} "
        f"replicate(s) per case, {meta['wall_s'] / 60:.1f} min on {meta['workers']} "
        f"process(es) (accal {meta['git']}, estimator sha256 "
        f"{meta.get('code', {}).get('sha256', {}).get('reference.py', '?')}).",
        "",
        "z = (estimate − truth)/σ; cells `std z (mean z)`, target std 0.8–1.25; "
        "tails `% |z|>2 / % |z|>3` (Gaussian 4.6/0.3 %). Bias z at every day start. "
        "p: cross-talk χ² test (diag vs full matrix), fraction p<0.05 / p<0.01. "
        "Day-mean bias error on x: RMS over days, with the reference vs the reference-free "
        "wavelet (ratio, target ≥ 10). s/fit: wall and CPU seconds per fit (a poly1/day "
        "fit is one day); peak RSS: VmHWM of the fitting process during a fit, the arc's "
        "arrays included.",
        "",
        "| truth | reference noise | basis | scale | fits | scales std z (mean) | scales |z|>2/3 "
        "| bias std z (mean) | bias |z|>2/3 | p<0.05 / p<0.01 | fall-backs | x day-mean err "
        "[m/s²] | wavelet x [m/s²] | ratio | s/fit wall (CPU) | peak RSS MB |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        if "scale" not in r:
            lines.append(
                f"| {r['truth']} | {r['noise']} | {r['basis']} | {r['mode']} | {r['fits']} "
                f"| FAILED: {'; '.join(r['errors'])} |" + " |" * 10
            )
            continue
        fb = f"{r['fallback_fits']}/{r['fits']}" + (
            f" ({r['fixed_axes']} axes fixed)" if r["fixed_axes"] else ""
        )
        lines.append(
            f"| {r['truth']} | {r['noise']} | {r['basis']} | {r['mode']} | {r['fits']} "
            f"| {_zcell(r['scale'])} | {_tail(r['scale'])} | {_zcell(r['bias'])} "
            f"| {_tail(r['bias'])} | {100 * r['p']['lt05']:.0f}/{100 * r['p']['lt01']:.0f} % "
            f"| {fb} | {_f(r['daymean_rms_err'][0], '.2e')} "
            f"| {_f(r.get('wavelet_daymean_rms_x'), '.2e')} | {_f(r.get('ratio_x'), '.3g')} "
            f"| {r['wall_s']:.1f} ({_f(r['cpu_s'], '.1f')}) | {r['rss_mb']:.0f} |"
        )
    lines += ["", "Per entry (std z (mean z)):", ""]
    names = [f"S{a}{b}" for a in "xyz" for b in "xyz"]
    lines.append(
        "| truth | noise | basis | scale | "
        + " | ".join(names)
        + " | bias x | bias y | bias z | RMS Ŝ−S diag / off-diag |"
    )
    lines.append("|---" * (4 + 9 + 3 + 1) + "|")
    for r in rows:
        if "scale" not in r:
            continue
        cells = [_zcell(r["scale_entries"].get(nm, {})) for nm in names]
        cells += [_zcell(r["bias_axes"][ax]) for ax in "xyz"]
        cells.append(" / ".join(_f(v, ".1e") for v in r["scale_rms_err"]))
        lines.append(
            f"| {r['truth']} | {r['noise']} | {r['basis']} | {r['mode']} | "
            + " | ".join(cells)
            + " |"
        )
    lines += ["", *targets(rows)]
    notes = sorted({n for r in rows for n in r.get("notes", [])})
    if notes:
        lines += ["", "Fall-back notes seen: " + "; ".join(notes)]
    return "\n".join(lines) + "\n"


def targets(rows: list[dict]) -> list[str]:
    """Issue 22's "Done means", per reference noise, on spline:6h (PASS/FAIL each)."""

    def find(truth, noise, mode):
        for r in rows:
            if (r["truth"], r["noise"], r["basis"], r["mode"]) == (truth, noise, "spline:6h", mode):
                return r if "scale" in r else None
        return None

    def band(s):
        if not s or not s.get("n"):
            return "–"
        ok = 0.8 <= s["std"] <= 1.25
        return f"{'PASS' if ok else 'FAIL'} {s['std']:.2f}"

    out = [
        "Targets (spline:6h; main case: `cross` truth, scale=fit-matrix; test: scale=fit):",
        "",
        "| reference noise | entries within 2σ (fits with all 9) | scales std z in 0.8–1.25 "
        "| bias std z in 0.8–1.25 | x day-mean ratio ≥ 10 | test power p<0.05 (cross) "
        "| false alarms p<0.05 / p<0.01 (diag) |",
        "|---|---|---|---|---|---|---|",
    ]
    for noise in dict.fromkeys(r["noise"] for r in rows):
        m, c, d = (
            find("cross", noise, "fit-matrix"),
            find("cross", noise, "fit"),
            find("diag", noise, "fit"),
        )
        if m is None:
            continue
        within = 1.0 - m["scale"]["gt2"]
        ratio = m.get("ratio_x", float("nan"))
        power = "–" if c is None else f"{100 * c['p']['lt05']:.0f} %"
        false = "–" if d is None else f"{100 * d['p']['lt05']:.0f} / {100 * d['p']['lt01']:.0f} %"
        out.append(
            f"| {noise} | {100 * within:.0f} % ({100 * m['scale_all_within_2sigma']:.0f} %) "
            f"| {band(m['scale'])} | {band(m['bias'])} "
            f"| {'PASS' if ratio >= 10 else 'FAIL'} {_f(ratio, '.3g')} | {power} | {false} |"
        )
    return out


def figure(records: list[dict], rows: list[dict], path: Path) -> None:
    """z histograms of scales and bias vs N(0,1) (spline:6h, ``cross`` fit-matrix and
    ``diag`` fit), x day-mean bias error with reference vs the wavelet's, p-value CDFs."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    main = [("cross", "spline:6h", "fit-matrix"), ("diag", "spline:6h", "fit")]
    noises = list(dict.fromkeys(r["noise"] for r in records))
    fig, axes = plt.subplots(2, 3, figsize=(17, 9))
    zz = np.linspace(-5, 5, 201)
    bins = np.linspace(-5, 5, 41)
    for col, (truth, basis, mode) in enumerate(main):
        sel = [
            r
            for r in records
            if (r["truth"], r["basis"], r["mode"]) == (truth, basis, mode) and "error" not in r
        ]
        for row, what in enumerate(("scale", "bias")):
            ax = axes[row, col]
            for k, noise in enumerate(noises):
                rs = [r for r in sel if r["noise"] == noise]
                if what == "scale":
                    z = [np.array(r["z_scale"], float).ravel() for r in rs]
                else:
                    z = [np.divide(r["bias_err"], r["bias_sigma"]).ravel() for r in rs]
                z = np.concatenate(z) if z else np.zeros(0)
                z = z[np.isfinite(z)]
                if z.size < 2:
                    continue
                ax.hist(
                    np.clip(z, -4.99, 4.99), bins=bins, density=True, histtype="step", lw=1.4,
                    color=f"C{k}", label=f"{noise}: std {np.std(z, ddof=1):.2f}, n={z.size}",
                )  # fmt: skip
            ax.plot(zz, stats.norm.pdf(zz), "k--", lw=1, label="N(0, 1)")
            ax.set_xlabel(
                f"z of {'each fitted scale entry' if what == 'scale' else 'b(t) at day starts'}"
                " (clipped at ±5)"
            )
            ax.set_title(f"{truth} truth, {basis}, scale={mode}", fontsize=10)
            ax.legend(fontsize=7, loc="upper left")
    ax = axes[0, 2]
    bars = (
        ("cross", "spline:6h", "fit-matrix", "C0", "with reference: spline:6h, fit-matrix"),
        ("cross/lin", "poly1/day", "fit-matrix", "C2", "with reference: poly1/day, fit-matrix"),
    )
    y = np.arange(len(noises))
    for j, (truth, basis, mode, color, label) in enumerate(bars):
        val = [
            next(
                (
                    r["daymean_rms_err"][0]
                    for r in rows
                    if (r["truth"], r["noise"], r["basis"], r["mode"]) == (truth, nz, basis, mode)
                    and "scale" in r
                ),
                np.nan,
            )
            for nz in noises
        ]
        ax.barh(y - 0.27 + 0.27 * j, val, height=0.27, color=color, label=label)
    wav = [r.get("wavelet_daymean_rms_x") for r in rows if r["truth"] == "cross"]
    wav = next((w for w in wav if w is not None), np.nan)
    ax.barh(y + 0.27, [wav] * len(noises), height=0.27, color="C3",
            label="no reference: wavelet per day (same raw data)")  # fmt: skip
    ax.set_xscale("log")
    ax.set_yticks(y, [f"{nz}\n(cross truth)" for nz in noises], fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("RMS error of the day-mean bias on x [m/s²]")
    ax.legend(fontsize=7, loc="lower right")
    ax = axes[1, 2]
    pp = np.logspace(-5, 0, 101)
    cases = (
        ("diag", "spline:6h", "fit", "-"),
        ("diag/lin", "poly1/day", "fit", "--"),
        ("cross", "spline:6h", "fit", ":"),
    )
    for k, noise in enumerate(noises):
        for truth, basis, mode, ls in cases:
            p = np.array(
                [
                    r["p"]
                    for r in records
                    if (r["truth"], r["basis"], r["mode"], r["noise"])
                    == (truth, basis, mode, noise)
                    and "error" not in r
                ],
                float,
            )
            if p.size:
                p = np.clip(p, 1e-5, 1.0)  # p below 1e-5 drawn at the left edge
                ax.step(np.sort(p), np.arange(1, p.size + 1) / p.size, where="post", ls=ls,
                        color=f"C{k}", label=f"{truth} {basis}, {noise} (n={p.size})")  # fmt: skip
    ax.plot(pp, pp, "k", lw=0.8, label="uniform (a calibrated test on a diagonal S)")
    ax.axvline(0.05, color="0.6", lw=0.8)
    ax.set_xscale("log")
    ax.set_xlim(1e-5, 1)
    ax.set_xlabel("cross-talk test p (scale=fit), empirical CDF; p < 1e-5 at the left edge")
    ax.legend(fontsize=5.5, loc="upper left", ncol=2)
    fig.suptitle(
        f"fit_reference Monte-Carlo: {records[0]['days']:g}-day arcs at 1 Hz "
        "(benchmarks/mc_reference.py)"
    )
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def code_state() -> dict:
    """Which estimator ran: ``git describe`` of the tree and a hash of each estimator
    module as imported (the tree may change while a long run goes on; the workers are
    forked after the import, so the hash is that of the code they ran)."""
    import hashlib
    import subprocess

    import accal.estimators.arnoise as m_ar
    import accal.estimators.refbasis as m_basis
    import accal.estimators.reference as m_ref
    import accal.estimators.trend as m_trend

    try:
        git = subprocess.run(
            ["git", "-C", str(Path(m_ref.__file__).parent), "describe", "--always", "--dirty"],
            capture_output=True, text=True, check=True,
        ).stdout.strip()  # fmt: skip
    except (OSError, subprocess.CalledProcessError):
        git = "unknown (not a git tree)"
    sha = {
        Path(m.__file__).name: hashlib.sha256(Path(m.__file__).read_bytes()).hexdigest()[:12]
        for m in (m_ref, m_ar, m_basis, m_trend)
    }
    return {"git": git, "accal": str(Path(m_ref.__file__).parents[2]), "sha256": sha}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="2-day arcs, 5 replicates (~2 min)")
    ap.add_argument("--days", type=float, default=None, help="arc length [days] (30)")
    ap.add_argument("--reps", type=int, default=None, help="replicates per case (5)")
    ap.add_argument("--noises", default=None, help=f"comma list of {', '.join(NOISES)}")
    ap.add_argument("--truths", default=",".join(TRUTHS))
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=2200)
    ap.add_argument("--out", default="/tmp/accal_mc_reference")
    ap.add_argument("--figure", default=str(ROOT / "docs" / "figures" / "reference_mc.png"))
    ap.add_argument(
        "--replot", action="store_true", help="tables and figure again from OUT/results.json"
    )
    args = ap.parse_args(argv)
    args.days = args.days or (2.0 if args.quick else 30.0)
    args.reps = args.reps or 5
    args.noises = tuple((args.noises or ",".join(NOISES)).split(","))
    args.truths = tuple(args.truths.split(","))
    for nm in args.noises:
        if nm not in NOISES:
            ap.error(f"--noises: unknown {nm!r}; known: {', '.join(NOISES)}")
    for nm in args.truths:
        if nm not in TRUTHS:
            ap.error(f"--truths: unknown {nm!r}; known: {', '.join(TRUTHS)}")
    out = Path(args.out)
    if args.replot:
        saved = json.loads((out / "results.json").read_text())
        meta, records = saved["meta"], saved["records"]
    else:
        tasks = make_tasks(args)
        code = code_state()  # before the run: the workers fork from this image
        print(f"# estimator: {code}", file=sys.stderr, flush=True)
        t0 = time.perf_counter()
        records = run_all(tasks, min(args.workers, 2))
        meta = {
            "days": args.days,
            "reps": args.reps,
            "workers": min(args.workers, 2),
            "wall_s": time.perf_counter() - t0,
            "git": code["git"],
            "code": code,
            "noises": list(args.noises),
            "truths": list(args.truths),
        }
    rows = summarise(records)
    out.mkdir(parents=True, exist_ok=True)
    (out / "results.json").write_text(
        json.dumps({"meta": meta, "summary": rows, "records": records}, indent=1, default=float)
    )
    md = markdown(rows, meta)
    (out / "summary.md").write_text(md)
    print(md)
    if args.figure:
        figure(records, rows, Path(args.figure))
        print(f"# figure: {args.figure}")
    print(f"# results: {out / 'results.json'}, {out / 'summary.md'}")


if __name__ == "__main__":
    main()
