"""Batch machinery shared by the commands: inputs, manifest, lock, executors, log.

A cron job over a mission archive needs more than a loop over files (this module
runs the tasks and gathers the public names of the others):

* :func:`discover` expands files, directories (``--recursive``) and glob patterns
  into a sorted, de-duplicated list, grouped by (satellite, day) when the name
  follows the Level-1B convention ``PROD_YYYY-MM-DD_S_RR.ext``
  (:mod:`accal.batch_discovery`);
* :class:`OutputLock` makes an output directory single-writer (``flock``: the lock
  dies with its process, so a ``kill -9`` never leaves a stale lock behind;
  :mod:`accal.batch_lock`);
* :class:`Manifest` remembers, per input, its size, mtime (or SHA-256), the accal
  version, the options and the outputs, so a re-run skips what is current
  (:mod:`accal.batch_manifest`);
* :func:`execute` runs a picklable ``task(path) -> outcome`` serially, on local
  worker processes, or on a dask.distributed cluster, yielding outcomes as they
  complete (the caller commits them in batches; the local workers are set up by
  :mod:`accal.batch_workers`);
* :class:`RunLog` appends a line per event to ``OUT/accal.log``
  (:mod:`accal.batch_manifest`);
* :class:`Outcome` and the one-line messages of an input: :mod:`accal.batch_messages`.

Crash safety comes from the order of the commits (see
:func:`accal.pipeline.run`): every output is written atomically, the cumulative
table is merged before the manifest records an input as done, and an input that
the manifest does not record is simply redone.  A batch killed at any instant and
re-run therefore ends with the same outputs as an uninterrupted one.
"""

from __future__ import annotations

import os
import re
import socket
import stat
import warnings
from collections.abc import Callable, Iterator, Sequence
from typing import Any

from accal.batch_discovery import (
    DEFAULT_INCLUDE,
    EXCLUDE,
    L1B_NAME,
    InputGroup,
    discover,
    group_inputs,
    name_key,
)
from accal.batch_lock import LOCK, LockedError, OutputLock, open_own, remove_stale_temporaries
from accal.batch_manifest import LOG, MANIFEST, Manifest, RunLog, file_signature
from accal.batch_messages import (
    Interrupted,
    Outcome,
    WorkerDied,
    check_input,
    failure_message,
    internal_error_message,
    write_error_message,
)
from accal.batch_workers import (
    FORK_SAFE_THREADS,
    PARENT_POLL,
    PRELOAD,
    default_workers,
    forced_start_method,
    interrupts_held,
    other_threads,
    start_method,
    worker_init,
)
from accal.errors import AccalError

#: The Level-1B name pattern under its former name (imported by accal.gracejob.reading).
_L1B_NAME = L1B_NAME
#: The worker set-up under its former name (named in accal.__main__).
_worker_init = worker_init

__all__ = [
    "DEFAULT_INCLUDE",
    "EXCLUDE",
    "FORK_SAFE_THREADS",
    "LOCK",
    "LOG",
    "MANIFEST",
    "PARENT_POLL",
    "PRELOAD",
    "InputGroup",
    "Interrupted",
    "LockedError",
    "Manifest",
    "Outcome",
    "OutputLock",
    "RunLog",
    "WorkerDied",
    "check_input",
    "default_workers",
    "discover",
    "execute",
    "failure_message",
    "file_signature",
    "forced_start_method",
    "group_inputs",
    "internal_error_message",
    "name_key",
    "open_own",
    "other_threads",
    "prefetch",
    "remove_stale_temporaries",
    "start_method",
    "worker_init",
    "write_error_message",
]


def execute(
    task: Callable[[Any], Any],
    paths: Sequence[Any],
    *,
    workers: int = 1,
    scheduler: str | Any | None = None,
    on_error: Callable[[Any, BaseException], Any],
    on_note: Callable[[str], Any] | None = None,
) -> Iterator[tuple[int, Any]]:
    """Run ``task`` on every path; yield ``(index, outcome)`` as each completes.

    Parameters
    ----------
    task : callable
        A picklable module-level function of one path (the work of one input).
        It should catch input errors itself and return an outcome.
    paths : sequence of Path
        Inputs (or other picklable arguments of ``task``: ``grace-bias --arc`` runs
        one task per arc of inputs; only paths are read ahead).
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
    # imported when workers are used (python -X importtime: multiprocessing ~35 ms,
    # concurrent.futures.process ~0.15 s, distributed ~0.7 s): the CLI imports accal.batch
    import multiprocessing as mp

    func = getattr(task, "func", task)  # functools.partial -> the function
    preload = [*PRELOAD, getattr(func, "__module__", "accal")]
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


def _pool_round(
    task: Callable[[Any], Any],
    paths: Sequence[Any],
    todo: Sequence[int],
    ctx: Any,
    n_workers: int,
    on_error: Callable[[Any, BaseException], Any],
    broken: list[int],
    *,
    died: bool = False,
) -> Iterator[tuple[int, Any]]:
    """Run ``paths[todo]`` in one pool; inputs cut off by a broken pool go to ``broken``
    (in ``todo`` order), unless ``died`` (an input alone: it is reported as failed)."""
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from concurrent.futures.process import BrokenProcessPool

    with ProcessPoolExecutor(
        max_workers=min(n_workers, len(todo)), mp_context=ctx, initializer=worker_init
    ) as pool:
        try:
            # the workers start as the inputs are submitted: a Ctrl-C then takes effect
            # once they are all known, so that stop_pool stops every one
            with interrupts_held(), warnings.catch_warnings():
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
            # Ctrl-C (or the caller stopped), also while the workers start
            stop_pool(pool)
            raise
    order = {i: k for k, i in enumerate(todo)}
    broken.sort(key=order.__getitem__)


def stop_pool(pool: Any) -> None:
    """Stop a process pool now (Ctrl-C): drop its queued inputs, end its workers, free it.

    The workers are terminated and joined first: the pool's own shutdown would
    wait for every queued input.  The pool is then shut down *with* waiting, which
    joins its manager thread (quick now: its workers are gone) and so frees the
    pool's queues.  With a fork server or spawn their locks are named semaphores
    registered with Python's resource tracker, unlinked when the queues are freed.
    A shutdown without waiting left them to the manager thread, still running when
    an interrupted run leaves by ``os._exit`` (:mod:`accal.__main__`, which skips
    multiprocessing's exit handlers): the resource tracker then printed
    "There appear to be 5 leaked semaphore objects" after ``accal: interrupted``.

    Parameters
    ----------
    pool : concurrent.futures.ProcessPoolExecutor
        The pool.
    """
    procs = list((getattr(pool, "_processes", None) or {}).values())
    for proc in procs:
        proc.terminate()
    for proc in procs:
        proc.join(timeout=10)
    pool.shutdown(wait=True, cancel_futures=True)


def prefetch(path: Any) -> None:
    """Ask the kernel to read ``path`` into the page cache in the background.

    ``posix_fadvise(POSIX_FADV_WILLNEED)`` starts the reads and returns; the
    worker that later reads the file finds it in memory instead of waiting for
    the disk (on a cold archive, ~9 MB per day file).  A no-op where not
    available or for anything but a readable regular file (a task's argument
    that is not a path: an arc of inputs); never raises.
    """
    if not isinstance(path, str | os.PathLike) or not hasattr(os, "posix_fadvise"):
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


#: Seconds the TCP probe of a scheduler address waits for an answer (:func:`_refused`).
PROBE_TIMEOUT = 3.0


def _refused(address: str) -> str | None:
    """Why a ``tcp://host:port`` (or ``host:port``) scheduler address cannot be reached
    at once, or ``None``.

    ``distributed.Client`` retries a refused connection until its connect timeout
    (30 s by default) before it fails; a plain TCP connection (:func:`socket.create_connection`)
    says "refused", "no route" or "unknown host" at once.  Only such immediate answers are
    reported: a probe that times out, another scheme (``tls://``, ``inproc://``, ``ucx://``)
    or an address that does not parse is left to the client and its timeout.
    """
    m = re.fullmatch(r"(?:tcp://)?\[?([^\]\s/]+?)\]?:(\d{1,5})/?", address.strip())
    if not m:
        return None
    host, port = m.group(1), int(m.group(2))
    try:
        with socket.create_connection((host, port), timeout=PROBE_TIMEOUT):
            return None
    except TimeoutError:
        return None
    except socket.gaierror as exc:
        return f"unknown host {host!r} ({exc.strerror or exc})"
    except OSError as exc:
        return exc.strerror or str(exc)


def _execute_dask(
    task: Callable[[Any], Any],
    paths: Sequence[Any],
    scheduler: str | Any,
    on_error: Callable[[Any, BaseException], Any],
) -> Iterator[tuple[int, Any]]:
    try:
        from distributed import Client, as_completed
    except ImportError:  # pragma: no cover - depends on the install
        raise AccalError("--scheduler needs dask.distributed: pip install 'accal[dask]'") from None
    own = not isinstance(scheduler, Client)
    if own:
        refused = _refused(str(scheduler))
        if refused:
            raise AccalError(f"cannot connect to the dask scheduler {scheduler!r}: {refused}")
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
