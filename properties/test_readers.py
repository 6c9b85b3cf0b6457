"""Property tests of the readers: writer -> reader round trips and robustness to bad bytes.

Floats are written with ``repr`` (L1B) or ``%.17g`` (CSV), both exact for every
finite double, so the round trips are asserted bit for bit (over every double the
readers accept as an acceleration, |a| <= 1000).  Corrupted input may
parse (e.g. a truncation exactly at a line end) but may only ever raise FormatError.
"""

import contextlib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from accal.errors import FormatError
from accal.io import read
from accal.io.common import MAX_ABS_ACCELERATION
from accal.io.grace_l1b import (
    AUX_COLUMNS,
    DEFAULT_INVALID_BITS,
    read_grace_acc1b,
    write_grace_acc1b,
)
from accal.io.tables import read_table_series, write_series
from accal.series import AccSeries

SAMPLES = Path(__file__).resolve().parents[1] / "data" / "samples"
SETTINGS = settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)

#: Accelerations as the readers accept them: any float64 within the plausible range
#: (beyond it a value is damage: tests/io test_absurd_*)
plausible = st.floats(-MAX_ABS_ACCELERATION, MAX_ABS_ACCELERATION, width=64)


@st.composite
def series(draw, satellites=("GRACE-A", "GRACE-B", "GRACE-FO-C", "GRACE-FO-D")):
    n = draw(st.integers(1, 30))
    start = draw(st.floats(-1e8, 1e9, allow_nan=False))
    steps = draw(hnp.arrays(np.float64, n - 1, elements=st.sampled_from([0.5, 1.0, 1.0, 7.0])))
    integral = draw(st.booleans())
    t0 = float(np.round(start)) if integral else start
    time = t0 + np.concatenate(([0.0], np.cumsum(steps)))
    if integral:
        time = np.round(time)
    if not np.all(np.diff(time) > 0):
        time = t0 + np.arange(n, dtype=float)
    acc = draw(hnp.arrays(np.float64, (n, 3), elements=plausible))
    quality = draw(hnp.arrays(np.uint32, n, elements=st.integers(0, 255)))
    aux = {c: draw(hnp.arrays(np.float64, n, elements=plausible)) for c in AUX_COLUMNS}
    return AccSeries(
        time=time,
        acc=acc,
        quality=quality,
        valid=(quality & DEFAULT_INVALID_BITS) == 0,
        aux=aux,
        satellite=draw(st.sampled_from(satellites)),
    )


def _same(a: AccSeries, b: AccSeries) -> None:
    assert np.array_equal(a.time, b.time)
    assert np.array_equal(a.acc, b.acc)
    assert np.array_equal(a.quality, b.quality) and np.array_equal(a.valid, b.valid)
    assert a.satellite == b.satellite and a.axes == b.axes
    for k in a.aux:
        assert np.array_equal(a.aux[k], b.aux[k])


@SETTINGS
@given(s=series())
def test_l1b_round_trip_exact(tmp_path, s):
    r = read_grace_acc1b(write_grace_acc1b(s, tmp_path / "a.asc"))
    _same(s, r)
    r2 = read_grace_acc1b(write_grace_acc1b(r, tmp_path / "b.asc.gz"))
    _same(r, r2)
    assert r2.meta == r.meta and r2.units == r.units


@SETTINGS
@given(
    s=series(),
    fmt=st.sampled_from(["parquet", "csv"]),
    hist=st.lists(st.text(max_size=8), max_size=2),
)
def test_table_round_trip_identical(tmp_path, s, fmt, hist):
    s = s.replace(history=tuple(hist), meta={"x": {"k": [1, "é", None]}})
    r = read_table_series(write_series(s, tmp_path / f"s.{fmt}"))
    _same(s, r)
    assert (r.meta, r.history, r.units, r.frame) == (s.meta, s.history, s.units, s.frame)


REAL = [
    SAMPLES / n
    for n in ("ACC1B_2003-09-14_A_00.asc", "ACT1B_2023-06-01_C_04.txt", "ACC1B_2003-09-14_A_00.dat")
]


def _only_format_error(path: Path) -> None:
    with contextlib.suppress(FormatError):
        read(path, format="grace-l1b")
    with contextlib.suppress(FormatError):
        read(path)


@SETTINGS
@given(data=st.binary(max_size=3000))
def test_random_bytes_raise_only_format_error(tmp_path, data):
    p = tmp_path / "r.bin"
    p.write_bytes(data)
    _only_format_error(p)
    with contextlib.suppress(FormatError):
        read_table_series(p)


@SETTINGS
@given(which=st.sampled_from(REAL), frac=st.floats(0, 1))
def test_truncations_raise_only_format_error(tmp_path, which, frac):
    raw = which.read_bytes()
    p = tmp_path / "t.asc"
    p.write_bytes(raw[: int(frac * len(raw))])
    _only_format_error(p)


@SETTINGS
@given(
    which=st.sampled_from(REAL),
    edits=st.lists(
        st.tuples(st.floats(0, 1), st.binary(min_size=0, max_size=3)), min_size=1, max_size=4
    ),
)
def test_mutations_raise_only_format_error(tmp_path, which, edits):
    raw = bytearray(which.read_bytes())
    for pos, new in edits:
        i = int(pos * (len(raw) - 1))
        raw[i : i + 1] = new
    p = tmp_path / "m.asc"
    p.write_bytes(bytes(raw))
    _only_format_error(p)


@pytest.mark.parametrize("which", REAL)
def test_every_single_line_deleted(tmp_path, which):
    if which.suffix == ".dat":
        pytest.skip("binary")
    lines = which.read_bytes().split(b"\n")
    for i in range(0, len(lines), 7):
        p = tmp_path / "d.asc"
        p.write_bytes(b"\n".join(lines[:i] + lines[i + 1 :]))
        _only_format_error(p)
