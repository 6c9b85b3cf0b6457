"""Cases of the closure benchmarks: data, one closure run, its scores (issue 19).

Shared by ``benchmarks/closure_detection.py`` and ``benchmarks/bench_closure.py``.
A :class:`Case` names the data (the independent generators of ``tests/indep`` or
accal's own simulator, the rotating platform, the real Swarm-A day), what is injected
into it and how the closure runs: through the library (``"api"``, the arguments of
``accal.pipeline_closure.close_the_loop``) or through the CLI on written files
(``"cli"``, what users run).  :func:`run_case` returns plain dicts (JSON-able), one
per analysed axis, with what was removed, rejected and reported, the coefficient
z-scores and the table's bias/drift before and after.

Scores: ``removed`` (instrument effects accepted: subtracted by ``grace-bias``; on the
platform every accepted effect), ``reported`` (anything accepted, or unexplained),
``rejected``; ``bias``/``drift`` before/after (wavelet) with ``change_sigmas``,
``true_err_*`` and ``twin_err_*`` (see ``closure_detection.py``); ``z`` of the matched
effect.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
import traceback
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # tests.indep: the independent generators
SAMPLES = ROOT / "data" / "samples"
ACCAL = str(Path(sys.executable).with_name("accal"))
ORBIT_NOMINAL = 5600.0  # [s] GraceBiasOptions.orbit_period
STEP_TOLERANCE = 0.02  # a step is found when within this share of the record of the truth
#: Effect names that count as "the right name" per injected kind.
RIGHT_NAMES = {
    "step": ("bias_step",),
    "coupling": ("auxiliary",),
    "twopole": ("auxiliary",),
    "quadratic": ("quadratic_drift",),
    "scale": ("scale",),
    "sawtooth": ("periodic",),
    "growing": ("periodic",),
    "exponential": ("exponential_drift",),
    "pf_step": ("bias_step",),
    "pf_coupling": ("auxiliary",),
    "pf_inperiod_quadratic": ("quadratic_drift", "intra_period_shape"),
    "swarm_step": ("bias_step",),
    "swarm_coupling": ("auxiliary",),
}


@dataclass(frozen=True)
class Case:
    """One closure run.

    Attributes
    ----------
    group : str
        Table the case belongs to (``clean``, ``noise``, ``storm``, ``alpha``,
        ``inject``, ``accsim``, ``platform``, ``swarm``, ``cli``).
    source : {"indep", "accsim", "platform", "swarm"}
        Data generator.
    seed : int
        Generator seed.
    satellite : str
        ``A``-``D`` (GRACE days).
    noise : str
        ``tests.indep.grace_day`` noise model.
    storm, thrusters : bool
        Real-acceleration events of the day.
    kind : str
        Injected effect kind (key of :data:`RIGHT_NAMES`), ``""`` for none.
    size : float
        Its size (SI: m/s², m/s² per K, m/s⁴, relative scale).
    axis : str
        Axis it is injected on (``x``/``y``/``z``; ``both`` on the platform).
    reference : bool
        Fit ``raw − reference`` (``--reference``: the true ``s·a_true``).
    alpha : float
        ``--alpha``.
    path : {"api", "cli"}
        Library call or command line.
    mode : str
        Swarm: ``table`` (temperature a column, no ``--aux``) or ``table+aux`` (the
        table also given as ``--aux``).
    """

    group: str
    source: str
    seed: int
    satellite: str = "A"
    noise: str = "white+1/f"
    storm: bool = False
    thrusters: bool = False
    kind: str = ""
    size: float = 0.0
    axis: str = ""
    reference: bool = False
    alpha: float = 0.01
    path: str = "api"
    mode: str = ""

    @property
    def name(self) -> str:
        """A short unique label."""
        bits = [self.group, self.source, self.path, str(self.seed), self.satellite, self.noise]
        bits += ["storm"] * self.storm + ["thr"] * self.thrusters
        if self.kind:
            bits += [self.kind, f"{self.size:.3g}", self.axis]
        bits += ["ref"] * self.reference + [f"a{self.alpha:g}"] + [self.mode] * bool(self.mode)
        return ":".join(bits)

    @property
    def cost(self) -> float:
        """Rough cost in core-seconds (to start the slow cases first)."""
        base = {"indep": 11.0, "accsim": 14.0, "platform": 9.0, "swarm": 2.0}[self.source]
        if self.kind and self.source == "indep" and self.path == "api":
            base = 8.0
        return base + (8.0 if self.path == "cli" else 0.0)


# ------------------------------------------------------------------ injected effects
def _rng(case: Case) -> np.random.Generator:
    code = list(RIGHT_NAMES).index(case.kind) if case.kind in RIGHT_NAMES else 99
    return np.random.default_rng([case.seed, 7919, code])


def draw_effect(case: Case, span: float = 86400.0) -> dict[str, Any]:
    """The injected effect's parameters (drawn from the case's seed).

    Steps at U(10 %, 90 %) of the record, random signs, lags U(0, 1800) s,
    sawtooth periods log-U(1200, 12000) s, exponential time constants
    log-U(600, 20000) s, two-pole couplings with time constants U(200, 1000) s and
    U(1000, 3000) s, a growing orbit-periodic term from 20 % to 100 % of ``size``.
    """
    rng = _rng(case)
    sign = float(rng.choice([-1.0, 1.0]))
    k, s = case.kind, case.size
    if k in ("step", "pf_step", "swarm_step"):
        return {"epoch": float(rng.uniform(0.1, 0.9) * span), "size": sign * s}
    if k in ("coupling", "pf_coupling", "swarm_coupling"):
        return {"coef": sign * s, "lag": float(rng.uniform(0.0, 1800.0)), "tau": 0.0}
    if k == "twopole":
        return {
            "coef": sign * s,
            "lag": float(rng.uniform(0.0, 900.0)),
            "tau": float(rng.uniform(200.0, 1000.0)),
            "tau2": float(rng.uniform(1000.0, 3000.0)),
        }
    if k in ("quadratic", "pf_inperiod_quadratic"):
        return {"coef": s if k == "pf_inperiod_quadratic" else sign * s}
    if k == "scale":
        return {"rel_error": sign * s}
    if k == "sawtooth":
        period = float(np.exp(rng.uniform(np.log(1200.0), np.log(12000.0))))
        return {"amp": s, "period": period, "phase": float(rng.uniform())}
    if k == "growing":
        return {"amp": 0.2 * s, "rate": 0.8 * s / span, "phase": float(rng.uniform())}
    if k == "exponential":
        tau = float(np.exp(rng.uniform(np.log(600.0), np.log(20000.0))))
        return {"amp": sign * s, "tau": tau}
    raise ValueError(f"unknown kind {k!r}")


def indep_effect(case: Case, p: dict[str, Any]) -> tuple | None:
    """The ``tests.indep`` effect tuple of a GRACE case (None for the custom two-pole)."""
    ax, k = case.axis, case.kind
    return {
        "step": lambda: ("step", ax, p["epoch"], p["size"]),
        "coupling": lambda: ("coupling", ax, "temperature", p["coef"], p["lag"], 0.0),
        "quadratic": lambda: ("quadratic", ax, p["coef"]),
        "scale": lambda: ("scale", ax, p["rel_error"]),
        "sawtooth": lambda: ("sawtooth", ax, p["amp"], p["period"], p["phase"]),
        "growing": lambda: ("growing_periodic", ax, p["amp"], "orbit", p["rate"], p["phase"]),
        "exponential": lambda: ("exponential", ax, p["amp"], p["tau"]),
        "twopole": lambda: None,
    }[k]()


def two_pole(x: np.ndarray, dt: float, p: dict[str, Any]) -> np.ndarray:
    """``coef · LP_tau2(LP_tau(x))(t − lag)`` on the record (steady state at the start)."""
    from scipy.signal import lfilter

    y = np.asarray(x, dtype=np.float64)
    for tau in (p["tau"], p["tau2"]):
        a = np.exp(-dt / tau)
        y, _ = lfilter([1 - a], [1, -a], y, zi=[a * y[0]])
    n_lag = int(round(p["lag"] / dt))
    y = np.r_[np.full(n_lag, y[0]), y[: y.size - n_lag]]
    return p["coef"] * y


#: The parameter each kind's matched coefficient estimates (no z-score for the others).
TRUE_PARAMETER = {"step": "size", "pf_step": "size", "swarm_step": "size", "scale": "rel_error",
                  "exponential": "amp", "coupling": "coef", "pf_coupling": "coef",
                  "swarm_coupling": "coef", "twopole": "coef", "quadratic": "coef",
                  "pf_inperiod_quadratic": "coef"}  # fmt: skip


# ------------------------------------------------------------------ results of one run
def effect_record(e: Any, t0: float) -> dict[str, Any]:
    """An :class:`accal.closure.Effect` (or its closure.json dict) as a small dict."""
    get = e.get if isinstance(e, dict) else lambda k, d=None: getattr(e, k, d)
    out = {k: get(k) for k in ("name", "channel", "unit")}
    out["instrument"] = bool(get("instrument", False))
    for k in ("coefficient", "sigma", "significance", "lag", "tau", "frequency", "epoch"):
        v = get(k)
        out[k] = None if v is None else float(v)
    if out["epoch"] is not None:
        out["epoch"] -= t0
    det = get("details") or {}
    out["reason"] = det.get("reason")
    for k in (
        "lag_sigma",
        "lag_interval",
        "lag_ambiguous",
        "lag_sigma_linearised",
        "lag_sigma_profile",
        "epoch_sigma",
        "epoch_interval",
        "epoch_ambiguous",
        "lag_sigma_sandwich",
        "lag_alternatives",
    ):
        if det.get(k) is not None:
            out[k] = det[k]
    if out.get("epoch_interval") is not None:  # relative to the record's start, as the epoch
        out["epoch_interval"] = [float(v) - t0 for v in out["epoch_interval"]]
    return out


def match(kind: str, p: dict[str, Any], effects: list[dict], span: float) -> dict | None:
    """The effect of ``effects`` that is the injected one (right name, epoch, channel)."""
    names = RIGHT_NAMES.get(kind, ())
    for e in effects:
        if e["name"] not in names:
            continue
        far = e["epoch"] is None or abs(e["epoch"] - p.get("epoch", 0.0)) > STEP_TOLERANCE * span
        if kind.endswith("step") and far:
            continue
        if names == ("auxiliary",) and str(e["channel"]).removesuffix("^2") != "temperature":
            continue
        if names == ("periodic",) and not _at_harmonic(e["frequency"], p.get("period"), span):
            continue
        return e
    return None


def _at_harmonic(f: float | None, period: float | None, span: float) -> bool:
    """Whether ``f`` is within two DFT bins of one of the first five harmonics of ``1/period``."""
    if f is None or not period:
        return period is None
    return bool(np.min(np.abs(f - np.arange(1, 6) / period)) < 2.0 / span)


def score(rec: dict[str, Any], kind: str, p: dict[str, Any], span: float) -> None:
    """Add ``hit``, ``z``, ``right_rejected`` and ``wrong_removed`` to an axis record
    (a periodic term is the injected one at a harmonic of its period)."""
    rec["span"] = span
    hit = match(kind, p, rec["effects"], span)
    rec["hit"] = hit
    rec["right_rejected"] = match(kind, p, rec["rejected"], span) is not None
    rec["right_reported"] = hit is not None or rec["right_rejected"]
    rec["z"] = None
    if hit is not None and kind in TRUE_PARAMETER and hit["sigma"]:
        rec["z"] = (hit["coefficient"] - p[TRUE_PARAMETER[kind]]) / hit["sigma"]
    rec["lag_z"] = None  # a coupling's lag against its σ (accal.closure.lagprofile)
    if hit is not None and p.get("lag") is not None and hit.get("lag_sigma"):
        rec["lag_z"] = (hit["lag"] - p["lag"]) / hit["lag_sigma"]
    rec["wrong_removed"] = [
        e["name"] for e in rec["effects"] if e["instrument"] and (hit is None or e is not hit)
    ]


def _quantity(
    fits: list, k: int, res_base: dict[str, dict] | None, removed: bool
) -> dict[str, float]:
    """Before/after of coefficient ``k`` (0 bias, 1 drift) from wavelet fits."""
    before, after = fits[0], fits[1]
    var = float(after.sigma[k]) ** 2
    name = ("bias", "drift")[k]
    if removed and res_base and name in res_base:  # the pipeline's with_effect_uncertainty
        b = res_base[name]
        var += max(0.0, float(b["sigma_after"]) ** 2 - float(b["sigma_plain"]) ** 2)
    out = {
        "before": float(before.coef[k]),
        "after": float(after.coef[k]),
        "sigma_before": float(before.sigma[k]),
        "sigma_after": float(np.sqrt(var)),
    }
    out["change_sigmas"] = abs(out["after"] - out["before"]) / out["sigma_after"]
    if len(fits) > 2:  # the twin: the same day without the injected effect
        out["twin_err_before"] = out["before"] - float(fits[2].coef[k])
        out["twin_err_after"] = out["after"] - float(fits[2].coef[k])
    return out


def estimates(
    t: np.ndarray,
    y: np.ndarray,
    inst: np.ndarray,
    use: np.ndarray,
    base: dict[str, dict],
    truth: tuple[float, float] | None,
    contribution: np.ndarray | None,
) -> dict[str, dict[str, float]]:
    """The table's bias and drift before/after (wavelet), with σ and errors."""
    from accal.estimators.trend import fit_trends

    cols = [y, y - inst] + ([y - contribution] if contribution is not None else [])
    fits = fit_trends(t, np.column_stack(cols), method="wavelet", valid=use)
    out = {}
    for k, q in enumerate(("bias", "drift")):
        out[q] = _quantity(fits, k, base, bool(np.any(inst)))
        if truth is not None:
            out[q]["true_err_before"] = out[q]["before"] - truth[k]
            out[q]["true_err_after"] = out[q]["after"] - truth[k]
    return out


def _base_dict(res: Any) -> dict[str, dict]:
    return {b.name: {"sigma_after": b.sigma_after, "sigma_plain": b.sigma_plain} for b in res.base}


def result_record(res: Any, t0: float) -> dict[str, Any]:
    """Effects, rejected, removed, unexplained and considered channels of a result."""
    effects = [effect_record(e, t0) for e in res.effects]
    return {
        "effects": effects,
        "rejected": [effect_record(e, t0) for e in getattr(res, "rejected", ())],
        "unexplained": len(res.unexplained),
        "removed": [e["name"] for e in effects if e["instrument"]],
        "reported": bool(effects or res.unexplained),
        "considered": [dict(c) for c in getattr(res, "considered", ())],
        "faults": faults_of(getattr(res, "notes", ())),
    }


def faults_of(notes) -> list[dict[str, Any]]:
    """The channel faults a closure marked (:mod:`accal.closure.channelfault` notes)."""
    return [
        {"channel": n.get("channel"), **n["details"]}
        for n in notes or ()
        if "fault_start" in (n.get("details") or {})
    ]


# ------------------------------------------------------------------ GRACE days, library path
def indep_day(case: Case) -> tuple[Any, dict[str, Any] | None, np.ndarray | None]:
    """The ``tests.indep`` day of a case, the injected effect (with its contribution)
    and the reference ``s·a_true`` (n, 3) when the case has one."""
    from tests.indep import grace_day

    kw = {"noise": case.noise, "storm": case.storm, "thrusters": case.thrusters}
    inj = None
    if case.kind:
        p = draw_effect(case)
        eff = indep_effect(case, p)
        day = grace_day(case.seed, case.satellite, effects=[eff] if eff else [], **kw)
        if eff is None:  # two-pole coupling: added here, on the generated temperature
            c = two_pole(day.channels["temperature"], float(day.truth["dt"]), p)
            lin = day.lin_accl.copy()
            lin[:, "xyz".index(case.axis)] += c
            day = replace(day, lin_accl=lin)
        else:
            c = np.asarray(day.truth["effects"][0]["contribution"])
        if case.kind == "growing":
            p["period"] = float(day.truth["orbit_period"])
        inj = {"params": p, "contribution": c}
    else:
        day = grace_day(case.seed, case.satellite, **kw)
    ref = day.signal * np.asarray(day.truth["scale"]) if case.reference else None
    return day, inj, ref


def l1b_channels(day: Any) -> tuple[dict, dict, list]:
    """The closure's channels of an L1B day with ``--aux`` temperatures: the angular
    accelerations (rad/s²; all-zero GRACE-FO columns are left out as flags, as
    ``candidate_channels`` does), the temperatures (K), low-passed like the L1B data as
    ``candidate_channels`` does with ``--aux`` channels (:func:`accal.crn.smooth_channel`);
    the residual columns left out."""
    from accal.crn import smooth_channel
    from accal.pipeline_closure import LOWPASSED

    aux, units, screened = {}, {}, []
    for i, ax in enumerate("xyz"):
        screened.append(
            {"channel": f"acl_{ax}_res", "status": "left out", "reason": "an acceleration"}
        )
        v = day.ang_accl[:, i]
        if np.all(np.mod(v, 1) == 0) and np.unique(v).size <= 8:
            screened.append({"channel": f"ang_accl_{ax}", "status": "left out", "reason": "a flag"})
            continue
        aux[f"ang_accl_{ax}"], units[f"ang_accl_{ax}"] = v, "rad/s^2"
    for k, v in day.channels.items():
        aux[k], units[k] = smooth_channel(day.time, v), "K"
        screened.append({"channel": k, "status": "considered", "reason": LOWPASSED})
    return aux, units, screened


def _candidates(reference: bool, span: float) -> tuple[str, ...]:
    """``pipeline_closure.closure_candidates`` (fallback: drop the reference-only kinds)."""
    from accal.pipeline import GraceBiasOptions

    try:
        from accal.pipeline_closure import closure_candidates

        opts = GraceBiasOptions(reference=Path("ref") if reference else None)
        return tuple(closure_candidates(opts, span)[0])
    except (ImportError, TypeError):  # the helper moved: the documented behaviour
        from accal.closure import DEFAULT_CANDIDATES, kind_of

        if reference:
            return tuple(DEFAULT_CANDIDATES)
        return tuple(c for c in DEFAULT_CANDIDATES if not kind_of(c).needs_reference)


def _detrended(t: np.ndarray, y: np.ndarray) -> np.ndarray:
    a = np.column_stack([np.ones_like(t), t - t[0]])
    return y - a @ np.linalg.lstsq(a, y, rcond=None)[0]


def _proxies(y_all: np.ndarray, k: int, ref: np.ndarray | None) -> dict:
    """``close_loop``'s other axes as signal proxies, as ``grace-bias --close-loop``
    passes them (none with a reference; nothing for a ``close_loop`` without them)."""
    import inspect

    from accal.closure import close_loop

    if ref is not None or "signal_proxies" not in inspect.signature(close_loop).parameters:
        return {}
    return {"signal_proxies": {ax: y_all[:, j] for j, ax in enumerate("xyz") if j != k}}


def run_grace_api(case: Case) -> list[dict[str, Any]]:
    """Close the loop on an independent GRACE day through the library, per axis as
    ``grace-bias --close-loop --aux temperatures`` does; the injected axis only when
    there is one (the other axes are clean days, counted there)."""
    from accal.closure import close_loop
    from accal.closure.period import estimate_period

    day, inj, ref = indep_day(case)
    t, raw = day.time, day.lin_accl
    y_all = raw - ref if ref is not None else raw
    use = np.ones(t.size, bool)
    aux, units, screened = l1b_channels(day)
    span = float(t[-1] - t[0])
    cands = _candidates(case.reference, span)
    period = ORBIT_NOMINAL
    if ref is None:  # refined once per file on all axes
        res3 = np.column_stack([_detrended(t, y_all[:, k]) for k in range(3)])
        period = float(estimate_period(t, res3, ORBIT_NOMINAL))
    tr = day.truth
    out = []
    for ax in [case.axis] if inj else list("xyz"):
        k = "xyz".index(ax)
        t_start = time.perf_counter()
        res = close_loop(
            t,
            y_all[:, k],
            valid=use,
            base="poly1",
            aux=aux,
            alpha=case.alpha,
            orbit_period=period,
            candidates=cands,
            resolution=float(
                np.finfo(float).eps * max(np.abs(raw[:, k]).max(), np.abs(y_all[:, k]).max())
            ),
            reference=ref[:, k] if ref is not None else None,
            channel_units=units,
            screened=screened,
            options={"orbit_period_fixed": True, "step_transition": True},  # L1B-like
            **_proxies(y_all, k, ref),
        )
        seconds = time.perf_counter() - t_start
        rec = {"axis": ax, "injected": bool(inj), "seconds": seconds, "period": period}
        rec.update(result_record(res, float(t[0])))
        truth = (tr["bias"][k], tr["drift"][k])
        if ref is None:
            truth = (truth[0] + tr["signal_trend"]["intercept"][k],
                     truth[1] + tr["signal_trend"]["slope"][k])  # fmt: skip
        rec.update(
            estimates(
                t,
                y_all[:, k],
                res.instrument_model(),
                use,
                _base_dict(res),
                truth,
                inj["contribution"] if inj else None,
            )
        )
        if inj:
            rec["params"] = inj["params"]
            score(rec, case.kind, inj["params"], span)
        out.append(rec)
    return out


# ------------------------------------------------------------------ command line
def accal_cli(args: list[str], timeout: float = 900.0) -> subprocess.CompletedProcess:
    """Run ``accal ARGS`` (one worker, one BLAS thread)."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    return subprocess.run(
        [ACCAL, *args], capture_output=True, text=True, env=env, timeout=timeout, check=False
    )


def _fail(proc: subprocess.CompletedProcess, what: str) -> RuntimeError:
    tail = (proc.stderr or proc.stdout or "").strip().splitlines()[-3:]
    return RuntimeError(f"{what} exited {proc.returncode}: {' | '.join(tail)}")


def json_record(e: dict[str, Any], t0: float) -> dict[str, Any]:
    """The record fields of one ``closure.json`` entry (an axis, or a demod run)."""
    rec = {
        "effects": [effect_record(x, t0) for x in e.get("effects") or []],
        "rejected": [effect_record(x, t0) for x in e.get("rejected") or []],
        "unexplained": len(e.get("unexplained") or []),
        "removed_from_calibrated": list(e.get("removed_from_calibrated") or []),
        "considered": list(e.get("considered") or []),
        "model": e.get("model"),
        "faults": faults_of(e.get("notes")),
    }
    rec["removed"] = [x["name"] for x in rec["effects"] if x["instrument"]]
    rec["reported"] = bool(rec["effects"] or rec["unexplained"])
    return rec


def closure_records(out_dir: Path, t0: float) -> dict[str, dict[str, Any]]:
    """Per axis of the one source in ``OUT/closure.json``: the axis record fields."""
    doc = json.loads((out_dir / "closure.json").read_text())
    (entry,) = doc["sources"].values()
    out = {}
    for ax, e in entry.items():
        rec = json_record(e, t0)
        for q in ("bias", "drift"):
            est = (e.get("estimates") or {}).get("wavelet", {}).get(q)
            if est:
                rec[q] = {k.replace("true_error", "true_err"): v for k, v in est.items()}
        out[ax] = rec
    return out


def _truth_json(day: Any, path: Path) -> Path:
    """``tests.indep`` truth in the layout of ``accal grace-bias --truth``."""
    tr = day.truth
    sat = {"A": "GRACE-A", "B": "GRACE-B", "C": "GRACE-FO-C", "D": "GRACE-FO-D"}
    doc = {
        "satellite": sat[day.satellite],
        "t0": tr["t0"],
        "bias": tr["bias"],
        "drift": tr["drift"],
        "signal_trend": {"bias": tr["signal_trend"]["intercept"],
                         "drift": tr["signal_trend"]["slope"]},
    }  # fmt: skip
    path.write_text(json.dumps(doc))
    return path


def run_grace_cli(case: Case, work: Path) -> list[dict[str, Any]]:
    """``accal grace-bias --close-loop --aux --truth [--reference]`` on a written
    independent day (ACC1B for A/B, ACT1B for C/D), all axes."""
    from tests.indep import write_acc1b_grace, write_act1b_gracefo, write_table

    day, inj, ref = indep_day(case)
    writer = write_act1b_gracefo if day.satellite in "CD" else write_acc1b_grace
    data = writer(day, work / day.l1b_name())
    aux = write_table(
        work / "aux.parquet",
        {"gps_time": day.time, **day.channels},
        {"gps_time": "s", **{k: "K" for k in day.channels}},
    )
    args = ["grace-bias", str(data), "--close-loop", "--aux", str(aux), "--out", str(work / "o")]
    args += ["--truth", str(_truth_json(day, work / "truth.json")), "--alpha", f"{case.alpha}"]
    if ref is not None:
        cols = {f"lin_accl_{a}": ref[:, i] for i, a in enumerate("xyz")}
        units = {"gps_time": "s", **{k: "m/s^2" for k in cols}}
        ref_path = write_table(work / "ref.parquet", {"gps_time": day.time, **cols}, units)
        args += ["--reference", str(ref_path)]
    t_start = time.perf_counter()
    proc = accal_cli([*args, "-j", "1", "-q", "--force"])
    seconds = time.perf_counter() - t_start
    if proc.returncode != 0:
        raise _fail(proc, "accal grace-bias")
    recs = closure_records(work / "o", float(day.time[0]))
    out = []
    for ax, rec in recs.items():
        rec.update(axis=ax, injected=bool(inj) and ax == case.axis, seconds=seconds)
        if rec["injected"]:
            rec["params"] = inj["params"]
            score(rec, case.kind, inj["params"], float(day.time[-1] - day.time[0]))
        out.append(rec)
    return out


#: ``accal simulate grace --effect`` spec per kind (times from the start of the day).
def accsim_effect(case: Case) -> tuple[str, dict[str, Any]]:
    """The ``--effect`` spec of an accal-simulator case and the parameters to score."""
    p = draw_effect(case)
    ax = case.axis
    if case.kind == "step":
        return f"step:axis={ax},epoch={p['epoch']:.0f},size={p['size']:.6g}", p
    if case.kind == "coupling":
        return f"coupling:axis={ax},channel=temperature,coef={p['coef']:.6g},lag={p['lag']:.0f}", p
    if case.kind == "quadratic":
        return f"quadratic:axis={ax},coef={p['coef']:.6g}", p
    if case.kind == "scale":
        return f"scale:axis={ax},factor={1 + p['rel_error']:.8g}", p
    raise ValueError(f"no accal simulate effect for {case.kind!r}")


def run_accsim_cli(case: Case, work: Path) -> list[dict[str, Any]]:
    """``accal simulate grace`` (real-like defaults) then ``accal grace-bias
    --close-loop --truth [--aux] [--reference]``; options the simulator lacks make
    the case fail with its message (recorded, the run goes on)."""
    date = str(np.datetime64("2005-01-01") + np.timedelta64(case.seed % 3650, "D"))
    if case.satellite in "CD":
        date = str(np.datetime64("2019-01-01") + np.timedelta64(case.seed % 1800, "D"))
    data = work / f"sim_{case.satellite}.asc"
    args = ["simulate", "grace", "--date", date, "--satellite", case.satellite]
    args += ["--seed", str(case.seed), "--out", str(data)]
    args += ["--storm"] * case.storm + ["--thrusters"] * case.thrusters
    p = None
    if case.kind:
        spec, p = accsim_effect(case)
        args += ["--effect", spec]
    if case.reference:
        args += ["--reference-out", str(work / "ref.parquet")]
    proc = accal_cli(args)
    if proc.returncode != 0:
        raise _fail(proc, "accal simulate grace")
    truth = json.loads(data.with_name(data.name + ".truth.json").read_text())
    gb = ["grace-bias", str(data), "--close-loop", "--truth", str(data) + ".truth.json"]
    gb += ["--out", str(work / "o"), "--alpha", f"{case.alpha}", "-j", "1", "-q", "--force"]
    aux = data.with_name(data.name + ".aux.parquet")
    if aux.exists():
        gb += ["--aux", str(aux)]
    if case.reference:
        gb += ["--reference", str(work / "ref.parquet")]
    t_start = time.perf_counter()
    proc = accal_cli(gb)
    seconds = time.perf_counter() - t_start
    if proc.returncode != 0:
        raise _fail(proc, "accal grace-bias")
    out = []
    t0 = float(truth["t0"])
    for ax, rec in closure_records(work / "o", t0).items():
        rec.update(axis=ax, injected=bool(p) and ax == case.axis, seconds=seconds)
        if rec["injected"]:
            rec["params"] = p
            score(rec, case.kind, p, 86400.0)
        out.append(rec)
    return out


# ------------------------------------------------------------------ rotating platform
PLATFORM = {"tau": 600.0, "mask": 200.0}


def platform_effect(case: Case) -> tuple[tuple, dict[str, Any]]:
    """The ``tests.indep.platform_run`` effect tuple of a platform case."""
    p = draw_effect(case)
    ax = case.axis or "both"
    if case.kind == "pf_step":
        return ("step", ax, p["epoch"], p["size"]), p
    if case.kind == "pf_coupling":
        return ("coupling", "temperature", p["coef"], p["lag"], ax), p
    return ("inperiod_quadratic", p["coef"], ax), p


def platform_scores(per: dict[str, np.ndarray], truth: Any) -> dict[str, Any]:
    """a_Y/a_Z errors before/after against the per-period truth, and the changes.

    ``per``: ``period``, ``a_X_before``, ``a_X_after``, ``sigma_X_after``,
    ``sigma_X_before`` (X = Y, Z) of the kept periods.
    """
    tp = truth.set_index("period")
    idx = np.asarray(per["period"])
    out: dict[str, Any] = {"n_periods": int(idx.size)}
    for ax in "YZ":
        tr = tp.loc[idx, f"a_{ax}_rest"].to_numpy()
        b, a = per[f"a_{ax}_before"] - tr, per[f"a_{ax}_after"] - tr
        s_a, s_b = per[f"sigma_{ax}_after"], per[f"sigma_{ax}_before"]
        ch = np.abs(per[f"a_{ax}_after"] - per[f"a_{ax}_before"]) / s_a
        out[f"a_{ax}"] = {
            "rms_err_before": float(np.sqrt(np.mean(b**2))),
            "rms_err_after": float(np.sqrt(np.mean(a**2))),
            "std_z_before": float(np.std(b / s_b)),
            "std_z_after": float(np.std(a / s_a)),
            "change_sigmas": [float(x) for x in np.round(ch, 4)],
        }
        out[f"a_{ax}"]["rms_ratio"] = out[f"a_{ax}"]["rms_err_after"] / max(
            out[f"a_{ax}"]["rms_err_before"], 1e-300
        )
    return out


def run_platform(case: Case, work: Path) -> list[dict[str, Any]]:
    """Close the loop on a one-day platform run (``tests.indep.platform_run``), through
    ``close_loop_demod`` as ``accal demod --close-loop`` calls it or the CLI."""
    from tests.indep import platform_run, write_platform_run

    p = None
    effects = []
    if case.kind:
        eff, p = platform_effect(case)
        effects = [eff]
    run = platform_run(case.seed, effects=effects)
    table = run.table
    t_start = time.perf_counter()
    if case.path == "api":
        from accal.closure.demod import close_loop_demod
        from accal.estimators.noise import as_psd

        res, per = close_loop_demod(
            table["time"].to_numpy(),
            (table["m_y"].to_numpy(), table["m_z"].to_numpy()),
            table["theta"].to_numpy(),
            tau=PLATFORM["tau"],
            aux={"temperature": table["temperature"].to_numpy()},
            alpha=case.alpha,
            rest_tol=1e-9,
            noise_psd=as_psd(None),
        )
        rec = result_record(res, 0.0)
        cols = {"period": per.period_index}
        for ax in "YZ":
            for w in ("before", "after"):
                cols[f"a_{ax}_{w}"] = getattr(per, f"a_{ax}_{w}")
                cols[f"sigma_{ax}_{w}"] = getattr(per, f"sigma_{ax}_{w}")
    else:
        import pyarrow.parquet as pq

        path = write_platform_run(run, work / "run.parquet")
        proc = accal_cli(
            ["demod", str(path), "--tau", "600", "--mask", "200", "--close-loop",
             "--alpha", f"{case.alpha}", "--out", str(work / "o"), "-q"]
        )  # fmt: skip
        if proc.returncode != 0:
            raise _fail(proc, "accal demod")
        (entry,) = json.loads((work / "o" / "closure.json").read_text())["sources"].values()
        rec = json_record(entry, 0.0)
        tab = pq.read_table(work / "o" / "periods.parquet").to_pandas()
        cols = {"period": tab["period"].to_numpy()}
        for ax in "YZ":
            cols[f"a_{ax}_before"] = tab[f"a_{ax}_before"].to_numpy()
            cols[f"sigma_{ax}_before"] = tab[f"sigma_{ax}_before"].to_numpy()
            cols[f"a_{ax}_after"] = tab[f"a_{ax}"].to_numpy()
            cols[f"sigma_{ax}_after"] = tab[f"sigma_{ax}"].to_numpy()
    rec["removed"] = [e["name"] for e in rec["effects"]]  # all enter the extended model
    rec.update(axis="YZ", injected=bool(p), seconds=time.perf_counter() - t_start)
    rec.update(platform_scores(cols, run.periods))
    if p is not None:
        rec["params"] = p
        score(rec, case.kind, p, float(table["time"].iloc[-1] - table["time"].iloc[0]))
        rec["wrong_removed"] = [e["name"] for e in rec["effects"] if e is not rec["hit"]]
    return [rec]


# ------------------------------------------------------------------ the real Swarm day
def run_swarm(case: Case, work: Path) -> list[dict[str, Any]]:
    """``accal grace-bias TABLE --column x=a_cal_x --close-loop`` on the real Swarm-A
    day with a temperature column (``table``: Parquet with units, no ``--aux``;
    ``table+aux``: the table is also its own ``--aux``; ``csv-nounits``: a plain CSV
    without unit metadata), an injected effect or none.  The null run of the same mode gives
    the twin errors (filled in by the caller)."""
    from tests.indep import swarm_day_with_channels, write_swarm_table

    p = None
    effects = []
    if case.kind == "swarm_step":
        p = draw_effect(case)
        effects = [("step", "x", p["epoch"], p["size"])]
    elif case.kind == "swarm_coupling":
        p = draw_effect(case)
        effects = [("coupling", "x", "temperature", p["coef"], p["lag"], 0.0)]
    day = swarm_day_with_channels(SAMPLES, case.seed, effects=effects)
    if case.mode == "csv-nounits":  # a plain CSV: no unit of any column
        path = work / "swarm.csv"
        day.table.to_csv(path, index=False)
    else:
        path = write_swarm_table(day, work / "swarm.parquet")
    args = ["grace-bias", str(path), "--column", "x=a_cal_x", "--close-loop"]
    args += ["--out", str(work / "o"), "--alpha", f"{case.alpha}", "-j", "1", "-q", "--force"]
    if case.mode == "table+aux":
        args += ["--aux", str(path)]
    t_start = time.perf_counter()
    proc = accal_cli(args)
    seconds = time.perf_counter() - t_start
    if proc.returncode != 0:
        raise _fail(proc, "accal grace-bias (Swarm table)")
    recs = closure_records(work / "o", float(day.truth["t0_gps"]))
    rec = recs["x"]
    rec.update(axis="x", injected=p is not None, seconds=seconds, stderr=proc.stderr[-2000:])
    if p is not None:
        rec["params"] = p
        score(rec, case.kind, p, float(day.truth["t"][-1]))
    return [rec]


# ------------------------------------------------------------------ dispatcher
def run_case(case: Case) -> dict[str, Any]:
    """Run one case in a scratch directory; exceptions are recorded, not raised."""
    out: dict[str, Any] = {"case": case.name, **asdict(case)}
    t_start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="accal-closure-") as tmp:
        work = Path(tmp)
        try:
            if case.source == "platform":
                out["axes"] = run_platform(case, work)
            elif case.source == "swarm":
                out["axes"] = run_swarm(case, work)
            elif case.source == "accsim":
                out["axes"] = run_accsim_cli(case, work)
            elif case.path == "cli":
                out["axes"] = run_grace_cli(case, work)
            else:
                out["axes"] = run_grace_api(case)
            out["error"] = None
        except Exception as exc:  # a failing case is a result
            out["axes"] = []
            out["error"] = f"{type(exc).__name__}: {exc}"
            out["traceback"] = traceback.format_exc(limit=6)
    out["wall"] = time.perf_counter() - t_start
    return out


def git_state() -> dict[str, str]:
    """Commit, modified files of ``src/`` and a hash of its contents (the engine is being
    tuned in the working tree: the hash tells whether it changed during a run)."""
    import hashlib

    def git(*a: str) -> str:
        r = subprocess.run(["git", *a], cwd=ROOT, capture_output=True, text=True, check=False)
        return r.stdout.strip()

    h = hashlib.sha256()
    for f in sorted((ROOT / "src").rglob("*.py")):
        h.update(f.read_bytes())
    return {"commit": git("rev-parse", "HEAD"), "dirty": git("status", "--short", "src"),
            "src_sha256": h.hexdigest()[:16]}  # fmt: skip
