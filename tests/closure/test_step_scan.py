"""The multiplicity of the bias-step scan (candidates.scan_multiplicity).

With a per-period base every period is a change-point scan of its own; a day of
demodulation periods is ~10⁴ tests.  The factor comes from Siegmund's
approximation; here it is checked against a simulated scan, and the clean
rotating-platform day that used to report a false step is checked to report none.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from accal.closure.candidates import scan_multiplicity


def _scan_max(rng, n_rep: int, n_blocks: int, length: int, k: int) -> np.ndarray:
    """Largest standardized step statistic (χ²_k) over every epoch of every block.

    White noise, an affine base per block (as the demodulation's per-period bias).
    """
    u = np.arange(length, dtype=float)
    q, _ = np.linalg.qr(np.column_stack([np.ones(length), u - u.mean()]))
    h = (u[:, None] >= np.arange(1, length)[None, :]).astype(float)
    h -= q @ (q.T @ h)
    h /= np.sqrt((h**2).sum(axis=0))
    out = np.empty(n_rep)
    for i in range(n_rep):
        e = rng.standard_normal((k, n_blocks, length))
        e -= (e @ q) @ q.T
        out[i] = ((e @ h) ** 2).sum(axis=0).max()
    return out


@pytest.mark.parametrize("k", [1, 2])
def test_scan_multiplicity_is_conservative_but_not_by_much(k):
    n_blocks, length, level = 20, 120, 0.05
    m = scan_multiplicity(np.full(n_blocks, 1.0 / length), k, level)
    # the per-epoch threshold the factor implies: p * m = level
    x2 = stats.chi2.isf(level / m, k)
    mx = _scan_max(np.random.default_rng(7), 3000, n_blocks, length, k)
    rate = float(np.mean(mx > x2))
    # measured: 0.032 (k=1), 0.031 (k=2) for a nominal 0.05
    assert level / 2.5 < rate < level * 1.15
    # a single test at the same threshold would be far too liberal
    assert stats.chi2.sf(x2, k) < level / 500


def test_scan_multiplicity_grows_with_blocks_and_keeps_one_scan_small():
    one = scan_multiplicity(np.array([0.02]), 1, 0.01 / 6)
    day = scan_multiplicity(np.full(144, 1.0 / 390), 2, 0.01 / 6)
    # one record-long scan (GRACE day, epochs 2 % from the ends): below the default
    # 200 the step builder keeps; 144 demodulation periods: ~2.8e4
    assert 30 < one < 200
    assert 2e4 < day < 4e4
    assert scan_multiplicity(np.full(288, 1.0 / 390), 2, 0.01 / 6) > 1.9 * day
    assert scan_multiplicity(np.array([]), 1, 0.01) == 1.0


def test_clean_demod_day_reports_no_step(tmp_path):
    """Seed 22: a clean simulated day where a 7e-11 m/s² 'step' (5σ) used to pass.

    The per-epoch p was 2.7e-6; against the old 200 tests that passed, against the
    scan's ~2.8e4 it does not.
    """
    import pandas as pd

    from accal.closure.demod import close_loop_demod
    from accal.pipeline_demod import write_simulated_gap

    p = tmp_path / "run.parquet"
    write_simulated_gap(p, days=1.0, tau=600.0, mask=200.0, seed=22)
    df = pd.read_parquet(p)
    m = (df["m_y"].to_numpy(), df["m_z"].to_numpy())
    res, _ = close_loop_demod(df["time"].to_numpy(), m, df["theta"].to_numpy(), tau=600.0)
    assert [e.name for e in res.effects] == []
