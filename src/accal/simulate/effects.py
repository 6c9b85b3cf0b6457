"""Instrument effects injected into a simulated raw reading, and auxiliary channels.

An effect is written ``NAME:key=value,key=value`` (``accal simulate grace
--effect``) and parsed by :func:`parse_effect`.  Each one adds a known term to
one axis of the raw reading, on top of eq. 9 of the wavelet paper
(``a_raw = s·a_true + b + d·(t − t0) + noise``); ``tau = t − t0`` is the time
since the start of the simulated day [s]:

=============  ==============================================  =====================================
effect         keys (defaults)                                 term added to the raw axis [m/s²]
=============  ==============================================  =====================================
step           axis, epoch [s], size [m/s²]                    ``size`` for ``tau >= epoch``
coupling       axis, channel, coef [m/s² per channel unit],    ``coef·y(tau − lag)``, ``y`` the channel
               lag [s] (0), tau [s] (0), tau2 [s] (0)          through first-order low-passes of
                                                               time constants ``tau`` and ``tau2``
                                                               (each skipped when 0)
quadratic      axis, coef [m/s⁴]                               ``coef·tau²``
scale          axis, factor                                    ``s·(factor − 1)·a_true``
sawtooth       axis, period [s], amp [m/s²], phase [cycles]    ``amp·(2·frac(tau/period + phase) − 1)``
               (0)
growing        axis, period [s], amp0, amp1 [m/s²],            ``(amp0 + (amp1 − amp0)·tau/duration)
               phase [rad] (0)                                 ·sin(2π tau/period + phase)``
exponential    axis, amp [m/s²], tau [s]                       ``amp·exp(−tau/tau)``
scalematrix    xx, xy, xz, yx, yy, yz, zx, zy, zz (identity)   all three axes: ``(S⁻¹ − I)·s·a_true``
splinebias     axis, step [s], amp [m/s²] or coefs [m/s²],     ``Σ_k c_k·B₃((t − t_k)/step)``, a cubic
               seed (0)                                        B-spline of node spacing ``step``
=============  ==============================================  =====================================

Conventions
-----------
* **scale**: the instrument's true scale is ``s·factor`` instead of the nominal
  ``s`` of the truth (``scale_s``), i.e. ``a_raw = s·factor·a_true + b + ...``.
  Calibrating with the nominal scale (TN-02 for GRACE) gives ``factor·a_true``.
* **coupling**: the channel enters as given (not about its mean), the convention of
  ``accal grace-bias --close-loop`` (README: "A coupling ``c·x`` to a channel
  enters as given, so the bias of such a day is the bias at channel value 0").
  A temperature of ~296 K with ``coef = 3e-9`` adds ~9e-7 m/s² to the raw offset.
  The channel is taken as piecewise linear between its samples, and the
  low-pass is the exact solution of ``τ y' + y = x`` for that input, started in
  steady state at the channel's first sample (:data:`CHANNEL_PREROLL` before the
  record): ``y_{k+1} = a y_k + (1 − a) x_k + (1 − τ(1 − a)/h)(x_{k+1} − x_k)``,
  ``a = exp(−h/τ)``, ``h`` the channel step.  The lagged value is linearly
  interpolated on the channel's grid (exact for a lag that is a multiple of ``h``).
* **growing**: ``duration`` is the simulated record length (``amp1`` is reached
  at its end).
* **scalematrix**: the keys are the entries of the matrix ``S`` of the reference
  calibration ``a_ref = S·(a_raw − b(t))`` (``accal grace-bias --reference REF
  --scale fit-matrix``; :mod:`accal.estimators.reference`), with ``a_ref`` the
  reference the simulator writes (``s·a_true``, ``accal simulate grace
  --reference-out``): the raw signal becomes ``S⁻¹·s·a_true``.  Keys not given are
  those of the identity (``scalematrix:xx=0.98,xy=1e-3`` is ``S = [[0.98, 1e-3, 0],
  [0, 1, 0], [0, 0, 1]]``).  Row ``i`` of ``S`` is what the ``bias_drift`` row of axis
  ``i`` reports as ``scale_x, scale_y, scale_z``.  A ``scale:axis=x,factor=f`` is the
  same as ``scalematrix:xx=1/f``.  With several scale effects the raw signal is
  ``M·s·a_true``, ``M = I + Σ diag(f − 1) + Σ (S⁻¹ − I)``, and the matrix to compare
  with the fit is ``M⁻¹`` (:func:`reference_scale`; ``truth["reference"]["scale"]``
  of a day written with a reference).
* **splinebias**: ``B₃`` is the centred cubic B-spline (support ``|x| < 2``,
  ``B₃(0) = 2/3``, ``B₃(±1) = 1/6``; de Boor, *A Practical Guide to Splines*, 2001,
  ch. IX), so the bias has two continuous derivatives.  With ``amp`` the
  coefficients are random, ``c_k = amp·N(0, 1)``, and the nodes sit at whole
  multiples of ``step`` in GPS time (``t_k = k·step`` seconds since 2000-01-01
  12:00:00; for ``step`` dividing 43200 s, a node at every day boundary): ``c_k``
  depends only on ``seed``, the axis and ``k`` (:func:`spline_coefficient`), so days
  simulated one by one with the same effect share their nodes and the bias is
  continuous across them.  With ``coefs=c0;c1;...`` (``;``-separated) the
  coefficients are given, for the nodes ``t0 − step, t0, t0 + step, ...`` of the
  record (``ceil(duration/step) + 3`` values).  The truth lists the node epochs
  (GPS s), the coefficients and the bias at the first sample
  (:func:`spline_nodes`, :func:`spline_bias`).

Channels
--------
A coupling names its channel; the simulator then draws it and writes it beside
the data (``<out>.aux.parquet``).  Known channels: ``temperature`` and any name
starting with ``temperature`` (``temperature_icu``, ...), each drawn independently
by :func:`temperature_channel` [K].
"""

from __future__ import annotations

import hashlib
import math
import re
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from accal.errors import ValidationError

#: Required keys and optional keys with their defaults, per effect.
EFFECTS: dict[str, tuple[tuple[str, ...], dict[str, float]]] = {
    "step": (("axis", "epoch", "size"), {}),
    "coupling": (("axis", "channel", "coef"), {"lag": 0.0, "tau": 0.0, "tau2": 0.0}),
    "quadratic": (("axis", "coef"), {}),
    "scale": (("axis", "factor"), {}),
    "sawtooth": (("axis", "period", "amp"), {"phase": 0.0}),
    "growing": (("axis", "period", "amp0", "amp1"), {"phase": 0.0}),
    "exponential": (("axis", "amp", "tau"), {}),
    "scalematrix": ((), {a + b: float(a == b) for a in "xyz" for b in "xyz"}),
    "splinebias": (("axis", "step"), {"amp": None, "coefs": None, "seed": 0.0}),
}

#: Effects that act on all three axes at once (``Effect.axis`` is ``"xyz"``).
VECTOR_EFFECTS = ("scalematrix",)

#: Largest condition number of a ``scalematrix`` (a near-singular ``S`` makes
#: ``S⁻¹`` and the raw reading meaningless).
MAX_CONDITION = 1e3

#: Units of the effect parameters (for the truth file).
PARAMETER_UNITS = {
    "epoch": "s from the start of the day",
    "size": "m/s^2",
    "coef": "m/s^2 per channel unit (coupling), m/s^4 (quadratic)",
    "lag": "s",
    "tau": "s",
    "tau2": "s",
    "factor": "1",
    "period": "s",
    "amp": "m/s^2",
    "amp0": "m/s^2",
    "amp1": "m/s^2",
    "phase": "cycles (sawtooth), rad (growing)",
}

#: Units of the parameters of ``scalematrix`` and ``splinebias`` (added to the truth's
#: units only when such an effect is injected, so that other truths stay as they were).
EXTRA_PARAMETER_UNITS = {
    "step": "s (spline node spacing)",
    "coefs": "m/s^2 (spline coefficients)",
    "seed": "1 (random stream of the spline coefficients)",
    "node_epochs": "s (GPS)",
    "coefficients": "m/s^2",
    "bias_t0": "m/s^2",
    **{a + b: "1 (entry of S in a_ref = S (a_raw - b))" for a in "xyz" for b in "xyz"},
}

#: Channel history simulated (and written) before the record [s]: the longest lag
#: plus five time constants of both low-passes fit in it, so that the start of the
#: response (steady state at the channel's first sample) is forgotten to < 1 %.
CHANNEL_PREROLL = 14400.0

#: Longest coupling lag [s] and low-pass time constant [s].
MAX_LAG, MAX_TAU = 3600.0, 1000.0

_CHANNEL_RE = re.compile(r"^temperature\w*$")


@dataclass(frozen=True)
class Effect:
    """One parsed ``--effect``.

    Attributes
    ----------
    name : str
        One of :data:`EFFECTS`.
    axis : str
        ``"x"``, ``"y"`` or ``"z"``; ``"xyz"`` for an effect on all axes
        (:data:`VECTOR_EFFECTS`).
    params : dict
        Numeric parameters (defaults filled in), plus ``channel`` for a coupling.
    spec : str
        The text it was parsed from.
    """

    name: str
    axis: str
    params: dict[str, Any]
    spec: str

    @property
    def index(self) -> int:
        """Column of the axis (0, 1, 2); ValueError for an effect on all axes."""
        if len(self.axis) != 1:
            raise ValueError(f"{self.name} acts on all three axes")
        return "xyz".index(self.axis)


def _number(key: str, text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ValidationError(f"{key} must be a number, got {text!r}") from None
    if not math.isfinite(value):
        raise ValidationError(f"{key} must be finite, got {text!r}")
    return value


def _coefs(text: str) -> list[float]:
    """``c0;c1;...`` as floats (each finite)."""
    items = [t.strip() for t in text.split(";")]
    if not all(items):
        raise ValidationError(f"coefs must be numbers separated by ';', got {text!r}")
    return [_number("coefs", t) for t in items]


def _check_ranges(name: str, p: dict[str, Any], duration: float) -> None:
    """ValidationError for a parameter outside its range."""
    if name == "scalematrix":
        _check_matrix(scale_matrix_of(p))
        return
    if name == "splinebias":
        _check_spline(p, duration)
    positive = {"period", "factor"} | ({"tau"} if name == "exponential" else set())
    positive |= {"step"} if name == "splinebias" else set()
    for key in positive & set(p):
        if not p[key] > 0:
            raise ValidationError(f"{key} must be > 0, got {p[key]:g}")
    if name == "step" and not 0 <= p["epoch"] < duration:
        raise ValidationError(
            f"epoch must be in [0, {duration:g}) s (from the start of the day), got {p['epoch']:g}"
        )
    if name == "coupling":
        if not 0 <= p["lag"] <= MAX_LAG:
            raise ValidationError(f"lag must be in [0, {MAX_LAG:g}] s, got {p['lag']:g}")
        for key in ("tau", "tau2"):
            if not 0 <= p[key] <= MAX_TAU:
                raise ValidationError(f"{key} must be in [0, {MAX_TAU:g}] s, got {p[key]:g}")
        if not _CHANNEL_RE.match(p["channel"]):
            raise ValidationError(
                f"channel must be 'temperature' or start with it (temperature_icu, ...), "
                f"got {p['channel']!r}"
            )


def parse_effect(spec: str, *, duration: float = 86400.0) -> Effect:
    """Parse ``NAME:key=value,...`` into an :class:`Effect`.

    Parameters
    ----------
    spec : str
        E.g. ``"step:axis=x,epoch=43200,size=3e-9"``.
    duration : float
        Record length [s]: a step's epoch must fall inside it.

    Returns
    -------
    Effect

    Raises
    ------
    ValidationError
        An unknown effect or key, a key given twice or missing, a value that is not
        a finite number or is out of range; the message names the bad part.
    """
    name, sep, rest = spec.strip().partition(":")
    if name not in EFFECTS:
        raise ValidationError(f"unknown effect {name!r}; known: {', '.join(EFFECTS)}")
    if not sep or not rest.strip():
        raise ValidationError(f"{name} needs key=value pairs after '{name}:'")
    required, optional = EFFECTS[name]
    given: dict[str, str] = {}
    for item in rest.split(","):
        key, eq, value = (s.strip() for s in item.partition("="))
        if not eq or not key or not value:
            raise ValidationError(f"expected key=value, got {item.strip()!r}")
        if key not in required and key not in optional:
            keys = ", ".join([*required, *optional])
            raise ValidationError(f"{name} has no key {key!r}; its keys: {keys}")
        if key in given:
            raise ValidationError(f"{key} given twice")
        given[key] = value
    missing = [k for k in required if k not in given]
    if missing:
        raise ValidationError(f"{name} needs {', '.join(missing)}")
    if name == "splinebias" and ("amp" in given) == ("coefs" in given):
        raise ValidationError(
            "splinebias needs either amp (random coefficients) or coefs (given ones), not both"
        )
    axis = given.pop("axis") if "axis" in required else "xyz"
    if axis not in ("x", "y", "z", "xyz"):
        raise ValidationError(f"axis must be x, y or z, got {axis!r}")
    params: dict[str, Any] = dict(optional)
    for key, value in given.items():
        if key == "channel":
            params[key] = value
        elif key == "coefs":
            params[key] = _coefs(value)
        else:
            params[key] = _number(key, value)
    _check_ranges(name, params, duration)
    return Effect(name, axis, params, spec.strip())


def scale_matrix_of(params: dict[str, Any]) -> NDArray[np.float64]:
    """The 3×3 matrix ``S`` of ``scalematrix`` parameters ``xx`` ... ``zz``."""
    return np.array([[float(params[a + b]) for b in "xyz"] for a in "xyz"])


def _check_matrix(m: NDArray[np.float64]) -> None:
    if not (np.diag(m) > 0).all():
        raise ValidationError(f"the diagonal xx, yy, zz must be > 0, got {np.diag(m).tolist()}")
    cond = float(np.linalg.cond(m))
    if not (np.linalg.det(m) > 0 and cond <= MAX_CONDITION):
        raise ValidationError(
            f"the matrix must be well conditioned with a positive determinant "
            f"(condition number <= {MAX_CONDITION:g}), got det = {np.linalg.det(m):.3g}, "
            f"condition number {cond:.3g}"
        )


def _check_spline(p: dict[str, Any], duration: float) -> None:
    if p["amp"] is not None and not p["amp"] >= 0:
        raise ValidationError(f"amp must be >= 0, got {p['amp']:g}")
    seed = p["seed"]
    if not (seed >= 0 and seed == int(seed)):
        raise ValidationError(f"seed must be an integer >= 0, got {seed:g}")
    if p["coefs"] is not None and p["step"] > 0:
        need = math.ceil(duration / p["step"] - 1e-9) + 3
        if len(p["coefs"]) != need:
            raise ValidationError(
                f"coefs: {need} values needed for a record of {duration:g} s with step "
                f"{p['step']:g} s (nodes t0 - step, t0, ..., t0 + {need - 2}*step), "
                f"got {len(p['coefs'])}"
            )


def bspline3(x: NDArray[np.float64]) -> NDArray[np.float64]:
    """The centred cubic B-spline: ``2/3 − x² + |x|³/2`` (``|x| < 1``), ``(2 − |x|)³/6`` (``< 2``), 0."""
    ax = np.abs(np.asarray(x, dtype=np.float64))
    inner = 2.0 / 3.0 - ax**2 + 0.5 * ax**3
    outer = np.clip(2.0 - ax, 0.0, None) ** 3 / 6.0
    return np.where(ax < 1.0, inner, outer)


#: Entropy tag of the spline coefficient streams (any fixed number; not a day's seed).
SPLINE_STREAM = 200
#: Offset added to the node index so that nodes before 2000 give non-negative entropy.
_NODE_OFFSET = 1 << 40


def spline_coefficient(seed: int, axis: str, k: int) -> float:
    """Random coefficient of node ``k`` (``k·step`` GPS s) of a ``splinebias``, per unit ``amp``.

    ``numpy.random.default_rng([SPLINE_STREAM, seed, axis index, k + 2**40])``'s first
    standard normal: the same for every day that contains the node.
    """
    rng = np.random.default_rng(
        [SPLINE_STREAM, int(seed), "xyz".index(axis), int(k) + _NODE_OFFSET]
    )
    return float(rng.standard_normal())


def spline_nodes(
    effect: Effect, t0: float, duration: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Node epochs [s, GPS] and coefficients [m/s²] of a ``splinebias`` on ``[t0, t0 + duration]``.

    Random coefficients (``amp``): every node ``k·step`` within two steps of the
    record.  Given ones (``coefs``): the nodes ``t0 + (j − 1)·step``.
    """
    p = effect.params
    step = float(p["step"])
    if p["coefs"] is not None:
        c = np.asarray(p["coefs"], dtype=np.float64)
        return t0 + step * (np.arange(c.size) - 1.0), c
    k = np.arange(math.floor(t0 / step) - 1, math.ceil((t0 + duration) / step) + 2)
    c = np.array([p["amp"] * spline_coefficient(int(p["seed"]), effect.axis, j) for j in k])
    return k * step, c


def spline_bias(
    t: NDArray[np.float64], nodes: NDArray[np.float64], coefs: NDArray[np.float64], step: float
) -> NDArray[np.float64]:
    """``Σ_k coefs[k]·B₃((t − nodes[k])/step)`` [m/s²] at GPS times ``t`` [s] (:func:`bspline3`)."""
    t = np.asarray(t, dtype=np.float64)
    out = np.zeros(t.shape)
    for node, c in zip(nodes, coefs, strict=True):
        out += c * bspline3((t - node) / step)
    return out


def reference_scale(effects: list[Effect] | tuple[Effect, ...]) -> NDArray[np.float64]:
    """The ``S`` of ``a_ref = S·(a_raw − b(t) − other terms)`` for the reference ``s·a_true``.

    The raw signal is ``M·s·a_true`` with ``M = I + Σ diag(factor − 1)`` over the
    ``scale`` effects ``+ Σ (S_j⁻¹ − I)`` over the ``scalematrix`` ones; returns
    ``M⁻¹`` (the identity without scale effects).
    """
    m = np.eye(3)
    for e in effects:
        if e.name == "scale":
            m[e.index, e.index] += e.params["factor"] - 1.0
        elif e.name == "scalematrix":
            m += np.linalg.inv(scale_matrix_of(e.params)) - np.eye(3)
    return np.linalg.inv(m)


def vector_term(effect: Effect, scaled_true: NDArray[np.float64]) -> NDArray[np.float64]:
    """The term of an effect on all axes (``scalematrix``) [m/s²], shape (n, 3).

    ``scaled_true`` is ``s·a_true``, shape (n, 3); the term is ``(S⁻¹ − I)·s·a_true``.
    """
    s_inv = np.linalg.inv(scale_matrix_of(effect.params))
    return scaled_true @ (s_inv - np.eye(3)).T


def first_order_recursion(g: NDArray[np.float64], a: float) -> NDArray[np.float64]:
    """``y[k] = a·y[k − 1] + g[k]``, ``y[0] = g[0]``, for ``0 <= a < 1``.

    A parallel prefix scan in ``log2(n)`` vector steps (``y[k] += a^d·y[k − d]`` for
    ``d = 1, 2, 4, ...``) instead of a Python loop or :func:`scipy.signal.lfilter`
    (whose import alone takes ~2 s); every multiplier is <= 1, so it is as stable as
    the recursion.
    """
    y = np.array(g, dtype=np.float64)
    d = 1
    while d < y.size:
        f = a**d
        if f == 0.0:
            break
        y[d:] = y[d:] + f * y[:-d]
        d *= 2
    return y


def lowpass(x: NDArray[np.float64], h: float, tau: float) -> NDArray[np.float64]:
    """First-order low-pass of a piecewise-linear channel sampled every ``h`` [s].

    Parameters
    ----------
    x : ndarray
        Channel samples, every ``h`` seconds.
    h : float
        Sampling step [s].
    tau : float
        Time constant [s]; 0 returns ``x``.

    Returns
    -------
    ndarray
        The exact solution of ``tau·y' + y = x`` for ``x`` linear between samples,
        with ``y[0] = x[0]`` (steady state):
        ``y[k] = a·y[k − 1] + (1 − a)·x[k − 1] + (1 − tau(1 − a)/h)·(x[k] − x[k − 1])``,
        ``a = exp(−h/tau)``.
    """
    if tau == 0 or x.size == 0:
        return x
    a = math.exp(-h / tau)
    c0 = 1.0 - tau * (1.0 - a) / h  # weight of x[k]
    c1 = (1.0 - a) - c0  # weight of x[k - 1]
    g = np.empty_like(x, dtype=np.float64)
    g[0] = x[0]
    g[1:] = c0 * x[1:] + c1 * x[:-1]
    return first_order_recursion(g, a)


def effect_term(
    effect: Effect,
    tau: NDArray[np.float64],
    *,
    duration: float,
    scaled_true: NDArray[np.float64],
    channels: dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]],
    t0: float = 0.0,
) -> NDArray[np.float64]:
    """The term an effect adds to its raw axis [m/s²].

    Parameters
    ----------
    effect : Effect
        An effect on one axis (for ``scalematrix`` see :func:`vector_term`).
    tau : ndarray, shape (n,)
        Time since the start of the day [s].
    duration : float
        Record length [s] (``growing``, ``splinebias``).
    scaled_true : ndarray, shape (n,)
        ``s·a_true`` of the effect's axis [m/s²] (``scale``).
    channels : dict
        Channel name -> (elapsed time of its samples [s], values), for couplings.
    t0 : float
        GPS seconds of ``tau = 0`` [s] (``splinebias``, whose nodes are in GPS time).

    Returns
    -------
    ndarray, shape (n,)
    """
    p = effect.params
    if effect.name == "splinebias":
        nodes, coefs = spline_nodes(effect, t0, duration)
        return spline_bias(t0 + tau, nodes, coefs, p["step"])
    if effect.name == "step":
        return np.where(tau >= p["epoch"], p["size"], 0.0)
    if effect.name == "quadratic":
        return p["coef"] * tau**2
    if effect.name == "scale":
        return (p["factor"] - 1.0) * scaled_true
    if effect.name == "sawtooth":
        return p["amp"] * (2.0 * np.mod(tau / p["period"] + p["phase"], 1.0) - 1.0)
    if effect.name == "growing":
        amp = p["amp0"] + (p["amp1"] - p["amp0"]) * tau / duration
        return amp * np.sin(2.0 * np.pi * tau / p["period"] + p["phase"])
    if effect.name == "exponential":
        return p["amp"] * np.exp(-tau / p["tau"])
    tc, x = channels[p["channel"]]
    h = float(tc[1] - tc[0])
    y = lowpass(lowpass(x, h, p["tau"]), h, p["tau2"])
    return p["coef"] * np.interp(tau - p["lag"], tc, y)


def effect_truth(
    effect: Effect, t0: float, scale_s: float, *, duration: float | None = None
) -> dict[str, Any]:
    """The truth entry of an effect: its parameters plus derived values.

    ``scalematrix``: ``matrix`` (``S``, row ``i`` = ``scale_x, scale_y, scale_z`` of
    the ``bias_drift`` row of axis ``i``) and ``inverse`` (``S⁻¹``, applied to
    ``s·a_true`` in the raw reading).  ``splinebias`` (with ``duration`` [s]):
    ``node_epochs`` [s, GPS], ``coefficients`` [m/s²] and ``bias_t0`` [m/s²], the bias
    at ``t0``.
    """
    out: dict[str, Any] = {"name": effect.name, "axis": effect.axis, **effect.params}
    out["spec"] = effect.spec
    if effect.name == "step":
        out["epoch_gps"] = t0 + effect.params["epoch"]
    if effect.name == "scale":
        out["scale_s_true"] = scale_s * effect.params["factor"]
    if effect.name == "scalematrix":
        m = scale_matrix_of(effect.params)
        out["matrix"] = m.tolist()
        out["inverse"] = np.linalg.inv(m).tolist()
    if effect.name == "splinebias" and duration is not None:
        nodes, coefs = spline_nodes(effect, t0, duration)
        out["node_epochs"] = nodes.tolist()
        out["coefficients"] = coefs.tolist()
        out["bias_t0"] = float(spline_bias(np.array([t0]), nodes, coefs, effect.params["step"])[0])
    return out


def channel_seed(seed: int, name: str) -> list[int]:
    """Entropy of a channel's random stream: the day's seed and a hash of the name."""
    digest = hashlib.sha256(f"accal.simulate.channel:{name}".encode()).digest()
    return [seed, 100, int.from_bytes(digest[:8], "little")]


def temperature_channel(
    tc: NDArray[np.float64], orbit_period: float, rng: np.random.Generator
) -> tuple[NDArray[np.float64], dict[str, float]]:
    """A temperature of an accelerometer unit [K] on the elapsed times ``tc`` [s].

    ``T0 + A_orb sin(2π tc/P + φ) + A_2 sin(4π tc/P + φ_2) + trend·tc/day``
    plus a random walk and a heater-like thermostat cycle (a square wave of
    period ``P_h`` through a first-order response of time constant ``P_h/4``).

    Magnitudes: ``T0`` 293–300 K (AHK1B samples of ``data/samples``: GRACE-A
    2003 ``tisu`` 26.8 °C, GRACE-FO C 2023 ``TSU_*`` 21.9–22.7 °C, ``TFEEU_*``
    24.7–27.0 °C); orbital cycle 0.1–0.5 K and a slow trend of up to ±0.3 K/day
    (typical thermal response of a LEO satellite; not measurable in the 10-min
    samples, where ``tesu`` varies by 0.013 K and ``taicu`` by 0.1 K); random walk
    of 1.5e-4 K per √s (~0.05 K over a day); heater cycle of 0.01–0.05 K peak to
    peak, period 600–1800 s.

    Returns
    -------
    values : ndarray
        Temperature [K].
    params : dict
        The drawn parameters (for the truth).
    """
    prm = {
        "mean": float(rng.uniform(293.0, 300.0)),
        "orbital_amplitude": float(rng.uniform(0.1, 0.5)),
        "orbital_phase": float(rng.uniform(0.0, 2.0 * np.pi)),
        "second_harmonic": float(rng.uniform(0.0, 0.1)),
        "second_phase": float(rng.uniform(0.0, 2.0 * np.pi)),
        "trend_per_day": float(rng.uniform(-0.3, 0.3)),
        "random_walk": 1.5e-4,
        "heater_period": float(rng.uniform(600.0, 1800.0)),
        "heater_amplitude": float(rng.uniform(0.01, 0.05)),
        "heater_phase": float(rng.uniform(0.0, 1.0)),
        "orbit_period": float(orbit_period),
    }
    h = float(tc[1] - tc[0]) if tc.size > 1 else 1.0
    w = 2.0 * np.pi / orbit_period
    temp = (
        prm["mean"]
        + prm["orbital_amplitude"] * np.sin(w * tc + prm["orbital_phase"])
        + prm["second_harmonic"] * np.sin(2.0 * w * tc + prm["second_phase"])
        + prm["trend_per_day"] * tc / 86400.0
    )
    walk = np.cumsum(rng.standard_normal(tc.size)) * prm["random_walk"] * math.sqrt(h)
    temp += walk - walk[0]
    on = np.mod(tc / prm["heater_period"] + prm["heater_phase"], 1.0) < 0.5
    heater = lowpass(on.astype(np.float64), h, prm["heater_period"] / 4.0)
    temp += prm["heater_amplitude"] * (heater - 0.5)
    return temp, prm
