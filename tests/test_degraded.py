"""Degraded-day classification: the built-in table, header evidence, user tables."""

import datetime as dt

import numpy as np
import pytest

from accal.degraded import (
    DEFAULT_PERIODS,
    STATUSES,
    Period,
    classify_day,
    header_evidence,
    header_product,
    load_periods,
    normalise_satellite,
)
from accal.errors import FormatError, ValidationError
from accal.io.grace_l1b import read_grace_acc1b

# ---------------------------------------------------------------- real sample files


def test_real_gracefo_d_is_a_transplant(samples):
    s = read_grace_acc1b(samples["gracefo_d"])
    status, reason = classify_day(s.satellite, "2023-06-01", s.meta)
    assert status == "transplant"
    assert "GRACE-C data transplanted to D" in reason and "June 2018" in reason


def test_real_gracefo_c_and_grace_2003_are_nominal(samples):
    for name, day in (
        ("gracefo_c", "2023-06-01"),
        ("grace_a", "2003-09-14"),
        ("grace_b", "2003-09-14"),
    ):
        s = read_grace_acc1b(samples[name])
        assert classify_day(s.satellite, day, s.meta) == ("nominal", ""), name


def test_real_headers_do_not_say_transplant(samples):
    """The RL04 ACT1B header of D reads like C's: the date table must do the flagging."""
    d = read_grace_acc1b(samples["gracefo_d"]).meta
    c = read_grace_acc1b(samples["gracefo_c"]).meta
    assert header_evidence(d, "GRACE-FO-D") is None
    assert d["gracefo"]["global_attributes"]["title"] == c["gracefo"]["global_attributes"]["title"]
    assert header_product(d) == header_product(c) == "ACT1B"
    assert header_product(read_grace_acc1b(samples["grace_a"]).meta) == "ACC1B"
    assert header_product(None) is None and header_product({"table": {}}) is None


# ---------------------------------------------------------------- the built-in table


@pytest.mark.parametrize(
    ("satellite", "day", "status"),
    [
        ("GRACE-B", "2016-08-31", "nominal"),
        ("GRACE-B", "2016-09-01", "off"),
        ("GRACE-B", "2016-10-31", "off"),
        ("GRACE-B", "2016-11-01", "transplant"),
        ("GRACE-B", "2017-06-29", "transplant"),
        ("GRACE-A", "2016-11-01", "nominal"),
        ("GRACE-FO-D", "2018-05-21", "nominal"),  # before launch: nothing known
        ("GRACE-FO-D", "2018-05-22", "transplant"),
        ("GRACE-FO-D", "2030-01-01", "transplant"),  # open-ended
        ("GRACE-FO-C", "2018-06-21", "nominal"),
    ],
)
def test_default_table_boundaries(satellite, day, status):
    assert classify_day(satellite, day)[0] == status


def test_gracefo_d_own_accelerometer_is_degraded():
    meta = {"gracefo": {"global_attributes": {"title": "GRACE-FO Level-1B Accelerometer Data"}}}
    assert header_product(meta) == "ACC1B"
    status, reason = classify_day("GRACE-FO-D", "2020-03-01", meta)
    assert status == "degraded" and "orders of magnitude" in reason
    # Same day, ACT1B (or an unknown product): the transplant row applies.
    act = {"grace": {"FILE TYPE ipACT1BF": "8"}}
    assert classify_day("GRACE-FO-D", "2020-03-01", act)[0] == "transplant"
    assert classify_day("GRACE-FO-D", "2020-03-01", {"table": {}})[0] == "transplant"


def test_default_table_is_well_formed():
    assert {p.status for p in DEFAULT_PERIODS} <= set(STATUSES)
    for p in DEFAULT_PERIODS:
        assert p.reason and "\n" not in p.reason and len(p.reason) < 160, p
        assert p.source, p
    # Product-specific rows must precede the general row they refine (first match wins).
    d = [p for p in DEFAULT_PERIODS if p.satellite == "GRACE-FO-D"]
    assert [p.product for p in d] == ["ACC1B", None]


# ---------------------------------------------------------------- header evidence


def test_cross_satellite_input_file_means_transplant():
    meta = {"grace": {"INPUT FILE NAME": ["ACC1A<-ACC1A_2005-01-01_A_02.dat", "CLK1B<-x"]}}
    status, reason = classify_day("GRACE-B", "2005-01-01", meta)
    assert status == "transplant"
    assert "ACC1A_2005-01-01_A_" in reason and "satellite A's data, not B's" in reason
    # Its own input file is not evidence.
    own = {"grace": {"INPUT FILE NAME": "ACC1A<-ACC1A_2005-01-01_B_02.dat"}}
    assert classify_day("GRACE-B", "2005-01-01", own) == ("nominal", "")


def test_header_saying_transplant_overrides_the_table():
    meta = {
        "gracefo": {
            "global_attributes": {
                "title": "GRACE-FO Level-1B Transformed Accelerometer Data",
                "comment": "Transplanted from GRACE C with TUG force models",
            }
        }
    }
    status, reason = classify_day("GRACE-FO-C", "2023-06-01", meta)
    assert status == "transplant"
    assert reason.startswith("header global_attributes.comment says 'Transplanted from GRACE C")
    # Evidence also wins over an "off" row: the file holds someone's data after all.
    assert classify_day("GRACE-B", "2016-10-01", meta)[0] == "transplant"


# ---------------------------------------------------------------- arguments


@pytest.mark.parametrize("alias", ["GRACE-FO-D", "GRACE D", "grace-d", "GF2", "d", "GRACE-FO 2"])
def test_satellite_aliases(alias):
    assert normalise_satellite(alias) == "GRACE-FO-D"
    assert classify_day(alias, "2019-01-01")[0] == "transplant"


@pytest.mark.parametrize(
    "day",
    [
        "2016-11-01",
        "2016-11-01T23:59:59",
        dt.date(2016, 11, 1),
        dt.datetime(2016, 11, 1, 12),
        np.datetime64("2016-11-01T06:00"),
    ],
)
def test_date_types(day):
    assert classify_day("GRACE-B", day)[0] == "transplant"


def test_bad_date():
    with pytest.raises(ValidationError, match="expected a date 'YYYY-MM-DD', got '2016-13-01'"):
        classify_day("GRACE-B", "2016-13-01")


def test_other_satellites_are_nominal_with_a_reason():
    assert classify_day("Swarm-A", "2024-05-11") == (
        "nominal",
        "no degraded-day entries for Swarm-A",
    )


def test_period_validation():
    with pytest.raises(ValidationError, match="'status'"):
        Period("GRACE-B", "2016-01-01", None, "broken", "x")
    with pytest.raises(ValidationError, match="before its start"):
        Period("GRACE-B", "2016-02-01", "2016-01-01", "off", "x")
    with pytest.raises(ValidationError, match="one line"):
        Period("GRACE-B", "2016-01-01", None, "off", "two\nlines")
    with pytest.raises(ValidationError, match="'product'"):
        Period("GRACE-B", "2016-01-01", None, "off", "x", product="KBR1B")
    p = Period("GRACE B", "2016-01-01", dt.date(2016, 1, 31), "off", "x")
    assert (p.satellite, p.start) == ("GRACE-B", dt.date(2016, 1, 1))


# ---------------------------------------------------------------- user tables

TOML = """
[[period]]
satellite = "GRACE-A"
start = 2016-09-01
end = 2016-10-11
status = "off"
reason = "ICU off for battery management"

[[period]]
satellite = "GRACE D"
start = "2019-01-01"
end = "2019-01-31"
status = "nominal"
reason = "checked by hand"
"""


def test_load_periods_toml_extends_and_overrides(tmp_path):
    p = tmp_path / "days.toml"
    p.write_text(TOML)
    table = load_periods(p)
    assert len(table) == 2 + len(DEFAULT_PERIODS)
    assert classify_day("GRACE-A", "2016-10-01", periods=table) == (
        "off",
        "ICU off for battery management",
    )
    # The user's row comes first, so it overrides the built-in GRACE-D row in January 2019...
    assert classify_day("GRACE-FO-D", "2019-01-15", periods=table)[0] == "nominal"
    # ...and nowhere else.
    assert classify_day("GRACE-FO-D", "2019-02-01", periods=table)[0] == "transplant"
    assert classify_day("GRACE-B", "2016-11-01", periods=table)[0] == "transplant"


def test_load_periods_yaml_replace_defaults(tmp_path):
    p = tmp_path / "days.yaml"
    p.write_text(
        "replace_defaults: true\n"
        "period:\n"
        "  - {satellite: GRACE-A, start: 2010-01-01, status: degraded, reason: test}\n"
    )
    table = load_periods(p)
    assert len(table) == 1
    assert classify_day("GRACE-A", "2011-01-01", periods=table) == ("degraded", "test")
    assert classify_day("GRACE-FO-D", "2023-06-01", periods=table) == ("nominal", "")


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("[[period]\n", "invalid TOML"),
        (
            '[[period]]\nsatellite = "GRACE-A"\nstart = 2016-01-01\nstatus = "bad"\n',
            "period 1: .*'status'",
        ),
        ('[[period]]\nsatellite = "GRACE-A"\nstatus = "off"\n', "period 1: missing key.*start"),
        (
            '[[period]]\nsatellite = "A"\nstart = 2016-01-01\nstatus = "off"\nsince = 1\n',
            "unknown key.*since",
        ),
        ("period = 3\n", "must be a list"),
        ('[[period]]\nsatellite = "A"\nstart = "2016-99-01"\nstatus = "off"\n', "expected a date"),
        (
            '[[period]]\nsatellite = "GRACE-E"\nstart = 2016-01-01\nstatus = "off"\n',
            "period 1: unknown GRACE satellite 'GRACE-E'",
        ),
    ],
    ids=["syntax", "status", "missing", "unknown-key", "not-a-list", "bad-date", "satellite"],
)
def test_load_periods_errors(tmp_path, text, match):
    p = tmp_path / "bad.toml"
    p.write_text(text)
    with pytest.raises(FormatError, match=match) as e:
        load_periods(p)
    assert e.value.path == str(p)
    assert "\n" not in str(e.value)


def test_load_periods_missing_file(tmp_path):
    with pytest.raises(FormatError, match="cannot read degraded-day table"):
        load_periods(tmp_path / "none.toml")
