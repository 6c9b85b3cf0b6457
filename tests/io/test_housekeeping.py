"""Housekeeping reader (AHK1B, generic tables) and interpolation onto accelerometer epochs.

Values are written out by hand from the raw text of the real sample files in
``data/samples/`` (see PROVENANCE.md); the line each one comes from is quoted.
"""

import gzip

import numpy as np
import pytest

from accal.errors import AccalError, FormatError, UnsupportedFormatError, ValidationError
from accal.io.grace_l1b import read_grace_acc1b
from accal.io.housekeeping import (
    DEFAULT_MAX_GAP,
    GRACE_FIELDS,
    GRACEFO_FIELDS,
    Housekeeping,
    read_housekeeping,
)
from accal.io.writers import write_table

GRACE_CHANNELS = [
    "bias_vol", "vd", "x1_out", "x2_out", "x3_out", "y1_out", "y2_out", "z1_out",
    "tesu", "taicu", "tisu", "v15picu", "v15micu", "vr5picu", "tcicu",
    "v15psu", "v15msu", "v48psu", "v48msu",
]  # fmt: skip
GRACEFO_CHANNELS = [
    "TFEEU_IF", "TFEEU_REF", "TFEEU_X", "TFEEU_YZ", "analog_GND", "+3.3V", "Vp", "MES_Vd",
    "MES_DET_X1", "MES_DET_X2", "MES_DET_X3", "MES_DET_Y1", "MES_DET_Y2", "MES_DET_Z1",
    "TSU_Y+", "TICUN", "TSU_Y-", "TSU_Z+", "TSU_Z-", "+5V", "TICUR",
    "+15V", "-15V", "+48V", "-48V",
]  # fmt: skip


def split_sample(path):
    """(header incl. its end line, data lines) of a sample file."""
    raw = path.read_bytes()
    for marker in (b"# End of YAML header\n", b"END OF HEADER"):
        i = raw.find(marker)
        if i >= 0:
            j = raw.index(b"\n", i) + 1
            return raw[:j], raw[j:].splitlines(keepends=True)
    raise AssertionError(path)


def at(h, t):
    """Index of epoch t in h.time (exactly one)."""
    (i,) = np.flatnonzero(h.time == t)
    return int(i)


# ---------------------------------------------------------------- real files


def test_grace_a(samples):
    h = read_housekeeping(samples["grace_ahk_a"])
    assert h.satellite == "GRACE-A"
    assert len(h) == 58 == int(h.meta["grace"]["NUMBER OF DATA RECORDS"])
    assert h.warnings == ()
    # TIME FIRST/LAST OBS(SEC PAST EPOCH): 116769301.990380 / 116769871.920781
    assert h.time[0] == 116769301.990380 and h.time[-1] == 116769871.920781
    assert np.all(np.diff(h.time) > 0)
    assert list(h.channels) == GRACE_CHANNELS
    assert list(h.flags) == ["qualflg", "status", "icu_blk_nr"]
    assert h.units["tesu"] == h.units["taicu"] == h.units["tisu"] == h.units["tcicu"] == "degC"
    assert h.units["bias_vol"] == h.units["vd"] == h.units["v48msu"] == "V"
    assert h.units["x1_out"] == "m"
    assert h.units["time"].startswith("s (GPS")
    assert h.meta["housekeeping"]["inferred_units"] == []
    assert h.meta["housekeeping"]["prod_flag_bits"]["tesu"] == 14
    # every record has bits 6-13 and 26; every 6th also 14-25 (temperatures every 60 s)
    assert all(np.isfinite(h.channels[c]).all() for c in GRACE_CHANNELS[:8])
    assert np.count_nonzero(np.isfinite(h.channels["tesu"])) == 9
    # "116769341  952275  G  A  00000100   00000111111111111111111111000000  10.14379795430327
    #  4.921208382 ... 33.48218918 57.56399918 26.8669529 14.92129993 -14.91238022 5.054299831
    #  23.61759949 14.03649998 -14.05799961 50.11500168 -50.51100159  10111111  35006"
    i = at(h, 116769341.952275)
    assert h.channels["bias_vol"][i] == 10.14379795430327
    assert h.channels["tesu"][i] == 33.48218918
    assert h.channels["taicu"][i] == 57.56399918
    assert h.channels["tcicu"][i] == 23.61759949
    assert h.channels["v15micu"][i] == -14.91238022
    assert h.channels["v48msu"][i] == -50.51100159
    assert h.flags["status"][i] == 0b10111111
    assert h.flags["icu_blk_nr"][i] == 35006
    assert h.flags["qualflg"][i] == 0b00000100
    # "116769331  986717  G  A  00000100   00000100000000000011111111000000  10.14387006146016
    #  4.921208382 9.723482464e-09 2.481763683e-09 ... 35"  (no temperatures)
    j = at(h, 116769331.986717)
    assert h.channels["x1_out"][j] == 9.723482464e-09
    assert np.isnan(h.channels["tesu"][j]) and h.flags["status"][j] == -1


def test_grace_b(samples):
    h = read_housekeeping(samples["grace_ahk_b"])
    assert h.satellite == "GRACE-B" and len(h) == 58 and h.warnings == ()
    # "116769303  32516  G  B  00000000   00000100000000000011111111000000  10.18224350351259 ..."
    assert h.time[0] == 116769303.032516
    assert h.channels["bias_vol"][0] == 10.18224350351259
    assert h.flags["qualflg"][0] == 0
    assert np.count_nonzero(np.isfinite(h.channels["tisu"])) == 9
    tesu = h.channels["tesu"][np.isfinite(h.channels["tesu"])]
    assert tesu[0] == 33.47094727


def test_gracefo_c(samples):
    h = read_housekeeping(samples["gracefo_ahk_c"])
    assert h.satellite == "GRACE-FO-C" and len(h) == 100
    assert h.meta["gracefo"]["dimensions"]["num_records"] == "864077"
    assert h.warnings == (
        "header announces 864077 data records, file has 100",
        "temperature channel(s) TICUR read below absolute zero (sensor not powered?)",
    )
    # first / last record: "738849600  91062  G  C ...", "738849609  990172  G  C ..."
    assert h.time[0] == 738849600.091062 and h.time[-1] == 738849609.990172
    start = float(h.meta["gracefo"]["non-standard_attributes"]["start_time_epoch_secs"])
    assert h.time[0] == pytest.approx(start, abs=1e-6)  # header has 0.0910619: µs rounding
    assert list(h.channels) == GRACEFO_CHANNELS
    assert list(h.flags) == ["qualflg", "icu_blk_nr", "PPS_source", "Sync_Qual", "statusflag"]
    assert h.units["TSU_Y+"] == h.units["TICUN"] == h.units["TFEEU_REF"] == "degC"
    assert h.units["+15V"] == h.units["Vp"] == h.units["MES_Vd"] == "V"
    assert h.units["MES_DET_X1"] == "unknown"
    inferred = h.meta["housekeeping"]["inferred_units"]
    assert "TSU_Y+" in inferred and "+15V" in inferred and "MES_DET_X1" not in inferred
    assert np.isfinite(h.channels["Vp"]).all()  # Vp (bit 6) is in every record
    # "738849600  91062  G  C  00000000   00111100000000000000010001000000  9.984976053237915
    #  0.001019239426 0 0 0  00000000000000000000000000000000"
    assert h.channels["Vp"][0] == 9.984976053237915
    assert h.channels["MES_DET_X3"][0] == 0.001019239426
    assert h.flags["statusflag"][0] == 0 and h.flags["icu_blk_nr"][0] == 0
    # "738849600  191055  G  C  00000000   00111100000000000000000001000100  26.0137372493744
    #  9.98498797416687 ..."  (bit 2 TFEEU_X comes before bit 6 Vp)
    i = at(h, 738849600.191055)
    assert h.channels["TFEEU_X"][i] == 26.0137372493744 and h.channels["Vp"][i] == 9.98498797416687
    # "738849601  390953  G  C  ...00000100000001000000  9.985065460205078 21.9377594 1 0 0 ..."
    assert h.channels["TSU_Y+"][at(h, 738849601.390953)] == 21.9377594
    # "738849603  390774  G  C  ...01000000000000000001000000  9.985005855560303 -48.62966537 3 ..."
    i = at(h, 738849603.390774)
    assert h.channels["-48V"][i] == -48.62966537 and h.flags["icu_blk_nr"][i] == 3
    # "738849600  491036 ... 4.947817326 0 0 0  00000000000000000010000000000000" (bit 13)
    assert h.flags["statusflag"][at(h, 738849600.491036)] == 1 << 13
    assert h.channels["TICUR"][np.isfinite(h.channels["TICUR"])][0] == -273.2031555


def test_gracefo_d(samples):
    h = read_housekeeping(samples["gracefo_ahk_d"])
    assert h.satellite == "GRACE-FO-D" and len(h) == 100
    assert h.warnings[0] == "header announces 864075 data records, file has 100"
    # "738849600  94671  G  D  00000000   00111100000000000000010001000000  9.990030527114868 ..."
    assert h.time[0] == 738849600.094671 and h.channels["Vp"][0] == 9.990030527114868
    assert list(h.channels) == GRACEFO_CHANNELS


def test_field_tables_have_unique_names():
    for fields in (GRACE_FIELDS, GRACEFO_FIELDS):
        names = [f.name for f in fields.values()]
        assert len(names) == len(set(names))
        assert all(f.kind in "fib" for f in fields.values())


def test_gzip_by_content(samples, tmp_path):
    p = tmp_path / "ahk_no_suffix.txt"
    p.write_bytes(gzip.compress(samples["gracefo_ahk_c"].read_bytes()))
    a, b = read_housekeeping(p), read_housekeeping(samples["gracefo_ahk_c"])
    assert np.array_equal(a.time, b.time)
    assert all(np.array_equal(a.channels[k], b.channels[k], equal_nan=True) for k in b.channels)


# ---------------------------------------------------------------- onto accelerometer epochs


def test_on_real_grace(samples):
    acc = read_grace_acc1b(samples["grace_a"])
    h = read_housekeeping(samples["grace_ahk_a"])
    aux = h.on(acc.time)
    assert set(aux) == set(h.channels)
    tesu = h.channels["tesu"][np.isfinite(h.channels["tesu"])]
    assert np.isfinite(aux["tesu"]).all()  # ACC1B 116769600...659 lies inside the AHK1B day
    assert tesu.min() <= aux["tesu"].min() and aux["tesu"].max() <= tesu.max()


def test_on_real_gracefo_coverage(samples):
    acc = read_grace_acc1b(samples["gracefo_c"])  # 738849600 ... 738849699, 1 s
    h = read_housekeeping(samples["gracefo_ahk_c"])  # 738849600.09 ... 738849609.99
    aux = h.on(acc.time)
    tsu = h.time[np.isfinite(h.channels["TSU_Y+"])]
    inside = (acc.time >= tsu[0]) & (acc.time <= tsu[-1])
    assert inside.sum() == 5  # TSU_Y+ sampled 738849601.39 ... 738849606.49
    assert np.isfinite(aux["TSU_Y+"][inside]).all() and np.isnan(aux["TSU_Y+"][~inside]).all()


def linear_hk(t, a=20.0, b=1e-3):
    return Housekeeping(time=t, channels={"T": a + b * (t - t[0])}, units={"T": "degC"})


def test_on_linear_channel_is_exact():
    t = 116769300.0 + np.cumsum(np.r_[0.0, np.full(99, 10.0)])
    h = linear_hk(t)
    q = np.linspace(t[0], t[-1], 1001)
    got = h.on(q)["T"]
    # exact up to double rounding of a + b (q - t0) (one ulp of ~20)
    assert np.allclose(got, 20.0 + 1e-3 * (q - t[0]), rtol=0, atol=1e-13)
    assert np.array_equal(h.on(t)["T"], h.channels["T"])  # sample epochs give the samples


def test_on_nan_outside_coverage_and_across_gaps():
    t = np.array([0.0, 10.0, 20.0, 200.0, 210.0])
    h = Housekeeping(time=t, channels={"T": t.copy()}, units={"T": "degC"})
    q = np.array([-1.0, 0.0, 5.0, 20.0, 21.0, 199.0, 200.0, 205.0, 210.0, 211.0, np.nan])
    got = h.on(q, max_gap=50.0)["T"]
    want = [np.nan, 0.0, 5.0, 20.0, np.nan, np.nan, 200.0, 205.0, 210.0, np.nan, np.nan]
    assert np.array_equal(got, want, equal_nan=True)
    # the gap of 180 s is bridged when allowed
    assert h.on(np.array([110.0]), max_gap=180.0)["T"][0] == 110.0
    assert np.isnan(h.on(np.array([110.0]))["T"][0])  # default 120 s
    assert DEFAULT_MAX_GAP == 120.0


def test_on_uses_each_channels_own_samples():
    t = np.arange(0.0, 60.0, 10.0)
    sparse = np.array([0.0, np.nan, np.nan, 30.0, np.nan, 50.0])
    h = Housekeeping(time=t, channels={"s": sparse}, units={"s": "V"})
    assert np.array_equal(h.on(np.array([15.0, 40.0]))["s"], [15.0, 40.0])
    assert np.array_equal(h.on(np.array([15.0]), max_gap=20.0)["s"], [np.nan], equal_nan=True)
    one = Housekeeping(time=t, channels={"s": np.r_[np.nan, 7.0, [np.nan] * 4]}, units={"s": "V"})
    assert np.array_equal(
        one.on(np.array([9.0, 10.0, 11.0]))["s"], [np.nan, 7.0, np.nan], equal_nan=True
    )


def test_on_bad_arguments():
    h = linear_hk(np.arange(5.0))
    with pytest.raises(ValidationError, match="max_gap must be positive"):
        h.on(np.arange(3.0), max_gap=0)
    with pytest.raises(ValidationError, match="max_gap must be positive"):
        h.on(np.arange(3.0), max_gap=float("nan"))
    with pytest.raises(ValidationError, match="1-D"):
        h.on(np.zeros((2, 2)))
    with pytest.raises(ValidationError, match="numeric"):
        h.on(["a", "b"])
    with pytest.raises(
        ValidationError, match=r"unknown housekeeping channel\(s\) 'x'; channels are T"
    ):
        h.on(np.arange(3.0), names=["x"])
    assert list(h.on(np.arange(3.0), names=["T"])) == ["T"] == list(h.on([0.0], names="T"))


def test_housekeeping_checks_its_arrays():
    with pytest.raises(ValidationError, match="strictly increasing"):
        Housekeeping(time=[0.0, 0.0], channels={}, units={})
    with pytest.raises(ValidationError, match="shape"):
        Housekeeping(time=[0.0, 1.0], channels={"T": [1.0]}, units={"T": "degC"})
    with pytest.raises(ValidationError, match="no unit"):
        Housekeeping(time=[0.0, 1.0], channels={"T": [1.0, 2.0]}, units={})
    with pytest.raises(ValidationError, match="finite"):
        Housekeeping(time=[0.0, np.inf], channels={}, units={})


# ---------------------------------------------------------------- generic tables


@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_table(tmp_path, fmt):
    p = tmp_path / f"hk.{fmt}"
    t = np.array([10.0, 11.0, 12.0, 13.0])
    write_table(
        {
            "gps_time": t,
            "T_plate": np.array([20.5, 20.75, np.nan, 21.0]),
            "heater_current": np.array([100.0, 110.0, 120.0, 130.0]),
            "v_ref": np.array([1, 2, 3, 4], dtype=np.int64),
            "label": np.array(["a", "b", "c", "d"]),
        },
        p,
        units={"gps_time": "s", "T_plate": "degC", "heater_current": "mA", "v_ref": "mV"},
    )
    h = read_housekeeping(p)
    assert np.array_equal(h.time, t) and h.satellite == ""
    assert list(h.channels) == ["T_plate", "heater_current", "v_ref"]
    assert np.array_equal(h.channels["T_plate"], [20.5, 20.75, np.nan, 21.0], equal_nan=True)
    assert np.array_equal(h.channels["heater_current"], np.array([100.0, 110, 120, 130]) * 1e-3)
    assert np.array_equal(h.channels["v_ref"], np.array([1.0, 2, 3, 4]) * 1e-3)
    assert h.units["T_plate"] == "degC" and h.units["heater_current"] == "A"
    assert h.units["v_ref"] == "V"
    assert h.meta["housekeeping"]["converted_units"] == {
        "heater_current": "mA -> A",
        "v_ref": "mV -> V",
    }
    assert h.warnings == ("non-numeric columns ignored: label",)
    assert h.on(np.array([12.0]))["T_plate"][0] == pytest.approx(20.875)  # skips the NaN row


def test_table_csv_gz_time_column_sorted_merged(tmp_path):
    text = "time,temp\n3,30\n1,10\n2,20\n2,\n"  # out of order; epoch 2 twice, second empty
    p = tmp_path / "hk.csv.gz"
    p.write_bytes(gzip.compress(text.encode()))
    h = read_housekeeping(p)
    assert np.array_equal(h.time, [1.0, 2.0, 3.0])
    assert np.array_equal(h.channels["temp"], [10.0, 20.0, 30.0])
    assert h.units["temp"] == "unknown"
    assert h.warnings == (
        "1 records out of time order (sorted)",
        "1 records with a repeated epoch merged",
    )


def test_table_time_utc(tmp_path):
    p = tmp_path / "hk.csv"
    p.write_text("time_utc,temp\n2024-05-11T00:00:00Z,1\n2024-05-11T00:00:01Z,2\n")
    h = read_housekeeping(p)
    # 2024-05-11 00:00 UTC = 768657600 s GPS-calendar + 18 leap seconds
    assert np.array_equal(h.time, [768657618.0, 768657619.0])


@pytest.mark.parametrize(
    ("text", "match", "line"),
    [
        ("a,b\n1,2\n", "no time column .* columns are a, b", None),
        ("gps_time\n1\n2\n", "no numeric channel besides 'gps_time'; columns are gps_time", None),
        ("gps_time,x\n1,2\n,3\n", "gps_time: missing or non-finite time", 3),
        ("gps_time,x\n", "header but no data rows", 2),
        # found by the housekeeping fuzz property (properties/test_fuzz_readers.py)
        ("gps_time,x\n1,2\n1e308,3\n", "gps_time 1e\\+308 s is outside 1980-01-06", 3),
        ("time_utc,x\n2003-09-14T00:00:00Z,2\n2600-01-01T00:00:00Z,3\n",
         "time_utc 2600-01-01T00:00:00 is outside 1980-01-06 ... 2100-01-01", 3),
        ("gps_time,x,x\n1,2,3\n", r"duplicated column name\(s\) x", 1),
        ('# units: {"x": 5}\ngps_time,x\n1,2\n', "unit of 'x' is a number, not a string", 1),
    ],
)  # fmt: skip
def test_table_bad(tmp_path, text, match, line):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(FormatError, match=match) as err:
        read_housekeeping(p)
    assert err.value.path == str(p) and err.value.line == line


def test_table_corrupt_parquet(tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    p = tmp_path / "hk.parquet"
    table = pa.table({"gps_time": [1.0, 2.0], "T": [3.0, 4.0]})
    pq.write_table(table.replace_schema_metadata({b"accal.units": b'{"T": "\xff\xfe"}'}), p)
    expect(p, "metadata|corrupt")  # whichever layer notices; names the file
    write_table({"gps_time": [1.0, 2.0], "T": [3.0, 4.0]}, p)
    expect(write(tmp_path, "cut.parquet", p.read_bytes()[:-20]), "corrupt Parquet file")


def test_table_odd_column_names_stay_on_one_line(tmp_path):
    p = write(tmp_path, "odd.csv", b'"a\nb",c\n1,2\n')
    expect(p, r"no time column .* columns are 'a\\nb', c")


def test_a_huge_column_name_keeps_the_message_short(tmp_path):
    """Found by the deep fuzz (seed 12): 400 '9's glued to the time column's name made the
    'no time column' message 500 characters long."""
    p = write(tmp_path, "hk.csv", b"9" * 400 + b'"gps_time","tesu"\n1,2\n3,4\n')
    err = expect(p, r"no time column .* columns are 9{39}…, tesu")
    assert len(str(err)) < len(str(p)) + 300
    many = ",".join(f"column_{k:03d}" for k in range(60)).encode()
    err = expect(
        write(tmp_path, "many.csv", many + b"\n" + b",".join([b"1"] * 60) + b"\n"), "no time column"
    )
    assert len(str(err)) < len(str(p)) + 300 and "more)" in str(err)


# ---------------------------------------------------------------- quirks of AHK1B files


def test_duplicates_merged_and_order_restored(samples, tmp_path):
    header, lines = split_sample(samples["grace_ahk_a"])
    p = tmp_path / "AHK1B_dup.asc"
    p.write_bytes(header + b"".join([lines[4], *lines[:4], lines[4], *lines[5:]]))
    h = read_housekeeping(p)
    ref = read_housekeeping(samples["grace_ahk_a"])
    assert np.array_equal(h.time, ref.time)
    assert all(np.array_equal(h.channels[k], ref.channels[k], equal_nan=True) for k in ref.channels)
    assert "1 records out of time order (sorted)" in h.warnings
    assert "1 records with a repeated epoch merged" in h.warnings
    assert "header announces 58 data records, file has 59" in h.warnings


def test_unverified_bit_named_by_position(samples, tmp_path):
    header, lines = split_sample(samples["grace_ahk_a"])
    # bit 30 ("not currently used" in GRACEiolib.h) set: one extra value after icu_blk_nr
    rec = b"116769900  0  G  A  00000100   01000100000000000000000001000000  10.5 35100 7.25\n"
    p = tmp_path / "AHK1B_bit30.asc"
    p.write_bytes(header + b"".join(lines) + rec)
    h = read_housekeeping(p)
    assert h.channels["ahk_field_30"][-1] == 7.25 and h.units["ahk_field_30"] == "unknown"
    assert np.isnan(h.channels["ahk_field_30"][:-1]).all()
    assert h.meta["housekeeping"]["positional_fields"] == ["ahk_field_30"]
    assert "prod_flag bits without a verified field read by position: ahk_field_30" in h.warnings


def test_receiver_time_and_foreign_id_are_warnings(samples, tmp_path):
    header, lines = split_sample(samples["grace_ahk_a"])
    p = tmp_path / "AHK1B_R.asc"
    p.write_bytes(header + b"".join(ln.replace(b"  G  A  ", b"  R  B  ") for ln in lines))
    h = read_housekeeping(p)
    assert h.satellite == "GRACE-A"
    assert "58 records carry receiver time (time_ref R), not GPS time" in h.warnings
    assert "records carry satellite id 'B' but the header names 'A'" in h.warnings


# ---------------------------------------------------------------- bad input


def write(tmp_path, name, data):
    p = tmp_path / name
    p.write_bytes(data)
    return p


def expect(path, match, line=None, exc=FormatError):
    with pytest.raises(exc, match=match) as err:
        read_housekeeping(path)
    assert isinstance(err.value, AccalError)
    assert err.value.path == str(path)
    assert line is None or err.value.line == line
    assert "\n" not in str(err.value) and str(path) in str(err.value)
    return err.value


def test_missing_dir_empty_garbage(tmp_path):
    expect(tmp_path / "nope.asc", "no such file")
    expect(tmp_path, "is a directory")
    expect(write(tmp_path, "empty.asc", b""), "empty file")
    expect(write(tmp_path, "blank.asc", b"  \n\n"), "empty file")
    expect(write(tmp_path, "bin.asc", bytes(range(256)) * 4), "binary data")
    expect(write(tmp_path, "text.asc", b"hello world\nfoo\n"), "no time column")
    expect(write(tmp_path, "bad.gz", gzip.compress(b"x" * 100)[:20]), "corrupt gzip")


@pytest.mark.parametrize("name", ["grace_ahk_a", "gracefo_ahk_c"])
def test_header_only_and_truncated_header(samples, tmp_path, name):
    header, lines = split_sample(samples[name])
    line = header.count(b"\n") + 1
    expect(write(tmp_path, "hdr.txt", header), "header but no data records", line)
    expect(write(tmp_path, "cut.txt", header[: len(header) // 2]), "no end-of-header marker")


@pytest.mark.parametrize("name", ["grace_ahk_b", "gracefo_ahk_d"])
def test_truncated_mid_record(samples, tmp_path, name):
    raw = samples[name].read_bytes()
    last = raw.count(b"\n")  # the cut line is the last one, without its newline
    expect(write(tmp_path, "cut.txt", raw[:-30]), "truncated last line", last)


def test_truncated_mid_record_gz(samples, tmp_path):
    raw = samples["grace_ahk_a"].read_bytes()
    expect(write(tmp_path, "cut.asc.gz", gzip.compress(raw[:-7])), "truncated last line")


def bad_record(samples, tmp_path, name, k, old, new):
    """Sample ``name`` with ``old`` replaced by ``new`` in data line k; returns (path, line).

    ``old=None`` replaces the whole line.
    """
    header, lines = split_sample(samples[name])
    if old is None:  # replace the whole line
        lines[k] = new
    else:
        assert old in lines[k]
        lines[k] = lines[k].replace(old, new, 1)
    return write(tmp_path, "bad.txt", header + b"".join(lines)), header.count(b"\n") + 1 + k


@pytest.mark.parametrize(
    ("k", "old", "new", "match"),
    [
        (3, b" 34996\n", b"\n", "record has 14 fields, its prod_flag 0000010000000000001111111"),
        (5, b"  00000100   0000", b"  00000100   1000", "record has 15 fields, its prod_flag 1000"),
        (2, b"00000100000000000011111111000000", b"0000010000000000001111111100000x", "prod_flag"),
        (2, b"  00000100   ", b"  0000010   ", "qualflg b'0000010' is not 8 characters"),
        (
            6,
            b"10.14370782035684",
            b"10.14.370782",
            r"bias_vol: not a finite number: b'10.14.370782'",
        ),
        (6, b"10.14370782035684", b"nan", "bias_vol: not a finite number: b'nan'"),
        (10, b"  10111111  ", b"  10121111  ", "status: not 0/1 bits"),
        (1, b"116769311  955939", b"116769311  1955939", r"time fraction 1955939 µs is not in"),
        (1, b"116769311  955939", b"11676x311  955939", "time: not an integer number of seconds"),
        (1, b"116769311  955939", b"99999999999  955939", "outside"),
        (1, b"  G  A  ", b"  GG  A  ", "time_ref b'GG' is not one character"),
        (1, b"  G  A  ", b"  X  A  ", "time_ref 'X' is not G"),
        (1, b"  G  A  ", b"  G  E  ", "satellite id 'E' is not one of A, B, C, D"),
        (1, b"  G  A  ", b"  G  B  ", r"mixed satellite ids \['A', 'B'\]"),
        (1, None, b"116769311  955939  G\n", "record has 3 fields, expected at least 6"),
        (1, b"  G  A  ", b"  G \x01A  ", "control character inside a record"),
    ],
)
def test_bad_grace_records(samples, tmp_path, k, old, new, match):
    p, line = bad_record(samples, tmp_path, "grace_ahk_a", k, old, new)
    err = expect(p, match)
    if "mixed" not in match and "'X'" not in match and "'E'" not in match:
        assert err.line == line


def test_bad_gracefo_record(samples, tmp_path):
    p, line = bad_record(samples, tmp_path, "gracefo_ahk_c", 9, b" 1 0 0 ", b" 1 0 ")
    expect(
        p, "record has 11 fields, its prod_flag 00111100001000000000000001000000 announces 12", line
    )


def test_other_products_are_unsupported(samples, tmp_path):
    expect(
        samples["grace_a"],
        r"'ipACC1BF' is not accelerometer housekeeping \(AHK1B\) \(accelerometer data: "
        r"give it as an input file, not as --aux; in Python read it with accal\.io\.read\)",
        3,
        UnsupportedFormatError,
    )
    expect(
        samples["gracefo_c"],
        "columns gps_time GRACEFO_id .* are not AHK1B",
        None,
        UnsupportedFormatError,
    )
    header, lines = split_sample(samples["grace_ahk_a"])
    binary = header.replace(
        b"FILE FORMAT 0=BINARY 1=ASCII  : 1", b"FILE FORMAT 0=BINARY 1=ASCII  : 0"
    )
    expect(
        write(tmp_path, "b.asc", binary + b"".join(lines)),
        "binary AHK1B",
        4,
        UnsupportedFormatError,
    )


def test_gracefo_unknown_prod_flag_layout(samples, tmp_path):
    header, lines = split_sample(samples["gracefo_ahk_c"])
    swapped = header.replace(b"bit 14 = TSU_Y+", b"bit 14 = TSU_X+")
    p = write(tmp_path, "swapped.txt", swapped + b"".join(lines))
    expect(
        p,
        "prod_flag bit 14 is 'TSU_X\\+' in the YAML header, expected 'TSU_Y\\+'",
        None,
        UnsupportedFormatError,
    )


def test_bad_headers(samples, tmp_path):
    header, lines = split_sample(samples["grace_ahk_a"])
    body = b"".join(lines)
    sat = header.replace(
        b"SATELLITE NAME                : GRACE A", b"SATELLITE NAME                : GRACE Q"
    )
    expect(write(tmp_path, "sat.asc", sat + body), "'SATELLITE NAME' is 'GRACE Q'", 9)
    n = header.replace(
        b"NUMBER OF DATA RECORDS        : 58", b"NUMBER OF DATA RECORDS        : many"
    )
    expect(write(tmp_path, "n.asc", n + body), "'NUMBER OF DATA RECORDS' is not an integer", 14)
    fheader, flines = split_sample(samples["gracefo_ahk_c"])
    plat = fheader.replace(b"platform: GRACE C", b"platform: GRACE X")
    expect(write(tmp_path, "p.txt", plat + b"".join(flines)), "platform is 'GRACE X'")
    yaml_bad = fheader.replace(b"  dimensions:\n", b"  dimensions: [\n", 1)
    expect(write(tmp_path, "y.txt", yaml_bad + b"".join(flines)), "YAML header")


def test_gracefo_global_attributes_not_a_mapping(samples, tmp_path):
    """Found by the deep fuzz (seed 34): a YAML header whose global_attributes is a list
    raised AttributeError instead of the one-line error naming the file."""
    header, lines = split_sample(samples["gracefo_ahk_c"])
    text = header.decode()
    start = text.index("  global_attributes:\n")
    end = text.index("\n  ", start + len("  global_attributes:\n") + 1)
    while text[end + 3] == " ":  # the mapping's indented lines
        end = text.index("\n  ", end + 1)
    mutated = text[:start] + "  global_attributes:\n    - platform: GRACE C" + text[end:]
    p = write(tmp_path, "AHK1B_2023-06-01_C_04.txt", mutated.encode() + b"".join(lines))
    expect(p, "'global_attributes' is not a mapping")
