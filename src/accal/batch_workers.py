"""Local worker processes of a batch: how they are started and set up.

:func:`start_method` forks when that is safe (no other thread runs) and uses a
fork server otherwise; :func:`worker_init` sets each worker up (one compute
thread, a tuned allocator, a watch that ends it with the batch process);
:func:`default_workers` is the number of cores available.
"""

from __future__ import annotations

import contextlib
import importlib
import os
import signal
import sys
import time
from collections.abc import Iterator, Sequence

from accal._runtime import tune_allocator
from accal.errors import AccalError


def default_workers() -> int:
    """Cores available to this process."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


#: Modules imported before the workers are forked (by this process or the fork server).
PRELOAD = ("numpy", "pyarrow.csv", "pyarrow.parquet")


#: Threads that may run while this process forks: the jemalloc bundled with
#: pyarrow starts one at import and handles fork itself (its ``pthread_atfork``
#: handlers take its locks around the fork; the child has consistent allocator
#: state and no background thread).
FORK_SAFE_THREADS = frozenset({"jemalloc_bg_thd"})


def other_threads() -> list[str] | None:
    """Names of this process's threads besides the calling one, native ones
    included (Linux ``/proc``); None where that cannot be known."""
    import threading  # ~15 ms (python -X importtime); accal.batch is imported by the CLI

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


def start_method(preload: Sequence[str] = PRELOAD) -> str:
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
    forced = forced_start_method()
    if forced:
        return forced
    if not sys.platform.startswith("linux"):
        return "forkserver"
    for name in preload:
        importlib.import_module(name)
    for _ in range(JOINED_THREAD_POLLS):
        others = other_threads()
        if others is None or all(n in FORK_SAFE_THREADS for n in others):
            break
        # a thread just joined (the manager thread of a pool that has just ended, e.g.
        # grace-bias --arc's scan before its arcs) is still listed for a moment
        time.sleep(0.01)
    if others is None or any(n not in FORK_SAFE_THREADS for n in others):
        return "forkserver"
    return "fork"


#: How often :func:`start_method` looks again, 10 ms apart, when another thread is listed.
JOINED_THREAD_POLLS = 5


@contextlib.contextmanager
def interrupts_held() -> Iterator[None]:
    """Hold a Ctrl-C (SIGINT) or SIGTERM while the block runs; it takes effect after it.

    For the start of a pool's workers (:func:`accal.batch.execute`).  A worker is
    started in two steps: the fork server forks it and reports its pid, then the
    child reads its set-up (the pool's queues, their named semaphores among them)
    from a pipe.  A Ctrl-C while this process waited for the pid (the fork server
    may still be importing its preload, ~0.4 s and more) left a child the pool
    never knew of: it was not stopped with the others, and it read its set-up after
    the pool's semaphores were freed, printing a ``FileNotFoundError`` traceback
    after ``accal: interrupted``.  Held, the signal is handled (by the handler in
    place, e.g. :mod:`accal.__main__`'s) once the workers started are all known.  A
    second one while held is handled at once (a fork server that hangs can still be
    left with Ctrl-C).  Signals ignored or left to the default action are not
    touched; outside the main thread this does nothing.
    """
    import threading  # ~15 ms (python -X importtime); imported where workers start

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held: list[int] = []
    handlers: dict[int, object] = {}

    def hold(signum: int, frame: object) -> None:
        if held:  # a second one: at once
            _run_handler(handlers.get(signum), signum, frame)
        held.append(signum)

    for sig in (signal.SIGINT, signal.SIGTERM):
        if callable(signal.getsignal(sig)):
            handlers[sig] = signal.signal(sig, hold)
    try:
        yield
    finally:
        for sig, handler in handlers.items():
            if signal.getsignal(sig) is hold:  # not if a handler run meanwhile changed it
                signal.signal(sig, handler)  # type: ignore[arg-type]
        if held:
            _run_handler(handlers.get(held[0]), held[0], None)


def _run_handler(handler: object, signum: int, frame: object) -> None:
    """Call a Python signal handler as the interpreter would."""
    if callable(handler):
        handler(signum, frame)


def worker_init() -> None:
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
    # imported in the worker only (python -X importtime: pyarrow ~0.5 s, multiprocessing
    # ~35 ms): accal.batch is imported by the CLI
    import multiprocessing as mp
    import threading

    import pyarrow as pa

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
