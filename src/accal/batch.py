"""Batch machinery shared by the commands: inputs, manifest, lock, executors, log.

A cron job over a mission archive needs more than a loop over files:

* :func:`discover` expands files, directories (``--recursive``) and glob patterns
  into a sorted, de-duplicated list, grouped by (satellite, day) when the name
  follows the Level-1B convention ``PROD_YYYY-MM-DD_S_RR.ext``;
* :class:`OutputLock` makes an output directory single-writer (``flock``: the lock
  dies with its process, so a ``kill -9`` never leaves a stale lock behind);
* :class:`Manifest` remembers, per input, its size, mtime (or SHA-256), the accal
  version, the options and the outputs, so a re-run skips what is current;
* :func:`execute` runs a picklable ``task(path) -> outcome`` serially, on local
  worker processes, or on a dask.distributed cluster, yielding outcomes as they
  complete (the caller commits them in batches);
* :class:`RunLog` appends a line per event to ``OUT/accal.log``.

Crash safety comes from the order of the commits (see
:func:`accal.pipeline.run`): every output is written atomically, the cumulative
table is merged before the manifest records an input as done, and an input that
the manifest does not record is simply redone.  A batch killed at any instant and
re-run therefore ends with the same outputs as an uninterrupted one.
"""

from __future__ import annotations

import contextlib
import errno
import fnmatch
import glob
import hashlib
import json
import os
import re
import secrets
import stat
import time as _time
import warnings
import weakref
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from accal import __version__
from accal._runtime import interrupted
from accal.errors import AccalError
from accal.io.writers import TEMP_MARK

#: Names taken from a directory scan unless ``--include`` says otherwise.
DEFAULT_INCLUDE = ("*ACC1B_*", "*ACT1B_*")
#: Names never taken from a directory scan (accal's own outputs).
EXCLUDE = (
    "*.calibrated.*",
    "*.noise.npz",
    "bias_drift.*",
    "*.json",
    "*.md",
    "*.png",
    "*.log",
    "*.rpt",
    "*.lock",
    ".*",
)
MANIFEST = "manifest.json"
LOCK = ".accal.lock"
LOG = "accal.log"

_L1B_NAME = re.compile(
    r"(?P<product>[A-Z]{3}1[AB])_(?P<date>\d{4}-\d{2}-\d{2})_(?P<sat>[A-Z])_(?P<rel>\d+)"
)
_GLOB_CHARS = re.compile(r"[*?\[]")


class LockedError(AccalError):
    """The output directory is being written by another accal run."""


class Interrupted(Exception):  # noqa: N818 - a state, not a failure of the input
    """A batch stopped by Ctrl-C (SIGINT) after committing the inputs that finished.

    ``summary`` is the run's summary at that point (inputs never started count as
    not run); a re-run finishes the batch.
    """

    def __init__(self, summary: Any) -> None:
        super().__init__("interrupted")
        self.summary = summary


@dataclass(frozen=True)
class Outcome:
    """What happened to one input of a batch (the part every command shares).

    Attributes
    ----------
    path : Path
        The input.
    ok : bool
        True if processed and written.
    message : str
        One-line error (``FILE[:LINE]: what is wrong``) when not ok.
    outputs : tuple of Path
        Files written for this input.
    """

    path: Path
    ok: bool
    message: str = ""
    outputs: tuple[Path, ...] = ()


def failure_message(path: Path | str, exc: AccalError) -> str:
    """One line ``FILE[:LINE]: what is wrong`` for an input error."""
    msg = str(exc).replace("\n", " ")
    if getattr(exc, "path", None) is None:
        msg = f"{path}: {msg}"
    return msg


def check_input(path: Path) -> None:
    """Refuse, before anything opens it, an input that no reader should touch.

    * a name that is not valid UTF-8 (its bytes kept as surrogates): the table,
      manifest and reports key inputs by name, and those are UTF-8;
    * a FIFO, device or socket: reading it could block for ever (with the output
      directory locked) or never end (``/dev/zero``).

    Raises
    ------
    ValidationError
        With the reason (the caller names the file).
    """
    from accal.errors import ValidationError

    try:
        str(path).encode("utf-8")
    except UnicodeEncodeError:
        raise ValidationError("file name is not valid UTF-8; rename the file") from None
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return  # missing or unreadable: the reader says so
    if not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
        kind = "a FIFO" if stat.S_ISFIFO(mode) else "a device or socket"
        raise ValidationError(f"not a regular file ({kind})")


def write_error_message(path: Path | str, exc: OSError) -> str:
    """One line for an output that could not be written (read-only or full disk, ...)."""
    where = f" ({exc.filename})" if exc.filename else ""
    return f"{path}: cannot write outputs{where}: {exc.strerror or exc}"


def internal_error_message(path: Path | str, exc: BaseException) -> str:
    """One line for a bug (not bad input); with ``ACCAL_DEBUG`` set, the traceback.

    A worker that died (:class:`WorkerDied`) is not a bug of accal: its line says
    what ended it.

    Raises
    ------
    KeyboardInterrupt
        The process was interrupted (:func:`accal._runtime.interrupted`): the error
        is the interruption's doing, and the run stops as on Ctrl-C.
    """
    if isinstance(exc, WorkerDied):
        return f"{path}: {exc}"
    if interrupted():  # a Ctrl-C that landed in an import or a C extension and came out as
        # ImportError ("initialization failed") or a partially initialised module: the run
        # was interrupted, it is not a bug (issue 23 finding 5)
        raise KeyboardInterrupt from exc
    msg = (
        f"{path}: internal error ({type(exc).__name__}: {exc}); "
        "please report it with the output of 'accal --debug ...'"
    )
    if os.environ.get("ACCAL_DEBUG"):
        import traceback

        msg += "\n" + "".join(traceback.format_exception(exc))
    return msg


@dataclass(frozen=True)
class InputGroup:
    """Inputs of one satellite and day (``key`` is ``("?", "?")`` when unknown)."""

    key: tuple[str, str]
    paths: tuple[Path, ...]


def name_key(path: Path) -> tuple[str, str] | None:
    """``(satellite, date)`` from a Level-1B file name, else None."""
    m = _L1B_NAME.search(path.name)
    return (m["sat"], m["date"]) if m else None


def discover(
    inputs: Iterable[str | Path],
    *,
    recursive: bool = False,
    include: Sequence[str] = DEFAULT_INCLUDE,
) -> tuple[list[Path], list[tuple[Path, str]]]:
    """Expand command-line inputs into files.

    Parameters
    ----------
    inputs : iterable of str or Path
        Files (taken as given, even if they do not exist: the reader reports them),
        directories (their files matching ``include``; the whole tree with
        ``recursive``) and glob patterns (``*``, ``?``, ``[...]``, ``**``).
    recursive : bool
        Descend into sub-directories of directory inputs.
    include : sequence of str
        Name patterns taken from directories (not applied to explicit files).

    Returns
    -------
    files : list of Path
        De-duplicated (by device and inode: symlinks and hard links to one file
        count once), in the order given; directory and
        pattern expansions sorted by name.
    problems : list of (Path, str)
        Inputs that expand to nothing, with a one-line reason.
    """
    files: list[Path] = []
    problems: list[tuple[Path, str]] = []
    seen: set[Any] = set()

    def add(p: Path) -> None:
        # the same file reached by two routes (symlink, hard link, ./x and x) once
        try:
            st = os.stat(p)
            key: Any = (st.st_dev, st.st_ino)
        except OSError:  # missing: the reader reports it (once per spelling)
            key = os.path.realpath(p)
        if key not in seen:
            seen.add(key)
            files.append(p)

    for raw in inputs:
        p = Path(raw)
        if p.is_dir():
            if not recursive:
                add(p)  # the task reports it, in input order, with the hint
                continue
            found = sorted(
                q
                for q in p.rglob("*")
                if q.is_file() and _wanted(q.name, include) and not _hidden(q, p)
            )
            if not found:
                problems.append((p, f"{p}: no input file in directory (include: {list(include)})"))
            for q in found:
                add(q)
        elif not p.exists() and _GLOB_CHARS.search(str(raw)):
            found = sorted(Path(q) for q in glob.glob(str(raw), recursive=True))
            found = [q for q in found if q.is_file()]
            if not found:
                problems.append((p, f"{raw}: no file matches this pattern"))
            for q in found:
                add(q)
        else:
            add(p)
    return files, problems


def _wanted(name: str, include: Sequence[str]) -> bool:
    if any(fnmatch.fnmatch(name, x) for x in EXCLUDE):
        return False
    return any(fnmatch.fnmatch(name, x) for x in include)


def _hidden(q: Path, root: Path) -> bool:
    return any(part.startswith(".") for part in q.relative_to(root).parts)


def group_inputs(paths: Sequence[Path]) -> list[InputGroup]:
    """Group inputs by (satellite, day) from their names, sorted by day then satellite.

    Inputs whose names do not follow the Level-1B convention form one group with
    key ``("?", "?")`` at the end, in their given order.
    """
    groups: dict[tuple[str, str], list[Path]] = {}
    for p in paths:
        groups.setdefault(name_key(p) or ("?", "?"), []).append(p)
    keys = sorted((k for k in groups if k != ("?", "?")), key=lambda k: (k[1], k[0]))
    if ("?", "?") in groups:
        keys.append(("?", "?"))
    return [InputGroup(k, tuple(groups[k])) for k in keys]


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
        import fcntl

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


def file_signature(path: Path, checksum: bool = False) -> dict[str, Any]:
    """Size and mtime (ns) of ``path``, plus its SHA-256 with ``checksum``."""
    st = path.stat()
    sig: dict[str, Any] = {"size": st.st_size, "mtime_ns": st.st_mtime_ns}
    if checksum:
        h = hashlib.sha256()
        with open(path, "rb") as fh:
            for chunk in iter(lambda: fh.read(1 << 20), b""):
                h.update(chunk)
        sig["sha256"] = h.hexdigest()
    return sig


@dataclass
class Manifest:
    """What an output directory holds: one entry per input processed there.

    ``entries[key]`` (``key``: the input's resolved path) holds ``size``,
    ``mtime_ns`` (and ``sha256`` with checksums), ``accal_version``, ``options``
    (the canonical options dict), ``outputs`` (file names in the directory),
    ``source`` (the table's key) and ``processed`` (UTC time).
    """

    path: Path
    entries: dict[str, dict[str, Any]] = field(default_factory=dict)
    #: Entries changed since the last :meth:`save` (see :meth:`is_current`).
    changed: bool = field(default=False, compare=False)

    @classmethod
    def load(cls, out_dir: Path) -> Manifest:
        """Read ``OUT/manifest.json`` (an unreadable manifest means: redo everything)."""
        path = Path(out_dir) / MANIFEST
        if os.path.lexists(path) and not path.is_file() or path.is_symlink():
            # found before any input is processed (issue 23: a manifest.json directory
            # failed the run after the outputs, naming a temporary file)
            raise OSError(
                errno.EEXIST, "not a regular file, not accal's own manifest: remove it", str(path)
            )
        try:
            data = json.loads(path.read_text())
            entries = data["entries"] if isinstance(data, dict) else {}
            if not isinstance(entries, dict):
                entries = {}
        except (OSError, ValueError, KeyError):
            entries = {}
        return cls(path, entries)

    @staticmethod
    def key(path: Path) -> str:
        """Manifest key of an input: its resolved absolute path."""
        return os.path.realpath(path)

    def is_current(self, path: Path, options: dict[str, Any], *, checksum: bool = False) -> bool:
        """True if ``path`` was processed with these options by this accal version,
        has not changed since, and all its outputs still exist."""
        e = self.entries.get(self.key(path))
        if not e or e.get("accal_version") != __version__ or e.get("options") != options:
            return False
        use_hash = checksum and "sha256" in e
        try:
            sig = file_signature(path, checksum=use_hash)
        except OSError:
            return False
        # with checksums, a touched but unchanged file is still current
        keys = ("size", "sha256") if use_hash else ("size", "mtime_ns")
        if any(e.get(k) != sig[k] for k in keys):
            return False
        out = self.path.parent
        if not all((out / name).exists() for name in e.get("outputs", ())):
            return False
        if checksum and not use_hash:  # recorded without one: add it (saved with the run)
            with contextlib.suppress(OSError):
                e["sha256"] = file_signature(path, checksum=True)["sha256"]
                self.changed = True
        return True

    def sharing_outputs(self, path: Path, outputs: Sequence[Path]) -> dict[str, dict[str, Any]]:
        """Entries of *other* inputs that name any of ``outputs`` (which ``path`` now wrote)."""
        names = {Path(o).name for o in outputs}
        me = self.key(path)
        return {
            k: e
            for k, e in self.entries.items()
            if k != me and names.intersection(e.get("outputs", ()))
        }

    def record(
        self,
        path: Path,
        options: dict[str, Any],
        outputs: Sequence[Path],
        source: str,
        *,
        checksum: bool = False,
        before: dict[str, Any] | None = None,
        n_rows: int | None = None,
    ) -> None:
        """Record ``path`` as processed (call only after its table rows are merged).

        ``n_rows``: how many table rows it has (a re-run redoes it when fewer are there).

        ``before``: the input's size and mtime taken before it was read.  If the
        file has changed since (replaced while the batch ran), that earlier
        signature is recorded instead, so the next run sees the change and redoes it.
        """
        try:
            sig = file_signature(path, checksum=checksum)
        except OSError:
            return
        if before is not None and any(sig[k] != before.get(k) for k in ("size", "mtime_ns")):
            sig = {k: before[k] for k in ("size", "mtime_ns")}
        self.entries[self.key(path)] = {
            **sig,
            "accal_version": __version__,
            "options": options,
            "outputs": sorted(Path(o).name for o in outputs),
            "source": source,
            "processed": _time.strftime("%Y-%m-%dT%H:%M:%SZ", _time.gmtime()),
        }
        if n_rows is not None:
            self.entries[self.key(path)]["n_rows"] = int(n_rows)

    def save(self) -> None:
        """Write the manifest atomically."""
        from accal.io.writers import atomic_path

        self.changed = False

        with atomic_path(self.path) as tmp:
            tmp.write_text(
                json.dumps(
                    {"accal_version": __version__, "entries": self.entries},
                    indent=1,
                    sort_keys=True,
                )
                + "\n"
            )


#: C0 and C1 control characters (tab kept) and DEL.
_CONTROL = re.compile(r"[\x00-\x08\x0a-\x1f\x7f-\x9f]")


class RunLog:
    """Append-only text log ``OUT/accal.log`` (one timestamped line per event)."""

    def __init__(self, out_dir: Path, enabled: bool = True) -> None:
        self.path = Path(out_dir) / LOG
        # a file name that is not UTF-8 (bytes kept as surrogates) is logged escaped
        self._fh = (
            open_own(self.path, "a", encoding="utf-8", errors="backslashreplace")
            if enabled
            else None
        )

    def __call__(self, msg: str) -> None:
        if self._fh is not None:
            stamp = _time.strftime("%Y-%m-%dT%H:%M:%S", _time.gmtime())
            # control characters (a file name's terminal escapes, newlines) as \xNN: one
            # line per event, and `cat accal.log` cannot drive the terminal (issue 23)
            msg = _CONTROL.sub(lambda m: f"\\x{ord(m.group()):02x}", msg)
            self._fh.write(f"{stamp}Z [{os.getpid()}] {msg}\n")
            self._fh.flush()

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None


def default_workers() -> int:
    """Cores available to this process."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def execute(
    task: Callable[[Path], Any],
    paths: Sequence[Path],
    *,
    workers: int = 1,
    scheduler: str | Any | None = None,
    on_error: Callable[[Path, BaseException], Any],
    on_note: Callable[[str], Any] | None = None,
) -> Iterator[tuple[int, Any]]:
    """Run ``task`` on every path; yield ``(index, outcome)`` as each completes.

    Parameters
    ----------
    task : callable
        A picklable module-level function of one path (the work of one input).
        It should catch input errors itself and return an outcome.
    paths : sequence of Path
        Inputs.
    workers : int
        Local worker processes (1: in this process, in order).
    scheduler : str or distributed.Client, optional
        Address of a dask.distributed scheduler (or a client): the tasks run on
        its workers, which must see the same file system as this process.
    on_error : callable
        ``on_error(path, exc)`` turns an exception that escaped ``task`` (a crashed
        worker, a bug) into an outcome, so the batch goes on.
    on_note : callable, optional
        Called with a line for the run's log: where the tasks run (e.g.
        ``"inputs run in 2 worker processes (fork)"``), and when a worker died.

    Yields
    ------
    (int, outcome)
        Index into ``paths`` and the task's outcome, in completion order.
    """
    say = on_note or (lambda _msg: None)
    if scheduler is not None:
        say(f"inputs run on dask scheduler {scheduler if isinstance(scheduler, str) else 'client'}")
        yield from _execute_dask(task, paths, scheduler, on_error)
        return
    if workers <= 1 or len(paths) <= 1:
        say("inputs run in this process")
        for i, p in enumerate(paths):
            try:
                yield i, task(p)
            except Exception as exc:  # task bugs: keep the batch going
                yield i, on_error(p, exc)
        return
    import multiprocessing as mp

    func = getattr(task, "func", task)  # functools.partial -> the function
    preload = [*_PRELOAD, getattr(func, "__module__", "accal")]
    method = start_method(preload)
    ctx = mp.get_context(method)
    if method == "forkserver":
        ctx.set_forkserver_preload(preload)
    n_workers = min(workers, len(paths))
    if method == "fork":
        say(f"inputs run in {n_workers} worker processes (fork)")
    else:  # say why, for whoever reads the log
        why = other_threads()
        say(f"inputs run in {n_workers} worker processes ({method}; other threads: {why})")
    # A worker that dies (the OOM killer, kill -9) breaks the whole pool: every input
    # not finished gets BrokenProcessPool.  The inputs that were in the workers' hands
    # are the first ones not finished (the pool hands them out in order): those are
    # each redone alone, to tell a killer input from a bystander; the rest go on in a
    # fresh pool.
    todo = list(range(len(paths)))
    while todo:
        broken: list[int] = []
        yield from _pool_round(task, paths, todo, ctx, n_workers, on_error, broken)
        if not broken:
            break
        suspects, todo = broken[: n_workers + 1], broken[n_workers + 1 :]
        say(
            f"a worker process died: the {len(suspects)} input(s) it may have been running "
            f"are redone one at a time, {len(todo)} more in a fresh pool"
        )
        for i in suspects:
            alone: list[int] = []
            yield from _pool_round(task, paths, [i], ctx, 1, on_error, alone, died=True)


class WorkerDied(RuntimeError):
    """The worker process running an input ended abruptly (killed, out of memory)."""


def _pool_round(
    task: Callable[[Path], Any],
    paths: Sequence[Path],
    todo: Sequence[int],
    ctx: Any,
    n_workers: int,
    on_error: Callable[[Path, BaseException], Any],
    broken: list[int],
    *,
    died: bool = False,
) -> Iterator[tuple[int, Any]]:
    """Run ``paths[todo]`` in one pool; inputs cut off by a broken pool go to ``broken``
    (in ``todo`` order), unless ``died`` (an input alone: it is reported as failed)."""
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from concurrent.futures.process import BrokenProcessPool

    with ProcessPoolExecutor(
        max_workers=min(n_workers, len(todo)), mp_context=ctx, initializer=_worker_init
    ) as pool:
        with warnings.catch_warnings():
            # Python >= 3.12 warns on any fork with another thread; start_method chose
            # fork knowing the only one (FORK_SAFE_THREADS)
            warnings.filterwarnings(
                "ignore", "This process .* is multi-threaded", DeprecationWarning
            )
            futures = {pool.submit(task, paths[i]): i for i in todo}
        procs = list((getattr(pool, "_processes", None) or {}).values())
        # The pool hands inputs out in order: while the workers compute, the inputs
        # the next free workers will take are read ahead into the page cache (one
        # per worker, topped up as each input completes).
        ahead = iter([paths[i] for i in todo[n_workers:]])
        for _ in range(n_workers):
            prefetch(next(ahead, None))
        try:
            for fut in as_completed(futures):
                prefetch(next(ahead, None))
                i = futures[fut]
                try:
                    yield i, fut.result()
                except BrokenProcessPool:
                    if died:
                        for proc in procs:  # reaped: its exit code is known
                            proc.join(timeout=5)
                        codes = sorted({p.exitcode for p in procs if p.exitcode})
                        yield i, on_error(paths[i], WorkerDied(_death(codes)))
                    else:
                        broken.append(i)
                except Exception as exc:  # pickling errors, bugs
                    yield i, on_error(paths[i], exc)
        except (KeyboardInterrupt, GeneratorExit):
            # Ctrl-C (or the caller stopped): drop the queued inputs and stop the
            # workers now; otherwise the pool's exit waits for every queued input
            procs = list((getattr(pool, "_processes", None) or {}).values())
            pool.shutdown(wait=False, cancel_futures=True)
            for proc in procs:
                proc.terminate()
            for proc in procs:
                proc.join(timeout=10)
            raise
    order = {i: k for k, i in enumerate(todo)}
    broken.sort(key=order.__getitem__)


def prefetch(path: Path | None) -> None:
    """Ask the kernel to read ``path`` into the page cache in the background.

    ``posix_fadvise(POSIX_FADV_WILLNEED)`` starts the reads and returns; the
    worker that later reads the file finds it in memory instead of waiting for
    the disk (on a cold archive, ~9 MB per day file).  A no-op where not
    available or for anything but a readable regular file; never raises.
    """
    if path is None or not hasattr(os, "posix_fadvise"):
        return
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    except OSError:
        return
    try:
        if stat.S_ISREG(os.fstat(fd).st_mode):
            os.posix_fadvise(fd, 0, 0, os.POSIX_FADV_WILLNEED)
    except OSError:
        pass
    finally:
        os.close(fd)


def _death(codes: Sequence[int]) -> str:
    """What ended a worker, from its exit codes (negative: the signal)."""
    import signal

    sig = [c for c in codes if c < 0]
    if sig:
        try:
            name = signal.Signals(-sig[0]).name
        except ValueError:
            name = f"signal {-sig[0]}"
        hint = (
            " (out of memory? the kernel's OOM killer sends SIGKILL)" if name == "SIGKILL" else ""
        )
        return f"the worker process running this input was killed by {name}{hint}"
    if codes:
        return f"the worker process running this input exited abruptly (exit codes {list(codes)})"
    # the pool may have reaped it first: how it ended is not known
    return "the worker process running this input ended abruptly (killed? out of memory?)"


#: Modules imported before the workers are forked (by this process or the fork server).
_PRELOAD = ("numpy", "pyarrow.csv", "pyarrow.parquet")


#: Threads that may run while this process forks: the jemalloc bundled with
#: pyarrow starts one at import and handles fork itself (its ``pthread_atfork``
#: handlers take its locks around the fork; the child has consistent allocator
#: state and no background thread).
FORK_SAFE_THREADS = frozenset({"jemalloc_bg_thd"})


def other_threads() -> list[str] | None:
    """Names of this process's threads besides the calling one, native ones
    included (Linux ``/proc``); None where that cannot be known."""
    import threading

    me = threading.get_native_id()
    try:
        tids = [int(t) for t in os.listdir("/proc/self/task")]
    except OSError:
        return None
    names = []
    for tid in tids:
        if tid == me:
            continue
        try:
            with open(f"/proc/self/task/{tid}/comm") as fh:
                names.append(fh.read().strip())
        except OSError:  # ended meanwhile
            continue
    return names


def forced_start_method() -> str | None:
    """``ACCAL_START_METHOD`` (lower case) if set, else None.

    Raises
    ------
    AccalError
        If it is set to anything but ``fork``, ``forkserver`` or ``spawn``.
    """
    forced = os.environ.get("ACCAL_START_METHOD", "").strip().lower()
    if not forced:
        return None
    if forced not in ("fork", "forkserver", "spawn"):
        raise AccalError(
            f"ACCAL_START_METHOD={forced!r}: use 'fork', 'forkserver' or 'spawn' (or unset it)"
        )
    return forced


def start_method(preload: Sequence[str] = _PRELOAD) -> str:
    """How local workers are started: ``"fork"`` when it is safe, else ``"forkserver"``.

    A forked worker starts in milliseconds with every module of this process
    already imported; a fork server first starts a fresh interpreter that imports
    ``preload`` (~0.4 s of every run, measured on the 2-core CI machine).  Forking
    is only safe while no other thread runs: a fork copies the locks other threads
    hold, not the threads.  So on Linux ``preload`` is imported here and the
    threads are listed afterwards (a BLAS set to several threads, a ``LocalCluster``
    in the same process or tqdm's monitor all count; only
    :data:`FORK_SAFE_THREADS` do not): none means ``"fork"``.  Elsewhere, or with
    any other thread, ``"forkserver"``.

    The environment variable ``ACCAL_START_METHOD`` (``fork``, ``forkserver`` or
    ``spawn``) overrides the choice.
    """
    import importlib
    import sys

    forced = forced_start_method()
    if forced:
        return forced
    if not sys.platform.startswith("linux"):
        return "forkserver"
    for name in preload:
        importlib.import_module(name)
    others = other_threads()
    if others is None or any(n not in FORK_SAFE_THREADS for n in others):
        return "forkserver"
    return "fork"


def _worker_init() -> None:
    """Set up a worker process: one compute thread, a tuned allocator, a parent watch.

    One compute thread per worker (the processes are the parallelism): BLAS
    threads are already 1 through the environment the workers inherit
    (:func:`accal._runtime.single_threaded_blas`); pyarrow's pools are set here.
    The allocator is tuned in each process (:func:`accal._runtime.tune_allocator`).

    A worker waits for its next input on a queue that never closes when the batch
    process is killed (``kill -9``: no clean-up runs), so without a watch it would
    stay forever.  A daemon thread waits on the parent's sentinel (a pipe that the
    kernel closes when the parent dies) and ends the worker then; a file it was
    writing is left as a temporary, which the next run removes.
    """
    import multiprocessing as mp
    import signal
    import threading

    import pyarrow as pa

    from accal._runtime import tune_allocator

    # the batch process turns SIGTERM into an interrupt (accal.__main__); a worker
    # keeps the default, so the pool's terminate() ends it at once
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if callable(signal.getsignal(signal.SIGINT)):  # Ctrl-C: KeyboardInterrupt, each time
        signal.signal(signal.SIGINT, signal.default_int_handler)
    tune_allocator()
    pa.set_cpu_count(1)
    pa.set_io_thread_count(1)
    parent = mp.parent_process()
    if parent is not None and getattr(parent, "sentinel", None) is not None:
        # fork/spawn: the batch process is the parent; forkserver: the fork server is
        direct = parent.pid if parent.pid == os.getppid() else None
        threading.Thread(
            target=_exit_with_parent,
            args=(parent.sentinel, direct),
            name="accal-parent-watch",
            daemon=True,
        ).start()


def _exit_with_parent(sentinel: int, parent_pid: int | None) -> None:
    """End this worker when the batch process has gone.

    The sentinel is ready when the parent dies, except that with ``fork`` the
    workers forked later hold copies of its write end (so a worker would wait for
    all later ones); a forked or spawned worker's parent is the batch process
    itself, so it also watches ``getppid()``, which changes when the parent dies.
    """
    from multiprocessing.connection import wait

    while not wait([sentinel], timeout=PARENT_POLL):
        if parent_pid is not None and os.getppid() != parent_pid:
            break
    os._exit(1)


#: How often a worker checks that the batch process still runs [s].
PARENT_POLL = 0.5


def _execute_dask(
    task: Callable[[Path], Any],
    paths: Sequence[Path],
    scheduler: str | Any,
    on_error: Callable[[Path, BaseException], Any],
) -> Iterator[tuple[int, Any]]:
    try:
        from distributed import Client, as_completed
    except ImportError:  # pragma: no cover - depends on the install
        raise AccalError("--scheduler needs dask.distributed: pip install 'accal[dask]'") from None
    own = not isinstance(scheduler, Client)
    try:
        client = Client(scheduler) if own else scheduler
    except (OSError, TimeoutError, ValueError) as exc:
        import dask

        wait = dask.config.get("distributed.comm.timeouts.connect", default="?")
        raise AccalError(
            f"cannot connect to the dask scheduler {scheduler!r}: {exc} (waited up to {wait}; "
            "DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT sets how long)"
        ) from None
    try:
        futures = client.map(task, list(paths), pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        for fut in as_completed(futures):
            i = index[fut.key]
            try:
                yield i, fut.result()
            except Exception as exc:  # a worker died or the task raised
                yield i, on_error(paths[i], exc)
            fut.release()
    finally:
        if own:
            client.close()
