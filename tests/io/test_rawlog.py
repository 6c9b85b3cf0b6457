"""Reader of rotating-platform run files (Parquet / CSV / CSV.gz) and PSD tables."""

from __future__ import annotations

import gzip

import numpy as np
import pandas as pd
import pytest

from accal.errors import FormatError
from accal.io.rawlog import read_psd, read_rawlog
from accal.io.writers import write_table

CSV = """# units: {"theta": "rad", "temperature": "K"}
time,m_y,m_z,theta,temperature
0,1e-6,2e-6,0,293.1
1,1.5e-6,2.5e-6,0,293.2
2,1e-6,2e-6,3.141592653589793,293.3
3,0.5e-6,1e-6,3.141592653589793,293.4
"""


def test_csv_by_hand(tmp_path):
    p = tmp_path / "run.csv"
    p.write_text(CSV)
    s = read_rawlog(p)
    np.testing.assert_array_equal(s.time, [0, 1, 2, 3])
    assert s.axes == ("y", "z")
    np.testing.assert_array_equal(s.axis("y"), [1e-6, 1.5e-6, 1e-6, 0.5e-6])
    np.testing.assert_array_equal(s.axis("z"), [2e-6, 2.5e-6, 2e-6, 1e-6])
    np.testing.assert_array_equal(s.aux["theta"], [0, 0, np.pi, np.pi])
    np.testing.assert_array_equal(s.aux["temperature"], [293.1, 293.2, 293.3, 293.4])
    assert s.units["theta"] == "rad" and s.units["temperature"] == "K"
    assert s.frame == "platform"


def test_gzip_and_parquet_with_m_x(tmp_path):
    p = tmp_path / "run.csv.gz"
    p.write_bytes(gzip.compress(CSV.encode()))
    assert read_rawlog(p).aux["temperature"][2] == 293.3
    df = pd.DataFrame(
        {
            "time": [0.0, 0.5],
            "m_x": [1.0, 2.0],
            "m_y": [3.0, 4.0],
            "m_z": [5.0, 6.0],
            "theta": [0, 0],
        }
    )
    q = write_table(df, tmp_path / "run.parquet", units={"m_y": "m/s^2", "theta": "rad"})
    s = read_rawlog(q)
    assert s.axes == ("x", "y", "z")
    np.testing.assert_array_equal(s.acc, [[1, 3, 5], [2, 4, 6]])
    assert set(s.aux) == {"theta"}


def test_missing_columns_listed(tmp_path):
    p = tmp_path / "bad.csv"
    p.write_text("time,m_y,angle\n0,1,0\n")
    with pytest.raises(FormatError, match=r"bad\.csv: missing column\(s\) m_z, theta"):
        read_rawlog(p)


def test_time_not_increasing_names_line(tmp_path):
    p = tmp_path / "back.csv"
    p.write_text(CSV.replace("\n2,1e-6", "\n0.5,1e-6"))
    with pytest.raises(FormatError, match=r"back\.csv:5: time is not strictly increasing"):
        read_rawlog(p)


def test_theta_declared_in_degrees(tmp_path):
    p = tmp_path / "deg.csv"
    p.write_text(CSV.replace('"theta": "rad"', '"theta": "deg"'))
    with pytest.raises(FormatError, match="theta is declared in 'deg'; give it in radians"):
        read_rawlog(p)


def test_non_numeric_and_missing_file(tmp_path):
    p = tmp_path / "txt.csv"
    p.write_text("time,m_y,m_z,theta\n0,a,1,0\n1,b,1,0\n")
    with pytest.raises(FormatError, match="column 'm_y' is not numeric"):
        read_rawlog(p)
    with pytest.raises(FormatError, match="nope.csv: no such file"):
        read_rawlog(tmp_path / "nope.csv")


def test_psd_table(tmp_path):
    p = tmp_path / "psd.csv"
    p.write_text("f,S\n1e-4,1e-18\n1,1e-20\n")
    f, s = read_psd(p)
    np.testing.assert_array_equal(f, [1e-4, 1])
    np.testing.assert_array_equal(s, [1e-18, 1e-20])
    p.write_text("freq,S\n1,2\n")
    with pytest.raises(FormatError, match=r"psd\.csv: PSD table: missing column\(s\) f"):
        read_psd(p)
