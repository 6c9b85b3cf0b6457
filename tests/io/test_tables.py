"""Table reader/writer (Parquet, CSV, gz) and the io registry."""

import gzip
from pathlib import Path

import numpy as np
import pytest

import accal.io as aio
from accal.errors import FormatError, ValidationError
from accal.io.grace_l1b import read_grace_acc1b
from accal.io.rawlog import open_rawlog, read_rawlog
from accal.io.tables import open_table, read_table_series, sniff_table, write_series
from accal.io.writers import write_table
from accal.series import AccSeries


def assert_identical(a: AccSeries, b: AccSeries) -> None:
    assert np.array_equal(a.time, b.time)
    assert np.array_equal(a.acc, b.acc, equal_nan=True)
    assert np.array_equal(a.quality, b.quality) and np.array_equal(a.valid, b.valid)
    assert (a.axes, a.satellite, a.frame, a.history) == (b.axes, b.satellite, b.frame, b.history)
    assert a.aux.keys() == b.aux.keys()
    for k in a.aux:
        assert a.aux[k].dtype == b.aux[k].dtype and np.array_equal(a.aux[k], b.aux[k]), k
    assert a.units == b.units
    assert a.meta == b.meta


def test_swarm_real_day(samples):
    s = read_table_series(samples["swarm_a"], columns={"x": "a_cal_x"})
    assert s.satellite == "Swarm-A" and s.axes == ("x",)
    assert len(s) == 86400
    # First row: 2024-05-11T00:00:00.796 UTC, GPS−UTC = 18 s; 8897 days after 2000-01-01.
    assert s.time[0] == pytest.approx(8897 * 86400 - 43200 + 18 + 0.796, abs=1e-6)
    assert s.acc[0, 0] == -7.433004188e-07 and s.acc[1, 0] == -7.426700355e-07
    assert s.valid.sum() == 77838  # flag_val == 0
    assert s.report.n_flagged == 86400 - 77838
    assert list(s.aux) == ["flag_thr"] and s.units["flag_thr"] == "unknown"
    assert s.report.n_gaps == 0 and s.report.nominal_step == 1.0
    assert s.meta["table"]["time_column"] == "time_utc"


def test_swarm_via_registry(samples):
    s = aio.read(samples["swarm_a"], columns={"x": "a_cal_x"})
    assert len(s) == 86400


def test_missing_mapped_column(samples):
    with pytest.raises(FormatError, match="column 'a_cal_y' \\(for axis y\\) not found"):
        read_table_series(samples["swarm_a"], columns={"y": "a_cal_y"})
    with pytest.raises(FormatError, match="no acceleration column"):
        read_table_series(samples["swarm_a"])
    with pytest.raises(ValidationError, match="'columns key'"):
        read_table_series(samples["swarm_a"], columns={"w": "a_cal_x"})


@pytest.mark.parametrize("suffix", ["parquet", "csv"])
@pytest.mark.parametrize("name", ["grace_b", "gracefo_c"])
def test_round_trip_from_l1b(samples, tmp_path, suffix, name):
    s = read_grace_acc1b(samples[name]).with_history("test: step 1")
    r = read_table_series(write_series(s, tmp_path / f"s.{suffix}"))
    assert_identical(s, r)


def test_round_trip_gz_csv(samples, tmp_path):
    s = read_grace_acc1b(samples["grace_a"])
    p = write_series(s, tmp_path / "s.csv")
    gz = tmp_path / "s.csv.gz"
    gz.write_bytes(gzip.compress(p.read_bytes()))
    assert_identical(s, read_table_series(gz))


def test_generic_columns(tmp_path):
    p = tmp_path / "g.csv"
    p.write_text(
        "# a comment\n"
        "time_utc,lin_accl_z,qualflg,temp\n"
        "2003-09-14T00:00:02Z,3e-7,00000000,20.5\n"
        "2003-09-14T00:00:00Z,1e-7,00000001,20.1\n"
        "2003-09-14T00:00:00Z,9e-7,00000000,20.2\n"
        "2003-09-14T00:00:01Z,2e-7,00000100,20.4\n"
        "2003-09-14T00:00:05Z,4e-7,00100000,20.3\n"
    )
    s = read_table_series(p)
    assert s.axes == ("z",)
    # 2003: GPS−UTC = 13 s.
    assert s.time.tolist() == [116769613.0, 116769614.0, 116769615.0, 116769618.0]
    assert s.acc[:, 0].tolist() == [1e-7, 2e-7, 3e-7, 4e-7]
    assert s.quality.tolist() == [1, 4, 0, 32]
    assert s.valid.tolist() == [False, False, True, True]
    r = s.report
    assert (r.n_rows, r.n_out_of_order, r.n_duplicates) == (5, 1, 1)
    assert (r.n_gaps, r.gap_seconds, r.nominal_step) == (1, 2.0, 1.0)
    assert s.aux["temp"].tolist() == [20.1, 20.4, 20.5, 20.3]


def test_units_from_metadata(tmp_path):
    import pandas as pd

    df = pd.DataFrame({"gps_time": [0.0, 1.0], "lin_accl_x": [1e-7, 2e-7], "temp": [1.0, 2.0]})
    p = write_table(df, tmp_path / "u.parquet", units={"temp": "degC"})
    s = read_table_series(p)
    assert s.units["temp"] == "degC"


def test_bad_tables(tmp_path):
    def w(name, content):
        p = tmp_path / name
        p.write_bytes(content)
        return p

    with pytest.raises(FormatError, match="empty file"):
        read_table_series(w("e.csv", b""))
    with pytest.raises(FormatError, match="header but no data"):
        read_table_series(w("h.csv", b"gps_time,lin_accl_x\n"))
    with pytest.raises(FormatError, match="no time column"):
        read_table_series(w("t.csv", b"a,lin_accl_x\n1,2\n"))
    # no final newline: a last row with every field is read (QA: editors and some tools
    # omit it); one cut short of its fields is a truncated last line
    assert len(read_table_series(w("nonl.csv", b"gps_time,lin_accl_x\n1,2e-7\n2,3e-7"))) == 2
    for cut in (b"gps_time,lin_accl_x\n1,2\n2", b"gps_time,lin_accl_x\n1,2\n2,"):
        with pytest.raises(FormatError, match="truncated last line") as e:
            read_table_series(w("tr.csv", cut))
        assert e.value.line == 3
    with pytest.raises(FormatError, match="CSV: .*columns") as e:
        read_table_series(w("c.csv", b"gps_time,lin_accl_x\n1,2\n2,3,4\n"))
    with pytest.raises(FormatError, match="'lin_accl_x' is not numeric"):
        read_table_series(w("n.csv", b"gps_time,lin_accl_x\n1,2\n2,abc\n"))
    with pytest.raises(FormatError, match="non-finite time") as e:
        read_table_series(w("nt.csv", b"gps_time,lin_accl_x\n1,2\nnan,3\n"))
    assert e.value.line == 3
    with pytest.raises(FormatError, match="corrupt Parquet"):
        read_table_series(w("p.parquet", b"PAR1" + b"\x00" * 50))
    with pytest.raises(FormatError, match="corrupt gzip"):
        read_table_series(w("g.csv.gz", gzip.compress(b"gps_time,lin_accl_x\n1,2\n")[:15]))


def test_nan_acc_is_invalid(tmp_path):
    p = tmp_path / "n.csv"
    p.write_text("gps_time,lin_accl_x\n1,2e-7\n2,nan\n3,1e-7\n")
    s = read_table_series(p)
    assert s.valid.tolist() == [True, False, True]
    assert "1 rows with missing or non-finite acceleration (invalid)" in s.report.warnings


def test_absurd_acc_is_damage_not_a_gap(tmp_path):
    """QA: 1e300 in a table went into the fit (infinite sigmas, a failed closure); a
    missing value is a gap (invalid sample), an absurd one an error with its line."""
    p = tmp_path / "h.csv"
    p.write_text("gps_time,lin_accl_x\n1,2e-7\n2,1e300\n3,1e-7\n")
    with pytest.raises(FormatError, match=r"h\.csv:3: lin_accl_x: 1e\+300 m/s² is not a plausible"):
        read_table_series(p)


# ---------------------------------------------------------------- registry


def test_registry_dispatch(samples):
    assert aio.detect_format(samples["grace_a"]) == "grace-l1b"
    assert aio.detect_format(samples["grace_a_bin"]) == "grace-l1b"
    assert aio.detect_format(samples["gracefo_c"]) == "grace-l1b"
    assert aio.detect_format(samples["swarm_a"]) == "table"
    assert aio.read(samples["gracefo_d"]).satellite == "GRACE-FO-D"
    assert sniff_table(samples["swarm_a"]) and not sniff_table(samples["grace_a"])


def test_registry_errors(samples, tmp_path):
    with pytest.raises(ValidationError, match="'format'.*'grace-l1b', 'table'.*'cdf'"):
        aio.read(samples["grace_a"], format="cdf")
    with pytest.raises(FormatError, match="format not recognised.*grace-l1b, table") as e:
        aio.read(samples["gracefo_rpt_c"])
    assert e.value.path == str(samples["gracefo_rpt_c"])
    with pytest.raises(FormatError, match="is a directory"):
        aio.read(tmp_path)
    with pytest.raises(FormatError, match="no such file"):
        aio.read(tmp_path / "nope.csv", format="table")


def test_permission_error_becomes_format_error(samples, monkeypatch):
    import accal.io.common

    def deny(*args, **kwargs):
        raise PermissionError(13, "Permission denied")

    # read_bytes opens the file itself (unbuffered, to skip a BOM without a copy)
    monkeypatch.setattr(accal.io.common, "open", deny, raising=False)
    with pytest.raises(FormatError, match="permission denied"):
        read_grace_acc1b(samples["grace_a"])
    with pytest.raises(FormatError, match="permission denied"):
        read_table_series(samples["swarm_a"])


def test_registry_write(samples, tmp_path):
    s = read_grace_acc1b(samples["grace_a"])
    p = aio.write(s, tmp_path / "a.asc", format="grace-l1b")
    assert aio.read(p).satellite == "GRACE-A"


def test_parquet_holding_grace_meta_is_a_table(samples, tmp_path):
    # A table written from a GRACE series carries the GRACE header in its metadata:
    # the GRACE sniffer must not claim it.
    s = read_grace_acc1b(samples["grace_a"])
    p = write_series(s, tmp_path / "a.parquet")
    assert aio.detect_format(p) == "table"
    assert aio.detect_format(write_series(s, tmp_path / "a.csv")) == "table"


# ---------------------------------------------------------------- bad input found by fuzzing
# (properties/test_fuzz_readers.py; T2-T7 are pinned there)


def _w(tmp_path: Path, name: str, content: bytes) -> Path:
    p = tmp_path / name
    p.write_bytes(content)
    return p


def _stream(path: Path, rows: int = 2) -> list:
    return list(open_table(path, rows=rows))


RUN_CSV = b"time,m_y,m_z,theta\n" + b"".join(b"%d,1e-7,2e-7,0.1\n" % i for i in range(200))


@pytest.mark.parametrize(
    ("content", "match"),
    [
        (gzip.compress(RUN_CSV)[:150], r"corrupt gzip stream \(truncated"),
        (gzip.compress(RUN_CSV)[:10] + b"garbage" * 10, "corrupt gzip stream .*invalid block type"),
        (gzip.compress(RUN_CSV) + b"junk", r"corrupt gzip stream \(garbage after the compressed"),
    ],
    ids=["truncated", "deflate_garbage", "trailing_garbage"],
)
def test_stream_corrupt_gzip(tmp_path, content, match):
    # EOFError, zlib.error and gzip.BadGzipFile escaped the chunked reader (accal demod)
    p = _w(tmp_path, "run.csv.gz", content)
    with pytest.raises(FormatError, match=match) as e:
        _stream(p)
    assert str(e.value).startswith(f"{p}: ")
    with pytest.raises(FormatError, match=match):
        list(open_rawlog(p, rows=50))
    with pytest.raises(FormatError, match="corrupt gzip stream"):  # the whole-file readers
        read_rawlog(p)


def test_stream_gzip_padding_is_fine(tmp_path):
    p = _w(tmp_path, "run.csv.gz", gzip.compress(RUN_CSV) + b"\x00" * 9)
    assert sum(t.num_rows for _, t in _stream(p, 64)) == 200


def test_duplicated_columns_everywhere(tmp_path):
    # pyarrow's KeyError ('Field "m_y" exists 2 times in schema') escaped every reader
    p = _w(tmp_path, "dup.csv", b"time,m_y,m_z,theta,m_y\n1,2,3,4,5\n2,3,4,5,6\n")
    for read in (open_table, lambda q: open_rawlog(q, rows=1), read_rawlog, read_table_series):
        with pytest.raises(FormatError, match=r"duplicated column name\(s\) m_y$") as e:
            read(p)
        assert e.value.line == 1
    import pyarrow as pa
    import pyarrow.parquet as pq

    q = tmp_path / "dup.parquet"
    pq.write_table(pa.Table.from_arrays([pa.array([1.0])] * 3, names=["time", "m_y", "m_y"]), q)
    for read in (open_table, read_rawlog, read_table_series):
        with pytest.raises(FormatError, match=r"duplicated column name\(s\) m_y$") as e:
            read(q)
        assert e.value.line is None


def test_units_must_be_strings(tmp_path):
    # a number went into RawlogStream.units["acc"] and AccSeries.units
    p = _w(tmp_path, "u.csv", b'# units: {"m_y": 5}\ntime,m_y,m_z,theta\n1,2,3,4\n2,3,4,5\n')
    for read in (open_table, open_rawlog, read_rawlog):
        with pytest.raises(FormatError, match="comment 'units:': unit of 'm_y' is a number"):
            read(p)
    q = write_table({"gps_time": [1.0, 2.0], "lin_accl_x": [1.0, 2.0]}, tmp_path / "u.parquet")
    import pyarrow.parquet as pq

    t = pq.read_table(q)
    pq.write_table(t.replace_schema_metadata({b"accal.units": b'{"lin_accl_x": null}'}), q)
    for read in (open_table, read_table_series):
        with pytest.raises(FormatError, match="accal metadata: unit of 'lin_accl_x' is null"):
            read(q)


def test_column_name_not_utf8(tmp_path):
    # a Parquet field name that is not UTF-8 raised UnicodeDecodeError from pyarrow
    import io

    import pyarrow as pa
    import pyarrow.parquet as pq

    buf = io.BytesIO()
    t = pa.table({"gps_time": [1.0, 2.0], "lin_accl_x": [1.0, 2.0], "zzzz": [1.0, 2.0]})
    pq.write_table(t, buf, store_schema=False)
    p = _w(tmp_path, "n.parquet", buf.getvalue().replace(b"zzzz", b"\xff\xfezz"))
    with pytest.raises(FormatError, match="a column name is not UTF-8"):
        read_table_series(p)
    with pytest.raises(FormatError, match="corrupt Parquet file"):
        open_table(p)


def test_time_utc_beyond_nanosecond_range(tmp_path):
    # 2600-01-01 wrapped around int64 nanoseconds into 2015 and was accepted
    p = _w(
        tmp_path, "u.csv", b"time_utc,lin_accl_x\n2003-09-14T00:00:00Z,1\n2600-01-01T00:00:00Z,2\n"
    )
    with pytest.raises(FormatError, match="time_utc 2600-01-01T00:00:00 is outside 1980") as e:
        read_table_series(p)
    assert e.value.line == 3


def test_stream_blank_first_line(tmp_path):
    p = _w(tmp_path, "b.csv", b"    \ntime,m_y,m_z,theta\n1,2,3,4\n")
    with pytest.raises(FormatError, match=r"blank first line \(expected the CSV header\)") as e:
        open_table(p)
    assert e.value.line == 1
    with pytest.raises(FormatError, match="empty file"):
        open_table(_w(tmp_path, "e.csv", b"  \n\n \n"))


def test_stream_parquet_short_column_is_not_silently_truncated(tmp_path):
    # Found by the stream fuzz property: one flipped byte in a data page header (its
    # num_values, 120 -> 56) made pyarrow's iter_batches(batch_size=1) stop after 56
    # rows without an error, so `accal demod` would have used half the file.
    import io

    import pyarrow as pa
    import pyarrow.parquet as pq

    n = 120
    t = pa.table({"time": np.arange(n, dtype=float), "m_y": np.zeros(n), "m_z": np.zeros(n),
                  "theta": np.zeros(n)})  # fmt: skip
    buf = io.BytesIO()
    pq.write_table(t, buf, compression="NONE", use_dictionary=False, write_statistics=False)
    raw = buf.getvalue()
    # compact Thrift: data_page_header (field 5, struct ","), num_values (i32) zigzag 240
    head = b",\x15\xf0\x01"
    assert raw.count(head) == 4, "page header layout changed: update this test"
    p = _w(tmp_path, "short.parquet", raw.replace(head, b",\x15\xf0\x00", 1))
    with pytest.raises(FormatError, match=r"corrupt Parquet file \(.*"):
        read_rawlog(p)
    with pytest.raises(FormatError, match=r"read 56 rows, the footer says 120"):
        list(open_table(p, rows=1))
    with pytest.raises(FormatError, match="corrupt Parquet file"):
        list(open_rawlog(p, rows=1))


def test_stray_quote_does_not_swallow_the_rest_of_the_file(tmp_path):
    # Found by the stream fuzz property (whole file vs chunks): pyarrow read from a
    # lone '"' to the end of the file as one text value, so read_table_series gave
    # 1 sample of 3 (the text column ignored as non-numeric) without an error.
    text = b'gps_time,lin_accl_x,note\n116769600,1e-7,"\n116769601,2e-7,a\n116769602,3e-7,b\n'
    p = _w(tmp_path, "q.csv", text)
    match = r"column 'note': a quoted value runs over several lines \(a stray '\"'\?\)"
    with pytest.raises(FormatError, match=match) as e:
        read_table_series(p)
    assert e.value.line == 2
    from accal.io.housekeeping import read_housekeeping

    with pytest.raises(FormatError, match=match):
        read_housekeeping(p)
    for rows in (1, 2, 100):
        with pytest.raises(FormatError, match=match) as e:
            _stream(p, rows)
        assert e.value.line == 2
    run = _w(tmp_path, "r.csv", b'time,m_y,m_z,theta\n1,2,3,4\n2,3,4,"5\n3,4,5,6\n')
    for read in (read_rawlog, lambda q: list(open_rawlog(q, rows=2))):
        with pytest.raises(FormatError, match="column 'theta': a quoted value runs") as e:
            read(run)
        assert e.value.line == 3
    # a quoted value on one line (with the separator inside) is fine
    ok = _w(tmp_path, "ok.csv", b'gps_time,lin_accl_x,note\n1,1e-7,"a,b"\n2,2e-7,c\n')
    assert len(read_table_series(ok)) == 2


# ---------------------------------------------------------------- QA pass: what the messages say


BOM = b"\xef\xbb\xbf"


@pytest.mark.parametrize("name", ["x.asc", "x.csv", "x.txt", "x.dat"])
@pytest.mark.parametrize("content", [b"", b"  \n\n", BOM, BOM + b"\n"], ids=repr)
def test_detect_empty_file(tmp_path, name, content):
    # was "format not recognised ... name one explicitly"
    p = _w(tmp_path, name, content)
    with pytest.raises(FormatError, match=r"empty file$") as e:
        aio.detect_format(p)
    assert str(e.value) == f"{p}: empty file"
    with pytest.raises(FormatError, match=r": empty file$"):
        aio.read(p)


@pytest.mark.parametrize(
    ("cut", "match"),
    [
        (lambda gz: gz[:2000], r"corrupt gzip stream \(truncated: no end-of-stream marker\)"),
        (lambda gz: gz[:10] + b"garbage" * 10, r"corrupt gzip stream \(.*invalid block type"),
        (lambda gz: gz[:5], r"corrupt gzip stream"),
        (lambda gz: gzip.compress(b""), r"empty file"),
    ],
    ids=["truncated", "deflate_garbage", "header_only", "empty_member"],
)
def test_detect_corrupt_gzip(samples, tmp_path, cut, match):
    gz = gzip.compress(samples["grace_a"].read_bytes())
    p = _w(tmp_path, "ACC1B.asc.gz", cut(gz))
    with pytest.raises(FormatError, match=match) as e:
        aio.detect_format(p)
    with pytest.raises(FormatError) as named:  # the same wording as with the format named
        aio.read(p, format="grace-l1b")
    assert str(e.value) == str(named.value)


def test_detect_unknown_gzip_content_is_still_unrecognised(tmp_path):
    p = _w(tmp_path, "x.gz", gzip.compress(b"hello world\n" * 10))
    with pytest.raises(FormatError, match="format not recognised"):
        aio.detect_format(p)


@pytest.mark.parametrize(
    ("name", "fmt"),
    [("grace_a", "grace-l1b"), ("gracefo_c", "grace-l1b"), ("grace_a_bin", "grace-l1b")],
)
def test_detect_and_read_after_a_bom(samples, tmp_path, name, fmt):
    p = _w(tmp_path, "bom_" + samples[name].name, BOM + samples[name].read_bytes())
    assert aio.detect_format(p) == fmt
    s, ref = aio.read(p), aio.read(samples[name])
    assert np.array_equal(s.acc, ref.acc) and s.meta == ref.meta


def test_csv_with_bom_and_comment_lines(tmp_path):
    csv = b'# units: {"lin_accl_x": "m/s^2", "temp": "degC"}\ngps_time,lin_accl_x,temp\n'
    csv += b"".join(b"%d,%de-9,20.5\n" % (116769600 + i, i) for i in range(5))
    ref = read_table_series(_w(tmp_path, "plain.csv", csv))
    for name, content in (("bom.csv", BOM + csv), ("bom.csv.gz", gzip.compress(BOM + csv))):
        p = _w(tmp_path, name, content)
        assert sniff_table(p) and aio.detect_format(p) == "table"
        s = read_table_series(p)
        assert_identical(s, ref)
        assert s.units["temp"] == "degC"  # the comment line was read, not taken as the header
        stream = _stream(p, rows=2)
        assert sum(t.num_rows for _, t in stream) == 5
        assert stream[0][1].column_names == ["gps_time", "lin_accl_x", "temp"]
    p = _w(tmp_path, "bomonly.csv", BOM)
    with pytest.raises(FormatError, match="empty file"):
        open_table(p)


def test_no_acceleration_column_names_the_cli_option(tmp_path):
    p = _w(tmp_path, "t.csv", b"gps_time,a_cal_x\n1,2\n2,3\n")
    with pytest.raises(FormatError, match=r"--column x=NAME.*columns=\{'x': NAME\}") as e:
        read_table_series(p)
    assert "a_cal_x" in str(e.value)


BAD_TIME = b"time_utc,a_cal_x\n2024-05-11T23:59:49.796,1e-7\n2024-05-11T25:00:49.796,2e-7\n"


def test_bad_utc_time_is_one_clean_line(tmp_path):
    # was pandas' text with a literal "\n", cut off in the middle
    p = _w(tmp_path, "t.csv", BAD_TIME)
    with pytest.raises(FormatError) as e:
        read_table_series(p, columns={"x": "a_cal_x"})
    assert str(e.value) == (
        f"{p}:3: time_utc: '2024-05-11T25:00:49.796' is not an ISO-8601 UTC time "
        "(YYYY-MM-DDThh:mm:ss[.fff][Z])"
    )
    # a blank line before it is counted; a comment line too
    p = _w(
        tmp_path, "t2.csv", b"# c\n" + BAD_TIME.replace(b"\n2024-05-11T25", b"\n\n2024-05-11T25")
    )
    with pytest.raises(FormatError, match="'2024-05-11T25:00:49.796' is not") as e:
        read_table_series(p, columns={"x": "a_cal_x"})
    assert e.value.line == 5
    # Parquet: the row
    import pyarrow as pa
    import pyarrow.parquet as pq

    pq.write_table(
        pa.table({"time_utc": ["2024-05-11T00:00:00", "x"], "lin_accl_x": [1.0, 2.0]}),
        tmp_path / "t.parquet",
    )
    with pytest.raises(FormatError, match=r"t\.parquet: row 2: time_utc: 'x' is not an ISO-8601"):
        read_table_series(tmp_path / "t.parquet")


@pytest.mark.parametrize(
    ("value", "match"),
    [
        (b"2600-05-11T00:00:00", r"time_utc 2600-05-11T00:00:00 is outside 1980-01-06"),
        (b"1960-05-11T00:00:00", r"time_utc 1960-05-11T00:00:00.* is outside 1980-01-06"),
        (b"", r"time_utc: empty value"),
    ],
)
def test_utc_time_out_of_range_or_empty_names_the_line(tmp_path, value, match):
    # a year 2600 without "Z" stayed text, and its [ns] conversion wrapped into 2015
    p = _w(tmp_path, "t.csv", BAD_TIME.replace(b"2024-05-11T25:00:49.796", value))
    with pytest.raises(FormatError, match=match) as e:
        read_table_series(p, columns={"x": "a_cal_x"})
    assert e.value.line == 3


def test_non_numeric_column_names_the_first_bad_line(tmp_path):
    csv = b"gps_time,lin_accl_x,m_y\n1,2,3\n2,3,\n\n3,4,x\n4,5,y\n"
    p = _w(tmp_path, "t.csv", csv)
    with pytest.raises(FormatError) as e:
        read_table_series(p, columns={"y": "m_y"})
    assert str(e.value) == f"{p}:5: column 'm_y' is not numeric (type string): 'x' is not a number"
    s = read_table_series(p)  # not an axis: an auxiliary text column is skipped, as before
    assert "non-numeric columns ignored: m_y" in s.report.warnings
    with pytest.raises(FormatError, match=r"^.*t\.csv:4: column 'gps_time' is not numeric"):
        read_table_series(_w(tmp_path, "t.csv", b"gps_time,lin_accl_x\n1,2\n2,3\nnow,4\n"))
    with pytest.raises(FormatError, match=r":3: column 'flag_val' is not numeric .*'bad'"):
        read_table_series(_w(tmp_path, "t.csv", b"gps_time,lin_accl_x,flag_val\n1,2,0\n2,3,bad\n"))
    with pytest.raises(FormatError, match=r":4: column 'quality' is neither .* integers: 'x1'"):
        read_table_series(
            _w(tmp_path, "t.csv", b"gps_time,lin_accl_x,quality\n1,2,00000000\n2,3,7\n3,4,x1\n")
        )


def test_non_numeric_parquet_column_names_the_row(tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    p = tmp_path / "t.parquet"
    pq.write_table(pa.table({"gps_time": [1.0, 2.0, 3.0], "lin_accl_x": ["1", "2", "zz"]}), p)
    with pytest.raises(FormatError) as e:
        read_table_series(p)
    assert str(e.value) == (
        f"{p}: row 3: column 'lin_accl_x' is not numeric (type string): 'zz' is not a number"
    )


def test_wrong_number_of_columns_names_the_line(tmp_path):
    csv = b"# units: {}\ngps_time,lin_accl_x,lin_accl_y\n1,2,3\n\n2,3,4\n3,4\n4,5,6\n"
    p = _w(tmp_path, "t.csv", csv)
    with pytest.raises(FormatError) as e:
        read_table_series(p)
    assert str(e.value) == f"{p}:6: CSV: Expected 3 columns, got 2: 3,4"
    q = _w(tmp_path, "q.csv", b'gps_time,lin_accl_x,note\n1,2,"a\nb"\n2,3,c,d\n')
    with pytest.raises(FormatError, match="Expected 3 columns, got 4") as e:
        read_table_series(q)
    assert e.value.line == 4  # the quoted value spans lines 2-3
    with pytest.raises(FormatError, match=r"t\.csv:6: CSV: Expected 3 columns, got 2"):
        _stream(p, rows=2)


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_calibrated_output_reads_back_with_its_satellite(samples, tmp_path, fmt):
    """grace-bias writes the satellite in the calibrated file's metadata: it comes back."""
    from accal.pipeline import GraceBiasOptions, process_file

    src = samples["grace_a"]
    out = process_file(src, tmp_path, GraceBiasOptions(fmt=fmt))
    cal = next(p for p in out.outputs if ".calibrated." in p.name)
    s = read_table_series(cal)
    assert (s.satellite, s.frame, s.axes) == ("GRACE-A", "SRF", ("x", "y", "z"))
    # without metadata, an L1B-style file name names the satellite
    for name, sat in [
        ("ACC1B_2005-01-01_B_02.csv", "GRACE-B"),
        ("ACT1B_2023-06-01_D_04.csv", "GRACE-FO-D"),
    ]:
        write_table({"gps_time": s.time, "lin_accl_x": s.acc[:, 0]}, tmp_path / name)
        assert read_table_series(tmp_path / name).satellite == sat


def test_parquet_floats_are_byte_stream_split_and_round_trip_exactly(tmp_path):
    """Float columns use BYTE_STREAM_SPLIT (a 1 Hz calibrated day 2.4 -> 1.6 MB); the
    others keep dictionary encoding; every value reads back bit for bit."""
    import pyarrow.parquet as pq

    rng = np.random.default_rng(3)
    t = 7.5e8 + np.arange(5000.0)
    a = 1e-7 + 1e-9 * rng.standard_normal(5000)
    flag = (rng.random(5000) < 0.01).astype(np.uint32)
    p = write_table({"gps_time": t, "lin_accl_x": a, "qualflg": flag}, tmp_path / "c.parquet")
    col = pq.ParquetFile(p).metadata.row_group(0)
    enc = {col.column(i).path_in_schema: col.column(i).encodings for i in range(3)}
    assert "BYTE_STREAM_SPLIT" in enc["gps_time"] and "BYTE_STREAM_SPLIT" in enc["lin_accl_x"]
    assert "BYTE_STREAM_SPLIT" not in enc["qualflg"]
    back = pq.read_table(p)
    np.testing.assert_array_equal(back["gps_time"].to_numpy(), t)
    np.testing.assert_array_equal(back["lin_accl_x"].to_numpy(), a)
    np.testing.assert_array_equal(back["qualflg"].to_numpy(), flag)


def test_parquet_required_columns_only_where_no_nulls_and_values_unchanged(tmp_path):
    """``required=True`` declares the columns without nulls REQUIRED (no definition
    levels); a column with a null stays optional; the values read back bit for bit,
    and a directory of optional and required files still reads as one dataset."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    rng = np.random.default_rng(4)
    a = rng.standard_normal(1000)
    a[3] = np.nan  # a float NaN is a value, not a null
    table = pa.table({"a": a, "b": pa.array([1.0, None] * 500), "v": rng.random(1000) < 0.5})
    p = write_table(table, tmp_path / "r" / "x.parquet", required=True)
    q = write_table(table, tmp_path / "r" / "y.parquet")
    req = {f.name: f.nullable for f in pq.read_schema(p)}
    assert req == {"a": False, "b": True, "v": False}
    assert all(f.nullable for f in pq.read_schema(q))
    back = pq.read_table(p)
    assert back["b"].to_pylist() == table["b"].to_pylist()
    assert back["v"].to_pylist() == table["v"].to_pylist()
    np.testing.assert_array_equal(back["a"].to_numpy(), a)  # NaN where NaN
    assert pq.read_table(tmp_path / "r").num_rows == 2000


def test_a_table_in_another_unit_gets_a_warning(tmp_path):
    """QA: a table in µm/s² without units was read as m/s² without a word."""
    p = tmp_path / "um.csv"
    p.write_text("gps_time,lin_accl_x,lin_accl_y\n1,1.2136,-28.512\n2,1.2137,-28.513\n")
    s = read_table_series(p)
    assert [w for w in s.report.warnings if "lin_accl_y" in w and "another unit" in w]
    assert [w for w in s.report.warnings if "lin_accl_x" in w and "another unit" in w]
    ok = tmp_path / "si.csv"
    ok.write_text("gps_time,lin_accl_x\n1,1.2136e-6\n2,1.2137e-6\n")
    assert not [w for w in read_table_series(ok).report.warnings if "another unit" in w]


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_a_time_column_of_utc_times_is_utc(tmp_path, suffix):
    """QA: UTC times in a column named ``time`` were refused as "not numeric"."""
    import pandas as pd

    stamps = ["2003-09-14T00:00:00Z", "2003-09-14T00:00:01Z", "2003-09-14T00:00:02Z"]
    df = pd.DataFrame({"time": stamps, "lin_accl_x": [1e-7, 2e-7, 3e-7]})
    if suffix == ".parquet":
        df["time"] = pd.to_datetime(df["time"]).dt.tz_localize(None)
    p = tmp_path / f"t{suffix}"
    df.to_csv(p, index=False) if suffix == ".csv" else df.to_parquet(p, index=False)
    s = read_table_series(p)
    assert s.time.tolist() == [116769613.0, 116769614.0, 116769615.0]  # GPS−UTC = 13 s


def test_a_time_column_of_any_name(tmp_path):
    """``columns={"time": NAME}`` (the CLI's ``--column time=NAME``): a column ``t`` of
    GPS seconds, or ``epoch`` of UTC strings, is the time (QA: ``t`` was refused)."""
    p = tmp_path / "t.csv"
    p.write_text("t,lin_accl_x,temp\n100,2e-7,20\n101,3e-7,21\n")
    s = read_table_series(p, columns={"time": "t"})
    assert list(s.time) == [100.0, 101.0] and list(s.aux) == ["temp"]
    with pytest.raises(FormatError, match="no time column .* --column time=NAME"):
        read_table_series(p)
    with pytest.raises(FormatError, match=r"no column 'tt' for the time \(--column time=tt\)"):
        read_table_series(p, columns={"time": "tt"})
    with pytest.raises(ValidationError, match="columns key"):
        read_table_series(p, columns={"when": "t"})
    u = tmp_path / "u.csv"
    u.write_text("epoch,lin_accl_x\n2000-01-01T12:00:00Z,2e-7\n2000-01-01T12:00:01Z,3e-7\n")
    s = read_table_series(u, columns={"time": "epoch"})
    # UTC 2000-01-01 12:00:00 is GPS 12:00:13 (GPS − UTC = 13 s then)
    assert list(s.time) == [13.0, 14.0]
