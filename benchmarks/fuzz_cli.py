"""Black-box mutation fuzzer of the accal command line (issue 23).

Seeds are the real files of ``data/samples/`` (GRACE ACC1B .asc/.dat 2003, GRACE-FO
ACT1B .txt 2023, the Swarm CSV .csv.gz read with ``--column x=a_cal_x``, and the
AHK1B/THR1B/SCA1B files as ``--aux``/``--thrusters``/``--attitude`` companions) and a
small rotating-platform run (``accal simulate gap --days 0.2 --tau 600 --mask 200``) for
``accal demod``.  Every *case* is one mutated file, made from its integer seed alone
(``random.Random("case-SEED")``): the seed file, the mutation kind (bit flips, byte runs
inserted/deleted/duplicated, truncation incl. mid-line and mid-gzip, lines duplicated,
deleted or swapped, a numeric field made huge/tiny/NaN/inf/garbage/empty, header lines
deleted/duplicated/edited (record count, times, satellite), CRLF/CR/BOM/UTF-16/Latin-1,
gzip of a mutated body, Parquet columns dropped/renamed/retyped/nulled, zero length, a
directory or a symlink in place of the file) and its parameters.  Cases run in
*batches*, one CLI process each, also made from an integer seed alone: ``accal
grace-bias`` with several mutated inputs (``-j 1``, sometimes ``-j 2``, ``--method
both``, ``--format csv``, ``--close-loop``), one clean input with a mutated companion,
or ``accal demod`` with mutated runs.

Each batch runs with a timeout (``--timeout``, 120 s) and its peak RSS measured (the
``ru_maxrss`` of ``os.wait4`` in a small helper process that forks it: the largest
process of the run that it waited for, or the run's own per-worker figure in
``accal.log`` when larger).  Every case is classified:

* ``ok``: exit 0/1, its outputs and rows written, no error line for it;
* ``clean_failure``: exit 1 or 2 and one ``accal: PATH[:LINE]: message`` line naming
  the mutated file, no rows or outputs for it;
* BAD kinds: ``traceback`` (a traceback or "internal error" in the output),
  ``exit_code`` (other than 0/1/2/130, or 0 with a failure, or 1/2 with nothing
  failed), ``unnamed_message`` (an error line naming no input, or a failure of a
  companion case named only by the input), ``stray_output`` (stderr lines that are not
  ``accal:`` lines under ``-q``), ``timeout``, ``partial_output`` (a temporary file left
  in the out dir), ``rows_for_failed`` (rows or outputs for an input that failed),
  ``not_processed`` (neither outputs nor a message: left out because another input
  failed), ``rss`` (peak RSS above ``--rss-limit-mb``, 1536 MB).

Writes ``results.json`` (every batch and case) and ``summary.md`` to ``--out`` (default
``out/fuzz-cli``), and copies the files of every BAD batch to ``OUT/bad/b<BATCH>/``.
Reproduce a batch with ``python benchmarks/fuzz_cli.py --replay BATCH [BATCH ...]``
(the files and the out dir stay in ``OUT/replay/b<BATCH>/``; the command and its output
are printed).  Run ``python benchmarks/fuzz_cli.py [--minutes 10] [--seed 0] [--out
DIR] [--timeout 120]`` (``make fuzz-cli FUZZ_MINUTES=10``).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import collections  # noqa: E402
import gzip  # noqa: E402
import json  # noqa: E402
import random  # noqa: E402
import re  # noqa: E402
import shutil  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from dataclasses import asdict, dataclass, field  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _closure_cases import ACCAL, ROOT, SAMPLES, git_state  # noqa: E402

RSS_LIMIT_MB = 1536.0
GOOD_EXIT = (0, 1, 2, 130)
CASES_PER_BATCH = 100  # case seeds of batch B: B*100 .. B*100+99


@dataclass(frozen=True)
class Seed:
    name: str  # file name in data/samples (run.parquet: made by accal simulate gap)
    role: str  # input | aux | thrusters | attitude | run
    fmt: str  # asc | dat | yaml | csvgz | parquet
    partner: tuple[str, ...] = ()  # companions: the clean input (and reference)


A03, B03 = "ACC1B_2003-09-14_A_00.asc", "ACC1B_2003-09-14_B_00.asc"
C23, D23 = "ACT1B_2023-06-01_C_04.txt", "ACT1B_2023-06-01_D_04.txt"
SWARM = "SW_A_ACCACAL_20240511_a_cal_x.csv.gz"
INPUTS = [
    Seed(A03, "input", "asc"),
    Seed(B03, "input", "asc"),
    Seed("ACC1B_2003-09-14_A_00.dat", "input", "dat"),
    Seed("ACC1B_2003-09-14_B_00.dat", "input", "dat"),
    Seed(C23, "input", "yaml"),
    Seed(D23, "input", "yaml"),
    Seed(SWARM, "input", "csvgz"),
]
OTHER = {"A": B03, "B": A03, "C": D23, "D": C23}
COMPANIONS = [
    Seed(
        f"{kind}_{day}_{sat}_{ver}.{ext}",
        role,
        "asc" if ext == "asc" else "yaml",
        (inp,) if role != "thrusters" else (inp, OTHER[sat]),
    )
    for kind, role in (("AHK1B", "aux"), ("THR1B", "thrusters"), ("SCA1B", "attitude"))
    for day, sat, ver, ext, inp in (
        ("2003-09-14", "A", "00", "asc", A03),
        ("2003-09-14", "B", "00", "asc", B03),
        ("2023-06-01", "C", "04", "txt", C23),
        ("2023-06-01", "D", "04", "txt", D23),
    )
]
RUN = Seed("run.parquet", "run", "parquet")

BYTE_KINDS = ["bitflip", "byte_insert", "byte_delete", "byte_dup", "truncate"]
LINE_KINDS = ["truncate_midline", "line_dup", "line_del", "line_swap"]
FIELD_KINDS = ["field_huge", "field_tiny", "field_nan", "field_inf", "field_garbage", "field_empty"]
HEADER_KINDS = ["header_del", "header_dup", "header_count", "header_times", "header_satellite"]
ENCODING_KINDS = ["crlf", "cr_only", "bom", "utf16", "latin1", "gzip_body"]
PARQUET_KINDS = ["pq_drop", "pq_rename", "pq_retype", "pq_nulls", "pq_nonfinite", "pq_empty"]
SPECIAL_KINDS = ["zero_length", "directory", "symlink"]
TEXT_KINDS = LINE_KINDS + FIELD_KINDS + HEADER_KINDS + ENCODING_KINDS
KINDS = {
    "asc": BYTE_KINDS + TEXT_KINDS,
    "yaml": BYTE_KINDS + TEXT_KINDS,
    "csvgz": BYTE_KINDS + TEXT_KINDS,
    "dat": BYTE_KINDS + HEADER_KINDS + ["bom", "latin1", "gzip_body"],
    "parquet": BYTE_KINDS + PARQUET_KINDS,
}
FIELD_VALUES = {
    "field_huge": ["1e308", "-1.7976931348623157e308", "1e400", "123456789012345678901234567890"],
    "field_tiny": ["5e-324", "-4.9e-324", "1e-320", "0", "-0.0"],
    "field_nan": ["nan", "NaN", "-nan", "NAN"],
    "field_inf": ["inf", "-inf", "Infinity", "+Inf"],
    "field_garbage": [
        "abc",
        "0x1F",
        "1.2.3",
        "--5",
        "1e",
        "e5",
        "1_000",
        "\u0661\u0662",
        "\x00",
        "#",
    ],
    "field_empty": [""],
}
HEADER_MARKS = (b"END OF HEADER", b"# End of YAML header")


# ----------------------------------------------------------------------------- mutation


@dataclass
class Mutated:
    """A mutated file: its content (or a special kind of path) and what was done."""

    name: str
    kind: str
    detail: str
    data: bytes | None = None
    special: str | None = None  # directory | symlink:<target> (target relative to the file)


def _split(body: bytes) -> tuple[list[bytes], int]:
    """Lines (with their ends) and the index of the first data line."""
    lines = body.splitlines(keepends=True)
    for i, line in enumerate(lines):
        if any(m in line for m in HEADER_MARKS):
            return lines, i + 1
    if lines and b"," in lines[0]:
        return lines, 1  # CSV: the column names
    return lines, 0


def _mutate_bytes(b: bytes, kind: str, rng: random.Random) -> tuple[bytes, str]:
    n = len(b)
    if kind == "bitflip":
        out, flips = bytearray(b), rng.choice([1, 1, 2, 4, 16])
        where = [rng.randrange(n) for _ in range(flips)]
        for i in where:
            out[i] ^= 1 << rng.randrange(8)
        return bytes(out), f"{flips} bit(s) at {sorted(where)[:4]}"
    i, k = rng.randrange(n), rng.choice([1, 2, 8, 64, 512])
    if kind == "byte_insert":
        run = bytes(rng.randrange(256) for _ in range(k))
        return b[:i] + run + b[i:], f"{k} random bytes at {i}"
    if kind == "byte_delete":
        return b[:i] + b[i + k :], f"{k} bytes deleted at {i}"
    if kind == "byte_dup":
        return b[:i] + b[i : i + k] * rng.choice([2, 3, 10]) + b[
            i + k :
        ], f"{k} bytes repeated at {i}"
    if kind == "truncate":
        return b[:i], f"truncated at byte {i} of {n}"
    raise ValueError(kind)


def _line_kind(body: bytes, kind: str, rng: random.Random) -> tuple[bytes, str]:
    lines, first = _split(body)
    data = range(first, len(lines))
    if not data:
        return _mutate_bytes(body, "byte_delete", rng)
    if kind == "truncate_midline":
        i = rng.choice(data)
        cut = sum(len(x) for x in lines[:i]) + rng.randrange(1, max(2, len(lines[i]) - 1))
        return body[:cut], f"truncated inside line {i + 1} (byte {cut})"
    if kind == "line_dup":
        i, k = rng.choice(data), rng.choice([1, 1, 3, 50])
        j = min(len(lines), i + rng.choice([1, 1, 5]))
        lines[j:j] = lines[i:j] * k
        return b"".join(lines), f"lines {i + 1}-{j} repeated {k}x"
    if kind == "line_del":
        k = rng.choice([1, 1, 3, 20, len(data) // 2 + 1])
        i = rng.choice(data)
        del lines[i : i + k]
        return b"".join(lines), f"{k} line(s) deleted from {i + 1}"
    if kind == "line_swap":
        i, j = rng.choice(data), rng.choice(data)
        lines[i], lines[j] = lines[j], lines[i]
        return b"".join(lines), f"lines {i + 1} and {j + 1} swapped"
    raise ValueError(kind)


def _field_kind(body: bytes, kind: str, rng: random.Random) -> tuple[bytes, str]:
    lines, first = _split(body)
    data = [i for i in range(first, len(lines)) if lines[i].strip()]
    if not data:
        return _mutate_bytes(body, "bitflip", rng)
    sep = "," if b"," in lines[data[0]] else " "
    done = []
    for _ in range(rng.choice([1, 1, 2, 5])):
        i = rng.choice(data)
        text = lines[i].decode("latin-1")
        end = text[len(text.rstrip("\r\n")) :]
        fields = text.rstrip("\r\n").split(sep)
        # numeric fields: not the GRACE id letter (column 2) or empty runs of spaces
        idx = [k for k, f in enumerate(fields) if re.fullmatch(r"[-+0-9.eE:T]+", f)]
        if not idx:
            continue
        k, value = rng.choice(idx), rng.choice(FIELD_VALUES[kind])
        fields[k] = value
        lines[i] = (sep.join(fields) + end).encode("utf-8")
        done.append(f"line {i + 1} field {k + 1}={value!r}")
    return b"".join(lines), "; ".join(done) or "no numeric field"


#: header edits: (pattern, replacement choices); {v} is the old value
HEADER_EDITS = {
    "header_count": [
        (rb"(NUMBER OF DATA RECORDS\s*:\s*)(\S+)", None),
        (rb"(num_records:\s*)(\S+)", None),
    ],
    "header_times": [
        (rb"(TIME FIRST OBS\(SEC PAST EPOCH\):\s*)(\S+)", None),
        (rb"(TIME LAST OBS\(SEC PAST EPOCH\)\s*:\s*)(\S+)", None),
        (rb"(start_time_epoch_secs:\s*)(\S+)", None),
        (rb"(stop_time_epoch_secs:\s*)(\S+)", None),
        (rb"(time_coverage_start:\s*)(\S+)", None),
        (rb"(TIME EPOCH \(GPS TIME\)\s*:\s*)(\S+)", None),
    ],
    "header_satellite": [
        (rb"(SATELLITE NAME\s*:\s*GRACE )(\S)", None),
        (rb"(platform:\s*GRACE )(\S)", None),
        (rb"(GRACEFO_id:|SATELLITE NAME\s*:\s*)(\S+)", None),
    ],
}


def _new_value(kind: str, old: bytes, rng: random.Random) -> bytes:
    if kind == "header_satellite":
        return rng.choice([b"A", b"B", b"C", b"D", b"X", b"", b"GRACE-Z", b"\xff"])
    try:
        v = float(old)
    except ValueError:
        return rng.choice([b"1999-01-01T00:00:00", b"2003-09-14T25:61:00", b"", b"abc"])
    if kind == "header_count":
        if rng.random() < 0.2:
            return rng.choice([b"abc", b"", b"nan", b"1e400"])
        n = int(v)
        return str(rng.choice([0, 1, n - 1, n + 1, 10 * n, -5, 10**15])).encode()
    shift = rng.choice([1.0, -1.0, 3600.0, -7200.0, 86400.0, 1e9, -1e9])
    return (
        f"{v + shift:.6f}" if rng.random() < 0.85 else rng.choice(["nan", "x", "", "1e400"])
    ).encode()


def _header_kind(body: bytes, kind: str, rng: random.Random, fmt: str) -> tuple[bytes, str]:
    head_end = body.find(b"\n", max(body.find(m) for m in HEADER_MARKS)) + 1
    if fmt == "csvgz":  # one line of column names
        head_end = body.find(b"\n") + 1
    head, rest = body[:head_end], body[head_end:]
    lines = head.splitlines(keepends=True)
    if kind == "header_del":
        k = rng.choice([1, 1, 2, 5])
        i = rng.randrange(len(lines))
        gone = b"".join(lines[i : i + k]).decode("latin-1").strip()[:60]
        del lines[i : i + k]
        return b"".join(lines) + rest, f"{k} header line(s) deleted at {i + 1}: {gone!r}"
    if kind == "header_dup":
        i = rng.randrange(len(lines))
        lines.insert(i, lines[i])
        return b"".join(lines) + rest, f"header line {i + 1} duplicated"
    if fmt == "csvgz":  # header edits of a table: a column renamed / emptied
        cols = lines[0].rstrip(b"\r\n").split(b",")
        k = rng.randrange(len(cols))
        new = rng.choice([b"", b"a_cal_y", b"time", cols[k] + b" ", cols[(k + 1) % len(cols)]])
        old, cols[k] = cols[k], new
        return b",".join(cols) + b"\n" + rest, f"column {old!r} renamed {new!r}"
    hits = [(p, m) for p, _ in HEADER_EDITS[kind] for m in re.finditer(p, head)]
    if not hits:
        return _header_kind(body, "header_del", rng, fmt)
    _, m = rng.choice(hits)
    new = _new_value(kind, m.group(2), rng)
    head = head[: m.start(2)] + new + head[m.end(2) :]
    return head + rest, f"{m.group(1).decode('latin-1').strip()} {m.group(2)!r} -> {new!r}"


def _encoding_kind(body: bytes, kind: str, rng: random.Random, fmt: str) -> tuple[bytes, str]:
    if kind == "crlf":
        if rng.random() < 0.5:
            return body.replace(b"\n", b"\r\n"), "all line ends CRLF"
        lines = body.splitlines(keepends=True)
        idx = sorted(rng.sample(range(len(lines)), max(1, len(lines) // 10)))
        for i in idx:
            lines[i] = lines[i].replace(b"\n", b"\r\n")
        return b"".join(lines), f"{len(idx)} line ends CRLF"
    if kind == "cr_only":
        return body.replace(b"\n", b"\r"), "line ends CR only"
    if kind == "bom":
        return b"\xef\xbb\xbf" + body, "UTF-8 BOM"
    if kind == "utf16":
        return body.decode("latin-1").encode("utf-16"), "UTF-16 with BOM"
    if kind == "latin1":
        i = rng.randrange(len(body))
        ins = rng.choice([b"\xe9", b"\xff\xfe", "\u00e9".encode(), b"\x80\x81"])
        return body[:i] + ins + body[i:], f"{ins!r} at byte {i}"
    if kind == "gzip_body":
        sub = rng.choice(
            BYTE_KINDS[:4] if fmt == "dat" else BYTE_KINDS[:4] + LINE_KINDS + FIELD_KINDS
        )
        new, what = _apply(body, sub, rng, fmt)
        return new, f"gzip of a body with {sub}: {what}"
    raise ValueError(kind)


def _parquet_kind(data: bytes, kind: str, rng: random.Random) -> tuple[bytes, str]:
    import io

    import pyarrow as pa
    import pyarrow.parquet as pq

    t = pq.read_table(io.BytesIO(data))
    k = rng.randrange(t.num_columns)
    name = t.column_names[k]
    if kind == "pq_drop":
        t, what = t.remove_column(k), f"column {name} dropped"
    elif kind == "pq_rename":
        new = rng.choice(["Time", "m_x", "", name + "_", t.column_names[(k + 1) % t.num_columns]])
        names = list(t.column_names)
        names[k] = new
        t, what = t.rename_columns(names), f"column {name} renamed {new!r}"
    elif kind == "pq_retype":
        typ = rng.choice(["string", "int64", "float32", "bool", "timestamp", "dictionary"])
        col = t.column(k)
        if typ == "string":
            new = pa.array([repr(v) for v in col.to_pylist()], pa.string())
        elif typ == "int64":
            new = pa.array([int(v) for v in col.to_pylist()], pa.int64())
        elif typ == "float32":
            new = col.cast(pa.float32())
        elif typ == "bool":
            new = pa.array([bool(v) for v in col.to_pylist()], pa.bool_())
        elif typ == "timestamp":
            new = pa.array([int(v * 1e9) for v in col.to_pylist()], pa.timestamp("ns"))
        else:
            new = pa.array([f"{v:.3g}" for v in col.to_pylist()]).dictionary_encode()
        t, what = t.set_column(k, name, new), f"column {name} retyped {typ}"
    elif kind in ("pq_nulls", "pq_nonfinite"):
        vals = t.column(k).to_pylist()
        n = rng.choice([1, 10, len(vals)])
        start = rng.randrange(len(vals))
        fill = None if kind == "pq_nulls" else rng.choice([float("nan"), float("inf"), -1e308])
        for i in range(start, min(len(vals), start + n)):
            vals[i] = fill
        new = pa.array(vals, t.schema.field(k).type)
        t, what = t.set_column(k, t.schema.field(k), new), f"{n} values of {name} set to {fill}"
    elif kind == "pq_empty":
        t, what = t.slice(0, rng.choice([0, 1, 5])), "rows cut"
    else:
        raise ValueError(kind)
    buf = io.BytesIO()
    pq.write_table(t, buf)
    return buf.getvalue(), what


def _apply(body: bytes, kind: str, rng: random.Random, fmt: str) -> tuple[bytes, str]:
    if kind in BYTE_KINDS:
        return _mutate_bytes(body, kind, rng)
    if kind in LINE_KINDS:
        return _line_kind(body, kind, rng)
    if kind in FIELD_KINDS:
        return _field_kind(body, kind, rng)
    if kind in HEADER_KINDS:
        return _header_kind(body, kind, rng, fmt)
    if kind in ENCODING_KINDS:
        return _encoding_kind(body, kind, rng, fmt)
    return _parquet_kind(body, kind, rng)


def _with_case(name: str, case: int) -> str:
    stem, dot, suffix = name.partition(".")
    return f"{stem}_c{case}{dot}{suffix}"


def mutate(seed: Seed, case: int, seeds_dir: Path) -> Mutated:
    """The mutated file of case ``case``: a function of ``case`` and the seed file only."""
    rng = random.Random(f"case-{case}")
    name = _with_case(seed.name, case)
    if rng.random() < 0.05:
        kind = rng.choice(SPECIAL_KINDS)
        if kind == "zero_length":
            return Mutated(name, kind, "empty file", data=b"")
        if kind == "directory":
            return Mutated(name, kind, "a directory", special="directory")
        target = rng.choice(["dangling", "self", "directory", "seed", "/dev/null"])
        link = {"dangling": "no-such-file", "self": name, "directory": ".", "seed": seed.name}
        return Mutated(
            name, kind, f"symlink to {target}", special=f"symlink:{link.get(target, target)}"
        )
    kind = rng.choice(KINDS[seed.fmt])
    raw = (seeds_dir / seed.name).read_bytes()
    if seed.fmt == "csvgz" and kind not in BYTE_KINDS:  # text mutations of the body, re-gzipped
        body, what = _apply(gzip.decompress(raw), kind, rng, seed.fmt)
        return Mutated(name, kind, what, data=gzip.compress(body, mtime=0))
    data, what = _apply(raw, kind, rng, seed.fmt)
    if kind == "gzip_body" and seed.fmt != "csvgz":
        return Mutated(name + ".gz", kind, what, data=gzip.compress(data, mtime=0))
    return Mutated(name, kind, what, data=data)


def materialize(m: Mutated, where: Path, seeds_dir: Path) -> Path:
    path = where / m.name
    if m.special == "directory":
        path.mkdir()
        (path / "x.asc").write_bytes(b"x\n")
    elif m.special:
        target = m.special.split(":", 1)[1]
        if target == Path(target).name and (seeds_dir / target).exists():
            shutil.copyfile(seeds_dir / target, where / target)
        path.symlink_to(target)
    else:
        path.write_bytes(m.data or b"")
    return path


# ----------------------------------------------------------------------------- batches


@dataclass
class Case:
    case: int
    seed_file: str
    role: str
    kind: str = ""
    detail: str = ""
    name: str = ""
    outcome: str = ""
    bad: list[str] = field(default_factory=list)
    message: str = ""


@dataclass
class Batch:
    batch: int
    command: str  # grace-bias | companion | demod
    argv: list[str] = field(default_factory=list)
    cases: list[Case] = field(default_factory=list)
    rc: int | None = None
    wall_s: float = 0.0
    rss_mb: float = 0.0
    timed_out: bool = False
    bad: list[str] = field(default_factory=list)
    stderr: str = ""
    stdout: str = ""


def plan(batch: int) -> tuple[Batch, list[str]]:
    """What batch ``batch`` runs: its cases' seed files and the command's options."""
    rng = random.Random(f"batch-{batch}")
    r, base = rng.random(), batch * CASES_PER_BATCH
    if r < 0.68:
        n = 1 if rng.random() < 0.1 else rng.randint(2, 6)
        b = Batch(batch, "grace-bias")
        b.cases = [Case(base + i, s.name, s.role) for i, s in enumerate(rng.choices(INPUTS, k=n))]
        opts = ["-j", "2" if rng.random() < 0.2 else "1"]
        if rng.random() < 0.2:
            opts += ["--method", "both"]
        if rng.random() < 0.15:
            opts += ["--format", "csv"]
        if rng.random() < 0.1:
            opts += ["--close-loop"]
        if any(c.seed_file == SWARM for c in b.cases):
            opts += ["--column", "x=a_cal_x"]
        return b, opts
    if r < 0.83:
        s = rng.choice(COMPANIONS)
        b = Batch(batch, "companion", cases=[Case(base, s.name, s.role)])
        return b, ["-j", "1"]
    n = rng.choice([1, 1, 2, 3])
    b = Batch(batch, "demod", cases=[Case(base + i, RUN.name, RUN.role) for i in range(n)])
    opts = ["--method", "gls"] if rng.random() < 0.3 else []
    if rng.random() < 0.3:
        opts += ["--bias-model", "affine+temperature"]
    if rng.random() < 0.15:
        opts += ["--resample"]
    if rng.random() < 0.15:
        opts += ["--format", "csv"]
    if rng.random() < 0.1:
        opts += ["--close-loop"]
    return b, opts


def build(batch: int, bdir: Path, seeds_dir: Path) -> Batch:
    """Write batch ``batch``'s files into ``bdir/in`` and return it with its argv."""
    b, opts = plan(batch)
    inp = bdir / "in"
    inp.mkdir(parents=True)
    seeds = {s.name: s for s in [*INPUTS, *COMPANIONS, RUN]}
    paths = []
    for c in b.cases:
        m = mutate(seeds[c.seed_file], c.case, seeds_dir)
        c.kind, c.detail, c.name = m.kind, m.detail, m.name
        paths.append(str(materialize(m, inp, seeds_dir)))
    out = str(bdir / "out")
    if b.command == "demod":
        b.argv = [
            ACCAL,
            "demod",
            *paths,
            "--tau",
            "600",
            "--mask",
            "200",
            "--out",
            out,
            "-q",
            *opts,
        ]
        return b
    if b.command == "grace-bias":
        b.argv = [ACCAL, "grace-bias", *paths, "--out", out, "-q", *opts]
        return b
    s = seeds[b.cases[0].seed_file]
    clean = []
    for name in s.partner:  # clean copies, away from the samples' own THR1B/SCA1B
        shutil.copyfile(seeds_dir / name, bdir / name)
        clean.append(str(bdir / name))
    extra = {
        "aux": ["--aux", paths[0]],
        "thrusters": ["--reference", clean[-1], "--scale", "1,1,1", "--bias-basis", "poly0",
                      "--thrusters", paths[0]],
        "attitude": ["--reference", clean[0], "--reference-frame", "inertial", "--scale", "1,1,1",
                     "--bias-basis", "poly0", "--attitude", paths[0]],
    }[s.role]  # fmt: skip
    b.argv = [ACCAL, "grace-bias", clean[0], *extra, "--out", out, "-q", *opts]
    return b


#: Runs one command in a small helper process (the command is forked from the helper's
#: ~10 MB image, so ``ru_maxrss`` is the command's own): timeout, peak RSS of the
#: largest process of its tree that was waited for, exit status.
_HELPER = r"""
import json, os, signal, sys, time
timeout, out_path, err_path, argv = float(sys.argv[1]), sys.argv[2], sys.argv[3], sys.argv[4:]
t0 = time.perf_counter()
pid = os.fork()
if pid == 0:
    try:
        os.setsid()
        fds = [os.open(os.devnull, os.O_RDONLY)]
        fds += [os.open(p, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644) for p in (out_path, err_path)]
        for i, fd in enumerate(fds):
            os.dup2(fd, i)
        os.execv(argv[0], argv)
    finally:
        os._exit(127)
timed_out = False
while True:
    wpid, status, ru = os.wait4(pid, os.WNOHANG)
    if wpid:
        break
    if time.perf_counter() - t0 > timeout:
        timed_out = True
        os.killpg(pid, signal.SIGKILL)
        _, status, ru = os.wait4(pid, 0)
        break
    time.sleep(0.02)
print(json.dumps({"wall_s": time.perf_counter() - t0, "rss_mb": ru.ru_maxrss / 1024.0,
                  "rc": os.waitstatus_to_exitcode(status), "timed_out": timed_out}))
"""


def execute(b: Batch, bdir: Path, timeout: float) -> None:
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    out, err = bdir / "stdout.txt", bdir / "stderr.txt"
    proc = subprocess.run([sys.executable, "-c", _HELPER, str(timeout), str(out), str(err), *b.argv],
                          env=env, capture_output=True, text=True, check=False)  # fmt: skip
    res = json.loads(proc.stdout.strip().splitlines()[-1])
    b.rc, b.wall_s, b.rss_mb, b.timed_out = (
        res["rc"],
        res["wall_s"],
        res["rss_mb"],
        res["timed_out"],
    )
    b.stdout = out.read_text(errors="replace")
    b.stderr = err.read_text(errors="replace")
    log = bdir / "out" / "accal.log"  # the run's own "peak RSS N MB per worker" (workers too)
    if log.is_file():
        for mb in re.findall(r"peak RSS (\d+) MB", log.read_text(errors="replace")):
            b.rss_mb = max(b.rss_mb, float(mb))


# ----------------------------------------------------------------------------- classification


def _names(line: str, name: str) -> bool:
    return re.search(re.escape(name) + r"(?![\w.-])", line) is not None


def _sources(out: Path) -> set[str]:
    """The ``source`` values of the cumulative table (bias_drift / periods)."""
    import pyarrow.csv as pcsv
    import pyarrow.parquet as pq

    found: set[str] = set()
    for stem in ("bias_drift", "periods"):
        for path in (out / f"{stem}.parquet", out / f"{stem}.csv"):
            if path.is_file():
                t = pq.read_table(path) if path.suffix == ".parquet" else pcsv.read_csv(path)
                if "source" in t.column_names:
                    found |= set(t.column("source").to_pylist())
    return found


def _outputs(out: Path, name: str) -> list[str]:
    """Per-input outputs of ``name`` (``<stem>.report.json``, ``<stem>.summary.json`` ...)."""
    stem = name.partition(".")[0]
    return sorted(p.name for p in out.glob(f"{stem}.*")) if out.is_dir() else []


def _complete(b: Batch, outputs: list[str]) -> bool:
    """An input that worked has all its outputs (with its rows, checked apart)."""
    if b.command == "demod":  # one run: OUT/summary.json, several: <stem>.summary.json
        return len(b.cases) == 1 or any(p.endswith(".summary.json") for p in outputs)
    return any(".calibrated." in p for p in outputs) and any(
        p.endswith(".report.json") for p in outputs
    )


def classify(b: Batch, bdir: Path, rss_limit_mb: float) -> None:
    out = bdir / "out"
    text = b.stdout + b.stderr
    lines = [x for x in b.stderr.splitlines() if x.strip()]
    errors = [x for x in lines if x.startswith("accal: ") and ": warning:" not in x]
    if b.timed_out:
        b.bad.append("timeout")
    if "Traceback" in text or "internal error" in text.lower():
        b.bad.append("traceback")
    if b.rc not in GOOD_EXIT and not b.timed_out:
        b.bad.append("exit_code")
    if any(not x.startswith("accal: ") for x in lines):
        b.bad.append("stray_output")
    if b.rss_mb > rss_limit_mb:
        b.bad.append("rss")
    if out.is_dir() and [p for p in out.rglob("*") if ".tmp" in p.name or ".accal-" in p.name]:
        b.bad.append("partial_output")
    sources = _sources(out)
    names = [c.name for c in b.cases]
    if b.command == "companion":
        clean = Path(b.argv[2]).name
        names.append(clean)
    unnamed = [
        x for x in errors if not any(_names(x, n) for n in names) and x != "accal: interrupted"
    ]
    if unnamed:
        b.bad.append("unnamed_message")
    failed_any = False
    for c in b.cases:
        mine = [x for x in errors if _names(x, c.name)]
        c.message = mine[0] if mine else ""
        if b.command == "companion":
            rows = clean in sources
            outputs = _outputs(out, clean)
            if mine:
                c.outcome = "clean_failure"
            elif b.rc == 0 and rows:
                c.outcome = "ok"
                if not _complete(b, outputs):
                    c.bad.append("partial_output")
            elif errors:  # the input failed, the mutated companion is not named
                c.bad.append("unnamed_message")
                c.message = errors[0]
            else:
                c.bad.append("not_processed")
            failed = c.outcome != "ok"
        else:
            rows = c.name in sources
            outputs = _outputs(out, c.name)
            failed = bool(mine)
            if failed:
                c.outcome = "clean_failure"
            elif rows or outputs:
                c.outcome = "ok"
                if not (rows and _complete(b, outputs)):
                    c.bad.append("partial_output")
            else:
                c.bad.append("not_processed")
        failed_any |= failed
        if failed and (rows or outputs):
            c.bad.append("rows_for_failed")
        if failed and b.rc not in (1, 2):
            c.bad.append("exit_code")
    if not failed_any and b.rc in (1, 2) and not unnamed:
        b.bad.append("exit_code")
    for c in b.cases:
        for kind in b.bad:
            if kind not in c.bad:
                c.bad.append(kind)
        if c.bad:
            c.outcome = "BAD:" + c.bad[0]


# ----------------------------------------------------------------------------- driver


def prepare_seeds(work: Path) -> Path:
    seeds_dir = work / "seeds"
    seeds_dir.mkdir(parents=True)
    for s in [*INPUTS, *COMPANIONS]:
        shutil.copyfile(SAMPLES / s.name, seeds_dir / s.name)
    cmd = [ACCAL, "simulate", "gap", "--days", "0.2", "--tau", "600", "--mask", "200",
           "--out", str(seeds_dir / RUN.name)]  # fmt: skip
    subprocess.run(cmd, capture_output=True, check=True)
    return seeds_dir


def run_one(batch: int, work: Path, seeds_dir: Path, args: argparse.Namespace) -> Batch:
    bdir = work / f"b{batch}"
    if bdir.exists():
        shutil.rmtree(bdir)
    b = build(batch, bdir, seeds_dir)
    execute(b, bdir, args.timeout)
    classify(b, bdir, args.rss_limit_mb)
    return b


def reproduce(batch: int) -> str:
    return f"OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/fuzz_cli.py --replay {batch}"


def _message_key(line: str) -> str:
    """An error line without its path and numbers: counts failures by reason."""
    msg = re.sub(r"^accal: \S+?(:\d+)?: ", "", line)
    return re.sub(r"(?<![A-Za-z0-9])-?\d[\d.e+-]*", "N", msg)[:110]


def report(batches: list[Batch], meta: dict, out: Path) -> dict:
    cases = [c for b in batches for c in b.cases]
    by_kind = collections.Counter(
        c.outcome.partition(":")[0] if c.bad else c.outcome for c in cases
    )
    bad_kinds = collections.Counter(k for c in cases for k in c.bad)
    by_mut: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
    for c in cases:
        by_mut[c.kind]["BAD" if c.bad else c.outcome] += 1
    rss = [b.rss_mb for b in batches]
    by_cmd: dict[str, list[float]] = collections.defaultdict(list)
    for b in batches:
        by_cmd[b.command].append(b.rss_mb)
    reasons = collections.Counter(
        _message_key(c.message) for c in cases if c.outcome == "clean_failure"
    )
    bad = [
        {**asdict(c), "batch": b.batch, "argv": b.argv, "rc": b.rc, "batch_bad": b.bad,
         "stderr": b.stderr[-3000:], "reproduce": reproduce(b.batch)}
        for b in batches for c in b.cases if c.bad
    ]  # fmt: skip
    summary = {
        **meta,
        "batches": len(batches),
        "cases": len(cases),
        "seed_files": sorted({c.seed_file for c in cases}),
        "outcomes": dict(by_kind),
        "outcomes_by_bad_kind": dict(bad_kinds),
        "outcomes_by_mutation": {k: dict(v) for k, v in sorted(by_mut.items())},
        "outcomes_by_command": {
            cmd: dict(
                collections.Counter(
                    "BAD" if c.bad else c.outcome
                    for b in batches
                    if b.command == cmd
                    for c in b.cases
                )
            )
            for cmd in sorted(by_cmd)
        },
        "rss_mb": {
            "max": max(rss, default=0.0),
            "median": statistics.median(rss) if rss else 0.0,
            "by_command": {
                k: {"max": max(v), "median": statistics.median(v)}
                for k, v in sorted(by_cmd.items())
            },
        },
        "wall_s_invocations": {
            "sum": sum(b.wall_s for b in batches),
            "max": max((b.wall_s for b in batches), default=0.0),
        },
        "top_failure_reasons": reasons.most_common(25),
        "bad_cases": bad,
    }
    out.mkdir(parents=True, exist_ok=True)
    doc = {"summary": summary, "batches": [asdict(b) for b in batches]}
    (out / "results.json").write_text(json.dumps(doc, indent=1, default=str) + "\n")
    (out / "summary.md").write_text(markdown(summary))
    return summary


def _table(what: str, counts: dict[str, dict[str, int]]) -> list[str]:
    rows = [f"| {what} | ok | clean_failure | BAD |", "|---|---:|---:|---:|"]
    rows += [f"| {k} | {v.get('ok', 0)} | {v.get('clean_failure', 0)} | {v.get('BAD', 0)} |"
             for k, v in counts.items()]  # fmt: skip
    return rows


def markdown(s: dict) -> str:
    lines = [
        "# accal CLI mutation fuzzing (issue 23)",
        "",
        f"- date {s['date']}, commit {s['git']['commit'][:12]}, src sha256 {s['git']['src_sha256']}"
        + (" (working tree of src/ modified)" if s["git"]["dirty"] else ""),
        f"- wall time {s['wall_s']:.0f} s (budget {s['minutes']} min), seed {s['seed']}, "
        f"timeout {s['timeout']} s per invocation, RSS limit {s['rss_limit_mb']:.0f} MB",
        f"- {s['batches']} CLI invocations, {s['cases']} cases (mutated files) from "
        f"{len(s['seed_files'])} seed files",
        f"- peak RSS per invocation: max {s['rss_mb']['max']:.0f} MB, median "
        f"{s['rss_mb']['median']:.0f} MB; "
        + ", ".join(
            f"{k}: max {v['max']:.0f} / median {v['median']:.0f} MB"
            for k, v in s["rss_mb"]["by_command"].items()
        ),
        f"- BAD cases: {len(s['bad_cases'])}",
        f"- src changed during the run: {s.get('git_end', s['git'])['src_sha256'] != s['git']['src_sha256']}",
        "",
        "## Outcomes",
        "",
        "| outcome | cases |",
        "|---|---:|",
        *[f"| {k} | {v} |" for k, v in sorted(s["outcomes"].items())],
        *[f"| BAD kind `{k}` | {v} |" for k, v in sorted(s["outcomes_by_bad_kind"].items())],
        "",
        *_table("command", s["outcomes_by_command"]),
        "",
        "## By mutation",
        "",
        *_table("mutation", s["outcomes_by_mutation"]),
        "",
        "## Most frequent failure messages (path and numbers left out)",
        "",
        *[f"- {n}x `{k}`" for k, n in s["top_failure_reasons"]],
        "",
        "## BAD cases",
        "",
    ]
    if not s["bad_cases"]:
        lines.append("none")
    for c in s["bad_cases"]:
        lines += [
            f"### case {c['case']} (batch {c['batch']}): {', '.join(c['bad'])}",
            "",
            f"- seed file {c['seed_file']} ({c['role']}), mutation `{c['kind']}`: {c['detail']}",
            f"- exit {c['rc']}; reproduce: `{c['reproduce']}`",
            "",
            "```",
            *(c["stderr"].strip().splitlines()[-15:] or ["(no stderr)"]),
            "```",
            "",
        ]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=10.0, help="time budget (default 10)")
    ap.add_argument("--seed", type=int, default=0, help="batches seed*10^6 + 0, 1, ...")
    ap.add_argument("--batches", type=int, default=None, help="stop after this many batches")
    ap.add_argument("--replay", type=int, nargs="+", help="run these batches only, keep them")
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "fuzz-cli")
    ap.add_argument("--timeout", type=float, default=120.0, help="per invocation [s]")
    ap.add_argument("--rss-limit-mb", type=float, default=RSS_LIMIT_MB)
    args = ap.parse_args(argv)
    meta = {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "git": git_state(),
            "minutes": args.minutes, "seed": args.seed, "timeout": args.timeout,
            "rss_limit_mb": args.rss_limit_mb}  # fmt: skip
    replay = args.replay is not None
    work = args.out / "replay" if replay else Path(tempfile.mkdtemp(prefix="accal-fuzz-"))
    if replay and work.exists():
        shutil.rmtree(work)
    t0 = time.perf_counter()
    seeds_dir = prepare_seeds(work)
    todo = iter(args.replay) if replay else (args.seed * 10**6 + i for i in range(10**6))
    batches: list[Batch] = []
    try:
        for batch in todo:
            if not replay and (
                time.perf_counter() - t0 > 60 * args.minutes
                or (args.batches is not None and len(batches) >= args.batches)
            ):
                break
            b = run_one(batch, work, seeds_dir, args)
            batches.append(b)
            bdir = work / f"b{batch}"
            if replay:
                print(f"batch {batch}: {' '.join(b.argv)}\nexit {b.rc}, {b.wall_s:.1f} s, "
                      f"{b.rss_mb:.0f} MB\n{b.stderr}", end="")  # fmt: skip
                for c in b.cases:
                    print(f"  case {c.case} {c.name} [{c.kind}: {c.detail}]: {c.outcome}")
                continue
            if any(c.bad for c in b.cases):
                dest = args.out / "bad" / f"b{batch}"
                if dest.exists():
                    shutil.rmtree(dest)
                shutil.copytree(bdir, dest, symlinks=True)
            shutil.rmtree(bdir, ignore_errors=True)
            if len(batches) % 25 == 0:
                meta["wall_s"] = time.perf_counter() - t0
                report(batches, meta, args.out)
                print(f"{len(batches)} batches, {sum(len(x.cases) for x in batches)} cases, "
                      f"{sum(1 for x in batches for c in x.cases if c.bad)} BAD, "
                      f"{meta['wall_s']:.0f} s", flush=True)  # fmt: skip
    except KeyboardInterrupt:
        print("interrupted: writing what ran", file=sys.stderr)
    finally:
        if not replay:
            shutil.rmtree(work, ignore_errors=True)
    meta["wall_s"] = time.perf_counter() - t0
    meta["git_end"] = git_state()  # src/ is edited by others while this runs: did it change?
    summary = report(batches, meta, args.out)
    print(f"{summary['batches']} invocations, {summary['cases']} cases, outcomes "
          f"{summary['outcomes']}, peak RSS max {summary['rss_mb']['max']:.0f} MB; "
          f"{args.out / 'summary.md'}")  # fmt: skip
    return summary


if __name__ == "__main__":
    main()
