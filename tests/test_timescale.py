"""Tests of accal.timescale against hand-computed values.

Leap seconds from IERS Bulletin C; GRACE day starts from SOURCES.md and the
``TIME FIRST OBS`` header lines of the real 2003-09-14 ACC1B files.
"""

import numpy as np
import pytest

from accal.errors import ValidationError
from accal.timescale import (
    gps_day_start,
    gps_minus_utc,
    gps_to_date,
    gps_to_gps_calendar,
    gps_to_utc,
    utc_to_gps,
)


def test_epoch_is_1159_47_utc():
    # 2000-01-01 12:00:00 GPS = 11:59:47 UTC (GPS−UTC = 13 s in 2000).
    assert utc_to_gps(["2000-01-01T11:59:47"])[0] == 0.0


@pytest.mark.parametrize(
    ("utc", "offset"),
    [
        ("1999-12-31", 13),
        ("2003-09-14", 13),
        ("2005-12-31T23:59:59", 13),
        ("2006-01-01", 14),
        ("2012-07-01", 16),
        ("2016-12-31T23:59:59", 17),
        ("2017-01-01", 18),
        ("2024-05-11", 18),
    ],
)
def test_gps_minus_utc_table(utc, offset):
    assert gps_minus_utc([utc])[0] == offset


def test_known_value_2024():
    # 2024-05-11 is 8897 days after 2000-01-01; GPS−UTC = 18 s.
    expected = 8897 * 86400 - 43200 + 18
    assert utc_to_gps(["2024-05-11T00:00:00"])[0] == expected
    assert utc_to_gps(np.array(["2024-05-11T00:00:00"], dtype="datetime64[ns]"))[0] == expected
    assert utc_to_gps(["2024-05-11T00:00:00Z"])[0] == expected
    assert gps_to_utc([expected])[0] == np.datetime64("2024-05-11T00:00:00")


def test_fraction_preserved():
    g = utc_to_gps(["2024-05-11T00:00:00.796"])[0]
    assert g == pytest.approx(768657618.796, abs=1e-6)
    # float64 resolution at 7.7e8 s is ~1.2e-7 s: the round trip is good to < 1 µs.
    back = gps_to_utc([g])[0] - np.datetime64("2024-05-11T00:00:00.796", "ns")
    assert abs(back.astype(np.int64)) < 1000


def test_across_leap_second_2017():
    # 2016-12-31T23:59:59 UTC = 536500799 + 17; 2017-01-01T00:00:00 UTC = 536500800 + 18:
    # two UTC seconds apart in SI time because of the inserted 23:59:60.
    a, b = utc_to_gps(["2016-12-31T23:59:59", "2017-01-01T00:00:00"])
    assert (a, b) == (536500816.0, 536500818.0)
    assert gps_to_utc([a])[0] == np.datetime64("2016-12-31T23:59:59")
    # 23:59:60 cannot be represented: it maps onto the following midnight.
    assert gps_to_utc([536500817.0])[0] == np.datetime64("2017-01-01T00:00:00")


def test_round_trip_vectorised():
    utc = np.arange("2000-01-02", "2024-12-31", np.timedelta64(997, "h"), dtype="datetime64[ns]")
    assert np.array_equal(gps_to_utc(utc_to_gps(utc)), utc)


def test_gps_day_start_grace_convention():
    assert gps_day_start("2003-09-14") == 116769600.0
    assert gps_day_start("2005-01-01") == 157809600.0
    assert gps_day_start("2023-06-01") == 738849600.0  # GRACE-FO start_time_epoch_secs
    assert gps_day_start("2003-09-14", scale="utc") == 116769613.0
    assert gps_day_start("2024-05-11", scale="utc") == 8897 * 86400 - 43200 + 18


def test_gps_to_date():
    assert gps_to_date(116769600.0) == "2003-09-14"
    assert gps_to_date(116769600.0 - 0.5) == "2003-09-13"
    assert gps_to_date(116769600.0 + 86399.5) == "2003-09-14"
    # 12 s after GPS midnight is still the previous UTC day in 2003.
    assert gps_to_date(116769612.0, scale="utc") == "2003-09-13"
    assert gps_to_date(116769613.0, scale="utc") == "2003-09-14"


def test_gps_calendar():
    assert gps_to_gps_calendar([116769600.0])[0] == np.datetime64("2003-09-14T00:00:00")


def test_errors():
    with pytest.raises(ValueError, match="before 1972"):
        utc_to_gps(["1970-01-01"])
    with pytest.raises(ValueError, match="finite"):
        gps_to_utc([np.nan])
    with pytest.raises(ValidationError, match="'scale'"):
        gps_day_start("2003-09-14", scale="tai")
    with pytest.raises(TypeError, match="datetime64"):
        utc_to_gps(np.array([1.0]))


def test_conversions_past_the_leap_second_table_warn():
    """Issue 21: the leap-second table has a "valid until" date and a warning past it;
    the last valid day and everything before it convert silently."""
    import warnings

    from accal.timescale import (
        LEAP_SECONDS_VALID_UNTIL,
        LeapSecondTableWarning,
        gps_to_utc,
        utc_to_gps,
    )

    last = np.datetime64(LEAP_SECONDS_VALID_UNTIL) + np.timedelta64(86399, "s")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        g = utc_to_gps([np.datetime64("2003-09-14T00:00:00"), last])
        assert gps_to_utc(g)[1] == last
    with pytest.warns(LeapSecondTableWarning, match=LEAP_SECONDS_VALID_UNTIL):
        later = utc_to_gps([last + np.timedelta64(1, "s")])
    with pytest.warns(LeapSecondTableWarning, match="update accal"):
        assert gps_to_utc(later)[0] == last + np.timedelta64(1, "s")
