"""``accal plot DIRECTORY``: the bias and drift of an archive over time (issue 21)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from accal.cli import main
from accal.errors import AccalError
from accal.plot_style import accel_scale
from accal.products.archive_plot import (
    BIAS_SCALE,
    DRIFT_SCALE,
    bias_drift_figure,
    periods_figure,
)

SAMPLES = Path(__file__).resolve().parents[1] / "data" / "samples"
INPUTS = [
    SAMPLES / "ACC1B_2003-09-14_A_00.asc",
    SAMPLES / "ACC1B_2003-09-14_B_00.asc",
    SAMPLES / "ACT1B_2023-06-01_C_04.txt",
]


def _run(*args):
    res = CliRunner().invoke(main, [str(a) for a in args])
    return res.exit_code, res.output


@pytest.fixture(scope="module")
def archive(tmp_path_factory):
    out = tmp_path_factory.mktemp("plot") / "out"
    code, msg = _run("grace-bias", *INPUTS, "--method", "both", "--out", out, "-q")
    assert code == 0, msg
    return out


def test_plot_writes_a_png_of_the_table(archive, tmp_path):
    code, msg = _run("plot", archive)
    assert code == 0, msg
    png = archive / "bias_drift.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert f"wrote {png} (18 rows)" in msg  # 3 files x 3 axes x 2 methods
    target = tmp_path / "sel.png"
    code, msg = _run("plot", archive, "--satellite", "C", "--axis", "y", "--out", target)
    assert code == 0 and target.exists() and "(2 rows)" in msg, msg
    assert not [p for p in archive.iterdir() if ".tmp" in p.name]


def test_the_figure_shows_the_table_values_in_readable_units(archive):
    table = pd.read_parquet(archive / "bias_drift.parquet")
    fig = bias_drift_figure(table, source="t")
    panels = np.array(fig.axes).reshape(3, 2)
    for i, axis in enumerate("xyz"):
        for j, (col, (factor, unit)) in enumerate((("bias", BIAS_SCALE), ("drift", DRIFT_SCALE))):
            ax = panels[i, j]
            assert ax.get_ylabel() == f"{col} {axis} [{unit}]"
            shown = sorted(float(y) for c in ax.containers for y in c.lines[0].get_ydata())
            want = sorted(table.loc[table["axis"] == axis, col].to_numpy() * factor)
            np.testing.assert_allclose(shown, want, rtol=1e-12)
    assert unit == "nm/s² per day" and factor == 1e9 * 86400.0


def test_plot_errors_are_one_line(archive, tmp_path):
    code, msg = _run("plot", archive, "--satellite", "Q")
    assert code == 2 and "--satellite 'Q' is not in" in msg
    code, msg = _run("plot", archive, "--start", "2030-01-01", "--out", tmp_path / "n.png")
    assert code == 1 and "no row to plot" in msg and not (tmp_path / "n.png").exists()
    empty = tmp_path / "empty"
    empty.mkdir()
    code, msg = _run("plot", empty)
    assert code == 1 and len(msg.strip().splitlines()) == 1, msg
    with pytest.raises(AccalError, match="series in one figure"):
        many = pd.DataFrame(
            {"satellite": [f"S{i}" for i in range(13)], "method": "lsq", "date": "2003-09-14",
             "axis": "x", "bias": 0.0, "bias_sigma": 1.0, "drift": 0.0, "drift_sigma": 1.0}
        )  # fmt: skip
        bias_drift_figure(many, source="t")


def test_plot_out_is_a_png_in_an_existing_directory(archive, tmp_path):
    """QA (2026-11-30): ``--out notes.txt`` replaced a user's file with a PNG, and
    ``--out /nonexist/x.png`` created /nonexist."""
    notes = tmp_path / "notes.txt"
    notes.write_text("mine")
    code, msg = _run("plot", archive, "--out", notes)
    assert code == 2 and "give a file name ending in .png" in msg
    assert notes.read_text() == "mine"
    code, msg = _run("plot", archive, "--out", tmp_path / "nonexist" / "x.png")
    assert code == 2 and "does not exist" in msg and not (tmp_path / "nonexist").exists()
    code, msg = _run("plot", archive, "--out", tmp_path / "ok.PNG")
    assert code == 0 and (tmp_path / "ok.PNG").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_one_day_is_plotted_over_a_week_not_years(archive):
    table = pd.read_parquet(archive / "bias_drift.parquet")
    one = table[table["date"] == table["date"].iloc[0]]
    fig = bias_drift_figure(one, source="t")
    lo, hi = fig.axes[0].get_xlim()
    assert 5.9 < hi - lo < 6.1  # days (matplotlib date units)


@pytest.fixture(scope="module")
def demod_dir(tmp_path_factory):
    base = tmp_path_factory.mktemp("plotdemod")
    runs = []
    for seed in (1, 2):
        run = base / f"run{seed}.parquet"
        code, msg = _run("simulate", "gap", "--days", "0.1", "--seed", seed, "--out", run)
        assert code == 0, msg
        runs.append(run)
    out = base / "out"
    code, msg = _run("demod", *runs, "--tau", 600, "--mask", 200, "--out", out, "-j", 1, "-q")
    assert code == 0, msg
    return out


def test_plot_of_a_demod_directory_shows_its_periods(demod_dir, tmp_path):
    """accal plot on an accal demod directory plots a_Y, a_Z per period (QA: it said
    'no bias_drift.parquet here' although accal table shows the periods)."""
    code, msg = _run("plot", demod_dir)
    assert code == 0, msg
    png = demod_dir / "periods.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    table = pd.read_parquet(demod_dir / "periods.parquet")
    assert f"wrote {png} ({len(table)} periods)" in msg
    code, msg = _run("plot", demod_dir, "--satellite", "A", "--out", tmp_path / "x.png")
    assert code == 2 and "periods table of accal demod" in msg
    assert not (tmp_path / "x.png").exists()


def test_the_periods_figure_shows_the_table_values(demod_dir):
    table = pd.read_parquet(demod_dir / "periods.parquet")
    table["t_mid_utc"] = pd.to_datetime(table["t_mid_utc"], utc=True)
    fig = periods_figure(table, source="t")
    factor, unit = accel_scale(table[["a_Y", "a_Z"]].to_numpy())
    assert 1.0 <= np.nanmax(np.abs(table[["a_Y", "a_Z"]].to_numpy())) * factor < 1000.0
    for ax, comp in zip(fig.axes[:2], ("Y", "Z"), strict=True):
        assert ax.get_ylabel() == f"a_{comp} [{unit}]"
        shown = sorted(float(y) for c in ax.containers for y in c.lines[0].get_ydata())
        np.testing.assert_allclose(shown, sorted(table[f"a_{comp}"] * factor), rtol=1e-12)
    assert accel_scale(np.array([3e-13, np.nan])) == (1e12, "pm/s²")
    assert accel_scale(np.array([2.0])) == (1.0, "m/s²")
