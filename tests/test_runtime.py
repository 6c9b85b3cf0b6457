"""Tests of the process settings (accal._runtime) and batch durability (sync_files)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from accal import _runtime
from accal.io import writers


def test_tune_allocator_leaves_a_user_setting_alone(monkeypatch):
    monkeypatch.setenv("MALLOC_TOP_PAD_", "0")
    assert _runtime.tune_allocator() is False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc mallopt")
def test_tune_allocator_applies_on_glibc():
    code = "from accal._runtime import tune_allocator as t; print(t())"
    env = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_")}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert out.returncode == 0
    libc = os.confstr("CS_GNU_LIBC_VERSION") if hasattr(os, "confstr") else None
    assert out.stdout.strip() == ("True" if libc and libc.startswith("glibc") else "False")


def test_console_entry_defaults_blas_to_one_thread():
    """`python -m accal` sets the thread variables before numpy loads (unless set)."""
    code = "import accal.__main__, os; print(os.environ['OPENBLAS_NUM_THREADS'])"
    env = {k: v for k, v in os.environ.items() if k not in _runtime.THREAD_VARS}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert out.stdout.strip() == "1"
    env["OPENBLAS_NUM_THREADS"] = "2"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert out.stdout.strip() == "2"


def test_sync_files_fsyncs_each_file_and_directory_without_syncfs(tmp_path, monkeypatch):
    files = [tmp_path / "a.bin", tmp_path / "sub" / "b.bin"]
    for f in files:
        f.parent.mkdir(exist_ok=True)
        f.write_bytes(b"x")
    synced = []
    real_fsync = os.fsync

    def fsync(fd):
        synced.append(os.readlink(f"/proc/self/fd/{fd}") if os.path.exists("/proc") else fd)
        real_fsync(fd)

    monkeypatch.setattr(writers, "_libc_syncfs", lambda: None)
    monkeypatch.setattr(os, "fsync", fsync)
    writers.sync_files([*files, tmp_path / "gone.bin"])
    if os.path.exists("/proc"):
        assert sorted(synced) == sorted(
            [str(files[0]), str(files[1]), str(tmp_path), str(tmp_path / "sub")]
        )
    else:
        assert len(synced) == 4


def test_sync_files_calls_syncfs_once_per_file_system(tmp_path, monkeypatch):
    files = [tmp_path / f"{k}.bin" for k in range(5)]
    for f in files:
        f.write_bytes(b"x")
    calls = []
    monkeypatch.setattr(writers, "_libc_syncfs", lambda: lambda fd: calls.append(fd) or 0)
    monkeypatch.setattr(os, "fsync", lambda fd: pytest.fail("fsync used despite syncfs"))
    writers.sync_files(files)
    assert len(calls) == 1


def test_atomic_path_without_sync_still_replaces_atomically(tmp_path):
    target = tmp_path / "out.txt"
    target.write_text("old")
    with pytest.raises(RuntimeError), writers.atomic_path(target, sync=False) as tmp:
        tmp.write_text("partial")
        raise RuntimeError
    assert target.read_text() == "old" and list(tmp_path.iterdir()) == [target]
    with writers.atomic_path(target, sync=False) as tmp:
        tmp.write_text("new")
    assert target.read_text() == "new"


def test_atomic_path_names_the_target_when_its_directory_refuses_files(tmp_path):
    """QA: ``accal table DIR --export /proc/x.parquet`` said
    ``/proc/.x.parquet.3lbbvdcz.tmp: No such file or directory``: the error names the
    file asked for, not the temporary."""
    target = Path("/proc/accal-test-x.parquet")
    with pytest.raises(OSError) as e, writers.atomic_path(target):
        pass
    assert e.value.filename == str(target)


@pytest.mark.parametrize(
    ("code", "status", "err"), [(None, 0, ""), (2, 2, ""), ("bad", 1, "bad\n")]
)
def test_the_exit_skips_finalization_with_the_status_systemexit_means(
    monkeypatch, capsys, code, status, err
):
    """With pyarrow loaded the CLI leaves by ``os._exit`` (its thread pools aborted the
    interpreter's finalization: exit 134 after a bad ``--aux``), with SystemExit's status."""
    from accal import __main__ as entry

    got = []
    monkeypatch.setattr(entry.os, "_exit", got.append)
    entry._exit_without_finalizing(code)
    assert got == [status] and capsys.readouterr().err == err


def test_a_bad_aux_table_exits_1_every_time(tmp_path):
    """The QA helper's case (a Parquet --aux without a time column) in fresh processes."""
    import pandas as pd

    bad = tmp_path / "aux.parquet"
    pd.DataFrame({"t": [0.0, 1.0], "temperature": [20.0, 20.1]}).to_parquet(bad)
    day = Path(__file__).parent.parent / "data" / "samples" / "ACC1B_2003-09-14_A_00.asc"
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    for k in range(4):
        out = subprocess.run(
            [sys.executable, "-m", "accal", "grace-bias", str(day), "--aux", str(bad),
             "--out", str(tmp_path / f"o{k}"), "-q"],
            capture_output=True, text=True, env=env, timeout=120,
        )  # fmt: skip
        assert out.returncode == 1, out.stderr
        assert "no time column" in out.stderr and "terminate called" not in out.stderr
