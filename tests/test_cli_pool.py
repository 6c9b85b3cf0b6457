"""``accal grace-bias --pool-days``: σ from a noise model fitted to adjacent days.

Days of white + random-walk noise drawn here (a table per day, 10 s samples), not by
accal's simulator.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from accal.cli import main
from accal.pipeline import read_bias_drift

N = 4320  # 12 h at 10 s


def _day(path, day: int, rng) -> None:
    t = pd.date_range(f"2024-05-{10 + day:02d}", periods=N, freq="10s")
    e = 1e-10 * rng.standard_normal((N, 2)) + 5e-12 * np.cumsum(rng.standard_normal((N, 2)), 0)
    pd.DataFrame(
        {"time_utc": t.strftime("%Y-%m-%dT%H:%M:%S"), "ax": e[:, 0] + 2e-7, "ay": e[:, 1]}
    ).to_csv(path, index=False)


def _run(*args) -> tuple[int, str]:
    res = CliRunner().invoke(main, ["grace-bias", *map(str, args)], catch_exceptions=False)
    return res.exit_code, res.output


@pytest.fixture
def days(tmp_path):
    rng = np.random.default_rng(3)
    paths = []
    for d in range(5):
        _day(tmp_path / f"day{d}.csv", d, rng)
        paths.append(tmp_path / f"day{d}.csv")
    return paths


COLS = ("--column", "x=ax", "--column", "y=ay", "-j", "1", "-q", "--method", "both")


def test_pooled_sigmas_in_the_table_and_a_later_day_pools_with_earlier_ones(days, tmp_path):
    out = tmp_path / "o"
    code, msg = _run(*days[:4], *COLS, "--pool-days", "4", "--out", out)
    assert code == 0, msg
    tab = read_bias_drift(out / "bias_drift.parquet")
    assert len(tab) == 16
    assert tab["sigma_model"].str.startswith("pooled: white + ").all()
    assert (tab["sigma_days"] == 4).all()
    assert sorted(p.name for p in out.glob("*.noise.npz")) == [
        f"day{d}.noise.npz" for d in range(4)
    ]
    # each report keeps the day's own estimate; the table's differ (red noise: larger)
    rep = json.loads((out / "day0.report.json").read_text())
    own = {(f["axis"], f["method"]): f["drift_sigma"] for f in rep["fits"]}
    row = tab[(tab.source == "day0.csv")].set_index(["axis", "method"])["drift_sigma"]
    assert all(row[k] > 1.2 * v for k, v in own.items())
    # a cron run with the next day alone pools it with the days before
    code, msg = _run(days[4], *COLS, "--pool-days", "4", "--out", out)
    assert code == 0, msg
    tab2 = read_bias_drift(out / "bias_drift.parquet")
    assert len(tab2) == 20 and (tab2["sigma_days"] == 4).all()
    assert "pooled sigmas (--pool-days 4): 20 of 20 rows" in (out / "accal.log").read_text()
    # a day alone has no neighbours: its own σ, said so
    solo = tmp_path / "solo"
    code, _ = _run(days[0], *COLS, "--pool-days", "4", "--out", solo)
    assert code == 0
    one = read_bias_drift(solo / "bias_drift.parquet")
    assert (one["sigma_model"] == "day").all() and (one["sigma_days"] == 1).all()
    back = one.set_index(["axis", "method"])["drift_sigma"]
    assert all(back[k] == pytest.approx(v, rel=1e-12) for k, v in own.items())


def test_without_pool_days_the_table_says_day_and_no_spectra_are_written(days, tmp_path):
    out = tmp_path / "o"
    code, _ = _run(*days[:2], *COLS, "--out", out)
    assert code == 0
    tab = read_bias_drift(out / "bias_drift.parquet")
    assert (tab["sigma_model"] == "day").all() and not list(out.glob("*.noise.npz"))


def test_pool_days_one_is_a_usage_error(days, tmp_path):
    code, msg = _run(days[0], *COLS, "--pool-days", "1", "--out", tmp_path / "o")
    assert code == 2 and "pool_days must be 0 (off) or >= 2" in msg


def test_a_day_unlike_its_pool_keeps_its_own_sigma(tmp_path):
    """QA (2026-11-30): a day with a large slow bump got its neighbours' pooled σ (2.1e-11
    for its own 6.0e-11 m/s², |z| 7.8).  A day whose spectrum the pool's model does not
    describe keeps its own σ, and the table says why; the other days pool."""
    rng = np.random.default_rng(11)
    paths = []
    for d in range(8):
        t = pd.date_range(f"2024-05-{10 + d:02d}", periods=N, freq="10s")
        e = 1e-10 * rng.standard_normal((N, 2))
        if d == 3:  # a slow bump of 3e-10 m/s² over ~10 min
            e += 3e-10 * np.exp(-0.5 * ((np.arange(N) - 1500) / 30.0) ** 2)[:, None]
        p = tmp_path / f"day{d}.csv"
        pd.DataFrame(
            {"time_utc": t.strftime("%Y-%m-%dT%H:%M:%S"), "ax": e[:, 0] + 2e-7, "ay": e[:, 1]}
        ).to_csv(p, index=False)
        paths.append(p)
    out = tmp_path / "o"
    code, msg = _run(*paths, *COLS, "--pool-days", "8", "--out", out)
    assert code == 0, msg
    tab = read_bias_drift(out / "bias_drift.parquet")
    odd = tab["source"] == "day3.csv"
    assert tab.loc[odd, "sigma_model"].str.startswith("day (not pooled: this day's spectrum").all()
    assert tab.loc[~odd, "sigma_model"].str.startswith("pooled: ").all()
    # its σ is its own (the report's), larger than its neighbours' pooled ones
    rep = json.loads((out / "day3.report.json").read_text())
    own = {(f["axis"], f["method"]): f["bias_sigma"] for f in rep["fits"]}
    row = tab[odd].set_index(["axis", "method"])["bias_sigma"]
    assert all(row[k] == pytest.approx(v, rel=1e-12) for k, v in own.items())
    assert row.min() > tab.loc[~odd, "bias_sigma"].max()
