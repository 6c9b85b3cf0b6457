"""False-alarm calibration of the platform coupling scan (issue 19), by Monte-Carlo.

On clean one-day rotating-platform runs (``tests.indep.platform_run``: no coupling
in the data, the temperature kicked at every rotation plus a random walk), the
corrected p-value of the best coupling the first selection step proposes (the
channel alone and the channel with its square) should be uniform or conservative:
``P(p_adj < a) ≤ a``.  Both lag scans are run on the same runs: every sample lag
(``lag_scan="fine"``, the default on a block base) and the 31-lag grid
(``"grid"``).  A second noise (white, 1e-11 m/s² per sample) and a temperature
without rotation kicks (a random walk only) check noise and channels the scan was
not built for.

    python benchmarks/coupling_scan_null.py --runs 200 --workers 2 --out DIR

Writes ``DIR/coupling_scan_null.json`` and prints a Markdown table.  The closure
itself is stopped after its first step (the p-values of that step are the ones
the family's Bonferroni correction must hold for).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from unittest import mock

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

LEVELS = (0.01, 0.05, 0.1, 0.2)
NOISES = {"microstar": "microstar", "white 1e-11": 1e-11}  # 1 Hz: L = σ per sample


class _FirstStep(Exception):
    """Raised at the second selection step: the first one's p-values are recorded."""


def one(seed: int, noise: str, scan: str, kicks: bool) -> dict:
    """The first step's coupling p-values on one clean run."""
    from tests.indep import platform_run

    from accal.closure import search as search_mod
    from accal.closure.demod import close_loop_demod
    from accal.estimators.noise import as_psd

    run = platform_run(seed, noise_psd=NOISES[noise])
    tb = run.table
    temp = tb["temperature"].to_numpy()
    if not kicks:  # a random walk only (no rotation-synchronous kicks)
        rng = np.random.default_rng(seed + 1)
        temp = 293.0 + 0.05 * np.cumsum(rng.standard_normal(temp.size)) / np.sqrt(600.0)
    got: dict[str, float] = {}
    calls = {"propose": 0}
    orig_test = search_mod.Search.test
    orig_propose = search_mod.Search.propose

    def test(self, basis, fit, lev, prop):
        out = orig_test(self, basis, fit, lev, prop)
        if prop.name == "auxiliary" and out is not None:
            key = "pair" if prop.params.get("pair") else "single"
            got[key] = min(got.get(key, 1.0), float(out.p_adj))
            got[key + "_mult"] = float(prop.multiplicity)
        return out

    def propose(self, ctx):
        calls["propose"] += 1
        if calls["propose"] > 1:
            raise _FirstStep
        return orig_propose(self, ctx)

    t0 = time.process_time()
    with (
        mock.patch.object(search_mod.Search, "test", test),
        mock.patch.object(search_mod.Search, "propose", propose),
        contextlib.suppress(_FirstStep),
    ):
        close_loop_demod(
            tb["time"].to_numpy(),
            (tb["m_y"].to_numpy(), tb["m_z"].to_numpy()),
            tb["theta"].to_numpy(),
            tau=600.0,
            aux={"temperature": temp},
            alpha=0.01,
            rest_tol=1e-9,
            noise_psd=as_psd(None),
            options={"lag_scan": scan},
        )
    return {"seed": seed, "noise": noise, "scan": scan, "kicks": kicks,
            "cpu": time.process_time() - t0, **got}  # fmt: skip


def _one(args):
    return one(*args)


def table(rows: list[dict]) -> list[str]:
    """Rates of p_adj < a per (noise, channel, scan), with binomial 95 % bounds."""
    out = [
        "| noise | temperature | scan | runs | "
        + " | ".join(f"P(p_adj < {a})" for a in LEVELS)
        + " | median multiplicity |",  # fmt: skip
        "|---|---|---|---|" + "---|" * len(LEVELS) + "---|",
    ]
    keys = sorted({(r["noise"], r["kicks"], r["scan"]) for r in rows})
    for noise, kicks, scan in keys:
        sel = [r for r in rows if (r["noise"], r["kicks"], r["scan"]) == (noise, kicks, scan)]
        n = len(sel)
        p = np.array([min(r.get("single", 1.0), r.get("pair", 1.0)) for r in sel])
        cells = []
        for a in LEVELS:
            k = int(np.sum(p < a))
            cells.append(f"{k}/{n} ({k / n:.3f})")
        m = np.median([r.get("single_mult", np.nan) for r in sel])
        kind = "kicked + walk" if kicks else "random walk"
        out.append(f"| {noise} | {kind} | {scan} | {n} | " + " | ".join(cells) + f" | {m:.0f} |")
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", type=Path, default=Path("coupling_scan_null"))
    ap.add_argument("--quick", action="store_true", help="microstar, kicked, 20 runs")
    a = ap.parse_args(argv)
    jobs = []
    noises = ["microstar"] if a.quick else list(NOISES)
    n = 20 if a.quick else a.runs
    for noise in noises:
        for kicks in (True,) if a.quick else (True, False):
            for scan in ("fine", "grid"):
                jobs += [(9000 + k, noise, scan, kicks) for k in range(n)]
    with ProcessPoolExecutor(a.workers) as ex:
        rows = list(ex.map(_one, jobs, chunksize=4))
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "coupling_scan_null.json").write_text(json.dumps(rows, indent=1))
    print("\n".join(table(rows)))
    cpu = {s: np.median([r["cpu"] for r in rows if r["scan"] == s]) for s in ("fine", "grid")}
    print(
        f"\nmedian CPU to the first step's end: fine {cpu['fine']:.2f} s, grid {cpu['grid']:.2f} s"
    )


if __name__ == "__main__":
    main()
