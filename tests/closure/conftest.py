"""Synthetic days for the closure tests (GRACE-like noise from accal.simulate.grace)."""

from __future__ import annotations

import numpy as np
import pytest

from accal.simulate.grace import coloured_noise

ORBIT = 5600.0  # [s]
BIAS, DRIFT = 1.3e-6, 2e-14  # [m/s²], [m/s³]


def make_day(
    seed: int,
    *,
    n: int = 86400,
    dt: float = 1.0,
    noise: float = 1e-10,
    corner: float = 1e-3,
    quadratic: float = 0.0,
    cubic: float = 0.0,
    step: tuple[float, float] | None = None,
    orbit: tuple[float, float] | None = None,
    temp_coupling: float = 0.0,
    temp_lag: float = 600.0,
    chirp: float = 0.0,
    n_gaps: int = 0,
) -> dict:
    """One synthetic day: bias + drift + coloured noise + the requested effects.

    ``step = (fraction of span, size)``, ``orbit = (amp 1/rev, amp 2/rev)``; the
    temperature is a day-scale plus once-per-orbit variation [K] (also returned).
    """
    rng = np.random.default_rng(seed)
    t = 1e8 + dt * np.arange(n)
    tau = t - t[0]
    y = BIAS + DRIFT * tau + coloured_noise(n, dt, noise, corner, rng)
    y += quadratic * tau**2 + cubic * tau**3
    if step is not None:
        y += step[1] * (tau >= step[0] * tau[-1])
    if orbit is not None:
        ph = rng.uniform(0, 2 * np.pi)
        w = 2 * np.pi / ORBIT
        y += orbit[0] * np.cos(w * tau + ph) + orbit[1] * np.sin(2 * w * tau + ph)
    p1 = rng.uniform(0, 2 * np.pi)
    temp = 20 + 1.5 * np.sin(2 * np.pi * tau / 86400 + p1) + 0.4 * np.sin(2 * np.pi * tau / ORBIT)
    temp += 0.3 * np.cumsum(rng.standard_normal(n)) / np.sqrt(n)
    if temp_coupling:
        y += temp_coupling * np.interp(tau - temp_lag, tau, temp)
    if chirp:
        # slow chirp: period 8 h at the start to 1.5 h at the end
        f = np.interp(tau, [0, tau[-1]], [1 / 28800, 1 / 5400])
        y += chirp * np.sin(2 * np.pi * np.cumsum(f) * dt)
    valid = np.ones(n, bool)
    for _ in range(n_gaps):
        a = int(rng.integers(1, n - 2000))
        valid[a : a + int(rng.integers(60, 1800))] = False
    return {"t": t, "y": y, "temp": temp, "valid": valid, "truth": {"bias": BIAS, "drift": DRIFT}}


@pytest.fixture(scope="session")
def sim():
    """The :func:`make_day` factory."""
    return make_day


# --------------------------------------------------------------------------------------
# rotating platform (accal.simulate.gap, MicroSTAR noise of eq. 1, fig2 pattern)

AY, AZ = 4.6e-7, -2.3e-7  # accal.simulate.gap defaults [m/s²]


def _four_angle_theta(n_per: int, rest: int = 100, rot: int = 50) -> np.ndarray:
    """One period of rests at 0, π/2, π, 3π/2 (100 s each, 50 s quintic moves), tiled."""
    from accal.estimators.design import _smoothstep

    angs = [0.0, np.pi / 2, np.pi, 3 * np.pi / 2]
    seg = []
    for i, a in enumerate(angs):
        seg.append(np.full(rest, a))
        b = angs[(i + 1) % 4]
        seg.append(a + (b - a) * _smoothstep(np.arange(1, rot + 1) / (rot + 1)))
    return np.tile(np.concatenate(seg), n_per)


def make_platform(
    seed: int,
    *,
    days: float = 0.25,
    pattern: str = "fig2",
    angle_error: tuple[float, float] | None = None,
    temp_coupling: float = 0.0,
    temp_lag: float = 0.0,
    step: tuple[float, float] | None = None,
    settle: tuple[float, float, float, str] | None = None,
    line: tuple[float, float] | None = None,
) -> dict:
    """Rotating-platform data at 1 Hz, τ = 600 s, with optional undeclared effects.

    ``pattern="fig2"``: :func:`accal.simulate.gap.simulate_gap` (rests at 0 and π);
    its temperature (kicks after each rotation) gets an orbital cycle and a random
    walk.  ``"four"``: rests at 0, π/2, π, 3π/2, same signal, bias and noise model;
    ``angle_error = (rest angle, δ)``: the platform really rests at angle + δ there.
    ``temp_coupling`` [m/s²/K] on m_y (half on m_z) with ``temp_lag`` [s];
    ``step = (epoch, size)`` on m_y; ``settle = (amp_y, amp_z, τ_s, "common"|"direction")``;
    ``line = (amplitude, period)``: a sinusoidal bias term on m_y.
    """
    from accal.closure.demod import _rest_runs
    from accal.estimators.design import rest_mask
    from accal.estimators.noise import MicroStarPSD
    from accal.simulate.gap import simulate_gap
    from accal.simulate.noise import coloured_noise as shaped

    rng = np.random.default_rng(seed)
    if pattern == "fig2":
        d, _ = simulate_gap(days=days, seed=seed)
        t = d.time.to_numpy()
        th = d.theta.to_numpy()
        my, mz = d.m_y.to_numpy().copy(), d.m_z.to_numpy().copy()
        temp = d.temperature.to_numpy().copy()
        temp += 0.3 * np.sin(2 * np.pi * t / 5400.0 + rng.uniform(0, 2 * np.pi))
        temp += 0.05 * np.cumsum(rng.standard_normal(t.size)) / np.sqrt(t.size)
    else:
        th = _four_angle_theta(int(days * 86400) // 600)
        t = np.arange(th.size, dtype=float)
        th_true = th.copy()
        if angle_error is not None:
            th_true = th + angle_error[1] * (np.abs(th - angle_error[0]) < 1e-9)
        c, s = np.cos(th_true), np.sin(th_true)
        nz = shaped(t.size, MicroStarPSD(), 1.0, rng, size=2)
        my = c * AY + s * AZ + 1e-6 + 1e-6 / 86400 * t + nz[0]
        mz = -s * AY + c * AZ - 0.7e-6 + 0.5e-6 / 86400 * t + nz[1]
        temp = np.zeros(t.size)
    if temp_coupling:
        tl = np.interp(t - temp_lag, t, temp - temp.mean())
        my += temp_coupling * tl
        mz += 0.5 * temp_coupling * tl
    if step is not None:
        my += step[1] * (t >= step[0])
    if line is not None:
        my += line[0] * np.sin(2 * np.pi * t / line[1] + 0.7)
    if settle is not None:
        since, direction, _ = _rest_runs(th, rest_mask(th), 1.0)
        sh = np.where(np.isfinite(since), np.exp(-np.nan_to_num(since) / settle[2]), 0.0)
        if settle[3] == "direction":
            sh = sh * direction
        my += settle[0] * sh
        mz += settle[1] * sh
    return {"t": t, "m": np.column_stack([my, mz]), "theta": th, "temp": temp}


@pytest.fixture(scope="session")
def platform():
    """The :func:`make_platform` factory."""
    return make_platform


def block_context(
    t, y, use, block, cols, n_blocks: int, aux: dict, *, extra=None, chan=None, names=()
):
    """A closure :class:`~accal.closure.candidates.Context` of ``y`` on a per-block base
    (``cols`` on the samples of each ``block``, ``extra`` dense columns beside them),
    fitted on the ``use`` samples; ``chan``/``names``: several data channels."""
    from accal.closure.basis import Basis
    from accal.closure.candidates import Context
    from accal.closure.residual import make_grid

    basis = Basis(block[use], cols[use], None if extra is None else extra[use], n_blocks)
    grid = make_grid(t[use], None if chan is None else chan[use])
    return Context(
        t_all=t,
        use=use,
        t0=float(t[use][0]),
        span=float(np.ptp(t[use])),
        grid=grid,
        residual=basis.fit(y[use]).resid,
        basis=basis,
        leverage=basis.leverage(grid),
        labels=frozenset(),
        aux=aux,
        orbit_period=None,
        channel_all=chan,
        channel_names=tuple(names),
    )


#: Start of the white-noise days [s] (GPS seconds of 2023-06-15).
WHITE_T0 = 740059202.0


def white_noise_day(seed: int, n: int = 86400) -> tuple[np.ndarray, np.ndarray]:
    """``(t, y)``: one day at 1 Hz of a 1e-6 m/s² bias, a 1e-12 m/s²/s drift and white
    noise of 1e-10 m/s² per sample, nothing else (drawn here with numpy)."""
    t = WHITE_T0 + np.arange(n, dtype=float)
    y = 1e-6 + 1e-12 * (t - WHITE_T0) + np.random.default_rng(seed).normal(0.0, 1e-10, n)
    return t, y


@pytest.fixture(scope="session")
def white_day():
    """The :func:`white_noise_day` factory."""
    return white_noise_day


def close_white(t, y, candidates):
    """:func:`accal.closure.close_loop` of a white-noise day with the orbit template in
    the null model (no reference; the period held at 5600 s)."""
    from accal.closure import close_loop

    return close_loop(t, y, orbit_period=5600.0, candidates=tuple(candidates),
                      options={"orbit_period_fixed": True})  # fmt: skip


@pytest.fixture(scope="session")
def close_white_day():
    """The :func:`close_white` runner."""
    return close_white
