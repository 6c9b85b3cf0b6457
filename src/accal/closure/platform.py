"""Rotating-platform candidates: angle errors and bias shapes repeating after every rotation.

They need the platform angle and the fitted demodulated signal
(:class:`PlatformInfo` in ``options["platform"]``), which
:func:`accal.closure.demod.close_loop_demod` supplies (Lenoir et al. 2013, eq. 4).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from accal.closure.candidates import Context, Proposal
from accal.errors import ValidationError

__all__ = ["PlatformInfo", "angle_offset", "intra_period_shape"]


@dataclass(frozen=True)
class PlatformInfo:
    """What the rotating-platform candidates need, on every (stacked) sample.

    Built by :func:`accal.closure.demod.close_loop_demod`; passed to
    :func:`close_loop` as ``options["platform"]``.

    Attributes
    ----------
    theta : ndarray, shape (N,)
        Platform angle θ at each sample [rad].
    signal_y, signal_z : ndarray, shape (N,)
        Fitted demodulated signal ``a_Y(t)``, ``a_Z(t)`` at each sample (base
        model, eqs. 14/17) [m/s²].
    axis_index : ndarray of int, shape (N,)
        0 for an ``m_y`` sample, 1 for an ``m_z`` sample.
    since_rest : ndarray, shape (N,)
        Time since the platform came to rest (end of the last rotation) [s]; NaN
        while rotating.
    direction : ndarray, shape (N,)
        Sign of the last rotation (+1: θ increased, −1: decreased, 0: none yet).
    rest_angle : ndarray, shape (N,)
        Rest angle, rounded to 1e-3 rad (NaN while rotating) [rad].
    """

    theta: NDArray[np.float64]
    signal_y: NDArray[np.float64]
    signal_z: NDArray[np.float64]
    axis_index: NDArray[np.int64]
    since_rest: NDArray[np.float64]
    direction: NDArray[np.float64]
    rest_angle: NDArray[np.float64]

    def dm_dtheta(self) -> NDArray[np.float64]:
        """``∂m/∂θ`` on every sample [m/s² per rad] (eq. 4 with k₂ = 0, δk₁ = 0).

        ``m_y = cos θ a_Y + sin θ a_Z`` → ``−sin θ a_Y + cos θ a_Z``;
        ``m_z = −sin θ a_Y + cos θ a_Z`` → ``−cos θ a_Y − sin θ a_Z``.
        """
        c, s = np.cos(self.theta), np.sin(self.theta)
        ay, az = self.signal_y, self.signal_z
        return np.where(self.axis_index == 0, -s * ay + c * az, -c * ay - s * az)


def _platform(ctx: Context, what: str) -> PlatformInfo:
    info = ctx.options.get("platform")
    if not isinstance(info, PlatformInfo):
        raise ValidationError(
            f"{what} needs the platform angle θ and the fitted demodulated signal: call it "
            "through accal.closure.demod.close_loop_demod (options['platform'])"
        )
    return info


_IDENT_TOL = 1e-6


def _identifiable(ctx: Context, col: NDArray[np.float64]) -> float:
    """Relative norm of the part of ``col`` (used rows) outside the current design."""
    z = col[ctx.use]
    nz = float(np.linalg.norm(z))
    if nz == 0:
        return 0.0
    return float(np.linalg.norm(z - ctx.basis.project(z)) / nz)


def angle_offset(ctx: Context) -> list[Proposal]:
    """An error of the platform angle: ``m = P(θ + δ) a`` ≈ ``P(θ) a + δ ∂m/∂θ``.

    Regressor: ``∂m/∂θ`` from the fitted demodulated signal (eq. 4; the quadrature
    of the demodulated signal), coefficient ``δ`` [rad].  Variants:

    * ``channel="common"``: one offset for every sample (an encoder zero error).
      Since ``P(θ + δ) = P(θ) P(δ)``, it is a rotation of ``(a_Y, a_Z)`` by ``δ``:
      with the signal free in every period (eqs. 18-19) it is *never* identifiable
      from the data, whatever the pattern.  It is not proposed; a note says so.
    * ``channel="rest@<θ_g>"``: the rest angle ``θ_g`` is off by ``δ_g`` relative to
      the others (rests not exactly where the log says, e.g. not exactly π apart).
      With rests at 0 and π only, per period the data hold four numbers (the mean
      of each axis at each angle, as many as ``a_Y, a_Z, b_y, b_z``), so ``δ_g``
      is absorbed into the signal and bias: not identifiable (note).  It becomes
      identifiable when the pattern rests at three or more angles (e.g. 0, π/2, π,
      3π/2) and ``a`` is non-zero.
    * ``channel="scale"``: a scale error of the angle, ``θ_true = (1 + s) θ`` (an
      encoder gain), i.e. an offset ``s θ_g`` at every rest angle ``θ_g`` as logged:
      regressor ``θ ∂m/∂θ`` at rest samples, coefficient ``s`` [rad/rad].  One
      parameter where the per-rest offsets need one per angle (QA: on a four-rest
      pattern a scale error of 1e-3 came out as the π/2 rest's offset alone, plus
      settling shapes and lines, and a_Y got 4.5x worse).  Proposed with three or
      more rest angles (with two it is the other rest's offset).

    Identifiability is decided numerically: the regressor must keep more than
    ``1e-6`` of its norm after projecting out the current design.  Each
    identifiable variant is one proposal; the multiplicity is their number.
    """
    info = _platform(ctx, "angle_offset")
    g = info.dm_dtheta()
    out: list[Proposal] = []
    notes: list[Proposal] = []
    at_rest = np.isfinite(info.rest_angle)
    variants = [("common", np.isfinite(g), None)]
    angles = np.unique(info.rest_angle[ctx.use & at_rest])
    if angles.size > 1:
        ref = angles[int(np.argmin(np.abs(np.angle(np.exp(1j * angles)))))]
        for a in angles:
            if a != ref:
                variants.append((f"rest@{a:.4g}", info.rest_angle == a, float(a)))
    if angles.size > 2:  # with two rest angles a scale is the other rest's offset
        variants.append(("scale", at_rest, None))
    for channel, sel, ang in variants:
        if ctx.has_label(f"angle:{channel}"):
            continue
        col = np.where(sel, g, 0.0)
        if channel == "scale":
            col = np.where(sel, np.nan_to_num(info.theta) * g, 0.0)
        rel = _identifiable(ctx, col)
        if rel <= _IDENT_TOL:
            why = (
                "a common angle offset is a rotation of (a_Y, a_Z): P(θ+δ)a = P(θ)P(δ)a"
                if channel == "common"
                else "absorbed by the per-period signal and bias (rests at two angles only, "
                "or the rest angle's samples carry no independent information)"
            )
            notes.append(
                Proposal(
                    "angle_offset",
                    channel,
                    np.zeros((col.size, 0)),
                    (),
                    params={"relative_norm_outside_base": rel},
                    note=f"not identifiable: {why}",
                )
            )
            continue
        out.append(
            Proposal(
                "angle_offset",
                channel,
                col[:, None],
                (f"angle:{channel}",),
                1.0,
                {
                    "rest_angle": ang,
                    "relative_norm_outside_base": rel,
                    "units": "rad/rad" if channel == "scale" else "rad",
                },
            )
        )
    out = [Proposal(p.name, p.channel, p.columns, p.labels, float(len(out)), p.params) for p in out]
    return out + notes


def intra_period_shape(ctx: Context) -> list[Proposal]:
    """A bias shape repeating after every rotation: a settling transient.

    Family: ``A_axis · exp(−φ/τ_s)`` with ``φ`` the time since the platform came to
    rest, either the same after every rotation (``channel="common"``) or with the
    sign of the rotation (``channel="direction"``: e.g. a proof-mass tilt in the
    sense of rotation), one amplitude ``A`` per axis [m/s²], ``τ_s`` searched over
    ``settle_taus`` (default 5, 10, 20, 50, 100, 200 s); multiplicity: the number
    of (τ_s, sign) pairs.

    Why a parametric shape and not a free basis in phase-within-period: the part of
    any periodic shape that lies in the span of the per-period columns (signal
    ``cos θ`` and bias) cannot be told apart from a constant signal offset, so a
    free basis could not correct ``a_Y``/``a_Z``.  With a fixed shape, the part
    outside that span fixes ``A``, and subtracting ``A·shape`` removes its leak into
    the demodulated signal as well (e.g. a direction-dependent transient, whose
    ``cos θ`` component does not cancel over the symmetric pattern).
    """
    info = _platform(ctx, "intra_period_shape")
    taus = tuple(ctx.options.get("settle_taus", (5.0, 10.0, 20.0, 50.0, 100.0, 200.0)))
    phi = info.since_rest
    rest = np.isfinite(phi)
    shapes, keys = [], []
    ph0 = np.where(rest, phi, 0.0)
    decay: dict[float, NDArray[np.float64]] = {}  # exp(−φ/τ_s), shared by both kinds
    for kind, sign in (("common", np.ones_like(phi)), ("direction", info.direction)):
        if ctx.has_label(f"shape:{kind}"):
            continue
        for ts in taus:
            if ts not in decay:
                decay[ts] = np.where(rest, np.exp(-ph0 / ts), 0.0)
            shapes.append(decay[ts] * sign)
            keys.append((kind, ts))
    if not shapes:
        return []
    z = np.column_stack(shapes)
    zu = z[ctx.use]
    z2 = np.sum(zu**2, axis=0)
    rel2 = 1.0 - ctx.basis.captured(zu) / np.maximum(z2, 1e-300)
    ok = (z2 > 0) & (rel2 > _IDENT_TOL**2)
    if not ok.any():
        return []
    pw = ctx.joint_power(zu)
    j = int(np.argmax(np.where(ok, pw, -1.0)))
    kind, ts = keys[j]
    sign = info.direction if kind == "direction" else np.ones_like(phi)
    ts = _refine_settle(ctx, phi, rest, sign, ts, sorted(taus))
    e = np.where(rest, np.exp(-np.where(rest, phi, 0.0) / ts), 0.0) * sign
    cols, labs, axes = ctx.split(e[:, None], (f"shape:{kind}",))

    def jacobian() -> list[tuple[str, NDArray[np.float64]]]:
        # ∂ exp(−φ/τ_s) / ∂ ln τ_s = (φ/τ_s) exp(−φ/τ_s)
        d = np.where(rest, np.where(rest, phi, 0.0) / ts, 0.0) * e
        return [("tau", ctx.split(d[:, None], (f"shape:{kind}",))[0])]

    return [
        Proposal(
            "intra_period_shape",
            kind,
            cols,
            labs,
            float(ok.sum()),
            {"tau": ts},
            axes=axes,
            jacobian=jacobian,
        )
    ]


def _refine_settle(
    ctx: Context,
    phi: NDArray[np.float64],
    rest: NDArray[np.bool_],
    sign: NDArray[np.float64],
    ts: float,
    grid: list[float],
) -> float:
    """The settling time constant of most explained power between the grid's neighbours.

    Bounded search on ln τ_s (to 1e-4), between the neighbouring grid values (a
    third / three times the end values).  On the grid alone a 60 s transient of
    2e-9 m/s² came out at 50 s with two lines, a step and a second shape, and
    a_Y's error stayed at 1.4e-10 m/s² (noise 4e-12).
    """
    from scipy.optimize import minimize_scalar

    k = grid.index(ts)
    lo = grid[k - 1] if k > 0 else ts / 3.0
    hi = grid[k + 1] if k + 1 < len(grid) else 3.0 * ts
    ph = np.where(rest, phi, 0.0)[ctx.use]
    sg = np.where(rest, sign, 0.0)[ctx.use]

    def neg_power(log_ts: float) -> float:
        col = np.exp(-ph / np.exp(log_ts)) * sg
        return -float(ctx.joint_power(col[:, None])[0])

    res = minimize_scalar(
        neg_power, bounds=(np.log(lo), np.log(hi)), method="bounded", options={"xatol": 1e-4}
    )
    if not res.success or -res.fun < -neg_power(np.log(ts)):
        return ts
    return float(np.exp(res.x))
