"""A noise whose level changes within a demod run (issue 20; ``level_factors``).

The run is drawn by ``tests.indep`` (no accal code): a constant signal, white noise
of 1e-11 m/s² per sample, and 3 times that in the run's first half (added here).  The
PSD behind σ is the run's average: a QA helper's such runs had per-period z std 1.33
in the noisy half (|z| > 3 on 2.6 %) and 0.45 in the quiet one, with nothing said.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
from click.testing import CliRunner
from tests.indep import platform_run, write_platform_run

from accal.cli import main


def _z_by_half(run, out):
    periods = pd.read_parquet(out / "periods.parquet").merge(
        run.periods, on="period", suffixes=("", "_true")
    )
    first = (periods["t_start_true"] < np.median(periods["t_start_true"])).to_numpy()
    zs = []
    for half in (first, ~first):
        z = [
            (periods[f"a_{ax}"] - periods[f"a_{ax}_rest"]).to_numpy()[half]
            / periods[f"sigma_{ax}"].to_numpy()[half]
            for ax in "YZ"
        ]
        zs.append(np.concatenate(z))
    return zs


def _demod(path, out):
    args = ["demod", str(path), "--tau", "600", "--mask", "200", "--out", str(out)]
    res = CliRunner().invoke(main, args, catch_exceptions=False)
    assert res.exit_code == 0, res.output
    return res.output


def test_sigma_follows_a_noise_level_that_changes_within_the_run(tmp_path):
    run = platform_run(5, days=1.0, noise_psd=1e-11, signal="constant")
    table = run.table.copy()
    rng = np.random.default_rng(55)
    first = (table["time"] < table["time"].median()).to_numpy()
    for col in ("m_y", "m_z"):  # total variance 9x: 3x the noise in the first half
        table.loc[first, col] += np.sqrt(8.0) * 1e-11 * rng.standard_normal(first.sum())
    path = tmp_path / "run.parquet"
    table.to_parquet(path, index=False)
    msg = _demod(path, tmp_path / "out")
    assert "the noise level near 2/tau changes over the run" in msg
    noisy, quiet = _z_by_half(run, tmp_path / "out")
    # measured: 1.01 and 1.04 (1.34 and 0.46 with the run's average level)
    assert 0.8 < noisy.std() < 1.25 and 0.8 < quiet.std() < 1.25, (noisy.std(), quiet.std())
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())["noise"]
    assert summary["level_scaled"] and summary["level_spread"] > 4


def test_a_stationary_run_is_not_scaled(tmp_path):
    run = platform_run(6, days=1.0, noise_psd=1e-11, signal="constant")
    path = write_platform_run(run, tmp_path / "run.parquet")
    msg = _demod(path, tmp_path / "out")
    assert "changes over the run" not in msg
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())["noise"]
    assert not summary["level_scaled"] and summary["level_spread"] < 2
