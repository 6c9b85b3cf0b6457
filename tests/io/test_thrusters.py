"""THR1B thruster reader, firing mask and THR1B file lookup.

Real files: the four THR1B samples in ``data/samples/`` (see PROVENANCE.md).  Values
written out by hand quote the line they come from; event counts are checked against
an independent count made with plain string splitting of the raw text.
"""

import gzip
import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from accal.errors import FormatError, UnsupportedFormatError, ValidationError
from accal.io.thrusters import (
    GRACE_ACCUM_COLUMNS,
    GRACEFO_ACCUM_COLUMNS,
    THRUSTERS,
    FiringEvents,
    ThrusterFirings,
    find_thruster_file,
    firing_mask,
    read_thrusters,
)

SAMPLES_DIR = Path(__file__).resolve().parents[2] / "data" / "samples"

THR = {
    "A": SAMPLES_DIR / "THR1B_2003-09-14_A_00.asc",
    "B": SAMPLES_DIR / "THR1B_2003-09-14_B_00.asc",
    "C": SAMPLES_DIR / "THR1B_2023-06-01_C_04.txt",
    "D": SAMPLES_DIR / "THR1B_2023-06-01_D_04.txt",
}
#: letter -> (satellite, records in the file, header's record count, 1-based line of record 1)
EXPECTED = {
    "A": ("GRACE-A", 58, 58, 31),
    "B": ("GRACE-B", 58, 58, 31),
    "C": ("GRACE-FO-C", 100, 459, 285),  # cut after 100 records (PROVENANCE.md)
    "D": ("GRACE-FO-D", 100, 454, 285),
}


def split_raw(path):
    """(header text incl. its end line, list of data lines) by plain string handling."""
    text = path.read_text()
    for marker in ("# End of YAML header\n", "END OF HEADER"):
        i = text.find(marker)
        if i >= 0:
            j = text.index("\n", i) + 1
            return text[:j], [ln for ln in text[j:].split("\n") if ln.strip()]
    raise AssertionError(path)


def independent_events(path, gracefo):
    """Events counted from the raw text: count increases between consecutive lines, plus
    on-times of the first line, plus (GRACE-FO) on-times of the uncounted orbit thrusters."""
    _, lines = split_raw(path)
    rows = [ln.split() for ln in lines]
    n = sum(1 for k in range(14) if int(rows[0][18 + k]) > 0)
    for prev, cur in zip(rows, rows[1:], strict=False):
        for k in range(14):
            if gracefo and k >= 12:
                n += int(cur[18 + k]) > 0
            elif int(cur[4 + k]) > int(prev[4 + k]):
                n += 1
    return n


def with_records(path, tmp_path, lines, name=None):
    """A copy of sample ``path`` with its data lines replaced by ``lines``."""
    header, _ = split_raw(path)
    out = tmp_path / (name or path.name)
    out.write_text(header + "".join(ln + "\n" for ln in lines))
    return out


# ---------------------------------------------------------------- real files


@pytest.mark.parametrize("letter", sorted(THR))
def test_real_samples(letter):
    sat, n_rows, n_header, _ = EXPECTED[letter]
    gracefo = letter in "CD"
    r = read_thrusters(THR[letter])
    assert isinstance(r, ThrusterFirings)
    assert r.satellite == sat
    assert len(r) == n_rows == r.meta["thrusters"]["n_rows"]
    assert r.meta["thrusters"]["n_records_header"] == n_header
    if gracefo:
        assert int(r.meta["gracefo"]["dimensions"]["num_records"]) == n_header
        assert r.warnings == (f"header announces {n_header} data records, file has {n_rows}",)
        assert r.uncounted == ("orb_ctrl_1", "orb_ctrl_2")
    else:
        assert int(r.meta["grace"]["NUMBER OF DATA RECORDS"]) == n_header == n_rows
        assert r.warnings == ()
        assert r.uncounted == ()
    assert r.counts.shape == r.on_time.shape == (n_rows, 14)
    assert np.all(np.diff(r.time) > 0)
    assert np.all(np.diff(r.counts, axis=0) >= 0)
    assert len(r.events) == independent_events(THR[letter], gracefo)
    # every event: its start is a record epoch, its duration that record's on-time
    e = r.events
    np.testing.assert_array_equal(e.start, r.time[e.record])
    np.testing.assert_array_equal(e.duration, r.on_time[e.record, e.thruster])
    assert np.all(np.diff(e.start) >= 0)
    assert np.all(e.duration > 0)
    # attitude thrusters fire in pairs: 1_k and 2_k at the same epoch, same on-time
    one = sorted(
        (s, k, d) for s, k, d in zip(e.start, e.thruster, e.duration, strict=True) if k < 6
    )
    two = sorted(
        (s, k - 6, d)
        for s, k, d in zip(e.start, e.thruster, e.duration, strict=True)
        if 6 <= k < 12
    )
    assert one == two
    assert not np.any(e.thruster >= 12)  # no orbit manoeuvre in the samples


def test_real_sample_counts_and_totals():
    """Events, thrusters that fired and total on-time of each sample (reported in the PR)."""
    got = {}
    for letter, path in THR.items():
        r = read_thrusters(path)
        fired = sorted({THRUSTERS[k] for k in r.events.thruster})
        got[letter] = (len(r.events), len(fired), round(float(r.events.duration.sum()), 3))
    assert got == {
        "A": (118, 10, 16.154),
        "B": (116, 8, 25.884),
        "C": (200, 8, 10.034),
        "D": (200, 6, 10.012),
    }


def test_grace_a_values_by_hand():
    r = read_thrusters(THR["A"])
    # line 31: 116769836 624445 G A   217258 ... 1 1 49 0 0 0 180 0 49 0 0 0 180 0 0 0 ...
    assert r.time[0] == 116769836 + 624445e-6
    assert r.counts[0, 0] == 217258 and r.counts[0, 12:].tolist() == [1, 1]
    first = r.events.record == 0  # first record: events from its on-times (cycles 0)
    assert sorted(THRUSTERS[k] for k in r.events.thruster[first]) == [
        "att_ctrl_1_1",
        "att_ctrl_1_5",
        "att_ctrl_2_1",
        "att_ctrl_2_5",
    ]
    assert sorted(r.events.duration[first].tolist()) == [0.049, 0.049, 0.18, 0.18]
    assert np.all(r.events.cycles[first] == 0)
    # line 32: 116769858 624440 G A   217259 ... (att_ctrl_1_1 +1, on-time 52 ms)
    second = r.events.record == 1
    assert r.events.start[second].tolist() == [116769858 + 624440e-6] * 2
    assert [THRUSTERS[k] for k in r.events.thruster[second]] == ["att_ctrl_1_1", "att_ctrl_2_1"]
    assert r.events.duration[second].tolist() == [0.052, 0.052]
    assert r.events.cycles[second].tolist() == [1, 1]
    # line 53 (record 22): 245387 -> 245389 for att_ctrl_1_3, on-time 108 ms: one event
    k = THRUSTERS.index("att_ctrl_1_3")
    (i,) = np.flatnonzero((r.events.record == 22) & (r.events.thruster == k))
    assert r.events.cycles[i] == 2 and r.events.duration[i] == 0.108


def test_accumulated_durations_match_on_times():
    """Fields 33-46: GRACE one per thruster, GRACE-FO att/orb totals; all in s."""
    for letter in "AB":
        r = read_thrusters(THR[letter])
        assert tuple(r.accum_dur) == GRACE_ACCUM_COLUMNS
        for k, name in enumerate(GRACE_ACCUM_COLUMNS):
            np.testing.assert_allclose(np.diff(r.accum_dur[name]), r.on_time[1:, k], atol=1e-9)
    for letter in "CD":
        r = read_thrusters(THR[letter])
        assert tuple(r.accum_dur) == GRACEFO_ACCUM_COLUMNS
        d = np.diff(r.accum_dur["accum_dur_att_ctrl"])
        np.testing.assert_allclose(d, r.on_time[1:, :12].sum(axis=1), atol=1e-9)
    # line 285 of D: ... 106517163 0 ... 27414000 0   00001100
    r = read_thrusters(THR["D"])
    assert r.accum_dur["accum_dur_att_ctrl"][0] == 106517.163
    assert r.accum_dur["accum_dur_orb_ctrl"][0] == 27414.0
    assert r.qualflg[0] == 0b00001100  # branches 1 and 2 active


def test_gzip_input(tmp_path):
    gz = tmp_path / (THR["C"].name + ".gz")
    gz.write_bytes(gzip.compress(THR["C"].read_bytes()))
    a, b = read_thrusters(THR["C"]), read_thrusters(gz)
    np.testing.assert_array_equal(a.time, b.time)
    np.testing.assert_array_equal(a.events.start, b.events.start)
    np.testing.assert_array_equal(a.counts, b.counts)


# ---------------------------------------------------------------- counters


def test_counter_going_back_is_no_event(tmp_path):
    _, lines = split_raw(THR["A"])
    rows = [ln.split() for ln in lines[:3]]
    rows[2][4] = "5"  # att_ctrl_1_1 counter 217259 -> 5 (reset) at the third record
    path = with_records(THR["A"], tmp_path, [" ".join(r) for r in rows])
    r = read_thrusters(path)
    assert not np.any((r.events.record == 2) & (r.events.thruster == 0))
    (w,) = [w for w in r.warnings if "went back" in w]
    assert w == "counters went back (reset or wrap), no event: 1 (att_ctrl_1_1; first at line 33)"


def test_on_time_without_count_and_zero_on_time(tmp_path):
    _, lines = split_raw(THR["C"])
    rows = [ln.split() for ln in lines[:3]]
    rows[1][4] = rows[0][4]  # no count increase for att_ctrl_1_1, on-time 50 ms kept
    rows[2][18] = "0"  # count increase with on-time 0 (on-time not calculated)
    r = read_thrusters(with_records(THR["C"], tmp_path, [" ".join(r) for r in rows]))
    assert not np.any((r.events.record == 1) & (r.events.thruster == 0))
    (i,) = np.flatnonzero((r.events.record == 2) & (r.events.thruster == 0))
    assert r.events.duration[i] == 0 and r.events.cycles[i] == 2  # 2 increases since record 0
    assert any(w.startswith("on-times without a count increase, not taken as firings: 1 (att")
               for w in r.warnings)  # fmt: skip
    assert "1 firings without an on-time (duration 0 s)" in r.warnings


def test_gracefo_orbit_thrusters_from_on_time(tmp_path):
    _, lines = split_raw(THR["D"])
    rows = [ln.split() for ln in lines[:2]]
    rows[1][30] = "1500"  # on_time_orb_ctrl_1 (field 31), counter undefined (0)
    r = read_thrusters(with_records(THR["D"], tmp_path, [" ".join(r) for r in rows]))
    k = THRUSTERS.index("orb_ctrl_1")
    (i,) = np.flatnonzero(r.events.thruster == k)
    assert r.events.record[i] == 1 and r.events.duration[i] == 1.5 and r.events.cycles[i] == 0


def test_out_of_order_records_sorted(tmp_path):
    _, lines = split_raw(THR["A"])
    path = with_records(THR["A"], tmp_path, [lines[1], lines[0], lines[2]])
    r = read_thrusters(path)
    assert np.all(np.diff(r.time) > 0)
    assert "1 records out of time order (sorted)" in r.warnings
    assert len(r.events) == independent_events(with_records(THR["A"], tmp_path, lines[:3], "x"), 0)


# ---------------------------------------------------------------- errors


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        (5, "12x", r"thrust_count_att_ctrl_1_2 \(field 6\): not a non-negative integer: '12x'"),
        (20, "-3", r"on_time_att_ctrl_1_3 \(field 21\): not a non-negative integer: '-3'"),
        (1, "1000000", r"time_frac 1000000 µs is not in 0 \.\.\. 999999"),
        (2, "X", r"time_ref 'X' is not G \(GPS\) or R \(receiver\)"),
        (3, "Q", r"satellite id 'Q' is not one of A, B, C, D"),
        (46, "0000110", r"qualflg '0000110' is not 8 characters of 0/1"),
        (46, "00001100 7", r"record has 48 fields, expected 47"),
    ],
)
def test_malformed_line_names_file_and_line(tmp_path, field, value, message):
    _, lines = split_raw(THR["C"])
    rows = [ln.split() for ln in lines[:5]]
    rows[3][field] = value
    path = with_records(THR["C"], tmp_path, [" ".join(r) for r in rows])
    with pytest.raises(FormatError, match=message) as info:
        read_thrusters(path)
    assert info.value.line == 285 + 3
    assert str(info.value).startswith(f"{path}:288: ")
    assert "\n" not in str(info.value)


def test_truncated_record(tmp_path):
    header, lines = split_raw(THR["A"])
    path = tmp_path / THR["A"].name
    path.write_text(header + lines[0] + "\n" + lines[1][:40] + "\n")
    with pytest.raises(FormatError, match=r"record has \d+ fields, expected 47") as info:
        read_thrusters(path)
    assert info.value.line == 32


def test_header_without_records(tmp_path):
    path = with_records(THR["B"], tmp_path, [])
    with pytest.raises(FormatError, match="header but no data records"):
        read_thrusters(path)


def test_other_products_refused():
    with pytest.raises(UnsupportedFormatError, match="ipACC1BF.*not thruster data"):
        read_thrusters(SAMPLES_DIR / "ACC1B_2003-09-14_A_00.asc")
    with pytest.raises(
        UnsupportedFormatError, match="column 1 is 'gps_time', expected 'time_intg'"
    ):
        read_thrusters(SAMPLES_DIR / "ACT1B_2023-06-01_C_04.txt")


def test_missing_file(tmp_path):
    with pytest.raises(FormatError, match="no such file"):
        read_thrusters(tmp_path / "THR1B_2003-09-14_A_00.asc")


# ---------------------------------------------------------------- firing_mask


def events(start, duration):
    return FiringEvents.from_intervals(start, duration)


def test_mask_interval_edges():
    ev = events([10.0], [0.5])
    lo, hi = 10.0 - 0.1, (10.0 + 0.5) + 0.7
    t = [np.nextafter(lo, -np.inf), lo, 10.0, 10.5, hi, np.nextafter(hi, np.inf), np.nan]
    assert firing_mask(t, ev).tolist() == [False, True, True, True, True, False, False]


def test_mask_zero_margins_and_zero_duration():
    ev = events([5.0], [0.0])
    assert firing_mask([4.999, 5.0, 5.001], ev, before=0, after=0).tolist() == [False, True, False]


def test_mask_overlapping_and_nested_intervals():
    # [-0.1, 1.7] and [1.4, 2.2] overlap; [2.9, 13.7] contains [4.9, 5.8]
    ev = events([5.0, 1.5, 0.0, 3.0], [0.1, 0.0, 1.0, 10.0])
    t = np.array([-0.2, -0.1, 1.8, 2.2, 2.3, 2.9, 6.0, 13.7, 13.8])
    want = [False, True, True, True, False, True, True, True, False]
    assert firing_mask(t, ev).tolist() == want
    rev = t[::-1]  # any order of the samples
    assert firing_mask(rev, ev).tolist() == want[::-1]


def test_mask_touching_intervals():
    ev = events([0.0, 1.0], [0.2, 0.0])  # [-0.1, 0.9] and [0.9, 1.7]
    assert firing_mask([0.9, 1.0, 1.7, 1.75], ev).tolist() == [True, True, True, False]


def test_mask_empty():
    empty = events([], [])
    assert firing_mask(np.arange(5.0), empty).tolist() == [False] * 5
    assert firing_mask([], events([1.0], [0.1])).shape == (0,)


def test_mask_on_real_firings():
    r = read_thrusters(THR["B"])
    t = np.arange(np.floor(r.time[0]) - 5, np.ceil(r.time[-1]) + 5, 0.1)
    m = firing_mask(t, r)
    np.testing.assert_array_equal(m, firing_mask(t, r.events))
    assert firing_mask(r.events.start, r).all()
    assert firing_mask(r.events.end + 0.7, r).all()
    assert not m[0] and not m[-1]


def test_mask_validation():
    ev = events([1.0], [0.1])
    with pytest.raises(ValidationError, match="before must be finite and >= 0"):
        firing_mask([1.0], ev, before=-0.1)
    with pytest.raises(ValidationError, match="after must be finite and >= 0"):
        firing_mask([1.0], ev, after=np.inf)
    with pytest.raises(ValidationError, match="must be 1-D"):
        firing_mask(np.zeros((2, 2)), ev)
    with pytest.raises(ValidationError, match="firings must be ThrusterFirings or FiringEvents"):
        firing_mask([1.0], [(1.0, 0.1)])
    with pytest.raises(ValidationError, match="durations must be finite and >= 0"):
        events([1.0], [-0.1])
    with pytest.raises(ValidationError, match="duration must have shape"):
        events([1.0, 2.0], [0.1])


finite = st.floats(-50, 50, allow_nan=False, allow_infinity=False)


@settings(max_examples=200, deadline=None)
@given(
    starts=st.lists(finite, max_size=12),
    data=st.data(),
    times=st.lists(finite, max_size=40),
    before=st.floats(0, 3),
    after=st.floats(0, 3),
)
def test_mask_equals_brute_force(starts, data, times, before, after):
    durations = data.draw(st.lists(st.floats(0, 5), min_size=len(starts), max_size=len(starts)))
    # samples on interval edges too
    times = (
        times
        + [s - before for s in starts]
        + [(s + d) + after for s, d in zip(starts, durations, strict=True)]
    )
    want = [
        any(s - before <= t <= (s + d) + after for s, d in zip(starts, durations, strict=True))
        for t in times
    ]
    assert firing_mask(times, events(starts, durations), before, after).tolist() == want


# ---------------------------------------------------------------- find_thruster_file


def test_find_thruster_file_samples():
    assert find_thruster_file(SAMPLES_DIR / "ACC1B_2003-09-14_A_00.asc") == THR["A"]
    assert find_thruster_file(SAMPLES_DIR / "ACC1B_2003-09-14_B_00.dat") == THR["B"]
    assert find_thruster_file(SAMPLES_DIR / "ACT1B_2023-06-01_C_04.txt") == THR["C"]
    assert find_thruster_file(str(SAMPLES_DIR / "ACT1B_2023-06-01_D_04.txt")) == THR["D"]
    assert find_thruster_file(SAMPLES_DIR / "ACC1B_2003-09-15_A_00.asc") is None  # other date
    assert find_thruster_file(SAMPLES_DIR / "ACC1B_2003-09-14_A_02.asc") is None  # other release
    assert find_thruster_file(SAMPLES_DIR / "SW_A_ACCACAL_20240511_a_cal_x.csv.gz") is None


def test_find_thruster_file_gz(tmp_path):
    acc = tmp_path / "ACC1B_2003-09-14_A_00.asc.gz"
    acc.write_bytes(b"")
    assert find_thruster_file(acc) is None
    thr_gz = tmp_path / "THR1B_2003-09-14_A_00.asc.gz"
    shutil.copy(THR["A"], thr_gz)
    assert find_thruster_file(acc) == thr_gz
    thr = tmp_path / "THR1B_2003-09-14_A_00.asc"
    shutil.copy(THR["A"], thr)
    assert find_thruster_file(acc) == thr_gz  # a gzipped input prefers the gzipped file
    assert find_thruster_file(tmp_path / "ACC1B_2003-09-14_A_00.asc") == thr
    act = tmp_path / "GRACEFO_ACT1B_2023-06-01_C_04.txt"
    thr_c = tmp_path / "GRACEFO_THR1B_2023-06-01_C_04.txt.gz"
    shutil.copy(THR["C"], thr_c)
    assert find_thruster_file(act) == thr_c
