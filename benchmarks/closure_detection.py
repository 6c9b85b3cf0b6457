"""False and true detections of ``--close-loop`` on real-like days (issue 19).

What it measures (Markdown tables on stdout, ``results.json`` with every run, PNG
figures, all in ``--out``, default ``out/closure-detection``):

1. **Clean days** (nothing injected): the share of days/axes with anything
   *removed* from the calibrated series (per kind) and with anything *reported*
   (accepted effects incl. periodic terms, or unexplained structure); rejected
   candidates; how far the closure moved the table's bias and drift
   (``|after − before| / σ_after``).  Independent GRACE A/B and GRACE-FO C/D days
   (``tests.indep.grace_day``, white+1/f noise), other noise models (random walk,
   AR(1), band-limited near 1/rev, white), storm + thruster days, α = 0.05 and 0.001
   on the same days as α = 0.01, days of accal's own simulator (CLI).
2. **Rotating platform**, clean one-day runs (``tests.indep.platform_run``): the
   same, and the per-period a_Y/a_Z error after vs before (RMS ratio, target ≤ 1.1).
3. **Injected effects** per kind and size: found (right name, accepted; a step within
   2 % of the day of its epoch, a coupling to the right channel, a periodic term at a
   harmonic of its period), right name reported (accepted or rejected), something else
   removed, coefficient z-scores (``(estimate − truth)/σ``: RMS, target ≤ 1.3, and
   ``|z| > 3``), and the error of the table's bias/drift (wavelet) before/after closure
   in σ_after (target ``|after| ≤ max(|before|/5, 2σ)``).  Library runs: the *twin*
   error, estimate − the plain fit of the same day without the effect (the error the
   effect causes); CLI runs: the true error from ``--truth``, estimate − (b + LS line
   of ``s·a_true`` without a reference), which also holds the signal's own misfit.  A
   coupling ``c·T`` enters as given (accal's convention: the bias at T = 0), so an
   undetected coupling to a ~293 K channel is an error of ``c·293 K``.  Kinds: step and lagged coupling to an
   undeclared temperature (no reference), quadratic and scale error (with the true
   reference), and effects the method was not built for (sawtooth, growing
   orbit-periodic term, exponential with and without reference, two-pole coupling);
   on the platform: in-period quadratic (incl. 2.28e-13 m/s⁴), step, coupling.
4. **The real Swarm-A day** (2024-05-11) as a table with a temperature column:
   nothing injected, a lagged coupling, a step; the table alone, the table as its
   own ``--aux`` (the target must be left out), and a plain CSV without units.
5. **CLI vs library**: the CLI runs of some days next to the library runs of the
   same days (the benchmark's library path mirrors ``grace-bias --close-loop``).

Case counts: see :func:`clean_cases`, :func:`inject_cases` and :func:`other_cases`
(full: 525 cases, ~5,300 core-seconds, ~45 min on two idle cores; ``--quick``: 15
cases, ~1.5 min; on a shared machine both scale with its load).  Run
``python benchmarks/closure_detection.py [--quick] [--out DIR] [--workers 2]
[--only GROUP ...] [--kinds KIND ...] [--report-only RESULTS_JSON]``.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import signal  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _closure_cases import Case, git_state, run_case, score  # noqa: E402

#: Injected sizes per (kind, reference): "undetectable" to "obvious".
SIZES = {
    ("step", False): [1e-10, 3e-10, 1e-9, 3e-9, 1e-8],  # m/s²
    ("coupling", False): [1e-10, 3e-10, 1e-9, 3e-9, 1e-8],  # m/s² per K
    ("quadratic", True): [3e-21, 1e-20, 3e-20, 1e-19],  # m/s⁴
    ("scale", True): [1e-4, 1e-3, 1e-2, 2e-2],  # relative, on x
    ("sawtooth", False): [1e-10, 3e-10, 1e-9, 3e-9],  # m/s²
    ("growing", False): [3e-10, 1e-9, 3e-9, 1e-8],  # m/s², final amplitude
    ("exponential", False): [3e-11, 1e-10, 1e-9, 1e-8],  # m/s² at t0
    ("exponential", True): [3e-11, 1e-10, 1e-9, 1e-8],
    ("twopole", False): [1e-9, 3e-9, 1e-8, 3e-8],  # m/s² per K
    ("pf_inperiod_quadratic", False): [1e-17, 5e-17, 2.28e-16, 2.28e-13],  # m/s⁴
    ("pf_step", False): [1e-10, 3e-10, 1e-9, 3e-9],  # m/s²
    ("pf_coupling", False): [3e-11, 3e-10, 3e-9, 3e-8],  # m/s² per K
}
QUICK_INJECT = [
    ("step", False, 3e-9, "y"),
    ("coupling", False, 3e-9, "z"),
    ("quadratic", True, 3e-20, "x"),
    ("scale", True, 2e-2, "x"),
    ("sawtooth", False, 1e-9, "z"),
    ("twopole", False, 1e-8, "y"),
    ("pf_inperiod_quadratic", False, 2.28e-13, "both"),
]
#: Most days per injected size (:func:`inject_cases`: the seeds of two sizes are 100 apart).
MAX_INJECT_DAYS = 99
NOISES = ("randomwalk", "ar1", "bandlimited-1rev", "white")
INSTRUMENT = ("bias_step", "auxiliary", "quadratic_drift", "cubic_drift", "exponential_drift",
              "scale", "angle_offset", "intra_period_shape")  # fmt: skip


def clean_cases(quick: bool) -> list[Case]:
    """Clean days: 50 A/B + 50 C/D, 8 per other noise model, 12 storm + thruster days,
    12 days at α = 0.05 and 0.001 (the first A/B and C/D clean days), 24 platform runs,
    12 days of ``accal simulate grace`` (every third with storm and thrusters)."""
    n = {"ab": 1, "cd": 1, "noise": 0, "storm": 0, "alpha": 0, "pf": 1, "acc": 0}
    if not quick:
        n = {"ab": 50, "cd": 50, "noise": 8, "storm": 12, "alpha": 6, "pf": 24, "acc": 12}
    out = [Case("clean", "indep", 1000 + k, "AB"[k % 2]) for k in range(n["ab"])]
    out += [Case("clean", "indep", 2000 + k, "CD"[k % 2]) for k in range(n["cd"])]
    for i, m in enumerate(NOISES[: 1 if quick else None]):
        out += [Case("noise", "indep", 3000 + 100 * i + k, "BADC"[k % 4], noise=m)
                for k in range(n["noise"])]  # fmt: skip
    out += [Case("storm", "indep", 4000 + k, "DCBA"[k % 4], storm=True, thrusters=True)
            for k in range(n["storm"])]  # fmt: skip
    for a in (0.05, 0.001):
        for k in range(n["alpha"]):
            out += [Case("alpha", "indep", 1000 + k, "AB"[k % 2], alpha=a),
                    Case("alpha", "indep", 2000 + k, "CD"[k % 2], alpha=a)]  # fmt: skip
    out += [Case("platform", "platform", 5000 + k, "-") for k in range(n["pf"])]
    out += [Case("accsim", "accsim", 6000 + k, "ABCD"[k % 4], storm=k % 3 == 2,
                 thrusters=k % 3 == 2, path="cli") for k in range(n["acc"])]  # fmt: skip
    return out


def inject_cases(quick: bool, days: int = 6) -> list[Case]:
    """Injected effects: every size of :data:`SIZES`, ``days`` days each (axes x, y, z
    in turn; scale on x only), platform 4 runs each (``days`` when more than 6; at most
    :data:`MAX_INJECT_DAYS`, the seeds of a size being 100 apart); ``--quick``:
    :data:`QUICK_INJECT`."""
    out = []
    if quick:
        for kind, ref, size, ax in QUICK_INJECT:
            src = "platform" if kind.startswith("pf_") else "indep"
            out.append(Case("inject", src, 7000, "B", kind=kind, size=size, axis=ax,
                            reference=ref))  # fmt: skip
        return out
    for (kind, ref), sizes in SIZES.items():
        pf = kind.startswith("pf_")
        for j, size in enumerate(sizes):
            for k in range((4 if days <= 6 else days) if pf else days):
                seed = 7000 + 100 * j + k
                ax = "both" if pf else ("x" if kind == "scale" else "xyz"[k % 3])
                out.append(Case("inject", "platform" if pf else "indep", seed, "ABCD"[k % 4],
                                kind=kind, size=size, axis=ax, reference=ref))  # fmt: skip
    return out


def other_cases(quick: bool) -> list[Case]:
    """CLI runs of days also run through the library, accal-simulator effects, the
    Swarm day (null, coupling 3e-7 and 9e-7 m/s²/K, step 1e-6 and 3e-6 m/s²: below and
    above the day's step detection limit, in the three table modes), platform runs through ``accal demod``."""
    sw_modes = ("table", "table+aux", "csv-nounits")
    if quick:
        out = [Case("cli", "indep", 1000, "A", path="cli")]
        out += [Case("accsim", "accsim", 6100, "A", kind="step", size=3e-9, axis="z", path="cli")]
        return out + [Case("swarm", "swarm", 0, "-", path="cli", mode=m) for m in sw_modes]
    out = [Case("cli", "indep", s, "ABCD"[k % 4], path="cli")
           for k, s in enumerate((1000, 1001, 2000, 2001))]  # fmt: skip
    out += [Case("cli", "indep", 4000 + k, "DCBA"[k], storm=True, thrusters=True, path="cli")
            for k in range(2)]  # fmt: skip
    for kind, ref, j in (("step", False, 3), ("coupling", False, 3), ("quadratic", True, 2),
                         ("scale", True, 3)):  # fmt: skip
        k = 1
        out.append(Case("cli", "indep", 7000 + 100 * j + k, "ABCD"[k % 4], kind=kind,
                        size=SIZES[(kind, ref)][j], axis="x" if kind == "scale" else "xyz"[k % 3],
                        reference=ref, path="cli"))  # fmt: skip
    for kind, ref, sizes in (
        ("step", False, (1e-9, 3e-9)),
        ("coupling", False, (1e-9, 3e-9)),
        ("quadratic", True, (1e-20, 3e-20)),
        ("scale", True, (1e-3, 2e-2)),
    ):
        for size in sizes:
            for k in range(2):
                out.append(Case("accsim", "accsim", 6100 + k, "AC"[k], kind=kind, size=size,
                                axis="x" if kind == "scale" else "yz"[k], reference=ref,
                                path="cli"))  # fmt: skip
    for m in sw_modes:
        out.append(Case("swarm", "swarm", 0, "-", path="cli", mode=m))
        for kind, sizes in (("swarm_coupling", (3e-7, 9e-7)), ("swarm_step", (1e-6, 3e-6))):
            out += [Case("swarm", "swarm", 0, "-", kind=kind, size=s, axis="x", path="cli",
                         mode=m) for s in sizes]  # fmt: skip
    out += [Case("platform", "platform", 5000 + k, "-", path="cli") for k in range(3)]
    out.append(Case("platform", "platform", 7300, "-", kind="pf_inperiod_quadratic",
                    size=2.28e-13, axis="both", path="cli"))  # fmt: skip
    return out


def cases(quick: bool, inject_days: int = 6) -> list[Case]:
    """All cases of a run (``inject_days``: days per injected size, :func:`inject_cases`)."""
    return clean_cases(quick) + inject_cases(quick, inject_days) + other_cases(quick)


def run_all(cases: list[Case], workers: int = 2, progress: bool = True) -> list[dict]:
    """Run ``cases`` on ``workers`` processes (slowest first); results in case order.

    The library is imported here, before the workers are forked, so that every library
    run of one benchmark uses the same code even if ``src/`` changes meanwhile (the
    CLI runs import it afresh).
    """
    import importlib
    import multiprocessing as mp
    import pkgutil

    import accal

    for m in pkgutil.walk_packages(accal.__path__, "accal."):
        if not m.name.endswith(".__main__"):  # accal.cli.__main__ runs the CLI on import
            importlib.import_module(m.name)
    importlib.import_module("tests.indep")

    order = sorted(range(len(cases)), key=lambda i: -cases[i].cost)
    results: list[dict | None] = [None] * len(cases)
    ctx = mp.get_context("fork")
    t_start = time.perf_counter()
    with ctx.Pool(workers) as pool:
        it = pool.imap_unordered(_indexed, [(i, cases[i]) for i in order], chunksize=1)
        for n, (i, res) in enumerate(it, 1):
            results[i] = res
            if progress:
                flag = f" ERROR {res['error']}" if res["error"] else ""
                print(
                    f"[{n}/{len(cases)} {time.perf_counter() - t_start:6.0f} s] "
                    f"{res['case']} {res['wall']:.1f} s{flag}",
                    file=sys.stderr,
                    flush=True,
                )
        # an orderly exit: the context's terminate() alone left a worker hanging in a
        # lock after a 196-case run (its SIGTERM caught), and the report unwritten
        pool.close()
        pool.join()
    return [r for r in results if r is not None]


def _indexed(item: tuple[int, Case]) -> tuple[int, dict]:
    return item[0], run_case(item[1])


# ------------------------------------------------------------------ aggregation
def _frac(n: int, d: int) -> str:
    return f"{n}/{d} ({100 * n / d:.0f} %)" if d else "–"


def _g(x: float | None, fmt: str = ".2f") -> str:
    return "–" if x is None or not np.isfinite(x) else format(x, fmt)


def _rms(v: list[float]) -> float | None:
    return float(np.sqrt(np.mean(np.square(v)))) if v else None


def label(r: dict) -> str:
    """Data label of a clean run."""
    pair = "GRACE A/B" if r["satellite"] in "AB" else "GRACE-FO C/D"
    src = {"indep": "indep", "accsim": "accal simulate", "platform": "platform"}[r["source"]]
    extra = ""
    if r["source"] == "indep" and r["noise"] != "white+1/f":
        extra = f", {r['noise']} noise"
    if r["storm"] or r["thrusters"]:
        extra += ", storm+thrusters"
    if r["source"] == "accsim":
        pair = "GRACE A–D"
    if r["source"] == "platform":
        return f"rotating platform ({r['path'].upper()})"
    return f"{pair} ({src}{extra}, {r['path'].upper()})"


def clean_runs(results: list[dict]) -> list[dict]:
    """GRACE runs with nothing injected (the platform and Swarm have their own tables)."""
    return [r for r in results if not r["kind"] and r["source"] in ("indep", "accsim")]


def _group(runs: list[dict], key) -> dict:
    out: dict = {}
    for r in runs:
        out.setdefault(key(r), []).append(r)
    return dict(sorted(out.items(), key=lambda kv: str(kv[0])))


def clean_table(results: list[dict]) -> list[str]:
    """False detections and changes on clean GRACE days, per data set and α."""
    lines = [
        "| data | α | days | axes removed | days removed | axes reported | axes rejected "
        "| axes unexplained | bias moved > 1σ | drift moved > 1σ | median / max bias Δ/σ "
        "| bias true err RMS after/before |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for (lab, alpha), runs in _group(clean_runs(results), lambda r: (label(r), r["alpha"])).items():
        axes = [a for r in runs for a in r["axes"]]
        days = [r for r in runs if r["axes"]]
        mb = [a["bias"]["change_sigmas"] for a in axes if "bias" in a]
        md = [a["drift"]["change_sigmas"] for a in axes if "drift" in a]
        eb = [a["bias"]["true_err_before"] for a in axes if "true_err_before" in a.get("bias", {})]
        ea = [a["bias"]["true_err_after"] for a in axes if "true_err_after" in a.get("bias", {})]
        ratio = _rms(ea) / _rms(eb) if eb and _rms(eb) else None
        lines.append(
            f"| {lab} | {alpha:g} | {len(days)} | {_frac(sum(bool(a['removed']) for a in axes), len(axes))} "
            f"| {_frac(sum(any(a['removed'] for a in r['axes']) for r in days), len(days))} "
            f"| {_frac(sum(a['reported'] for a in axes), len(axes))} "
            f"| {_frac(sum(bool(a['rejected']) for a in axes), len(axes))} "
            f"| {_frac(sum(a['unexplained'] > 0 for a in axes), len(axes))} "
            f"| {_frac(sum(x > 1 for x in mb), len(mb))} | {_frac(sum(x > 1 for x in md), len(md))} "
            f"| {_g(np.median(mb) if mb else None)} / {_g(max(mb) if mb else None)} | {_g(ratio, '.3f')} |"
        )
    return lines


def kinds_table(results: list[dict]) -> list[str]:
    """Per kind: axes of clean days with that kind removed, periodic reported, rejected."""
    runs = clean_runs(results) + [r for r in results if r["source"] == "platform" and not r["kind"]]
    head = "| data | α | axes | " + " | ".join(INSTRUMENT) + " | periodic (kept) | rejected kinds |"
    lines = [head, "|" + "---|" * (len(INSTRUMENT) + 5)]
    for (lab, alpha), rs in _group(runs, lambda r: (label(r), r["alpha"])).items():
        axes = [a for r in rs for a in r["axes"]]
        cnt = {k: sum(k in a["removed"] for a in axes) for k in INSTRUMENT}
        per = sum(any(e["name"] == "periodic" for e in a["effects"]) for a in axes)
        rej: dict[str, int] = {}
        for a in axes:
            for e in a["rejected"]:
                rej[e["name"]] = rej.get(e["name"], 0) + 1
        lines.append(
            f"| {lab} | {alpha:g} | {len(axes)} | "
            + " | ".join(str(cnt[k]) for k in INSTRUMENT)
            + f" | {per} | {', '.join(f'{k} {v}' for k, v in sorted(rej.items())) or '–'} |"
        )
    return lines


def reasons_table(results: list[dict], top: int = 12) -> list[str]:
    """The most frequent rejection reasons on clean data (GRACE and platform)."""
    count: dict[tuple[str, str], int] = {}
    for r in results:
        if r["kind"] or r["source"] == "swarm":
            continue
        for a in r["axes"]:
            for e in a["rejected"]:
                why = str(e.get("reason") or "?").split(":")[0][:70]
                count[(e["name"], why)] = count.get((e["name"], why), 0) + 1
    lines = ["| kind | reason (first clause) | axes |", "|---|---|---|"]
    for (k, why), n in sorted(count.items(), key=lambda kv: -kv[1])[:top]:
        lines.append(f"| {k} | {why} | {n} |")
    return lines


def platform_table(results: list[dict]) -> list[str]:
    """Clean platform runs: detections, a_Y/a_Z RMS error ratio after/before, changes."""
    lines = [
        "| path | α | runs | runs with effects in the model | kinds | runs rejected | "
        "a_Y RMS err ratio median / max | a_Z ratio median / max | runs ratio > 1.1 | "
        "periods moved > 1σ | std z after (median) |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    runs = [r for r in results if r["source"] == "platform" and not r["kind"] and r["axes"]]
    for (path, alpha), rs in _group(runs, lambda r: (r["path"], r["alpha"])).items():
        recs = [r["axes"][0] for r in rs]
        ry = [a["a_Y"]["rms_ratio"] for a in recs]
        rz = [a["a_Z"]["rms_ratio"] for a in recs]
        ch = [x for a in recs for q in ("a_Y", "a_Z") for x in a[q]["change_sigmas"]]
        kinds = sorted({n for a in recs for n in a["removed"]})
        sz = [a[q]["std_z_after"] for a in recs for q in ("a_Y", "a_Z")]
        lines.append(
            f"| {path} | {alpha:g} | {len(recs)} | {_frac(sum(bool(a['removed']) for a in recs), len(recs))} "
            f"| {', '.join(kinds) or '–'} | {_frac(sum(bool(a['rejected']) for a in recs), len(recs))} "
            f"| {_g(np.median(ry))} / {_g(max(ry))} | {_g(np.median(rz))} / {_g(max(rz))} "
            f"| {_frac(sum(max(y, z) > 1.1 for y, z in zip(ry, rz, strict=True)), len(recs))} "
            f"| {_frac(sum(x > 1 for x in ch), len(ch))} | {_g(np.median(sz))} |"
        )
    return lines


def _err_stats(recs: list[dict], q: str, how: str) -> tuple[str, str]:
    """RMS of the error before → after in σ_after, and the share meeting the target."""
    b, a, ok = [], [], 0
    for x in recs:
        e = x.get(q, {})
        if f"{how}_err_before" not in e:
            continue
        s = e["sigma_after"]
        b.append(e[f"{how}_err_before"] / s)
        a.append(e[f"{how}_err_after"] / s)
        ok += abs(a[-1]) <= max(abs(b[-1]) / 5, 2.0)
    if not b:
        return "–", "–"
    return f"{_g(_rms(b), '.3g')} → {_g(_rms(a), '.3g')}", _frac(ok, len(b))


def inject_table(results: list[dict], how: str = "twin") -> list[str]:
    """Per injected kind and size: found, right name, other removals, z, errors."""
    lines = [
        "| data | kind | ref | size | n | found | right name reported | other removed "
        "| z RMS (n) | \\|z\\| > 3 | bias err RMS before → after [σ] | bias target "
        "| drift err RMS before → after [σ] | drift target |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    runs = [r for r in results if r["kind"] and r["source"] in ("indep", "accsim")]
    key = lambda r: (r["source"] + "/" + r["path"], r["kind"], r["reference"], r["size"])  # noqa: E731
    for (src, kind, ref, size), rs in _group(runs, key).items():
        recs = [a for r in rs for a in r["axes"] if a.get("injected")]
        n = len(recs)
        z = [a["z"] for a in recs if a.get("z") is not None]
        hb, hd = (
            _err_stats(recs, "bias", how if "api" in src else "true"),
            _err_stats(recs, "drift", how if "api" in src else "true"),
        )
        by_axis = " ".join(
            f"{ax}{sum(a['hit'] is not None for a in recs if a['axis'] == ax)}/"
            f"{sum(a['axis'] == ax for a in recs)}"
            for ax in "xyz"
            if any(a["axis"] == ax for a in recs)
        )
        lines.append(
            f"| {src} | {kind} | {'yes' if ref else 'no'} | {size:.3g} | {n} "
            f"| {_frac(sum(a['hit'] is not None for a in recs), n)} ({by_axis}) "
            f"| {_frac(sum(a['right_reported'] for a in recs), n)} "
            f"| {_frac(sum(bool(a['wrong_removed']) for a in recs), n)} "
            f"| {_g(_rms(z))} ({len(z)}) | {_frac(sum(abs(v) > 3 for v in z), len(z))} "
            f"| {hb[0]} | {hb[1]} | {hd[0]} | {hd[1]} |"
        )
    return lines


def platform_inject_table(results: list[dict]) -> list[str]:
    """Injected platform effects: found, z, a_Y/a_Z RMS error before → after."""
    lines = [
        "| path | kind | size | n | found | right name reported | other effects in model "
        "| z RMS (n) | \\|z\\| > 3 | a_Y RMS err before → after | a_Z before → after "
        "| RMS ratio ≤ 1.1 |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    runs = [r for r in results if r["kind"] and r["source"] == "platform" and r["axes"]]
    for (path, kind, size), rs in _group(runs, lambda r: (r["path"], r["kind"], r["size"])).items():
        recs = [r["axes"][0] for r in rs]
        n = len(recs)
        z = [a["z"] for a in recs if a.get("z") is not None]

        def ba(q, recs=recs):
            b = _rms([a[q]["rms_err_before"] for a in recs])
            return f"{_g(b, '.2e')} → {_g(_rms([a[q]['rms_err_after'] for a in recs]), '.2e')}"

        ok = sum(max(a["a_Y"]["rms_ratio"], a["a_Z"]["rms_ratio"]) <= 1.1 for a in recs)
        lines.append(
            f"| {path} | {kind} | {size:.3g} | {n} | {_frac(sum(a['hit'] is not None for a in recs), n)} "
            f"| {_frac(sum(a['right_reported'] for a in recs), n)} "
            f"| {_frac(sum(bool(a['wrong_removed']) for a in recs), n)} | {_g(_rms(z))} ({len(z)}) "
            f"| {_frac(sum(abs(v) > 3 for v in z), len(z))} | {ba('a_Y')} | {ba('a_Z')} | {_frac(ok, n)} |"
        )
    return lines


def lag_table(results: list[dict]) -> list[str]:
    """Found couplings: the lag against its σ (``accal.closure.lagprofile``)."""
    lines = [
        "| data | kind | size | found with a lag σ | lag z RMS | \\|lag z\\| > 3 "
        "| ambiguous (interval over other lags) | true lag inside the interval |",
        "|---|---|---|---|---|---|---|---|",
    ]
    runs = [r for r in results if r["kind"] in ("coupling", "pf_coupling") and r["axes"]]
    key = lambda r: (r["source"] + "/" + r["path"], r["kind"], r["size"])  # noqa: E731
    for (src, kind, size), rs in _group(runs, key).items():
        hits = [
            (a["hit"], a["params"]["lag"])
            for r in rs
            for a in r["axes"]
            if a.get("injected", True) and a.get("hit") and a["hit"].get("lag_sigma")
        ]
        if not hits:
            continue
        z = [(h["lag"] - lag) / h["lag_sigma"] for h, lag in hits]
        inside = sum(
            h.get("lag_interval") is not None
            and h["lag_interval"][0] - 1e-9 <= lag <= h["lag_interval"][1] + 1e-9
            for h, lag in hits
        )
        lines.append(
            f"| {src} | {kind} | {size:.3g} | {len(hits)} | {_g(_rms(z))} "
            f"| {_frac(sum(abs(v) > 3 for v in z), len(z))} "
            f"| {_frac(sum(bool(h.get('lag_ambiguous')) for h, _ in hits), len(hits))} "
            f"| {_frac(inside, len(hits))} |"
        )
    return lines


def epoch_table(results: list[dict]) -> list[str]:
    """Found steps: the epoch against its interval (``accal.closure.epochprofile``)."""
    lines = [
        "| data | kind | size | found with an epoch interval | true epoch inside "
        "| median width [s] | ambiguous |",
        "|---|---|---|---|---|---|---|",
    ]
    runs = [r for r in results if r["kind"] in ("step", "pf_step", "swarm_step") and r["axes"]]
    key = lambda r: (r["source"] + "/" + r["path"], r["kind"], r["size"])  # noqa: E731
    for (src, kind, size), rs in _group(runs, key).items():
        hits = [
            (a["hit"], a["params"]["epoch"])
            for r in rs
            for a in r["axes"]
            if a.get("injected", True) and a.get("hit") and a["hit"].get("epoch_interval")
        ]
        if not hits:
            continue
        inside = 0  # epochs and intervals relative to the record's start (effect_record)
        widths = []
        for h, e0 in hits:
            lo, hi = h["epoch_interval"]
            inside += lo - 1e-6 <= e0 <= hi + 1e-6
            widths.append(hi - lo)
        lines.append(
            f"| {src} | {kind} | {size:.3g} | {len(hits)} | {_frac(inside, len(hits))} "
            f"| {_g(float(np.median(widths)), '.3g')} "
            f"| {_frac(sum(bool(h.get('epoch_ambiguous')) for h, _ in hits), len(hits))} |"
        )
    return lines


def _status(a: dict, channel: str) -> str:
    for c in a.get("considered") or []:
        if c.get("channel") == channel:
            why = str(c.get("reason") or "")[:45]
            return f"{c.get('status')}{': ' + why if why else ''}"
    return "not offered"


def swarm_table(results: list[dict]) -> list[str]:
    """The real Swarm day: what is removed/rejected, how the temperature and the
    target column are treated, and the bias error against the null run of the mode."""
    lines = [
        "| input | injected | size | removed | rejected (reason) | unexplained "
        "| temperature | a_cal_x | bias moved [σ] | bias err vs null before → after [σ] |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    runs = [r for r in results if r["source"] == "swarm"]
    null = {r["mode"]: r["axes"][0] for r in runs if not r["kind"] and r["axes"]}
    for r in runs:
        if not r["axes"]:
            lines.append(f"| {r['mode']} | {r['kind'] or '–'} | | failed: {r['error']} |||||||")
            continue
        a = r["axes"][0]
        rej = "; ".join(f"{e['name']} ({str(e.get('reason') or '')[:50]})" for e in a["rejected"])
        err = "–"
        n0 = null.get(r["mode"])
        if r["kind"] and n0 and "bias" in a:
            s = a["bias"]["sigma_after"]
            b0 = n0["bias"]["before"]
            err = f"{(a['bias']['before'] - b0) / s:+.2f} → {(a['bias']['after'] - b0) / s:+.2f}"
        found = "" if not r["kind"] else (" (found)" if a.get("hit") else " (not found)")
        lines.append(
            f"| {r['mode']} | {r['kind'] or 'nothing'}{found} | {r['size'] or 0:.3g} "
            f"| {', '.join(a['removed']) or '–'} | {rej or '–'} | {a['unexplained']} "
            f"| {_status(a, 'temperature')} | {_status(a, 'a_cal_x')} "
            f"| {_g(a.get('bias', {}).get('change_sigmas'))} | {err} |"
        )
    return lines


def _same(r: dict) -> tuple:
    return tuple(r[k] for k in ("source", "seed", "satellite", "noise", "storm", "thrusters",
                                "kind", "size", "axis", "reference", "alpha"))  # fmt: skip


def cli_api_table(results: list[dict]) -> list[str]:
    """The same day through the CLI and through the benchmark's library path."""
    api = {_same(r): r for r in results if r["path"] == "api" and r["source"] == "indep"}
    lines = [
        "| day | axis | removed (CLI) | removed (library) | bias after CLI − library [σ] "
        "| drift after [σ] |",
        "|---|---|---|---|---|---|",
    ]
    for r in results:
        if r["path"] != "cli" or r["source"] != "indep" or _same(r) not in api:
            continue
        lib = {a["axis"]: a for a in api[_same(r)]["axes"]}
        for a in r["axes"]:
            b = lib.get(a["axis"])
            if b is None:
                continue
            d = [(a[q]["after"] - b[q]["after"]) / b[q]["sigma_after"] for q in ("bias", "drift")]
            lines.append(
                f"| {r['satellite']} {r['seed']} {r['kind'] or 'clean'} | {a['axis']} "
                f"| {', '.join(a['removed']) or '–'} | {', '.join(b['removed']) or '–'} "
                f"| {d[0]:+.3f} | {d[1]:+.3f} |"
            )
    return lines


def faults_table(results: list[dict]) -> list[str]:
    """Runs where a coupled channel was taken as unknown over a stretch
    (:mod:`accal.closure.channelfault`), per group, kind and size."""
    lines = [
        "| runs | n | runs with a fault | stretches (data time [s], relative change) |",
        "|---|---|---|---|",
    ]
    key = lambda r: f"{r['source']} {r['path']} {r['kind'] or 'clean'} {r['size'] or ''}"  # noqa: E731
    for k, rs in _group([r for r in results if r["axes"]], key).items():
        hit = [(r, f) for r in rs for a in r["axes"] for f in a.get("faults") or []]
        where = "; ".join(
            f"{r['seed']}: {f['fault_start']:.0f}-{f['fault_stop']:.0f} "
            f"({', '.join(f'{v:+.2f}' for v in f['relative_change'])})"
            for r, f in hit[:6]
        )
        n_hit = len({id(r) for r, _ in hit})
        lines.append(f"| {k} | {len(rs)} | {_frac(n_hit, len(rs))} | {where or '–'} |")
    return lines


def timing_table(results: list[dict]) -> list[str]:
    """Median seconds of one closure (library: per axis; CLI: per file, all axes)."""
    lines = ["| runs | n | median s | max s |", "|---|---|---|---|"]
    key = lambda r: f"{r['source']} {r['path']} {'injected' if r['kind'] else 'clean'}"  # noqa: E731
    for k, rs in _group([r for r in results if r["axes"]], key).items():
        s = [a["seconds"] for r in rs for a in (r["axes"] if r["path"] == "api" else r["axes"][:1])]
        if s:
            lines.append(f"| {k} | {len(s)} | {np.median(s):.1f} | {max(s):.1f} |")
    return lines


# ------------------------------------------------------------------ figures
def figures(results: list[dict], out: Path) -> list[Path]:
    """Detection rate vs size, z-score histogram, |change|/σ on clean days, platform
    error ratios, table errors before/after (matplotlib, Agg)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    inj = [r for r in results if r["kind"] and r["path"] == "api" and r["axes"]]
    kinds = sorted({(r["kind"], r["reference"]) for r in inj})
    if kinds:
        ncol = 4
        fig, axs = plt.subplots(-(-len(kinds) // ncol), ncol, figsize=(14, 3 * -(-len(kinds) // ncol)),
                                squeeze=False)  # fmt: skip
        for axp, (kind, ref) in zip(axs.flat, kinds, strict=False):
            rs = [r for r in inj if r["kind"] == kind and r["reference"] == ref]
            sizes = sorted({r["size"] for r in rs})
            for what, lab, sty in (("hit", "found", "o-"), ("right_reported", "right name "
                                   "reported", "s--"), ("wrong_removed", "other removed", "^:")):  # fmt: skip
                rate = [np.mean([bool(a.get(what)) for r in rs if r["size"] == s
                                 for a in r["axes"] if a.get("injected")]) for s in sizes]  # fmt: skip
                axp.semilogx(sizes, rate, sty, ms=9 if sty == "o-" else 5, label=lab)
            axp.set_title(f"{kind}{' (reference)' if ref else ''}", fontsize=9)
            axp.set_ylim(-0.05, 1.05)
        for axp in axs.flat[len(kinds) :]:
            axp.axis("off")
        axs.flat[0].legend(fontsize=7)
        fig.supxlabel("injected size (SI)")
        fig.tight_layout()
        paths.append(out / "detection_vs_size.png")
        fig.savefig(paths[-1], dpi=110)
        plt.close(fig)
    z = {}
    for r in results:
        for a in r["axes"]:
            if a.get("z") is not None:
                z.setdefault(r["kind"], []).append(a["z"])
    if z:
        fig, ax = plt.subplots(figsize=(7, 4))
        bins = np.linspace(-8, 8, 33)
        ax.hist([np.clip(v, -8, 8) for v in z.values()], bins=bins, stacked=True, label=list(z))
        n = sum(len(v) for v in z.values())
        ax.plot(bins, n * 0.5 * np.exp(-(bins**2) / 2) / np.sqrt(2 * np.pi), "k--", label="N(0,1)")
        ax.set_xlabel("(coefficient − truth)/σ (clipped at ±8)")
        ax.legend(fontsize=7)
        paths.append(out / "zscores.png")
        fig.savefig(paths[-1], dpi=110)
        plt.close(fig)
    clean = clean_runs(results)
    if clean:
        fig, axs = plt.subplots(1, 2, figsize=(11, 4))
        for axp, q in zip(axs, ("bias", "drift"), strict=True):
            groups = _group(clean, label)
            vals = [[max(a[q]["change_sigmas"], 1e-3) for r in rs for a in r["axes"] if q in a]
                    for rs in groups.values()]  # fmt: skip
            axp.hist(vals, bins=np.logspace(-3, 2, 26), stacked=True, label=list(groups))
            axp.set_xscale("log")
            axp.axvline(1.0, color="k", ls="--")
            axp.set_xlabel(f"clean days: |{q} after − before| / σ_after (0 shown at 1e-3)")
        axs[0].legend(fontsize=6)
        fig.tight_layout()
        paths.append(out / "clean_change_sigmas.png")
        fig.savefig(paths[-1], dpi=110)
        plt.close(fig)
    pf = [r for r in results if r["source"] == "platform" and r["axes"]]
    if pf:
        fig, ax = plt.subplots(figsize=(7, 4))
        for kind in sorted({r["kind"] for r in pf}):
            rs = [r for r in pf if r["kind"] == kind]
            y = [
                max(r["axes"][0]["a_Y"]["rms_ratio"], r["axes"][0]["a_Z"]["rms_ratio"]) for r in rs
            ]
            ax.semilogy(np.full(len(y), sorted({r["kind"] for r in pf}).index(kind))
                        + np.linspace(-0.2, 0.2, len(y)), y, "o", label=kind or "clean")  # fmt: skip
        ax.axhline(1.1, color="k", ls="--")
        ax.set_ylabel("platform: max(a_Y, a_Z) RMS error after / before")
        ax.set_xticks([])
        ax.legend(fontsize=7)
        paths.append(out / "platform_error_ratio.png")
        fig.savefig(paths[-1], dpi=110)
        plt.close(fig)
    if inj:
        fig, axs = plt.subplots(1, 2, figsize=(11, 4.5))
        for axp, q in zip(axs, ("bias", "drift"), strict=True):
            for kind, ref in kinds:
                recs = [a for r in inj if r["kind"] == kind and r["reference"] == ref
                        for a in r["axes"] if "twin_err_before" in a.get(q, {})]  # fmt: skip
                if recs:
                    b = [
                        max(abs(a[q]["twin_err_before"] / a[q]["sigma_after"]), 1e-3) for a in recs
                    ]
                    f = [max(abs(a[q]["twin_err_after"] / a[q]["sigma_after"]), 1e-3) for a in recs]
                    axp.loglog(b, f, "o", ms=4, label=f"{kind}{' ref' if ref else ''}")
            g = np.logspace(-3, 4, 50)
            axp.loglog(g, np.maximum(g / 5, 2), "k--", lw=1, label="target")
            axp.loglog(g, g, "k:", lw=1)
            axp.set_xlabel(f"|{q} error| before [σ_after]")
            axp.set_ylabel(f"|{q} error| after [σ_after]")
        axs[0].legend(fontsize=6, ncol=2)
        fig.tight_layout()
        paths.append(out / "table_error_before_after.png")
        fig.savefig(paths[-1], dpi=110)
        plt.close(fig)
    return paths


# ------------------------------------------------------------------ main
def report(results: list[dict], meta: dict) -> str:
    """All tables as one Markdown document."""
    errors = [f"- `{r['case']}`: {r['error']}" for r in results if r["error"]]
    changed = meta["git"].get("src_sha256") != meta.get("git_end", {}).get("src_sha256")
    sec = [
        ("Clean GRACE days: false detections and changes (library path unless CLI)",
         clean_table(results)),
        ("Removed per kind on clean data (axes; platform: runs)", kinds_table(results)),
        ("Most frequent rejections on clean data", reasons_table(results)),
        ("Rotating platform, clean one-day runs", platform_table(results)),
        ("Injected effects on GRACE days (library: twin errors; CLI: true errors)",
         inject_table(results)),
        ("Injected effects on the platform", platform_inject_table(results)),
        ("Lags of the couplings found", lag_table(results)),
        ("Epochs of the steps found", epoch_table(results)),
        ("The real Swarm-A day (CLI, table input)", swarm_table(results)),
        ("Same days through the CLI and the library path", cli_api_table(results)),
        ("Channel faults marked", faults_table(results)),
        ("Time per closure", timing_table(results)),
    ]  # fmt: skip
    lines = [
        f"# closure detection ({meta['mode']}, {meta['n_cases']} cases, "
        f"{meta['wall_s'] / 60:.1f} min on {meta['workers']} workers)",
        "",
        f"accal commit {meta['git']['commit'][:10]}; src/ modified in the working tree: "
        f"{len(meta['git']['dirty'].splitlines())} files; src hash "
        f"{meta['git'].get('src_sha256', '?')} at the start, "
        f"{meta.get('git_end', {}).get('src_sha256', '?')} at the end"
        + (" (changed during the run: CLI runs used the newer code)." if changed else "."),
        "",
    ]
    for title, table in sec:
        lines += [f"## {title}", "", *table, ""]
    lines += ["## Failed cases", "", *(errors or ["none"]), ""]
    return "\n".join(lines)


def rescore(results: list[dict]) -> None:
    """Score the injected runs again (after a change of the scoring, ``--report-only``)."""
    for r in results:
        for rec in r["axes"] if r["kind"] else []:
            p = rec.get("params")
            if p is None:
                continue
            if r["kind"] == "growing" and "period" not in p:
                p["period"] = rec.get("period")  # the estimated orbit period
            score(rec, r["kind"], p, rec.get("span", 86400.0))
            if r["source"] == "platform":  # every accepted effect is in the model
                rec["wrong_removed"] = [e["name"] for e in rec["effects"] if e is not rec["hit"]]


def main(argv: list[str] | None = None) -> int:
    """Run the cases, print the tables, write results.json, summary.md and the figures."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="a few cases (~2-3 min)")
    ap.add_argument("--out", type=Path, default=Path("out/closure-detection"))
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--only", nargs="*", help="groups to run (clean noise storm alpha "
                    "platform accsim inject cli swarm)")  # fmt: skip
    ap.add_argument("--kinds", nargs="*", help="injected kinds to run (e.g. coupling "
                    "pf_coupling; 'none' for the cases without one)")  # fmt: skip
    ap.add_argument("--inject-days", type=int, default=6, metavar="N",
                    help="days per injected kind and size (default 6, at most "
                    f"{MAX_INJECT_DAYS}): a Monte-Carlo of detection and z-scores")  # fmt: skip
    ap.add_argument("--no-figures", action="store_true")
    ap.add_argument("--report-only", type=Path, metavar="RESULTS_JSON",
                    help="no runs: the tables and figures of an earlier results.json")  # fmt: skip
    args = ap.parse_args(argv)
    if args.report_only:
        doc = json.loads(args.report_only.read_text())
        rescore(doc["results"])
        return _write(doc["results"], doc["meta"], args)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))  # the pool's workers end too
    if not 1 <= args.inject_days <= MAX_INJECT_DAYS:
        ap.error(f"--inject-days must be 1..{MAX_INJECT_DAYS}")
    todo = [c for c in cases(args.quick, args.inject_days) if not args.only or c.group in args.only]
    if args.kinds:
        todo = [c for c in todo if (c.kind or "none") in args.kinds]
    args.out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    git0 = git_state()
    results = run_all(todo, workers=args.workers)
    meta = {
        "mode": "quick" if args.quick else "full",
        "n_cases": len(todo),
        "workers": args.workers,
        "wall_s": time.perf_counter() - t0,
        "git": git0,
        "git_end": git_state(),
        "date": time.strftime("%Y-%m-%d %H:%M:%S"),
    }
    (args.out / "results.json").write_text(json.dumps({"meta": meta, "results": results}))
    return _write(results, meta, args)


def _write(results: list[dict], meta: dict, args: argparse.Namespace) -> int:
    args.out.mkdir(parents=True, exist_ok=True)
    text = report(results, meta)
    (args.out / "summary.md").write_text(text)
    print(text)
    if not args.no_figures:
        for p in figures(results, args.out):
            print(f"figure: {p}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
