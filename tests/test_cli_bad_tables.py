"""End to end: `accal grace-bias` on a batch of broken tables and one good L1B file.

Each broken table once escaped the table reader as a Python exception or went
through unnoticed: a ``gps_time`` of 1e300 s gave "internal error (OverflowError
...)" when the pipeline computed its date, a duplicated column name gave pyarrow's
KeyError, and a ``quality`` of 1e30 wrapped around to 0 (a flagged sample looked
valid).  Now each is one line ``accal: FILE[:LINE]: what is wrong`` and the batch
goes on with the good file.
"""

from __future__ import annotations

import json
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
from click.testing import CliRunner

from accal.cli import main

SAMPLES = Path(__file__).resolve().parents[1] / "data" / "samples"
GRACE_A = SAMPLES / "ACC1B_2003-09-14_A_00.asc"


def _bad_tables(d: Path) -> dict[Path, str]:
    """Write the broken tables; map each to how its stderr line goes on after the path."""
    d.mkdir()
    huge = d / "huge_time.parquet"
    table = pa.table(
        {"gps_time": [116769600.0, 1e300, 116769602.0], "lin_accl_x": [1e-7, 2e-7, 3e-7]}
    )
    pq.write_table(table, huge)
    dup = d / "dup_columns.csv"
    dup.write_text("gps_time,lin_accl_x,lin_accl_x\n116769600,1e-7,1e-7\n116769601,2e-7,2e-7\n")
    quality = d / "quality_1e30.csv"
    quality.write_text(
        "gps_time,lin_accl_x,quality\n116769600,1e-7,0\n116769601,2e-7,1e30\n116769602,3e-7,0\n"
    )
    return {
        huge: ": row 2: gps_time 1e+300 s is outside 1980-01-06 ... 2100-01-01",
        dup: ":1: duplicated column name(s) lin_accl_x",
        quality: ":3: column 'quality' must hold integers 0 ... 4294967295 (a bitmask), got 1e+30",
    }


def test_bad_tables_fail_one_line_each_and_the_good_file_is_processed(tmp_path):
    bad = _bad_tables(tmp_path / "in")
    out = tmp_path / "out"
    args = ["grace-bias", *map(str, bad), str(GRACE_A), "--out", str(out), "-q"]
    res = CliRunner().invoke(main, args, catch_exceptions=False)

    assert res.exit_code == 1, res.output
    err = res.stderr
    assert "internal error" not in err and "Traceback" not in err and 'File "' not in err
    lines = err.strip().splitlines()
    assert len(lines) == len(bad), err
    for path, rest in bad.items():
        mine = [ln for ln in lines if ln.startswith(f"accal: {path}")]
        assert len(mine) == 1 and mine[0].startswith(f"accal: {path}{rest}"), err
    # the good file is processed and is the only one recorded as done
    assert (out / "ACC1B_2003-09-14_A_00.calibrated.parquet").is_file()
    assert (out / "ACC1B_2003-09-14_A_00.report.json").is_file()
    manifest = json.loads((out / "manifest.json").read_text())["entries"]
    assert [Path(k).name for k in manifest] == [GRACE_A.name]
    assert not any(out.glob("huge_time*") or out.glob("dup_columns*") or out.glob("quality*"))


def _qa_inputs(d: Path) -> tuple[dict[Path, str], list[Path]]:
    """Inputs of the black-box QA pass: broken ones (-> stderr rest) and good ones."""
    import gzip

    d.mkdir()
    raw = GRACE_A.read_bytes()
    empty = d / "ACC1B_empty.asc"
    empty.write_bytes(b"")
    cut = d / "ACC1B_cut.asc.gz"
    cut.write_bytes(gzip.compress(raw)[:2000])
    bad_time = d / "bad_time.csv"
    bad_time.write_text(
        "time_utc,lin_accl_x\n2024-05-11T00:00:49.796,1e-7\n2024-05-11T25:00:49.796,2e-7\n"
    )
    text_acc = d / "text_acc.csv"
    text_acc.write_text("gps_time,lin_accl_x\n116769600,1e-7\n116769601,abc\n")
    short_row = d / "short_row.csv"
    short_row.write_text("gps_time,lin_accl_x,lin_accl_y\n116769600,1e-7,1e-7\n116769601,2e-7\n")
    lines = raw.decode().split("\n")
    empty_field = d / "ACC1B_empty_field.asc"
    fields = lines[40].split(" ")
    fields[6] = ""  # ang_accl_y
    empty_field.write_text("\n".join([*lines[:40], " ".join(fields), *lines[41:]]))
    bom = d / "ACC1B_2003-09-14_A_bom.asc"
    bom.write_bytes(b"\xef\xbb\xbf" + raw)
    no_newline = d / "ACC1B_2003-09-14_A_nonl.asc"
    no_newline.write_bytes(raw[:-1])
    bad = {
        empty: ": empty file",
        cut: ": corrupt gzip stream (truncated: no end-of-stream marker)",
        bad_time: ":3: time_utc: '2024-05-11T25:00:49.796' is not an ISO-8601 UTC time",
        text_acc: ":3: column 'lin_accl_x' is not numeric (type string): 'abc' is not a number",
        short_row: ":3: CSV: Expected 3 columns, got 2: 116769601,2e-7",
        empty_field: ":41: ang_accl_y: empty field (two spaces where a value was expected)",
    }
    return bad, [bom, no_newline]


def test_qa_inputs_say_what_is_wrong_and_quirky_good_files_are_read(tmp_path):
    bad, good = _qa_inputs(tmp_path / "in")
    out = tmp_path / "out"
    args = ["grace-bias", *map(str, [*bad, *good]), "--out", str(out), "-q"]
    res = CliRunner().invoke(main, args, catch_exceptions=False)

    assert res.exit_code == 1, res.output
    err = res.stderr
    assert "format not recognised" not in err and "internal error" not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == len(bad), err
    for path, rest in bad.items():
        mine = [ln for ln in lines if ln.startswith(f"accal: {path}")]
        assert len(mine) == 1 and mine[0].startswith(f"accal: {path}{rest}"), err
    manifest = json.loads((out / "manifest.json").read_text())["entries"]
    assert sorted(Path(k).name for k in manifest) == sorted(p.name for p in good)


def test_a_time_column_of_unix_seconds_is_said(tmp_path):
    """QA (2026-11-30): Unix seconds in ``time`` were read as GPS seconds since
    2000-01-01 12:00 and the day dated 2054-05-12, without a word."""
    import numpy as np

    t = 1_715_385_600.0 + np.arange(600.0)  # 2024-05-11 in Unix seconds
    x = -7e-7 + 1e-10 * np.random.default_rng(0).standard_normal(t.size)
    path = tmp_path / "swarm.csv"
    path.write_text(
        "time,a_cal_x\n" + "".join(f"{a:.3f},{b:.6e}\n" for a, b in zip(t, x, strict=True))
    )
    res = CliRunner().invoke(
        main, ["grace-bias", str(path), "--column", "x=a_cal_x", "--out", str(tmp_path / "o")]
    )
    assert res.exit_code == 0, res.output
    assert "column 'time' dates the data from 2054-05-1" in res.output
    assert "Unix seconds count from 1970" in res.output
