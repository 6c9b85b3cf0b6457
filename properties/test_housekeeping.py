"""Property tests of the housekeeping reader and of its interpolation.

* Random channels written as a generic CSV or Parquet table by
  :func:`accal.io.writers.write_table` (shortest exact float text in CSV) read back
  bit for bit, with prefixed voltages and currents converted to V and A.
* A real AHK1B sample or a table cut at any byte, optionally gzipped, either parses
  or raises one of accal's own errors (a cut at a line end is a valid shorter file).
* Interpolating a linear channel gives the line, to double rounding.
"""

import gzip
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from accal.errors import AccalError
from accal.io.housekeeping import SI_PREFIXED, Housekeeping, read_housekeeping
from accal.io.writers import write_table

SAMPLES = Path(__file__).resolve().parents[1] / "data" / "samples"
AHK_SAMPLES = sorted(SAMPLES.glob("AHK1B_*"))
SETTINGS = settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)

finite = st.floats(allow_nan=False, allow_infinity=False, width=64)
names = st.from_regex(r"[A-Za-z][A-Za-z0-9_+\-]{0,8}", fullmatch=True).filter(
    lambda s: s not in ("gps_time", "time", "time_utc")
)
units = st.sampled_from(["degC", "K", "V", "A", "Pa", "mV", "uA", "kV", "unknown"])


@st.composite
def tables(draw):
    n = draw(st.integers(1, 25))
    steps = draw(hnp.arrays(np.float64, n, elements=st.floats(1e-3, 1e4)))
    time = draw(st.floats(-6e8, 3e9)) + np.cumsum(steps)
    time = np.unique(time)  # a step may vanish in rounding
    n = time.size
    chans = {}
    for name in draw(st.lists(names, min_size=1, max_size=5, unique=True)):
        values = draw(hnp.arrays(np.float64, n, elements=finite))
        holes = draw(hnp.arrays(np.bool_, n))
        holes[draw(st.integers(0, n - 1))] = False  # at least one value (else no type)
        values[holes] = np.nan
        chans[name] = values
    return time, chans, {k: draw(units) for k in chans}


@SETTINGS
@given(
    tab=tables(),
    fmt=st.sampled_from(["csv", "parquet"]),
    tname=st.sampled_from(["gps_time", "time"]),
)
def test_table_round_trip(tmp_path, tab, fmt, tname):
    time, chans, declared = tab
    p = tmp_path / f"hk.{fmt}"
    write_table({tname: time, **chans}, p, units=declared)
    h = read_housekeeping(p)
    assert np.array_equal(h.time, time)
    assert list(h.channels) == list(chans)
    for k, v in chans.items():
        factor, si = SI_PREFIXED.get(declared[k], (None, declared[k]))
        with np.errstate(over="ignore"):
            want = v if factor is None else v * factor
        assert np.array_equal(h.channels[k], want, equal_nan=True), k
        assert h.units[k] == si
    assert h.warnings == ()


def _read_or_accal_error(path: Path) -> None:
    try:
        h = read_housekeeping(path)
    except AccalError as exc:
        assert "\n" not in str(exc)
        return
    assert isinstance(h, Housekeeping)
    assert np.all(np.diff(h.time) > 0)


@SETTINGS
@given(
    sample=st.sampled_from(AHK_SAMPLES),
    frac=st.floats(0.0, 1.0),
    gz=st.booleans(),
    gz_cut=st.booleans(),
)
def test_truncated_ahk1b_never_escapes(tmp_path, sample, frac, gz, gz_cut):
    raw = sample.read_bytes()
    cut = raw[: int(frac * len(raw))]
    if gz:
        data = gzip.compress(raw if gz_cut else cut, mtime=0)
        cut = data[: int(frac * len(data))] if gz_cut else data
    p = tmp_path / "cut.txt"
    p.write_bytes(cut)
    _read_or_accal_error(p)


@SETTINGS
@given(tab=tables(), fmt=st.sampled_from(["csv", "parquet"]), frac=st.floats(0.0, 1.0))
def test_truncated_table_never_escapes(tmp_path, tab, fmt, frac):
    time, chans, declared = tab
    full = tmp_path / f"full.{fmt}"
    write_table({"gps_time": time, **chans}, full, units=declared)
    raw = full.read_bytes()
    p = tmp_path / f"cut.{fmt}"
    p.write_bytes(raw[: int(frac * len(raw))])
    _read_or_accal_error(p)


@SETTINGS
@given(
    steps=hnp.arrays(np.float64, st.integers(2, 30), elements=st.floats(0.1, 100.0)),
    t0=st.floats(-1e8, 1e9),
    a=st.floats(-1e3, 1e3),
    b=st.floats(-10.0, 10.0),
    q=hnp.arrays(np.float64, 20, elements=st.floats(-0.5, 1.5)),
)
def test_linear_channel_interpolates_to_the_line(steps, t0, a, b, q):
    time = t0 + np.concatenate(([0.0], np.cumsum(steps)))
    time = np.unique(time)
    rel = time - time[0]
    h = Housekeeping(time=time, channels={"x": a + b * rel}, units={"x": "V"})
    span = rel[-1]
    tq = time[0] + q * span
    got = h.on(tq, max_gap=np.inf)["x"]
    inside = (tq >= time[0]) & (tq <= time[-1])
    assert np.isnan(got[~inside]).all()
    want = a + b * (tq[inside] - time[0])
    # error: rounding of the samples, of tq - time[0] (ulp of |time|) and of the interpolation
    tol = 8 * np.finfo(float).eps * (abs(a) + abs(b) * (span + np.abs(time).max()))
    assert np.allclose(got[inside], want, rtol=0, atol=tol)
    assert np.array_equal(h.on(time, max_gap=np.inf)["x"], h.channels["x"])
