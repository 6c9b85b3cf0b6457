"""Wall time and peak RSS of ``--close-loop`` against the plain run (issue 19).

The command-line runs users make, one process each (``-j 1``, one BLAS thread),
alternating plain and closure runs on the same file in the same session:

* a real-like 1 Hz GRACE-A day of ``tests.indep.grace_day`` (storm and thruster pulses,
  all 12 ACC1B columns live, 86,400 records) with four temperature channels as
  ``--aux`` housekeeping: ``accal grace-bias DAY`` vs ``accal grace-bias DAY
  --close-loop --aux AUX`` (all candidates: step, periodic, couplings to the three
  angular accelerations and the four temperatures);
* a day of accal's own simulator (``accal simulate grace --storm --thrusters``),
  the same two runs (no ``--aux``: the simulator writes channels only for couplings);
* a one-day rotating-platform run (``tests.indep.platform_run``, τ = 600 s, mask
  200 s): ``accal demod`` vs ``accal demod --close-loop``;
* (not with ``--quick``) a GRACE-FO day and a platform run each with a temperature
  coupling closure finds (:data:`COUPLED_GRACE`, :data:`COUPLED_PLATFORM`): the lag,
  τ and coefficient profiles and the search again without the coupling's unknown
  history cost most on such days.

Targets (issue 19): a GRACE day with closure ≤ 15 s and ≤ 600 MB, a demod day ≤ 5 s.
Peak RSS is the ``ru_maxrss`` of the run's process (``os.wait4`` in a small helper
process that starts it), CPU time its user + system time (less sensitive to other
jobs on a shared machine than the wall time).  Each pair is repeated ``--repeat`` times (default 3; ``--quick``: 1,
GRACE indep day and demod day only); the tables give the median and the range.  The
machine's load average is printed: on a shared machine the times scale with it.

Run ``python benchmarks/bench_closure.py [--quick] [--repeat 3] [--out DIR] [--cpu N]``
(writes ``summary.md``, ``results.json``, ``bench_closure.png`` into ``--out``,
default ``out/bench-closure``).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import textwrap  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _closure_cases import ACCAL, git_state  # noqa: E402

TEMPERATURES = ("temperature", "temperature_icu", "temperature_sensor", "temperature_sca")
TARGETS = {"grace": (15.0, 600.0), "demod": (5.0, None)}  # [s], [MB] of the closure run
#: Days with an effect closure finds (closure-detection cases whose coupling is found):
#: ``tests.indep`` effect tuples, (kind, axis, channel, coef [m/s²/K], lag [s], τ [s]) and
#: (kind, channel, coef, lag, axes).
COUPLED_GRACE = ("coupling", "z", "temperature", 1e-8, 1755.07, 0.0)
COUPLED_PLATFORM = ("coupling", "temperature", 3e-8, 23.3, "both")


#: Runs one command in a small helper process and prints its rusage: the command is
#: forked from the helper's ~10 MB image, not from this process (``ru_maxrss`` keeps the
#: high-water mark of the image a child was forked from across ``exec``).
_HELPER = """
import json, os, sys, time
if len(sys.argv) > 1 and sys.argv[1] != "-":
    os.sched_setaffinity(0, {int(sys.argv[1])})
t0 = time.perf_counter()
pid = os.fork()
if pid == 0:
    os.execv(sys.argv[2], sys.argv[2:])
_, status, ru = os.wait4(pid, 0)
print(json.dumps({"wall_s": time.perf_counter() - t0, "rss_mb": ru.ru_maxrss / 1024.0,
                  "cpu_s": ru.ru_utime + ru.ru_stime, "rc": os.waitstatus_to_exitcode(status)}))
"""


def measure(args: list[str], cpu: int | None = None) -> dict:
    """Run ``accal ARGS``: wall time [s], CPU time [s], peak RSS [MB], exit status,
    the end of its stderr."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    pin = "-" if cpu is None else str(cpu)
    proc = subprocess.run([sys.executable, "-c", _HELPER, pin, ACCAL, *args], env=env,
                          capture_output=True, text=True, check=False)  # fmt: skip
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    out["stderr"] = " | ".join(proc.stderr.strip().splitlines()[-2:])
    return out


def inputs(work: Path, quick: bool) -> dict[str, tuple[list[str], list[str]]]:
    """Write the inputs; per data set the plain and the closure command lines."""
    from tests.indep import (
        grace_day,
        platform_run,
        write_acc1b_grace,
        write_platform_run,
        write_table,
    )

    day = grace_day(5, "A", storm=True, thrusters=True, channels=TEMPERATURES)
    data = write_acc1b_grace(day, work / day.l1b_name())
    aux = write_table(work / "AHK_temperatures.parquet", {"gps_time": day.time, **day.channels},
                      {"gps_time": "s", **{k: "K" for k in day.channels}})  # fmt: skip
    out = {}
    gb = ["grace-bias", str(data), "-j", "1", "-q", "--force", "--out"]
    out["grace (tests.indep A, storm+thrusters, 4 temperatures --aux)"] = (
        [*gb, str(work / "plain")],
        [*gb, str(work / "closure"), "--close-loop", "--aux", str(aux)],
    )
    if not quick:
        sim = work / "ACC1B_2005-03-01_A_sim.asc"
        proc = subprocess.run([ACCAL, "simulate", "grace", "--date", "2005-03-01", "--satellite",
                               "A", "--storm", "--thrusters", "--out", str(sim)],
                              capture_output=True, text=True, check=False)  # fmt: skip
        if proc.returncode == 0:
            gb = ["grace-bias", str(sim), "-j", "1", "-q", "--force", "--out"]
            out["grace (accal simulate A, storm+thrusters)"] = (
                [*gb, str(work / "plain-sim")],
                [*gb, str(work / "closure-sim"), "--close-loop"],
            )
        else:
            print(f"accal simulate grace failed: {proc.stderr.strip()[-300:]}", file=sys.stderr)
    if not quick:  # a day whose coupling closure finds: the lag and coefficient profiles
        cday = grace_day(7411, "D", effects=[COUPLED_GRACE], channels=("temperature",))
        cdata = write_acc1b_grace(cday, work / cday.l1b_name())
        caux = write_table(work / "AHK_coupled.parquet",
                           {"gps_time": cday.time, "temperature": cday.channels["temperature"]},
                           {"gps_time": "s", "temperature": "K"})  # fmt: skip
        gb = ["grace-bias", str(cdata), "-j", "1", "-q", "--force", "--out"]
        out["grace (tests.indep D, a 1e-8 m/s²/K temperature coupling, --aux)"] = (
            [*gb, str(work / "plain-c")],
            [*gb, str(work / "closure-c"), "--close-loop", "--aux", str(caux)],
        )
    run = write_platform_run(platform_run(5), work / "platform_run.parquet")
    # --force: demod skips a run its manifest says is current (a repeat would time the skip)
    dm = ["demod", str(run), "--tau", "600", "--mask", "200", "-q", "--force", "--out"]
    out["demod (tests.indep platform, 1 day)"] = (
        [*dm, str(work / "dplain")],
        [*dm, str(work / "dclosure"), "--close-loop"],
    )
    if not quick:
        crun = write_platform_run(platform_run(7304, effects=[COUPLED_PLATFORM]),
                                  work / "platform_coupled.parquet")  # fmt: skip
        dm = ["demod", str(crun), "--tau", "600", "--mask", "200", "-q", "--force", "--out"]
        out["demod (tests.indep platform, 1 day, a 3e-8 m/s²/K temperature coupling)"] = (
            [*dm, str(work / "dplain-c")],
            [*dm, str(work / "dclosure-c"), "--close-loop"],
        )
    return out


def _stat(v: list[float]) -> str:
    return f"{np.median(v):.2f} ({min(v):.2f}–{max(v):.2f})"


def table(rows: dict[str, dict[str, list[dict]]]) -> list[str]:
    """The Markdown table: median (range) of wall time and peak RSS, ratios, targets."""
    lines = [
        "| data | run | n | wall s median (range) | CPU s median (range) "
        "| peak RSS MB median (range) | ratio closure/plain (wall, CPU, RSS) | target (wall, RSS) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, runs in rows.items():
        med = {k: [np.median([r[q] for r in v]) for q in ("wall_s", "cpu_s", "rss_mb")]
               for k, v in runs.items() if v}  # fmt: skip
        tw, tm = TARGETS["demod" if name.startswith("demod") else "grace"]
        for k, v in runs.items():
            if not v:
                continue
            ratio = target = ""
            if k == "closure" and "plain" in med:
                pairs = zip(med["closure"], med["plain"], strict=True)
                ratio = ", ".join(f"{c / p:.2f}" for c, p in pairs)
                ok = med["closure"][0] <= tw and (tm is None or med["closure"][2] <= tm)
                target = f"≤ {tw:g} s" + (f", ≤ {tm:g} MB" if tm else "")
                target += ": met" if ok else ": NOT met"
            bad = [r["stderr"] for r in v if r["rc"] != 0]
            note = f" (exit ≠ 0: {bad[0][:80]})" if bad else ""
            lines.append(
                f"| {name} | {k}{note} | {len(v)} | {_stat([r['wall_s'] for r in v])} "
                f"| {_stat([r['cpu_s'] for r in v])} | {_stat([r['rss_mb'] for r in v])} "
                f"| {ratio} | {target} |"
            )
    return lines


def _label(name: str) -> str:
    """A data set's name wrapped for a tick label: the command, then its description."""
    head, _, rest = name.partition(" (")
    return head + "\n" + "\n".join(textwrap.wrap(rest.rstrip(")"), 18)[:5])


def figure(rows: dict[str, dict[str, list[dict]]], path: Path) -> None:
    """Bars of the median wall time and peak RSS, with the range; the targets dashed
    (15 s and 5 s, 600 MB)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, 2, figsize=(11, 4))
    names = list(rows)
    for axp, q, lab in zip(axs, ("wall_s", "rss_mb"), ("wall time [s]", "peak RSS [MB]"),
                           strict=True):  # fmt: skip
        for j, k in enumerate(("plain", "closure")):
            v = [[r[q] for r in rows[n][k]] or [np.nan] for n in names]
            med = np.array([np.median(x) for x in v])
            err = np.array([[m - min(x), max(x) - m] for m, x in zip(med, v, strict=True)]).T
            axp.bar(np.arange(len(names)) + 0.4 * j, med, 0.4, yerr=err, label=k)
        axp.set_xticks(np.arange(len(names)) + 0.2, [_label(n) for n in names], fontsize=6)
        axp.set_ylabel(lab)
    for y, axp in ((15.0, axs[0]), (5.0, axs[0]), (600.0, axs[1])):
        axp.axhline(y, color="k", ls="--", lw=0.8)
    axs[0].legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    """Write the inputs, time the runs, print and write the results."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one repeat, two data sets")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", type=Path, default=Path("out/bench-closure"))
    ap.add_argument("--cpu", type=int, default=None, help="pin the runs to this CPU")
    args = ap.parse_args(argv)
    repeat = 1 if args.quick else args.repeat
    args.out.mkdir(parents=True, exist_ok=True)
    # bytecode first, as an install has it: with PYTHONDONTWRITEBYTECODE set (CI images,
    # containers) every run would otherwise compile accal's modules again (~0.3 s)
    import accal

    subprocess.run([sys.executable, "-m", "compileall", "-q", str(Path(accal.__file__).parent)],
                   check=False, capture_output=True)  # fmt: skip
    load0 = os.getloadavg()
    rows: dict[str, dict[str, list[dict]]] = {}
    with tempfile.TemporaryDirectory(prefix="accal-bench-closure-") as tmp:
        cmds = inputs(Path(tmp), args.quick)
        for name, (plain, closure) in cmds.items():
            rows[name] = {"plain": [], "closure": []}
            for i in range(repeat):  # alternate, so a change of load hits both alike
                for k, cmd in (("plain", plain), ("closure", closure))[:: 1 if i % 2 == 0 else -1]:
                    rows[name][k].append(measure(cmd, args.cpu))
                    r = rows[name][k][-1]
                    print(f"{name} {k} #{i + 1}: {r['wall_s']:.2f} s (CPU {r['cpu_s']:.2f} s) "
                          f"{r['rss_mb']:.0f} MB "
                          f"rc {r['rc']}", file=sys.stderr, flush=True)  # fmt: skip
    load1 = os.getloadavg()
    lines = [
        f"# bench-closure ({'quick' if args.quick else 'full'}, {repeat} repeat(s), one process "
        f"per run, -j 1, one BLAS thread, bytecode compiled"
        f"{f', CPU {args.cpu}' if args.cpu is not None else ''})",
        "",
        f"Load average before {load0[0]:.2f}, after {load1[0]:.2f} on {os.cpu_count()} CPUs "
        f"(other jobs slow every run alike); accal commit {git_state()['commit'][:10]}.",
        "",
        *table(rows),
        "",
    ]
    text = "\n".join(lines)
    print(text)
    (args.out / "summary.md").write_text(text)
    doc = {"load": [load0, load1], "git": git_state(), "repeat": repeat, "runs": rows}
    (args.out / "results.json").write_text(json.dumps(doc, indent=1))
    figure(rows, args.out / "bench_closure.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
