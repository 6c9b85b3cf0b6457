"""The lock of an output directory and accal's own files in it.

:class:`OutputLock` makes an output directory single-writer (``flock``: the lock
dies with its process, so a ``kill -9`` never leaves a stale lock behind; a forked
worker drops its copy of the lock's file); :func:`open_own` opens accal's own files
of the directory (never through a symbolic link); :func:`remove_stale_temporaries`
deletes what a killed run left.
"""

from __future__ import annotations

import contextlib
import errno
import os
import secrets
import stat
import time as _time
import weakref
from pathlib import Path
from typing import Any

from accal.errors import AccalError
from accal.io.writers import TEMP_MARK

LOCK = ".accal.lock"


class LockedError(AccalError):
    """The output directory is being written by another accal run."""


def open_own(path: Path, mode: str, **kw: Any) -> Any:
    """Open one of accal's own files of an output directory for appending (``"a"`` or
    ``"a+"``), created if missing; never through a symbolic link or onto anything but
    a regular file.

    Issue 23: ``OUT/.accal.lock`` or ``OUT/accal.log`` as a symlink to any file got that
    file truncated or appended to.  ``O_NOFOLLOW`` refuses a link in the last component.

    Raises
    ------
    OSError
        ``PATH: a symbolic link or not a regular file, not accal's own: remove it``.
    """
    flags = os.O_CREAT | os.O_APPEND | (os.O_RDWR if "+" in mode else os.O_WRONLY)
    flags |= getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0)
    why = "a symbolic link or not a regular file, not accal's own: remove it"
    try:
        fd = os.open(path, flags, 0o666)
    except OSError as exc:
        if exc.errno in (errno.ELOOP, errno.ENXIO, errno.EISDIR):
            raise OSError(exc.errno, why, str(path)) from None
        raise
    if not stat.S_ISREG(os.fstat(fd).st_mode):  # a FIFO or a device
        os.close(fd)
        raise OSError(errno.EINVAL, why, str(path))
    return os.fdopen(fd, mode, **kw)


class OutputLock:
    """Exclusive lock on an output directory (``OUT/.accal.lock``, ``fcntl.flock``).

    The lock is held by the open file description, so it is released by the
    kernel when the process ends in any way (including ``kill -9``); the file
    itself stays and records the holder's pid and start time for the message.
    """

    def __init__(self, out_dir: Path, what: str = "accal") -> None:
        self.path = Path(out_dir) / LOCK
        self.what = what
        self.token: str | None = None  # names this run in the lock file (run_guard)
        self._fh: Any = None

    def acquire(self) -> None:
        """Take the lock or raise :class:`LockedError` at once (never waits)."""
        import fcntl  # Unix only: imported where a lock is taken

        self.path.parent.mkdir(parents=True, exist_ok=True)
        fh = open_own(self.path, "a+")  # kept open while locked
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            fh.seek(0)
            holder = fh.read().strip() or "unknown process"
            fh.close()
            raise LockedError(
                f"{self.path.parent}: output directory is in use by another accal run "
                f"({holder}); wait for it to finish or use another --out"
            ) from None
        fh.seek(0)
        fh.truncate()
        self.token = secrets.token_hex(8)
        fh.write(
            f"pid {os.getpid()}, {self.what}, started {_time.strftime('%Y-%m-%d %H:%M:%S')}, "
            f"run {self.token}"
        )
        fh.flush()
        self._fh = fh
        _HELD_LOCKS.add(self)

    def release(self) -> None:
        """Release the lock (the file stays)."""
        _HELD_LOCKS.discard(self)
        if self._fh is not None:
            self._fh.close()
            self._fh = None

    def __enter__(self) -> OutputLock:
        self.acquire()
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


#: Locks this process holds; a forked child closes its copies of their files.
_HELD_LOCKS: weakref.WeakSet[OutputLock] = weakref.WeakSet()


def _forget_locks_in_child() -> None:
    """In a forked child (a worker): drop the inherited descriptors of held locks.

    ``flock`` belongs to the open file, which a fork shares: a worker that kept its
    copy would hold the directory locked after the batch process ended.  Closing
    the copy does not unlock (only the last descriptor's close does).
    """
    for lock in list(_HELD_LOCKS):
        fh, lock._fh = lock._fh, None
        if fh is not None:
            with contextlib.suppress(OSError, ValueError):
                fh.close()  # its buffer is empty (flushed after the holder line)
    _HELD_LOCKS.clear()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_locks_in_child)


def remove_stale_temporaries(out_dir: Path) -> int:
    """Delete temporary files left by a killed run (``.NAME.accal-XXXX.tmp``, and a
    plot's ``.NAME.accal-XXXX.tmp.png``); call under the lock.  Other programs'
    temporaries are not accal's to remove."""
    n = 0
    mark = f".*.{TEMP_MARK}*.tmp"
    stale = {*Path(out_dir).glob(mark), *Path(out_dir).glob(mark + ".*")}
    for q in stale:
        with contextlib.suppress(OSError):
            q.unlink()
            n += 1
    return n
