"""``accal plot DIRECTORY``: the bias and drift of an archive over time (issue 21)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from accal.cli import main
from accal.errors import AccalError
from accal.products.archive_plot import BIAS_SCALE, DRIFT_SCALE, bias_drift_figure

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
