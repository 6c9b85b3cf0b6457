"""``accal demod`` on the shared batch runner (issue 21): workers, manifest, Dask, failures.

The runs are the tests' small simulated platform runs (20 periods of τ = 60 s at
1 Hz, as in ``tests/test_cli_demod.py``); every output but the log, the manifest
and the lock must be byte-identical however the runs are spread over processes.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from accal.cli import main
from accal.io.writers import write_table
from accal.simulate.gap import simulate_gap

ARGS = ("--tau", 60, "--mask", 20)
#: Bookkeeping of a run: differs between runs (times, pids, the lock's token).
BOOKKEEPING = {".accal.lock", "accal.log", "manifest.json"}


def invoke(*args: object) -> tuple[int, str, str]:
    res = CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)
    return res.exit_code, res.stdout, res.stderr


def small_run(seed: int, nan_at: int | None = None):
    data, _ = simulate_gap(days=1200 / 86400, tau=60, mask=20, seed=seed)
    if nan_at is not None:
        y = data["m_y"].to_numpy().copy()
        y[nan_at] = np.nan
        data["m_y"] = y
    return data


@pytest.fixture
def runs(tmp_path) -> list[Path]:
    """Three small runs (a Parquet file, a CSV and another Parquet file)."""
    paths = [tmp_path / "in" / n for n in ("r1.parquet", "r2.csv", "r3.parquet")]
    paths[0].parent.mkdir()
    for seed, p in enumerate(paths, start=1):
        write_table(small_run(seed), p, units={"theta": "rad"})
    return paths


def outputs(out: Path) -> dict[str, bytes]:
    """Every output file's bytes, the bookkeeping left out."""
    return {p.name: p.read_bytes() for p in sorted(out.iterdir()) if p.name not in BOOKKEEPING}


def manifest(out: Path) -> dict[str, dict]:
    """The manifest's entries without their processing times."""
    entries = json.loads((out / "manifest.json").read_text())["entries"]
    for e in entries.values():
        e.pop("processed")
    return entries


def test_two_workers_write_what_one_writes(runs, tmp_path):
    a, b = tmp_path / "j1", tmp_path / "j2"
    code, _, err = invoke("demod", *runs, *ARGS, "--out", a, "-j", 1)
    assert code == 0, err
    assert "accal demod: 3 ok, 0 skipped (current), 0 failed, 0 not run;" in err
    assert "1 worker" in err and f"table: {a / 'periods.parquet'}" in err
    code, _, err = invoke("demod", *runs, *ARGS, "--out", b, "-j", 2)
    assert code == 0, err
    assert "3 ok, 0 skipped (current), 0 failed" in err and "2 workers" in err
    assert outputs(a) == outputs(b)
    assert sorted(outputs(a)) == [
        "periods.parquet", "r1.summary.json", "r1.summary.md", "r2.summary.json",
        "r2.summary.md", "r3.summary.json", "r3.summary.md",
    ]  # fmt: skip
    assert manifest(a) == manifest(b)
    assert {Path(k).name for k in manifest(a)} == {"r1.parquet", "r2.csv", "r3.parquet"}
    log = (b / "accal.log").read_text()
    assert "start accal demod: 3 runs" in log and "inputs run in 2 worker processes" in log
    assert "accal demod: 3 ok, 0 skipped (current)" in log


def test_rerun_skips_current_runs_and_redoes_changed_ones(runs, tmp_path):
    out = tmp_path / "out"
    assert invoke("demod", *runs, *ARGS, "--out", out, "-j", 2)[0] == 0
    first = outputs(out)
    code, _, err = invoke("demod", *runs, *ARGS, "--out", out, "-j", 2)
    assert code == 0, err
    assert "accal demod: 0 ok, 3 skipped (current), 0 failed, 0 not run" in err
    assert outputs(out) == first  # nothing rewritten
    assert "skip " in (out / "accal.log").read_text()
    # an option that changes the results redoes every run; one that does not, none
    code, _, err = invoke("demod", *runs, *ARGS, "--out", out, "--method", "gls", "-j", 2)
    assert code == 0 and "3 ok, 0 skipped (current)" in err, err
    code, _, err = invoke(
        "demod", *runs, *ARGS, "--out", out, "--method", "gls", "--chunk-size", 64
    )
    assert code == 0 and "0 ok, 3 skipped (current)" in err, err
    # a changed run file is redone, alone
    write_table(small_run(7), runs[1], units={"theta": "rad"})
    code, _, err = invoke("demod", *runs, *ARGS, "--out", out, "--method", "gls")
    assert code == 0 and "1 ok, 2 skipped (current)" in err, err
    # a deleted summary or table, and --force, redo
    (out / "r3.summary.md").unlink()
    code, _, err = invoke("demod", *runs, *ARGS, "--out", out, "--method", "gls")
    assert code == 0 and "1 ok, 2 skipped (current)" in err, err
    (out / "periods.parquet").unlink()
    code, _, err = invoke("demod", *runs, *ARGS, "--out", out, "--method", "gls")
    assert code == 0 and "3 ok, 0 skipped (current)" in err, err
    code, _, err = invoke("demod", *runs, *ARGS, "--out", out, "--method", "gls", "--force")
    assert code == 0 and "3 ok, 0 skipped (current)" in err, err


def test_a_run_alone_after_a_batch_is_redone_under_its_own_summary_name(runs, tmp_path):
    """Alone into an empty directory a run writes summary.json; with others the same run
    writes <stem>.summary.json: the manifest's record of the one is not current for the other."""
    out = tmp_path / "out"
    assert invoke("demod", runs[0], *ARGS, "--out", out, "-q")[0] == 0
    assert (out / "summary.json").exists()
    code, _, err = invoke("demod", *runs, *ARGS, "--out", out)
    assert code == 0 and "3 ok, 0 skipped (current)" in err, err
    assert not (out / "summary.json").exists() and (out / "r1.summary.json").exists()
    code, _, err = invoke("demod", runs[0], *ARGS, "--out", out)  # its summary is r1.summary.*
    assert code == 0 and "0 ok, 1 skipped (current)" in err, err


def test_a_bad_run_among_good_ones(runs, tmp_path):
    bad = tmp_path / "in" / "bad.csv"
    write_table(small_run(4, nan_at=10), bad, units={"theta": "rad"})
    out = tmp_path / "out"
    code, _, err = invoke("demod", runs[0], bad, *runs[1:], *ARGS, "--out", out, "-j", 2)
    assert code == 1
    errors = [ln for ln in err.splitlines() if str(bad) in ln]
    assert errors == [f"accal: {bad}: m_y has 1 NaN/inf value(s), first at t = 10 s (row 11)"]
    assert "accal demod: 3 ok, 0 skipped (current), 1 failed, 0 not run" in err
    assert {p.name for p in out.iterdir()} == BOOKKEEPING | {
        "periods.parquet", "r1.summary.json", "r1.summary.md", "r2.summary.json",
        "r2.summary.md", "r3.summary.json", "r3.summary.md",
    }  # fmt: skip
    assert "bad.csv" not in {Path(k).name for k in manifest(out)}
    # again: the good runs are current, the bad one fails again
    code, _, err = invoke("demod", runs[0], bad, *runs[1:], *ARGS, "--out", out, "-j", 2)
    assert code == 1 and "0 ok, 3 skipped (current), 1 failed" in err, err


def test_interrupted_batch_keeps_finished_runs_and_a_rerun_does_the_rest(runs, tmp_path):
    """Ctrl-C between two runs: the finished one is written and recorded; Interrupted."""
    from accal.batch import Interrupted
    from accal.pipeline_demod import DemodOptions, run_demod

    def stop_after_one(gen, total):
        yield next(iter(gen))
        raise KeyboardInterrupt

    out = tmp_path / "out"
    opts = DemodOptions(tau=60, mask=20)
    with pytest.raises(Interrupted) as exc:
        run_demod(runs, out, opts, progress=stop_after_one)
    assert exc.value.summary.n_ok == 1 and exc.value.summary.n_not_run == 2
    assert len(manifest(out)) == 1 and not [p for p in out.iterdir() if ".tmp" in p.name]
    summary = run_demod(runs, out, opts)
    assert (summary.n_ok, summary.n_skipped, summary.n_failed) == (2, 1, 0)
    ref = tmp_path / "ref"
    run_demod(runs, ref, opts)
    assert outputs(out) == outputs(ref)


def test_dask_scheduler_writes_what_one_worker_writes(runs, tmp_path):
    distributed = pytest.importorskip("distributed")
    a, b = tmp_path / "j1", tmp_path / "dask"
    assert invoke("demod", *runs, *ARGS, "--out", a, "-j", 1, "-q")[0] == 0
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None
    ) as cluster:
        code, _, err = invoke(
            "demod", *runs, *ARGS, "--out", b, "--scheduler", cluster.scheduler_address
        )
    assert code == 0, err
    assert "3 ok, 0 skipped (current), 0 failed" in err
    assert outputs(a) == outputs(b)
    assert "inputs run on dask scheduler " in (b / "accal.log").read_text()


def _terminal_signals() -> None:
    """In the child before exec: SIGINT and SIGTERM as a terminal gives them (a mask
    and an ignored disposition are inherited across exec; see tests/test_batch.py)."""
    import signal

    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _pool_processes(pid: int) -> tuple[bool, list[float]]:
    """Whether ``pid`` has started a fork server, and the CPU time [s] of each worker
    that server forked (from ``/proc``; the workers start with their modules loaded,
    so their CPU time is the work done)."""
    import os

    procs: dict[int, tuple[int, float]] = {}
    for d in Path("/proc").iterdir():
        try:
            stat = (d / "stat").read_text() if d.name.isdigit() else ""
        except OSError:
            continue
        if stat:
            fields = stat[stat.rindex(")") + 2 :].split()
            ticks = int(fields[11]) + int(fields[12])  # utime + stime
            procs[int(d.name)] = (int(fields[1]), ticks / os.sysconf("SC_CLK_TCK"))
    servers = []
    for c, (parent, _) in procs.items():
        try:
            cmdline = Path(f"/proc/{c}/cmdline").read_bytes()
        except OSError:
            continue
        if parent == pid and b"forkserver" in cmdline:
            servers.append(c)
    workers = [cpu for c, (parent, cpu) in procs.items() if parent in servers]
    return bool(servers), workers


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="POSIX signals, /proc")
@pytest.mark.parametrize("when", ["workers starting", "workers running"])
def test_ctrl_c_on_two_workers_prints_one_line(tmp_path, when):
    """Issue 21: SIGINT to a ``-j 2`` batch whose workers come from a fork server
    printed, after ``accal: interrupted``, the resource tracker's "There appear to
    be 5 leaked semaphore objects" (the pool's queues were still held when the run
    left by ``os._exit``) or, while the workers started, a worker's
    ``FileNotFoundError`` traceback (a worker the pool did not know yet read its
    set-up after the pool was freed).  Only the one line now, status 130."""
    import os
    import signal
    import subprocess
    import time

    from tests.indep import platform_run, write_platform_run

    src = [
        write_platform_run(platform_run(seed, days=2.0), tmp_path / f"run{seed}.parquet")
        for seed in (1, 2)
    ]
    out = tmp_path / "o"
    cmd = [sys.executable, "-m", "accal", "demod", *map(str, src), "--tau", "600", "--mask",
           "200", "--close-loop", "--out", str(out), "-q", "-j", "2"]  # fmt: skip
    proc = subprocess.Popen(
        cmd,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "ACCAL_START_METHOD": "forkserver"},
        start_new_session=True,
        preexec_fn=_terminal_signals,
    )
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        server, workers = _pool_processes(proc.pid)
        if when == "workers starting" and server and not workers:
            break  # the fork server is importing its preload: no worker yet
        if when == "workers running" and len(workers) == 2 and min(workers) > 1.0:
            break  # both workers are demodulating
        time.sleep(0.01)
    assert proc.poll() is None, "the batch finished before it could be interrupted"
    os.kill(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=60)  # to its end: the workers and tracker share stderr
    assert proc.returncode == 130, err
    assert err.strip().splitlines()[-1] == "accal: interrupted", err
    assert "leaked" not in err and "Traceback" not in err, err
