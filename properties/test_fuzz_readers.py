"""Fuzzing the readers: any input either gives a sane AccSeries or one accal input error.

The contract (issue 5, "Hardening") for :func:`accal.io.read` and every reader:

* a returned series is sane: time 1-D, finite and strictly increasing; ``acc`` of
  shape (n, number of axes) and finite wherever ``valid``; flags and auxiliary
  channels of length n; at least one sample;
* otherwise the reader raises an :class:`~accal.errors.AccalError` whose message is
  one line, starts with the file name (``FILE[:LINE]: what is wrong``) and is short.

Anything else escaping (IndexError, UnicodeDecodeError, pyarrow's ArrowInvalid,
RecursionError, OverflowError, MemoryError, ...) is a bug in the reader.

Inputs are the real files of ``data/samples/`` mutated the ways real archives break
(bit flips, inserted/deleted/duplicated lines, truncations at every kind of position,
swapped columns, huge/NaN/inf numbers, wrong encodings, gzip of garbage, a valid gzip
header with a truncated body, header-only files, YAML tricks), plus random bytes.

Budgets: the default suite runs each property with a fixed seed
(``derandomize=True``, so CI is reproducible) and a few dozen to a few hundred
examples, ~20 s in all on the 2-core machine; the ``slow``-marked variants run
the same properties with fresh random seeds and 20x the examples
(``pytest -m slow properties/test_fuzz_readers.py``).

Known bugs of the table and run-file readers (:mod:`accal.io.tables`,
:mod:`accal.io.rawlog`, owned elsewhere at the time of writing) are pinned by the
strict xfail tests at the end and tolerated, by exact signature only, in the table
properties (:func:`_known_table_bug`); fixing one turns its xfail into a failure,
which is the reminder to delete both.
"""

from __future__ import annotations

import gzip
import tempfile
import traceback
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from accal.errors import AccalError
from accal.io import read
from accal.io.grace_l1b import TIME_RANGE, read_grace_acc1b
from accal.io.rawlog import read_psd, read_rawlog
from accal.io.tables import read_table_series, write_series
from accal.series import AccSeries

SAMPLES = Path(__file__).resolve().parents[1] / "data" / "samples"
L1B_FILES = (
    "ACC1B_2003-09-14_A_00.asc",
    "ACC1B_2003-09-14_B_00.asc",
    "ACC1B_2003-09-14_A_00.dat",
    "ACT1B_2023-06-01_C_04.txt",
    "ACT1B_2023-06-01_D_04.txt",
)
L1B = {name: (SAMPLES / name).read_bytes() for name in L1B_FILES}
HEADER_MARKERS = (b"END OF HEADER", b"# End of YAML header")


def _fuzz_settings(max_examples: int, *, deep: bool = False) -> settings:
    return settings(
        max_examples=max_examples * (20 if deep else 1),
        derandomize=not deep,
        deadline=None,
        database=None,
        suppress_health_check=[
            HealthCheck.function_scoped_fixture,
            HealthCheck.too_slow,
            HealthCheck.data_too_large,
        ],
    )


# ------------------------------------------------------------------------ the contract


def _assert_sane(s: AccSeries) -> None:
    n = len(s)
    if s.satellite.startswith("GRACE"):  # L1B epochs are GPS seconds of 1980-2100
        assert TIME_RANGE[0] <= s.time[0] and s.time[-1] <= TIME_RANGE[1]
    assert n >= 1
    t = s.time
    assert t.dtype == np.float64 and t.ndim == 1
    assert np.isfinite(t).all()
    assert np.all(np.diff(t) > 0)
    assert s.acc.dtype == np.float64 and s.acc.shape == (n, len(s.axes))
    assert s.valid.shape == (n,) and s.valid.dtype == bool
    assert s.quality.shape == (n,)
    assert np.isfinite(s.acc[s.valid]).all()
    for k, v in s.aux.items():
        assert np.shape(v) == (n,), k
    assert s.report.n_rows >= n


def _assert_input_error(exc: AccalError, path: Path) -> None:
    msg = str(exc)
    assert "\n" not in msg and "\r" not in msg, f"message is not one line: {msg!r}"
    assert msg.startswith(str(path)), f"message does not name the file: {msg!r}"
    assert len(msg) < len(str(path)) + 300, f"message too long: {msg[:400]!r}..."
    line = getattr(exc, "line", None)
    assert line is None or (isinstance(line, int) and line >= 1)


def _innermost(exc: BaseException, filename: str) -> traceback.FrameSummary | None:
    frames = [
        f for f in traceback.extract_tb(exc.__traceback__) if Path(f.filename).name == filename
    ]
    return frames[-1] if frames else None


def _known_table_bug(exc: BaseException) -> str | None:
    """Name the known table/run-file reader bug ``exc`` is (see KNOWN_TABLE_BUGS), or None.

    Matched on the exception type and the source line of the innermost frame in
    the reader module, so an unknown bug in the same module is not hidden.
    """
    frame = _innermost(exc, "tables.py")
    src = (frame.line or "") if frame is not None else ""
    if isinstance(exc, TypeError | ValueError) and "astype(dt)" in src:
        return "T2"
    if isinstance(exc, TypeError | ValueError | AttributeError) and "series_meta" in src:
        return "T4"
    if isinstance(exc, KeyError) and "exists" in str(exc) and "times in schema" in str(exc):
        return "T5"
    return None


def _check(path: Path, readers: tuple[Callable[[Path], object], ...], *, tolerate: bool) -> None:
    """Apply the contract to every reader on ``path``."""
    for reader in readers:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                out = reader(path)
        except AccalError as exc:
            if tolerate and _known_table_bug(exc):
                continue
            _assert_input_error(exc, path)
        except Exception as exc:
            if tolerate and _known_table_bug(exc):
                continue
            raise
        else:
            if isinstance(out, AccSeries):
                _assert_sane(out)


L1B_READERS = (read_grace_acc1b, read)
TABLE_READERS = (read_table_series, read)
RUN_READERS = (read_rawlog, read_psd)


def _write_and_check(data: bytes, readers, *, name: str = "f.asc", tolerate=False) -> None:
    # A fresh directory per example (the hypothesis tests cannot use tmp_path).
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / name
        p.write_bytes(data)
        _check(p, readers, tolerate=tolerate)


# ------------------------------------------------------------------------ mutations

#: Tokens that break parsers: non-finite and huge numbers, separators, control and
#: non-ASCII bytes, YAML syntax, header markers, 0/1 flags of the wrong length.
TOKENS = (
    b"nan",
    b"NaN",
    b"inf",
    b"-inf",
    b"1e999",
    b"-1e999",
    b"1e308",
    b"-1e300",
    b"4294967296",
    b"-0",
    b"0x1F",
    b"1_0",
    b"",
    b" ",
    b"  ",
    b"\t",
    b"\r",
    b"\n",
    b"\r\n",
    b"\x00",
    b"\xff\xfe",
    b"\xc3",
    b"\xe9",
    b"\xef\xbb\xbf",
    b"9" * 400,
    b"A",
    b"D",
    b"Q",
    b"#",
    b":",
    b",",
    b'"',
    b"- ",
    b"[",
    b"{",
    b"&a [x]",
    b"*a",
    b"!!int 1",
    b"!!float .inf",
    b"!!timestamp 2001-01-01",
    b"!!python/object:os.system",
    b"END OF HEADER",
    b"# End of YAML header",
    b"header:",
    b"00000000",
    b"0000000",
    b"000000002",
)
ENCODINGS = ("utf-16", "utf-32", "utf-16-le", "utf-8-sig", "cp500", "latin-1")

_pos = st.integers(0, 2**31)


def _lines(raw: bytes) -> list[bytes]:
    return raw.split(b"\n")


def _header_end(raw: bytes) -> int:
    """Offset just after the end-of-header line (0 if there is none)."""
    for marker in HEADER_MARKERS:
        i = raw.find(marker)
        if i >= 0:
            j = raw.find(b"\n", i)
            return len(raw) if j < 0 else j + 1
    return 0


@st.composite
def _edit(draw, raw: bytes) -> bytes:  # noqa: C901 (a flat menu of edits)
    """One realistic corruption of ``raw``."""
    kind = draw(
        st.sampled_from(
            (
                "flip",
                "insert",
                "delete",
                "field",
                "last_field",
                "yaml_value",
                "swap_fields",
                "swap_columns",
                "del_line",
                "dup_line",
                "swap_lines",
                "token_line",
                "truncate",
                "encode",
                "header_only",
                "tabs",
            )
        )
    )
    if not raw:
        return draw(st.sampled_from(TOKENS))
    n = len(raw)
    lines = _lines(raw)
    i = draw(_pos) % n
    li = draw(_pos) % len(lines)
    if kind == "flip":
        b = bytearray(raw)
        b[i] ^= 1 << draw(st.integers(0, 7))
        return bytes(b)
    if kind == "insert":
        return raw[:i] + draw(st.sampled_from(TOKENS)) + raw[i:]
    if kind == "delete":
        return raw[:i] + raw[i + draw(st.integers(1, 80)) :]
    if kind == "last_field":  # edits of the last record hit end-of-buffer code paths
        k = len(lines) - 2 if len(lines) > 1 and not lines[-1] else len(lines) - 1
        fields = lines[k].split(b" ")
        fields[draw(_pos) % len(fields)] = draw(st.sampled_from(TOKENS))
        lines[k] = b" ".join(fields)
        return b"\n".join(lines)
    if kind == "yaml_value":  # replace the value of a 'key: value' header line
        n_head = raw[: _header_end(raw)].count(b"\n")
        keyed = [k for k, ln in enumerate(lines[:n_head]) if b": " in ln]
        if keyed:
            k = keyed[draw(_pos) % len(keyed)]
            key = lines[k].split(b": ", 1)[0]
            lines[k] = key + b": " + draw(st.sampled_from(TOKENS))
        return b"\n".join(lines)
    if kind in ("field", "swap_fields"):
        fields = lines[li].split(b" ")
        a, c = draw(_pos) % len(fields), draw(_pos) % len(fields)
        if kind == "field":
            fields[a] = draw(st.sampled_from(TOKENS))
        else:
            fields[a], fields[c] = fields[c], fields[a]
        lines[li] = b" ".join(fields)
        return b"\n".join(lines)
    if kind == "swap_columns":  # the same two columns swapped on every data line
        a, c = draw(st.integers(0, 12)), draw(st.integers(0, 12))
        start = raw[: _header_end(raw)].count(b"\n")
        for k in range(start, len(lines)):
            f = lines[k].split(b" ")
            if max(a, c) < len(f):
                f[a], f[c] = f[c], f[a]
                lines[k] = b" ".join(f)
        return b"\n".join(lines)
    if kind == "del_line":
        del lines[li]
        return b"\n".join(lines)
    if kind == "dup_line":
        lines.insert(draw(_pos) % len(lines), lines[li])
        return b"\n".join(lines)
    if kind == "swap_lines":
        lj = draw(_pos) % len(lines)
        lines[li], lines[lj] = lines[lj], lines[li]
        return b"\n".join(lines)
    if kind == "token_line":
        lines.insert(li, draw(st.sampled_from(TOKENS)))
        return b"\n".join(lines)
    if kind == "truncate":
        where = draw(st.sampled_from(("byte", "line_end", "after_header", "in_header", "last")))
        h = _header_end(raw)
        if where == "byte":
            return raw[:i]
        if where == "line_end":
            return b"\n".join(lines[:li]) + b"\n"
        if where == "after_header":
            return raw[:h]
        if where == "in_header":
            return raw[: i % max(h, 1)]
        return raw[: n - 1 - draw(st.integers(0, 40)) % n]
    if kind == "encode":
        enc = draw(st.sampled_from(ENCODINGS))
        return raw.decode("latin-1").encode(enc, "replace")
    if kind == "header_only":
        tail = draw(st.sampled_from((b"", b"\n", b"\n\n", b"   \n", b"\x00", b"x\n", b"1 A\n")))
        return raw[: _header_end(raw)] + tail
    # tabs: separators replaced on one line
    lines[li] = lines[li].replace(b" ", b"\t")
    return b"\n".join(lines)


@st.composite
def _wrap(draw, raw: bytes) -> bytes:
    """Optionally gzip the bytes, possibly breaking the gzip stream."""
    how = draw(st.sampled_from(("plain",) * 6 + ("gzip", "gzip_cut", "gzip_garbage", "tail")))
    if how == "plain":
        return raw
    gz = gzip.compress(raw, mtime=0)
    if how == "gzip":
        return gz
    if how == "gzip_cut":  # a valid gzip header, then a truncated body
        return gz[: 10 + draw(_pos) % max(len(gz) - 10, 1)]
    if how == "gzip_garbage":  # a valid gzip header and deflate garbage
        return gz[:10] + draw(st.binary(min_size=0, max_size=200))
    return gz + draw(st.sampled_from((b"\x00" * 9, b"junk", gz[:20])))


@st.composite
def mutated(draw, sources: dict[str, bytes]) -> tuple[str, bytes]:
    """A real file with 1-4 corruptions, optionally gzipped."""
    name = draw(st.sampled_from(sorted(sources)))
    raw = sources[name]
    for _ in range(draw(st.integers(1, 4))):
        raw = draw(_edit(raw))
    return name, draw(_wrap(raw))


def _garbage_after_header() -> st.SearchStrategy[bytes]:
    heads = [raw[: _header_end(raw)] for raw in L1B.values()]
    return st.builds(
        lambda h, b: h + b, st.sampled_from(heads), st.binary(min_size=0, max_size=600)
    )


# ------------------------------------------------------------------------ L1B properties


def _l1b_mutations(data):
    name, raw = data
    _write_and_check(raw, L1B_READERS, name=name)


def _l1b_random(raw):
    _write_and_check(raw, L1B_READERS)


@_fuzz_settings(600)
@given(data=mutated(L1B))
def test_l1b_mutations(data):
    _l1b_mutations(data)


@_fuzz_settings(150)
@given(raw=st.one_of(st.binary(max_size=2000), _garbage_after_header()))
def test_l1b_random_bytes(raw):
    _l1b_random(raw)


@pytest.mark.slow
@_fuzz_settings(300, deep=True)
@given(data=mutated(L1B))
def test_l1b_mutations_deep(data):
    _l1b_mutations(data)


@pytest.mark.slow
@_fuzz_settings(60, deep=True)
@given(raw=st.one_of(st.binary(max_size=2000), _garbage_after_header()))
def test_l1b_random_bytes_deep(raw):
    _l1b_random(raw)


# ------------------------------------------------------------------------ table properties


def _table_sources() -> dict[str, bytes]:
    """The Swarm CSV (first 300 rows) and a real L1B series written as CSV and Parquet."""
    swarm = gzip.decompress((SAMPLES / "SW_A_ACCACAL_20240511_a_cal_x.csv.gz").read_bytes())
    cut = 0
    for _ in range(301):
        cut = swarm.index(b"\n", cut) + 1
    out = {"SW_A_ACCACAL_20240511_a_cal_x.csv": swarm[:cut]}
    series = read_grace_acc1b(SAMPLES / "ACC1B_2003-09-14_B_00.asc")
    with tempfile.TemporaryDirectory() as tmp:
        for fmt in ("csv", "parquet"):
            p = write_series(series, Path(tmp) / f"ACC1B_B.{fmt}")
            out[p.name] = p.read_bytes()
    return out


TABLES = _table_sources()


@st.composite
def _mutated_table(draw) -> tuple[str, bytes]:
    name, raw = draw(mutated(TABLES))
    if name.endswith(".parquet") and raw and draw(st.booleans()):
        # Parquet is binary: flip bytes anywhere, including the footer and its metadata.
        b = bytearray(raw)
        for _ in range(draw(st.integers(1, 6))):
            b[draw(_pos) % len(b)] = draw(st.integers(0, 255))
        raw = bytes(b)
    return name, raw


def _table_mutations(data):
    name, raw = data
    _write_and_check(raw, TABLE_READERS, name=name, tolerate=True)
    _write_and_check(raw, RUN_READERS, name=name, tolerate=True)


@_fuzz_settings(300)
@given(data=_mutated_table())
def test_table_mutations(data):
    _table_mutations(data)


@pytest.mark.slow
@_fuzz_settings(150, deep=True)
@given(data=_mutated_table())
def test_table_mutations_deep(data):
    _table_mutations(data)


# ------------------------------------------------------------------------ a fixed corpus


def _yaml_head() -> bytes:
    raw = L1B["ACT1B_2023-06-01_C_04.txt"]
    return raw[: raw.index(b"# End of YAML header")]


def _ascii() -> tuple[bytes, bytes]:
    raw = L1B["ACC1B_2003-09-14_A_00.asc"]
    h = _header_end(raw)
    return raw[:h], raw[h:]


FO_HEAD = _yaml_head()
FO_END = b"# End of YAML header\n"
FO_DATA = L1B["ACT1B_2023-06-01_C_04.txt"][len(FO_HEAD) + len(FO_END) :]
A_HEAD, A_DATA = _ascii()


def _alias_bomb(levels: int = 30) -> bytes:
    """A 2 kB YAML header whose aliases expand to 10**30 strings if ever copied out."""
    lines = [b"header:", b"  a0: &a0 [" + b", ".join([b"x"] * 10) + b"]"]
    for k in range(1, levels):
        ref = b"*a%d" % (k - 1)
        lines.append(b"  a%d: &a%d [" % (k, k) + b", ".join([ref] * 10) + b"]")
    return b"\n".join(lines) + b"\n" + FO_END + FO_DATA


#: Inputs that once escaped a reader (see tests/io/test_grace_l1b.py) or that are
#: edge cases worth pinning: each must give a sane series or one input error.
CORPUS = {
    "empty": b"",
    "blanks": b" \n\n\t\n",
    "nul": b"\x00" * 100,
    "header_only_grace": A_HEAD,
    "header_only_gracefo": FO_HEAD + FO_END,
    "empty_yaml_header": b"header:\n" + FO_END + FO_DATA,
    "yaml_header_null": b"header: ~\n" + FO_END + FO_DATA,
    "yaml_header_list": b"header: [1, 2]\n" + FO_END + FO_DATA,
    "yaml_only_marker": FO_END + FO_DATA,
    "yaml_deep": b"header:\n  x: " + b"[" * 20000 + b"]" * 20000 + b"\n" + FO_END + FO_DATA,
    "yaml_alias_bomb": _alias_bomb(),
    "yaml_tags": FO_HEAD.replace(b"num_records: 86400", b"num_records: !!float .inf")
    + FO_END
    + FO_DATA,
    "yaml_attrs_list": FO_HEAD.replace(
        b"  global_attributes:\n", b"  global_attributes: [x]\n  g:\n"
    )
    + FO_END
    + FO_DATA,
    "grace_empty_id_last": A_HEAD
    + A_DATA[:-1].rsplit(b"\n", 1)[0]
    + b"\n"
    + A_DATA[:-1].rsplit(b"\n", 1)[1].replace(b" A ", b"  ", 1)
    + b"\n",
    "grace_time_huge": A_HEAD + A_DATA.replace(b"116769600 A", b"1e300 A", 1),
    "grace_utf16": (A_HEAD + A_DATA).decode().encode("utf-16"),
    "gzip_header_only": gzip.compress(A_HEAD + A_DATA)[:10],
    "gzip_of_garbage": gzip.compress(b"\xff\xfe" * 300),
    "gzip_empty": gzip.compress(b""),
    "gzip_truncated_body": gzip.compress(A_HEAD + A_DATA)[:200],
}


@pytest.mark.parametrize("name", sorted(CORPUS))
def test_corpus(tmp_path, name):
    p = tmp_path / f"{name}.asc"
    p.write_bytes(CORPUS[name])
    _check(p, L1B_READERS, tolerate=False)


def test_contract_checker_catches_escapes(tmp_path):
    """The checker itself must fail on an escaping exception and on a bad message."""
    p = tmp_path / "x.asc"
    p.write_bytes(b"x")

    def boom(path):
        raise IndexError("escaped")

    def multiline(path):
        raise AccalError(f"{path}: two\nlines")

    def unnamed(path):
        raise AccalError("no file name")

    def insane(path):
        return AccSeries(time=np.array([1.0, np.inf]), acc=np.zeros((2, 3)))

    with pytest.raises(IndexError):
        _check(p, (boom,), tolerate=True)
    for bad in (multiline, unnamed):
        with pytest.raises(AssertionError):
            _check(p, (bad,), tolerate=False)
    with pytest.raises(AssertionError):
        _check(p, (insane,), tolerate=False)


# ------------------------------------------------------------------------ known bugs elsewhere
# Found by test_table_mutations in accal.io.tables / accal.io.rawlog (not owned by the
# author of this file at the time).  Each test states the contract and fails today;
# strict=True makes a fix visible (XPASS fails): then delete the xfail mark and the
# matching branch of _known_table_bug.  (T1, a UnicodeDecodeError from non-UTF-8
# Parquet metadata, and T3, multi-line messages quoting pandas errors or column
# names, were fixed in those modules while this file was written.)

KNOWN_TABLE_BUGS = {
    "T2": "aux_dtypes from the file's accal_series metadata reach ndarray.astype unchecked",
    "T4": "accal_series metadata fields of the wrong type (history, units, aux_dtypes)",
    "T5": "duplicated column names raise pyarrow's KeyError",
    "T6": "gps_time far outside the GPS era is accepted (pipeline then fails on the date)",
    "T7": "quality values >= 2**32 wrap around to 0 (the sample looks valid)",
}


def _table_file(tmp_path, text: bytes, name: str = "t.csv") -> Path:
    p = tmp_path / name
    p.write_bytes(text)
    return p


def _expect_one_line_error(path: Path, reader=read_table_series, **kw) -> None:
    with pytest.raises(AccalError) as e:
        reader(path, **kw)
    _assert_input_error(e.value, path)


@pytest.mark.xfail(strict=True, reason="T2: " + KNOWN_TABLE_BUGS["T2"])
def test_known_bug_t2_aux_dtypes(tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    meta = b'{"accal_series": {"aux_dtypes": {"a": "<f8x"}}}'
    table = pa.table({"gps_time": [1.0, 2.0], "lin_accl_x": [1.0, 2.0], "a": [1.0, 2.0]})
    p = tmp_path / "t.parquet"
    pq.write_table(table.replace_schema_metadata({b"accal.meta": meta}), p)
    _expect_one_line_error(p)


@pytest.mark.xfail(strict=True, reason="T4: " + KNOWN_TABLE_BUGS["T4"])
@pytest.mark.parametrize(
    "series_meta",
    [b'{"history": 5}', b'{"units": "m/s2"}', b'{"aux_dtypes": [1]}'],
    ids=["history", "units", "aux_dtypes"],
)
def test_known_bug_t4_series_meta_types(tmp_path, series_meta):
    text = b'# meta: {"accal_series": ' + series_meta + b"}\ngps_time,lin_accl_x\n1,1\n2,2\n"
    _expect_one_line_error(_table_file(tmp_path, text))


@pytest.mark.xfail(strict=True, reason="T5: " + KNOWN_TABLE_BUGS["T5"])
def test_known_bug_t5_duplicated_columns(tmp_path):
    text = b"gps_time,gps_time,lin_accl_x\n1,1,1\n2,2,2\n"
    _expect_one_line_error(_table_file(tmp_path, text))


@pytest.mark.xfail(strict=True, reason="T6: " + KNOWN_TABLE_BUGS["T6"])
def test_known_bug_t6_time_outside_gps_era(tmp_path):
    # `accal grace-bias` on this file: "internal error (OverflowError: int too big to
    # convert)".  Fix: accal.io._common.check_gps_time(time, path, ...) in the reader.
    text = b"gps_time,lin_accl_x\n1e300,1e-7\n2e300,2e-7\n"
    _expect_one_line_error(_table_file(tmp_path, text))


@pytest.mark.xfail(strict=True, reason="T7: " + KNOWN_TABLE_BUGS["T7"])
@pytest.mark.filterwarnings("ignore:invalid value encountered in cast:RuntimeWarning")
def test_known_bug_t7_quality_overflow(tmp_path):
    text = b"gps_time,lin_accl_x,quality\n1,1,1e30\n2,2,0\n"
    _expect_one_line_error(_table_file(tmp_path, text))
