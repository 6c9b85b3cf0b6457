"""Tests of the shared reader helpers (accal.io.common)."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest

from accal.errors import FormatError
from accal.io.common import arrow_to_numpy, bits_from_strings


@pytest.mark.parametrize("width", [1, 3, 8, 12, 32])
def test_bits_from_strings_round_trips_every_pattern(width):
    """'0'/'1' strings of any width come back as their integer (first char = MSB)."""
    rng = np.random.default_rng(width)
    values = np.arange(256) if width == 8 else rng.integers(0, 2**width, 300, dtype=np.int64)
    strings = [format(int(v), f"0{width}b") for v in values]
    arr = pa.chunked_array([pa.array(strings[:100]), pa.array(strings[100:])])
    bits = bits_from_strings(arr, "f.txt", 1, width=width)
    assert bits.dtype == np.uint32
    assert np.array_equal(bits, values.astype(np.uint32))
    # an array slice (non-zero offset into the buffers)
    sliced = bits_from_strings(pa.array(strings).slice(7), "f", 1, width=width)
    assert np.array_equal(sliced, values[7:])


@pytest.mark.parametrize(
    ("bad", "why"), [("0000x000", "characters"), ("0000000", "characters"), ("00000/00", "0/1")]
)
def test_bits_from_strings_names_the_bad_line(bad, why):
    values = ["00000000"] * 5 + [bad] + ["00000001"] * 3
    with pytest.raises(FormatError, match=why) as info:
        bits_from_strings(pa.array(values), "f.txt", 10)
    assert info.value.line == 15


def test_tidy_says_when_dropped_duplicates_had_other_values():
    from accal.io.common import tidy

    t = np.array([0.0, 1, 1, 2, 3, 3, 3])
    acc = np.arange(14.0).reshape(7, 2)
    acc[2], acc[5], acc[6] = acc[1], acc[4], acc[4]
    flags = np.zeros(7, np.uint32)
    res = tidy(t, {"acc": acc, "flags": flags})
    assert res.warnings == ["3 duplicated epochs dropped (first kept)"]
    assert np.array_equal(res.time, [0, 1, 2, 3]) and np.array_equal(res.arrays["acc"][1], [2, 3])
    acc[6, 1] += 1e-12  # one dropped record differs from the one kept
    flags[2] = 1  # and another only in its flag
    res = tidy(t, {"acc": acc, "flags": flags})
    assert res.warnings == [
        "3 duplicated epochs dropped (first kept); 2 of them with different values"
    ]


def test_arrow_to_numpy_copies_chunks_once_into_a_writable_array():
    """Chunked and sliced (offset) arrays come back whole and writable; ``out`` (a
    strided column of a 2-D array) is filled in place; nulls fall back to pyarrow."""
    v = np.arange(50, dtype=np.float64) * 0.5
    chunked = pa.chunked_array([pa.array(v[:7]), pa.array(v).slice(7, 20), pa.array(v[27:])])
    got = arrow_to_numpy(chunked)
    assert np.array_equal(got, v) and got.dtype == np.float64 and got.flags.writeable
    got[0] = -1.0  # writable, and not a view of the Arrow buffers
    assert chunked.chunk(0)[0].as_py() == 0.0
    out = np.zeros((50, 3))
    res = arrow_to_numpy(chunked, out[:, 1])
    assert np.shares_memory(res, out) and np.array_equal(out[:, 1], v)
    assert not out[:, [0, 2]].any()
    ints = arrow_to_numpy(
        pa.chunked_array([pa.array([1, 2], pa.int32()), pa.array([], pa.int32())])
    )
    assert ints.dtype == np.int32 and ints.tolist() == [1, 2]
    empty = arrow_to_numpy(pa.chunked_array([], pa.float64()))
    assert empty.shape == (0,)
    with_null = arrow_to_numpy(pa.array([1.0, None, 3.0]))
    assert np.isnan(with_null[1]) and with_null[[0, 2]].tolist() == [1.0, 3.0]
