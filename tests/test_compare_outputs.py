"""The before/after output comparison of ``benchmarks/compare_outputs.py`` (issue 21) can
fail: a changed number, column, JSON value or text line is reported; what only records
when or where a run happened is not."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import compare_outputs as co  # noqa: E402


def _roots(tmp_path: Path):
    oa, ob = tmp_path / "a", tmp_path / "b"
    oa.mkdir()
    ob.mkdir()
    return oa, ob, ((oa, tmp_path / "tree-a"), (ob, tmp_path / "tree-b"))


def test_tables_equal_and_one_ulp_apart(tmp_path):
    oa, ob, roots = _roots(tmp_path)
    df = pd.DataFrame({"axis": ["x", "y"], "bias": [1e-7, -2.5e-8], "n": [3, 4]})
    for ext, write in ((".parquet", df.to_parquet), (".csv", lambda p: df.to_csv(p, index=False))):
        write(oa / f"t{ext}")
        write(ob / f"t{ext}")
        assert co.compare_file(oa / f"t{ext}", ob / f"t{ext}", roots) is None
    changed = df.copy()
    changed.loc[1, "bias"] = np.nextafter(-2.5e-8, 0.0)
    changed.to_parquet(ob / "t.parquet")
    diff = co.compare_file(oa / "t.parquet", ob / "t.parquet", roots)
    assert diff is not None and diff.startswith("column bias")
    df.rename(columns={"n": "count"}).to_parquet(ob / "t.parquet")
    assert co.compare_file(oa / "t.parquet", ob / "t.parquet", roots) == (
        "columns only before: ['n']; columns only after: ['count']"
    )
    added = df.assign(t_utc=["a", "b"])
    added.loc[0, "bias"] = 2e-7
    added.to_parquet(ob / "t.parquet")
    diff = co.compare_file(oa / "t.parquet", ob / "t.parquet", roots)
    assert diff.startswith("columns only after: ['t_utc']; column bias: max")


def test_json_ignores_run_times_and_roots_but_not_values(tmp_path):
    oa, ob, roots = _roots(tmp_path)
    a = {"created": "2026-11-27T10:00:00Z", "wall_seconds": 1.2, "input": f"{oa}/x.asc", "b": 1.0}
    b = {"created": "2026-11-27T11:00:00Z", "wall_seconds": 3.4, "input": f"{ob}/x.asc", "b": 1.0}
    (oa / "r.json").write_text(json.dumps(a))
    (ob / "r.json").write_text(json.dumps(b))
    assert co.compare_file(oa / "r.json", ob / "r.json", roots) is None
    (ob / "r.json").write_text(json.dumps({**b, "b": 1.0000001}))
    assert co.compare_file(oa / "r.json", ob / "r.json", roots) == "/b: 1.0 vs 1.0000001"


def test_text_and_bytes(tmp_path):
    oa, ob, roots = _roots(tmp_path)
    (oa / "s.md").write_text(f"# report\nbias 1e-7\nwall time 3.2 s\nfile {oa}/d.asc\n")
    (ob / "s.md").write_text(f"# report\nbias 1e-7\nwall time 9.9 s\nfile {ob}/d.asc\n")
    assert co.compare_file(oa / "s.md", ob / "s.md", roots) is None
    log = 'entry {"aux": {"mtime_ns": %d, "path": "x"}, "bias": %s}\n'
    (oa / "accal.log").write_text(log % (1795843727511070189, "1e-7"))
    (ob / "accal.log").write_text(log % (1795843804487717405, "1e-7"))
    assert co.compare_file(oa / "accal.log", ob / "accal.log", roots) is None
    (ob / "accal.log").write_text(log % (1795843804487717405, "2e-7"))
    assert co.compare_file(oa / "accal.log", ob / "accal.log", roots).startswith("line 1")
    (ob / "s.md").write_text("# report\nbias 2e-7\n")
    assert co.compare_file(oa / "s.md", ob / "s.md", roots).startswith("line 2")
    (oa / "p.png").write_bytes(b"\x89PNG1")
    (ob / "p.png").write_bytes(b"\x89PNG2")
    assert co.compare_file(oa / "p.png", ob / "p.png", roots) == "bytes differ"
