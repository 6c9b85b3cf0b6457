"""Every CSV accal writes opens with ``pandas.read_csv`` defaults; units are in a sidecar.

Issue 21: the ``# units:`` comment lines garbled ``pd.read_csv("bias_drift.csv")`` into a
(33, 36) frame.  The units and metadata now live in ``<file>-metadata.json`` (a CSV on
the Web metadata document); accal reads both that and the comment lines of older files.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
from click.testing import CliRunner
from tests.indep import platform_run

from accal.cli import main
from accal.io import read
from accal.io.writers import read_table_metadata

SAMPLES = Path(__file__).resolve().parents[1] / "data" / "samples"


def _invoke(*args) -> None:
    res = CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)
    assert res.exit_code == 0, res.output


def _check_csvs(out: Path) -> set[str]:
    names = set()
    for csv in sorted(out.glob("*.csv")):
        df = pd.read_csv(csv)  # no options
        header = csv.read_text().splitlines()[0]
        assert list(df.columns) == [c.strip('"') for c in header.split(",")]
        assert len(df) > 0 and not any(str(c).startswith("#") for c in df.columns)
        side = json.loads(csv.with_name(csv.name + "-metadata.json").read_text())
        assert side["url"] == csv.name
        assert [c["name"] for c in side["tableSchema"]["columns"]] == list(df.columns)
        units, _ = read_table_metadata(csv)
        assert units and set(units) <= set(df.columns)
        names.add(csv.name)
    return names


def test_grace_bias_and_demod_csvs_open_with_pandas_defaults(tmp_path):
    out = tmp_path / "g"
    _invoke("grace-bias", SAMPLES / "ACC1B_2003-09-14_A_00.asc", "--format", "csv", "--out", out,
            "-q", "--method", "both")  # fmt: skip
    assert _check_csvs(out) == {"bias_drift.csv", "ACC1B_2003-09-14_A_00.calibrated.csv"}
    tab = pd.read_csv(out / "bias_drift.csv")
    assert set(tab["axis"]) == {"x", "y", "z"} and tab["bias"].notna().all()
    # accal reads its own CSV back with the units (the calibrated series as an input)
    series = read(out / "ACC1B_2003-09-14_A_00.calibrated.csv")
    assert len(series) == len(pd.read_csv(out / "ACC1B_2003-09-14_A_00.calibrated.csv"))

    run = platform_run(1, days=0.05)
    src = tmp_path / "run.parquet"
    run.table.to_parquet(src)
    dout = tmp_path / "d"
    _invoke("demod", src, "--tau", 600, "--mask", 200, "--format", "csv", "--out", dout, "-q")
    assert "periods.csv" in _check_csvs(dout)
    per = pd.read_csv(dout / "periods.csv")
    assert np.isfinite(per["a_Y"]).all()


def test_older_csvs_with_comment_lines_still_read(tmp_path):
    p = tmp_path / "old.csv"
    p.write_text('# units: {"gps_time": "s", "lin_accl_x": "m/s^2"}\n# meta: {"k": 1}\n'
                 "gps_time,lin_accl_x\n1,2e-7\n2,3e-7\n")  # fmt: skip
    assert read_table_metadata(p) == ({"gps_time": "s", "lin_accl_x": "m/s^2"}, {"k": 1})
