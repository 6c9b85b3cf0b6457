"""Reader of rotating-platform run files (Parquet / CSV / CSV.gz) and PSD tables."""

from __future__ import annotations

import gzip
import re

import numpy as np
import pandas as pd
import pytest

from accal.errors import FormatError
from accal.io.rawlog import open_rawlog, read_psd, read_rawlog
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


def test_theta_declared_in_degrees_is_converted(tmp_path):
    p = tmp_path / "deg.csv"
    p.write_text(
        CSV.replace('"theta": "rad"', '"theta": "deg"').replace("3.141592653589793", "180")
    )
    s = read_rawlog(p)
    np.testing.assert_allclose(s.aux["theta"], [0, 0, np.pi, np.pi], rtol=1e-15)
    assert s.units["theta"] == "rad"
    assert any("theta from 'deg' (× 0.01745329252)" in w for w in s.report.warnings)


@pytest.mark.parametrize(
    ("unit", "factor"),
    [
        ("g", 9.80665),
        ("mg", 9.80665e-3),
        ("um/s^2", 1e-6),
        ("µm/s²", 1e-6),
        ("nm s^-2", 1e-9),
        ("mGal", 1e-5),
        ("milli-g", 9.80665e-3),
        ("milligal", 1e-5),
        ("m/s^2", 1.0),
        ("m s-2 (raw)", 1.0),
    ],
)
def test_declared_acceleration_units_are_converted(tmp_path, unit, factor):
    """QA: m_y in g was read as m/s² (9.8× wrong, no warning); um/s² gave 0.46 "m/s²"."""
    p = tmp_path / "run.csv"
    p.write_text(CSV.replace('"theta": "rad"', f'"theta": "rad", "m_y": "{unit}", "m_z": "{unit}"'))
    s = read_rawlog(p)
    np.testing.assert_allclose(s.axis("y"), factor * np.array([1e-6, 1.5e-6, 1e-6, 0.5e-6]))
    np.testing.assert_allclose(s.axis("z"), factor * np.array([2e-6, 2.5e-6, 2e-6, 1e-6]))
    said = [w for w in s.report.warnings if "converted to SI" in w]
    assert bool(said) == (factor != 1.0)


@pytest.mark.parametrize(("unit", "factor"), [("ms", 1e-3), ("min", 60.0), ("s (GPS)", 1.0)])
def test_declared_time_units_are_converted(tmp_path, unit, factor):
    p = tmp_path / "run.csv"
    p.write_text(CSV.replace('"theta": "rad"', f'"theta": "rad", "time": "{unit}"'))
    np.testing.assert_allclose(read_rawlog(p).time, factor * np.arange(4.0))


@pytest.mark.parametrize(
    ("col", "unit"),
    [
        ("m_y", "V"),
        ("theta", "turns"),
        ("time", "m"),
        ("m_y", "Mm/s^2"),
        ("time", "Ms"),
        ("theta", "Mrad"),
        ("m_y", "MG"),
    ],
)
def test_unknown_declared_unit_is_refused(tmp_path, col, unit):
    p = tmp_path / "run.csv"
    p.write_text(CSV.replace('"theta": "rad"', f'"theta": "rad", "{col}": "{unit}"'))
    with pytest.raises(
        FormatError, match=rf"run\.csv: {col} is declared in '{re.escape(unit)}', not a unit"
    ):
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


# --- streamed reading (open_rawlog) ------------------------------------------


def _concat(stream):
    chunks = list(stream)
    return chunks, {
        "time": np.concatenate([c.time for c in chunks]),
        "acc": np.concatenate([c.acc for c in chunks]),
        "theta": np.concatenate([c.theta for c in chunks]),
        "temperature": np.concatenate([c.aux["temperature"] for c in chunks]),
    }


@pytest.mark.parametrize("kind", ["csv", "csv.gz", "parquet"])
def test_stream_equals_whole_file(tmp_path, kind):
    rng = np.random.default_rng(0)
    n = 103
    df = pd.DataFrame(
        {
            "time": np.arange(n) * 0.5,
            "m_y": rng.normal(size=n),
            "m_z": rng.normal(size=n),
            "theta": np.where(np.arange(n) % 20 < 10, 0.0, np.pi),
            "temperature": 293.0 + rng.normal(size=n),
        }
    )
    p = tmp_path / f"run.{kind}"
    if kind == "csv.gz":
        write_table(df, tmp_path / "run.csv", units={"theta": "rad", "temperature": "K"})
        p.write_bytes(gzip.compress((tmp_path / "run.csv").read_bytes()))
    else:
        write_table(df, p, units={"theta": "rad", "temperature": "K"})
    whole = read_rawlog(p)
    stream = open_rawlog(p, rows=10)
    assert stream.axes == ("y", "z") and stream.units["temperature"] == "K"
    chunks, cat = _concat(stream)
    assert [c.first_row for c in chunks] == list(range(0, n, 10))
    assert max(len(c) for c in chunks) == 10
    np.testing.assert_array_equal(cat["time"], whole.time)
    np.testing.assert_array_equal(cat["acc"], whole.acc)
    np.testing.assert_array_equal(cat["theta"], whole.aux["theta"])
    np.testing.assert_array_equal(cat["temperature"], whole.aux["temperature"])
    # a stream can be read again (each pass re-opens the file)
    np.testing.assert_array_equal(_concat(stream)[1]["time"], whole.time)


def test_stream_csv_types_fixed_on_first_chunk(tmp_path):
    """An integer column in the first chunk may hold decimals later (read as float)."""
    p = tmp_path / "int.csv"
    p.write_text("time,m_y,m_z,theta,heater\n0,1,2,0,1\n1,1,2,0,2\n2,1,2,3.14,2.5\n3,1,2,3.14,x\n")
    chunks = []
    with pytest.raises(
        FormatError,
        match=r"int\.csv:5: CSV: column 'heater': invalid value 'x' \(expected double\)",
    ):
        for c in open_rawlog(p, rows=2):
            chunks.append(c)
    assert [c.aux["heater"].tolist() for c in chunks] == [[1.0, 2.0]]
    p.write_text(p.read_text().replace(",x\n", ",3\n"))
    heater = np.concatenate([c.aux["heater"] for c in open_rawlog(p, rows=2)])
    np.testing.assert_array_equal(heater, [1, 2, 2.5, 3])


def test_stream_time_checked_across_chunks(tmp_path):
    p = tmp_path / "back.csv"
    p.write_text(CSV.replace("\n2,1e-6", "\n0.5,1e-6"))
    with pytest.raises(FormatError, match=r"back\.csv:5: time is not strictly increasing"):
        list(open_rawlog(p, rows=2))  # the bad step is the first row of the second chunk
    p.write_text(CSV.rstrip("\n"))  # no final newline, last row complete: read
    assert _concat(open_rawlog(p, rows=3))[1]["time"].tolist() == read_rawlog(p).time.tolist()
    assert len(read_rawlog(p)) == 4
    p.write_text(CSV.rstrip("\n").rsplit(",", 1)[0])  # cut: a field short
    with pytest.raises(FormatError, match=r":6: truncated last line"):
        list(open_rawlog(p, rows=3))


def test_stream_header_checks_on_open(tmp_path):
    p = tmp_path / "bad.csv"
    p.write_text("time,m_y,angle\n0,1,0\n")
    with pytest.raises(FormatError, match=r"missing column\(s\) m_z, theta"):
        open_rawlog(p, rows=5)
    p.write_text(CSV.replace('"theta": "rad"', '"theta": "cycles"'))
    with pytest.raises(FormatError, match="theta is declared in 'cycles', not a unit of angle"):
        open_rawlog(p, rows=5)
    p.write_text("time,m_y,m_z,theta\n")
    with pytest.raises(FormatError, match="header but no data rows"):
        list(open_rawlog(p, rows=5))
    with pytest.raises(FormatError, match="no such file"):
        open_rawlog(tmp_path / "nope.parquet")


@pytest.mark.parametrize("rows", [None, 7])  # whole file, and streamed in 7-row chunks
def test_non_numeric_value_names_its_line_or_row(tmp_path, rows):
    lines = [f"{k},{1e-7 * k},1e-7,0.5" for k in range(20)]
    lines[12] = "12,oops,1e-7,0.5"
    csv = tmp_path / "t.csv"
    csv.write_text("time,m_y,m_z,theta\n" + "\n".join(lines) + "\n")
    with pytest.raises(FormatError, match=r"t\.csv:14: .*'m_y'.*'oops'"):
        list(open_rawlog(csv, rows=rows)) if rows else read_rawlog(csv)
    df = pd.DataFrame([ln.split(",") for ln in lines], columns=["time", "m_y", "m_z", "theta"])
    pq_path = tmp_path / "t.parquet"
    df.astype({"time": float, "m_z": float, "theta": float}).to_parquet(pq_path)
    with pytest.raises(FormatError, match=r"row 13: column 'm_y' is not numeric.*'oops'"):
        read_rawlog(pq_path)


def _parquet_with_time(tmp_path, time) -> object:
    n = len(time)
    df = pd.DataFrame({"time": time, "m_y": np.zeros(n), "m_z": np.zeros(n), "theta": np.zeros(n)})
    p = tmp_path / "t.parquet"
    df.to_parquet(p)
    return p


@pytest.mark.parametrize("rows", [None, 7, 12])  # whole file, chunks of 7 and of 12 rows
@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({12: np.nan}, r"row 13: time: missing or non-finite value"),
        ({12: 11.0}, r"row 13: time is not strictly increasing: 11 s after 11 s"),
        ({12: 10.5}, r"row 13: time is not strictly increasing: 10\.5 s after 11 s"),
    ],
    ids=["nan", "duplicate", "backwards"],
)
def test_parquet_time_errors_name_the_row(tmp_path, rows, change, message):
    """CSV messages give the line; Parquet ones gave nothing to find the bad time by."""
    t = np.arange(20.0)
    for i, v in change.items():
        t[i] = v
    p = _parquet_with_time(tmp_path, t)
    with pytest.raises(FormatError, match=rf"t\.parquet: {message}"):
        list(open_rawlog(p, rows=rows)) if rows else read_rawlog(p)


@pytest.mark.parametrize("rows", [None, 2])
def test_content_that_does_not_match_the_name_is_a_warning(tmp_path, rows):
    """A text file named .parquet is read as CSV (the content decides), with a warning."""
    text = tmp_path / "run.parquet"
    text.write_text(CSV)
    stream = open_rawlog(text, rows=rows)
    assert stream.warnings == ["named .parquet but is text: read as CSV"]
    list(stream)  # a pass keeps it
    assert stream.warnings == ["named .parquet but is text: read as CSV"]
    assert read_rawlog(text).report.warnings == ("named .parquet but is text: read as CSV",)
    binary = tmp_path / "run.csv"
    write_table(pd.read_csv(tmp_path / "run.parquet", comment="#"), binary, fmt="parquet")
    assert open_rawlog(binary, rows=rows).warnings == ["named .csv but is Parquet: read as Parquet"]
    right = tmp_path / "ok.csv"
    right.write_text(CSV)
    assert open_rawlog(right, rows=rows).warnings == []


def test_an_absurd_acceleration_is_damage_with_its_line(tmp_path):
    """QA: m_y = 1e300 in a run was demodulated into a mean a_Y of -1.8e296 '± 1e-12'
    (exit 0, numpy overflow warnings); beyond 1000 m/s² a value is damage or a wrong unit."""
    p = tmp_path / "huge.csv"
    p.write_text(CSV.replace("\n2,1e-6", "\n2,-1e300"))
    with pytest.raises(FormatError, match=r"huge\.csv:5: m_y: -1e\+300 m/s² is not a plausible"):
        read_rawlog(p)
    p.write_text(CSV.replace("\n2,1e-6", "\n2,999.0"))  # large but within the bound: read
    assert read_rawlog(p).axis("y")[2] == 999.0


@pytest.mark.parametrize("column", ["m_y", "m_z", "theta", "m_x"])
def test_a_boolean_time_acceleration_or_angle_column_is_refused(tmp_path, column):
    """The mutation fuzzer (issue 23): a Boolean m_y was read as 0/1 m/s² and
    demodulated without a word.  A Boolean auxiliary channel (a flag) is still read."""
    df = pd.DataFrame(
        {"time": np.arange(8.0), "m_x": 1e-7, "m_y": 1e-6, "m_z": 2e-6,
         "theta": np.repeat([0.0, np.pi], 4), "flag": [True, False] * 4}
    )  # fmt: skip
    df[column] = df[column] > 0
    p = tmp_path / "run.parquet"
    df.to_parquet(p)
    with pytest.raises(FormatError, match=f"{column}: a Boolean column, not a number in"):
        read_rawlog(p)
    ok = df.assign(**{column: 1e-6 if column != "theta" else df["theta"] * 0.0})
    ok.to_parquet(p)
    assert read_rawlog(p).aux["flag"].tolist() == [1.0, 0.0] * 4


def test_a_wild_theta_is_an_error_naming_its_line(tmp_path):
    """The mutation fuzzer (issue 23): θ = -1e308 rad on ten samples was masked and moved
    its period by 2.5σ without a word.  A θ beyond 1e7 rad is damage (its CSV line is
    named); unwrapped θ of many turns and a missing θ (a gap) are still read."""
    n = 12
    theta = np.repeat([0.0, np.pi], n // 2) + 2 * np.pi * 1000.0  # unwrapped, 1000 turns
    df = pd.DataFrame({"time": np.arange(float(n)), "m_y": 1e-6, "m_z": 2e-6, "theta": theta})
    df.loc[3, "theta"] = np.nan
    ok = tmp_path / "ok.csv"
    write_table(df, ok, units={"theta": "rad"})
    assert np.isnan(read_rawlog(ok).aux["theta"][3])
    df.loc[7, "theta"] = -1e308
    bad = tmp_path / "bad.csv"
    write_table(df, bad, units={"theta": "rad"})
    lines = bad.read_text().splitlines()
    line = 1 + next(i for i, text in enumerate(lines) if "-1e+308" in text)
    with pytest.raises(FormatError, match="theta: -1e\\+308 rad is not a plausible angle") as exc:
        read_rawlog(bad)
    assert exc.value.line == line
