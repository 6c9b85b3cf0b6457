"""The CLI outputs of the README commands and ``make demo``, before and after a change.

Issue 21 ("the CLI outputs of the README commands and ``make demo`` identical
before/after"): a refactor must not change what users get.  This script runs the same
commands with two versions of accal, each from its own tree (``PYTHONPATH=<tree>/src``,
the same Python and dependencies), on the same inputs, into two output directories,
and compares them file by file:

* tables (``.parquet``, ``.csv``): columns only in one of them, then the dtypes and values
  of the common columns (exactly; for floats the largest absolute and relative
  difference is printed when they differ);
* JSON: the whole document, after the output roots are replaced by ``<OUT>``, the keys
  that record when or how long something ran (:data:`VOLATILE`) are removed and strings
  are masked as text (below);
* text (``.md``, ``.txt``, ``.log``, the commands' stdout and stderr): line by line, after
  the same substitutions and with durations, rates, memory, timestamps and versions
  masked (:data:`VOLATILE_TEXT`); a log's lines in sorted order (workers log in the order
  they finish);
* anything else (``.asc``, ``.npz``, ``.png``, ``.gz``): bytes.

Usage::

    python benchmarks/compare_outputs.py BASE [--head REV] [--out DIR] [--only run demo ...]

``BASE`` and ``--head`` are git revisions; without ``--head`` the working tree is the
"after" (so an uncommitted refactor can be checked before it is committed).  Writes
``DIR/compare.md`` and exits 1 when anything differs.  ``make compare-outputs BASE=REV``.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tarfile
import tempfile
from io import BytesIO
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = "data/samples"

#: The commands: group -> list of argument lists ({OUT} is the side's output root,
#: {TREE} its source tree; ``accal`` runs ``python -m accal``).  ``run`` and ``demo`` are
#: the Makefile's targets of those names, ``walk`` the README's walk-through.
COMMANDS: dict[str, list[list[str]]] = {
    "run": [
        ["accal", "grace-bias", f"{SAMPLES}/ACC1B_2003-09-14_A_00.asc",
         f"{SAMPLES}/ACC1B_2003-09-14_B_00.asc", f"{SAMPLES}/ACT1B_2023-06-01_C_04.txt",
         f"{SAMPLES}/ACT1B_2023-06-01_D_04.txt", "--method", "both", "--format", "csv",
         "--out", "{OUT}/grace-bias"],
        ["accal", "simulate", "grace", "--date", "2005-01-01", "--satellite", "A", "--out",
         "{OUT}/sim/ACC1B_2005-01-01_A_sim.asc"],
        ["accal", "grace-bias", "{OUT}/sim/ACC1B_2005-01-01_A_sim.asc", "--method", "both",
         "--scale", "tn02", "--format", "csv", "--out", "{OUT}/grace-bias"],
        ["accal", "table", "{OUT}/grace-bias"],
    ],
    "demo": [
        ["python", "{TREE}/benchmarks/closure_demo.py", "--out", "{OUT}/demo"],
        ["accal", "grace-bias", f"{SAMPLES}/SW_A_ACCACAL_20240511_a_cal_x.csv.gz", "--column",
         "x=a_cal_x", "--close-loop", "--plots", "--force", "--format", "csv", "--out",
         "{OUT}/demo/swarm-cli"],
        ["accal", "simulate", "gap", "--days", "0.5", "--tau", "600", "--mask", "200",
         "--temperature-coupling", "1e-9", "--out", "{OUT}/demo/gap/run.parquet"],
        ["accal", "demod", "{OUT}/demo/gap/run.parquet", "--tau", "600", "--mask", "200",
         "--close-loop", "--plots", "--out", "{OUT}/demo/gap/res"],
    ],
    "walk": [
        ["accal", "simulate", "grace", "--date", "2005-01-01", "--satellite", "A", "--gaps", "3",
         "--flagged", "0.01", "--out", "{OUT}/sim/day.asc"],
        ["accal", "grace-bias", "{OUT}/sim/day.asc", "--method", "both", "--scale", "tn02",
         "--out", "{OUT}/walk", "--format", "csv"],
        ["accal", "simulate", "grace", "--storm", "--thrusters", "--effect",
         "step:axis=x,epoch=43200,size=3e-9", "--effect",
         "coupling:axis=y,channel=temperature,coef=3e-9,lag=600,tau=300", "--reference-out",
         "{OUT}/sim/ref.parquet", "--out", "{OUT}/sim/day2.asc"],
        ["accal", "grace-bias", "{OUT}/sim/day2.asc", "--aux", "{OUT}/sim/day2.asc.aux.parquet",
         "--out", "{OUT}/demo2"],
        ["accal", "grace-bias", f"{SAMPLES}/SW_A_ACCACAL_20240511_a_cal_x.csv.gz", "--column",
         "x=a_cal_x", "--out", "{OUT}/walk", "--format", "csv"],
        ["accal", "grace-bias", "{OUT}/sim/day.asc", "--config", "configs/grace_daily.toml",
         "--out", "{OUT}/walk-parquet"],
        ["accal", "simulate", "gap", "--days", "1", "--tau", "600", "--mask", "200", "--out",
         "{OUT}/gap/run.parquet"],
        ["accal", "demod", "{OUT}/gap/run.parquet", "--tau", "600", "--mask", "200", "--method",
         "gls", "--out", "{OUT}/gap/res"],
        ["accal", "design", "--tau", "600", "--mask", "200", "--fs", "1", "--out",
         "{OUT}/gap/pattern.csv"],
        ["accal", "budget", "--mask", "200", "--tau", "600", "--method", "gls", "--integration",
         "10800"],
        ["accal", "budget", "--mask", "200", "--method", "gls", "--json"],
    ],
}  # fmt: skip

#: JSON keys that say when, where or how long something ran (removed before comparing).
VOLATILE = re.compile(
    r"(^|_)(created|written|started|finished|timestamp|time_utc_run|wall|elapsed|duration|"
    r"seconds|cpu|rss|mtime|ctime|atime|host|hostname|pid|version|accal_version|commit|python|platform)($|_)",
    re.IGNORECASE,
)
#: What a run's text says about when and how fast it ran: (pattern, replacement).
VOLATILE_TEXT = [
    # durations after a word that introduces one ("in 0.81 s", "both runs 12.3 s", "took 3 min")
    (
        re.compile(
            r"\b(in|runs?|took|wall|cpu|elapsed|time)(:?\s+)\d+(\.\d+)?\s*(s|ms|min|h)\b",
            re.IGNORECASE,
        ),
        r"\1\2<T> \4",
    ),
    (re.compile(r"\d[\d,]*(\.\d+)?\s*(MB|kB|GB|samples|rows|files|inputs)/s\b"), r"<RATE> \2/s"),
    (re.compile(r"\b(peak RSS|RSS)(:?\s+)\d+(\.\d+)?\s*(kB|MB|GB)"), r"\1\2<RSS> \4"),
    # ISO timestamps of log lines and reports, and process ids after them
    (re.compile(r"\d{4}-\d{2}-\d{2}[T ]\d{2}:\d{2}:\d{2}(\.\d+)?Z?( \[\d+\])?"), "<WHEN>"),
    (re.compile(r"\b(accal|version)\s+v?\d+\.\d+[\w.+-]*", re.IGNORECASE), r"\1 <VERSION>"),
    # file times inside JSON written into a text line (the manifest entries a log quotes)
    (re.compile(r'"(\w*(?:mtime|ctime|atime)\w*)":\s*[\d.]+'), r'"\1": <FILETIME>'),
]
#: Files that only a run's bookkeeping writes (a lock holding the process id).
SKIP_FILES = {".accal.lock"}


def materialise(rev: str, dest: Path) -> Path:
    """The tree of git revision ``rev`` in ``dest`` (``git archive``)."""
    blob = subprocess.run(
        ["git", "-C", str(ROOT), "archive", "--format=tar", rev],
        check=True,
        capture_output=True,
    ).stdout
    dest.mkdir(parents=True)
    with tarfile.open(fileobj=BytesIO(blob)) as tar:
        tar.extractall(dest, filter="data")
    return dest


def run_side(tree: Path, out: Path, groups: list[str]) -> list[dict[str, Any]]:
    """Run the commands of ``groups`` with accal from ``tree``; their exit codes and
    output (roots replaced)."""
    env = {**os.environ, "PYTHONPATH": str(tree / "src"), "MPLBACKEND": "Agg"}
    env.pop("PYTHONSTARTUP", None)
    out.mkdir(parents=True, exist_ok=True)
    done = []
    for g in groups:
        for cmd in COMMANDS[g]:
            args = [a.replace("{OUT}", str(out)).replace("{TREE}", str(tree)) for a in cmd]
            if args[0] == "accal":
                args = [sys.executable, "-m", "accal", *args[1:]]
            elif args[0] == "python":
                args = [sys.executable, *args[1:]]
            p = subprocess.run(args, cwd=tree, env=env, capture_output=True, text=True)
            done.append(
                {
                    "command": " ".join(cmd),
                    "rc": p.returncode,
                    "stdout": normalise_text(p.stdout, out, tree),
                    "stderr": normalise_text(p.stderr, out, tree),
                }
            )
    return done


def normalise_text(text: str, out: Path, tree: Path) -> str:
    """Roots replaced; durations, rates, timestamps and versions masked
    (:data:`VOLATILE_TEXT`)."""
    text = text.replace(str(out), "<OUT>").replace(str(tree), "<TREE>")
    for pattern, repl in VOLATILE_TEXT:
        text = pattern.sub(repl, text)
    return text


def _strip(doc: Any, out: Path, tree: Path) -> Any:
    if isinstance(doc, dict):
        return {
            _strip(k, out, tree): _strip(v, out, tree)
            for k, v in doc.items()
            if not VOLATILE.search(str(k))
        }
    if isinstance(doc, list):
        return [_strip(v, out, tree) for v in doc]
    if isinstance(doc, str):
        return normalise_text(doc, out, tree)
    return doc


def _read_table(path: Path) -> pd.DataFrame:
    if path.suffix == ".parquet":
        return pd.read_parquet(path)
    return pd.read_csv(path, comment=None)


def compare_tables(a: Path, b: Path) -> str | None:
    """``None`` when equal, else what differs: columns only in one of the two, then the
    first common column whose values differ (so an added column does not hide a changed
    number)."""
    ta, tb = _read_table(a), _read_table(b)
    out = []
    only_a = [c for c in ta.columns if c not in tb.columns]
    only_b = [c for c in tb.columns if c not in ta.columns]
    if only_a:
        out.append(f"columns only before: {only_a}")
    if only_b:
        out.append(f"columns only after: {only_b}")
    if len(ta) != len(tb):
        return "; ".join(out + [f"rows {len(ta)} vs {len(tb)}"])
    for c in (c for c in ta.columns if c in tb.columns):
        diff = _column_difference(c, ta[c], tb[c])
        if diff:
            out.append(diff)
            break
    if not out and list(ta.columns) != list(tb.columns):
        out.append(f"column order {list(ta.columns)} vs {list(tb.columns)}")
    return "; ".join(out) or None


def _column_difference(c: str, x: pd.Series, y: pd.Series) -> str | None:
    if x.dtype != y.dtype:
        return f"column {c}: dtype {x.dtype} vs {y.dtype}"
    if pd.api.types.is_float_dtype(x):
        xv, yv = x.to_numpy(), y.to_numpy()
        if np.array_equal(xv, yv, equal_nan=True):
            return None
        d = np.abs(xv - yv)
        rel = d / np.maximum(np.abs(xv), np.finfo(float).tiny)
        return f"column {c}: max |Δ| {np.nanmax(d):.3g}, max relative {np.nanmax(rel):.3g}"
    if x.equals(y):
        return None
    k = int(np.flatnonzero((x != y).to_numpy())[0])
    return f"column {c}, row {k}: {x.iloc[k]!r} vs {y.iloc[k]!r}"


def compare_file(
    a: Path, b: Path, roots: tuple[tuple[Path, Path], tuple[Path, Path]]
) -> str | None:
    """``None`` when the two outputs are the same (see the module docstring)."""
    (oa, ta_), (ob, tb_) = roots
    suf = "".join(a.suffixes[-2:]) if a.suffix == ".gz" else a.suffix
    if suf in (".parquet", ".csv"):
        return compare_tables(a, b)
    if suf == ".json":
        ja = _strip(json.loads(a.read_text()), oa, ta_)
        jb = _strip(json.loads(b.read_text()), ob, tb_)
        return None if ja == jb else _first_json_difference(ja, jb)
    if suf in (".md", ".txt", ".log"):
        la = normalise_text(a.read_text(), oa, ta_).splitlines()
        lb = normalise_text(b.read_text(), ob, tb_).splitlines()
        if suf == ".log":  # worker processes log in the order they finish
            la, lb = sorted(la), sorted(lb)
        return _first_line_difference(la, lb)
    return None if a.read_bytes() == b.read_bytes() else "bytes differ"


def _first_line_difference(la: list[str], lb: list[str]) -> str | None:
    for k, (x, y) in enumerate(zip(la, lb, strict=False)):
        if x != y:
            i = next(
                (j for j, (u, v) in enumerate(zip(x, y, strict=False)) if u != v),
                min(len(x), len(y)),
            )
            a = max(i - 30, 0)
            return f"line {k + 1}: …{x[a : i + 50]!r} vs …{y[a : i + 50]!r}"
    return None if len(la) == len(lb) else f"{len(la)} vs {len(lb)} lines"


def _first_json_difference(a: Any, b: Any, where: str = "") -> str:
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b), key=str):
            if k not in a or k not in b:
                return f"{where}/{k}: only in {'after' if k in b else 'before'}"
            if a[k] != b[k]:
                return _first_json_difference(a[k], b[k], f"{where}/{k}")
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        for k, (x, y) in enumerate(zip(a, b, strict=True)):
            if x != y:
                return _first_json_difference(x, y, f"{where}[{k}]")
    return f"{where}: {str(a)[:80]} vs {str(b)[:80]}"


def compare(before: dict, after: dict) -> list[tuple[str, str | None]]:
    """Every command's exit code and output, and every output file: (name, difference)."""
    rows = []
    for ca, cb in zip(before["commands"], after["commands"], strict=True):
        for key in ("rc", "stdout", "stderr"):
            if ca[key] != cb[key]:
                diff = (
                    f"{ca[key]} vs {cb[key]}"
                    if key == "rc"
                    else _first_line_difference(ca[key].splitlines(), cb[key].splitlines())
                )
            else:
                diff = None
            rows.append((f"`{ca['command'][:70]}` {key}", diff))
    oa, ob = before["out"], after["out"]
    fa = {p.relative_to(oa) for p in oa.rglob("*") if p.is_file() and p.name not in SKIP_FILES}
    fb = {p.relative_to(ob) for p in ob.rglob("*") if p.is_file() and p.name not in SKIP_FILES}
    roots = ((oa, before["tree"]), (ob, after["tree"]))
    for rel in sorted(fa | fb):
        if rel not in fa or rel not in fb:
            rows.append((str(rel), f"only {'after' if rel in fb else 'before'}"))
            continue
        try:
            rows.append((str(rel), compare_file(oa / rel, ob / rel, roots)))
        except Exception as exc:  # an unreadable output is a difference, reported
            rows.append((str(rel), f"not comparable: {exc}"))
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("base", help="git revision of the 'before'")
    ap.add_argument("--head", help="git revision of the 'after' (default: the working tree)")
    ap.add_argument("--out", type=Path, default=Path("out/compare"))
    ap.add_argument("--only", nargs="*", choices=list(COMMANDS), default=list(COMMANDS))
    ap.add_argument("--keep", action="store_true", help="keep both output trees in --out")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="accal-compare-") as tmp:
        work = Path(tmp)
        sides = {}
        for side, rev in (("before", args.base), ("after", args.head)):
            tree = materialise(rev, work / f"tree-{side}") if rev else ROOT
            out = work / f"out-{side}"
            print(f"{side}: {rev or 'working tree'} ...", flush=True)
            sides[side] = {"tree": tree, "out": out, "commands": run_side(tree, out, args.only)}
        rows = compare(sides["before"], sides["after"])
        if args.keep:
            for side in ("before", "after"):
                dest = args.out / side
                shutil.rmtree(dest, ignore_errors=True)
                shutil.copytree(sides[side]["out"], dest)
    differ = [(n, d) for n, d in rows if d is not None]
    lines = [
        f"# CLI outputs: {args.base} vs {args.head or 'working tree'} ({', '.join(args.only)})",
        "",
        f"{len(rows)} outputs compared (commands' exit codes, stdout and stderr; files); "
        f"**{len(differ)} differ**.",
        "",
    ]
    if differ:
        lines += ["| output | difference |", "|---|---|"]
        lines += [f"| {n} | {d} |" for n, d in differ]
    text = "\n".join(lines) + "\n"
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "compare.md").write_text(text)
    print(text)
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
