"""Issue 23, finding 1: a task of a killed run must not overwrite a later run's outputs.

A task carries the lock token of the run that submitted it; every rename into the
output directory checks that the lock still names it.  Here the "later run" is a
lock taken in the test, and the orphaned task is ``process_one`` with the old token
(what a Dask worker does after its client was killed).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from accal.batch import OutputLock
from accal.io.writers import RunSuperseded, atomic_path, run_guard
from accal.pipeline import GraceBiasOptions, process_one


def _day(path: Path) -> Path:
    t = pd.date_range("2024-05-10", periods=3600, freq="1s")
    rng = np.random.default_rng(0)
    pd.DataFrame(
        {"time_utc": t.strftime("%Y-%m-%dT%H:%M:%S"), "ax": 2e-7 + 1e-10 * rng.normal(size=3600)}
    ).to_csv(path, index=False)
    return path


def test_an_orphaned_task_writes_nothing_once_a_later_run_holds_the_lock(tmp_path):
    day = _day(tmp_path / "day.csv")
    out = tmp_path / "out"
    opts = GraceBiasOptions(columns={"x": "ax"})
    with OutputLock(out, "first run") as first:
        old = first.token
        ok = process_one(day, out, opts, run_token=old)  # the holder writes
    assert ok.ok and (out / "day.calibrated.parquet").exists()
    before = (out / "day.calibrated.parquet").read_bytes()
    with OutputLock(out, "later run") as later:
        assert later.token != old
        orphan = process_one(day, out, GraceBiasOptions(columns={"x": "ax"}, scale="2"), old)
        assert not orphan.ok and "later accal run" in orphan.message
        assert (out / "day.calibrated.parquet").read_bytes() == before  # not overwritten
        assert not list(out.glob(".*accal-*.tmp"))  # and no temporary left behind
        again = process_one(day, out, opts, run_token=later.token)
        assert again.ok


def test_the_guard_is_scoped_to_its_directory_and_off_by_default(tmp_path):
    lock = tmp_path / "a" / ".accal.lock"
    lock.parent.mkdir()
    lock.write_text("pid 1, accal, run other")
    with run_guard(lock, "mine"):
        with pytest.raises(RunSuperseded), atomic_path(tmp_path / "a" / "x.txt") as tmp:
            tmp.write_text("x")
        with atomic_path(tmp_path / "b" / "y.txt") as tmp:  # another directory: free
            tmp.write_text("y")
    assert not (tmp_path / "a" / "x.txt").exists() and (tmp_path / "b" / "y.txt").exists()
    with atomic_path(tmp_path / "a" / "z.txt") as tmp:  # no guard: plain atomic write
        tmp.write_text("z")
    assert (tmp_path / "a" / "z.txt").read_text() == "z"


@pytest.mark.slow
def test_dask_tasks_of_a_killed_client_do_not_overwrite_the_next_run(tmp_path):
    """The issue's reproduction with a LocalCluster: kill -9 the client mid-run, re-run,
    let the orphaned tasks finish, compare with a clean run."""
    import os
    import signal
    import subprocess
    import sys
    import time

    distributed = pytest.importorskip("distributed")
    src = tmp_path / "in"
    src.mkdir()
    for k in range(4):
        t = pd.date_range(f"2024-05-{10 + k}", periods=86400, freq="1s")
        rng = np.random.default_rng(k)
        pd.DataFrame(
            {
                "time_utc": t.strftime("%Y-%m-%dT%H:%M:%S"),
                "ax": 2e-7 + 1e-10 * rng.normal(size=86400),
            }
        ).to_csv(src / f"day{k}.csv", index=False)
    out = tmp_path / "out"
    base = ["grace-bias", *sorted(map(str, src.glob("*.csv"))), "--column", "x=ax", "-q"]
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
        first = subprocess.Popen(
            [sys.executable, "-m", "accal", *base, "--close-loop", "--scale", "2",
             "--scheduler", cluster.scheduler_address, "--out", str(out)],
            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )  # fmt: skip
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not (out / ".accal.lock").exists():
            time.sleep(0.2)
        time.sleep(3.0)  # tasks running on the worker
        first.send_signal(signal.SIGKILL)
        first.wait()
        second = subprocess.run(
            [sys.executable, "-m", "accal", *base, "-j", "1", "--out", str(out)], env=env
        )
        assert second.returncode == 0
        after_second = {p.name: p.read_bytes() for p in out.glob("*.calibrated.parquet")}
        time.sleep(20.0)  # the orphaned closure tasks finish meanwhile
    assert {p.name: p.read_bytes() for p in out.glob("*.calibrated.parquet")} == after_second
    clean = tmp_path / "clean"
    subprocess.run([sys.executable, "-m", "accal", *base, "-j", "1", "--out", str(clean)], env=env)
    for name, data in after_second.items():
        assert data == (clean / name).read_bytes() or pd.read_parquet(out / name).equals(
            pd.read_parquet(clean / name)
        )
