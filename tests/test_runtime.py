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
