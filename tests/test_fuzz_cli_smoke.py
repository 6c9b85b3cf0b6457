"""The CLI mutation fuzzer (benchmarks/fuzz_cli.py, issue 23) on a few fixed batches.

Keeps the fuzzer working and checks the CLI on them: every mutated input either
works or fails with one ``accal: PATH: message`` line, nothing BAD.
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import fuzz_cli  # noqa: E402

#: demod with 3 runs, grace-bias with 6 inputs (-j 1), an AHK1B --aux, -j 2 --method both
#: (~15 s on 2 busy cores; the THR1B/SCA1B companion batches cost ~5 s each: left to the fuzzer)
BATCHES = [0, 2, 8, 25]


def test_mutations_are_reproducible_from_the_case_seed(tmp_path):
    seeds = tmp_path / "seeds"
    seeds.mkdir()
    (seeds / fuzz_cli.A03).write_bytes((fuzz_cli.SAMPLES / fuzz_cli.A03).read_bytes())
    seed = fuzz_cli.INPUTS[0]
    runs = [[fuzz_cli.mutate(seed, case, seeds) for case in range(40)] for _ in range(2)]
    assert runs[0] == runs[1]
    assert len({m.kind for m in runs[0]}) > 10


def test_fixed_batches_have_no_bad_outcome(tmp_path):
    s = fuzz_cli.main(["--replay", *map(str, BATCHES), "--out", str(tmp_path), "--timeout", "60"])
    assert s["batches"] == len(BATCHES)
    assert not s["bad_cases"], s["bad_cases"]
    assert s["outcomes"].get("ok", 0) > 0 and s["outcomes"].get("clean_failure", 0) > 0
    assert {"demod", "grace-bias", "companion"} <= set(s["outcomes_by_command"])
    assert (tmp_path / "summary.md").is_file() and (tmp_path / "results.json").is_file()
    assert 0 < s["rss_mb"]["max"] < fuzz_cli.RSS_LIMIT_MB


def test_the_classifier_tells_bad_outcomes(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    names = ["a_c1.asc", "b_c2.asc", "c_c3.asc", "d_c4.asc"]
    with open(out / "bias_drift.csv", "w") as fh:
        fh.write("source,axis\na_c1.asc,x\nb_c2.asc,x\n")
    for stem in ("a_c1", "b_c2"):
        (out / f"{stem}.report.json").write_text("{}")
        (out / f"{stem}.calibrated.csv").write_text("")
    (out / ".x.accal-1.tmp").write_text("")
    b = fuzz_cli.Batch(1, "grace-bias", argv=["accal", "grace-bias"], rc=1)
    b.cases = [fuzz_cli.Case(i, "seed", "input", name=n) for i, n in enumerate(names)]
    b.stderr = "accal: /x/b_c2.asc:3: bad\naccal: /x/c_c3.asc: bad\nRuntimeWarning: x\n"
    fuzz_cli.classify(b, tmp_path, fuzz_cli.RSS_LIMIT_MB)
    assert set(b.bad) == {"stray_output", "partial_output"}
    got = {c.name: [k for k in c.bad if k not in b.bad] for c in b.cases}
    assert got == {"a_c1.asc": [], "b_c2.asc": ["rows_for_failed"], "c_c3.asc": [],
                   "d_c4.asc": ["not_processed"]}  # fmt: skip
    assert b.cases[2].message == "accal: /x/c_c3.asc: bad"
