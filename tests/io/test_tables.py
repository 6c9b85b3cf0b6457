"""Table reader/writer (Parquet, CSV, gz) and the io registry."""

import gzip
from pathlib import Path

import numpy as np
import pytest

import accal.io as aio
from accal.errors import FormatError, ValidationError
from accal.io.grace_l1b import read_grace_acc1b
from accal.io.tables import read_table_series, sniff_table, write_series
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
    with pytest.raises(FormatError, match="truncated last line") as e:
        read_table_series(w("tr.csv", b"gps_time,lin_accl_x\n1,2\n2,3"))
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
    def deny(self):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(Path, "read_bytes", deny)
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
