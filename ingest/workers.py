"""Worker processes that end with their parent and on Ctrl-C, without hanging.

:func:`map_in_processes` is ``ProcessPoolExecutor.map`` made safe to interrupt:

* Each worker ignores SIGINT (a Ctrl-C in a terminal reaches the whole process group;
  the parent alone decides what happens) and asks the kernel to send it SIGTERM when its
  parent dies (``prctl(PR_SET_PDEATHSIG)`` on Linux; elsewhere a thread that watches the
  parent's pid), so that ``kill -9`` of the parent leaves no orphan behind.
* On any exception in the parent (``KeyboardInterrupt`` above all), the workers are
  terminated (then killed if they linger) *before* the pool is shut down, pending work
  is cancelled, and nothing waits on a worker again. ``with ProcessPoolExecutor(...)``
  instead waits for every queued job on the way out, and CPython's result thread can
  die with ``InvalidStateError: CANCELLED`` on a cancelled future, after which that
  wait never ends (the hang seen in issue 17).
* Each worker's native thread pools (BLAS, OpenMP, numba) get the cores divided among
  the workers. Left at their default, every worker's BLAS starts a thread per core and
  the threads of all workers spin for the same cores: ingesting GRID's 800 clips on 2
  cores took 90 s to read the clips instead of 45 (``docs/results/speed.md``, "Ingest").

:func:`in_forked_child` runs one call in a forked child that dies at a Ctrl-C and with
its parent: for a long compiled call that keeps Python's lock, which would otherwise hold
back the main thread's Ctrl-C until it returned.
"""

from __future__ import annotations

import contextlib
import functools
import multiprocessing
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor

from db.system import usable_cpus

#: Seconds a terminated worker gets to exit before it is killed.
TERMINATE_GRACE_S = 3.0
#: Seconds between two looks at the parent's pid (where prctl is not available).
PARENT_POLL_S = 0.5
_PR_SET_PDEATHSIG = 1  # <linux/prctl.h>
#: Variables read by native thread pools when they load (those loaded later in a worker).
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                    "BLIS_NUM_THREADS", "NUMBA_NUM_THREADS")


def threads_per_worker(workers: int) -> int:
    """Native threads each of ``workers`` processes gets: the usable cores shared out."""
    return max(1, usable_cpus(cap=4096) // max(1, workers))


def limit_threads(threads: int) -> None:
    """Limit this process' native thread pools to ``threads``, loaded or not yet loaded."""
    for name in THREAD_VARIABLES:
        os.environ[name] = str(threads)
    numba = sys.modules.get("numba")
    if numba is not None:  # loaded already: it read its variable before this
        # First: this starts numba's threading layer, which sizes the OpenMP pool.
        numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=threads)  # the pools already loaded (numpy's BLAS above all)


def die_with_parent(parent: int | None = None) -> None:
    """Make this process end when its parent does (call it first thing in a worker).

    Parameters
    ----------
    parent : int, optional
        The parent's pid as the parent saw it (to catch a parent that died before this
        ran); default ``os.getppid()`` now.
    """
    parent = os.getppid() if parent is None else parent
    armed = False
    if sys.platform.startswith("linux"):
        import ctypes

        try:
            libc = ctypes.CDLL(None, use_errno=True)
            armed = libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0) == 0
        except (OSError, AttributeError):
            armed = False
    if os.getppid() != parent:  # the parent is already gone
        os._exit(1)
    if not armed:
        threading.Thread(target=_watch_parent, args=(parent,), daemon=True,
                         name="animegraph-parent-watch").start()


def _watch_parent(parent: int) -> None:
    import time

    while os.getppid() == parent:
        time.sleep(PARENT_POLL_S)
    os._exit(1)


class ChildFailed(RuntimeError):
    """The work of :func:`in_forked_child` raised ``RuntimeError`` (its message kept)."""


def in_forked_child(work: Callable[[], object]) -> object:
    """``work()`` in a forked child process; its value, or its ``RuntimeError``.

    The child is a copy of this process (``os.fork``): ``work`` sees the same objects in
    the same state (a decoder already built, words already added), so it computes what it
    would compute here, while the calling thread waits in a ``read`` that lets go of
    Python's lock. The child dies at a Ctrl-C (SIGINT at its default action: a terminal's
    Ctrl-C reaches the whole process group) and with its parent
    (:func:`die_with_parent`). Its value comes back as JSON through a pipe (never a
    pickle): a number, string, list (tuples become lists), dict or None.

    Parameters
    ----------
    work : callable
        Called with no argument in the child. It must not need another thread of this
        process (only the calling thread exists in the child) and must not print.

    Returns
    -------
    object
        ``work()``'s value, JSON round-tripped.

    Raises
    ------
    ChildFailed
        ``work`` raised ``RuntimeError`` (a ``RuntimeError``: callers that catch that
        from a compiled library keep working).
    DataError
        ``work`` raised anything else, or the child ended without an answer (killed).
    """
    import json
    import warnings

    from db.errors import DataError

    parent = os.getpid()
    read_fd, write_fd = os.pipe()
    with warnings.catch_warnings():
        # Python 3.12+ warns of fork in a threaded process: the child only runs ``work``
        # (no lock another thread may hold is taken there) and ends with os._exit.
        warnings.simplefilter("ignore", DeprecationWarning)
        pid = os.fork()
    if pid == 0:  # pragma: no cover - the child (its work is covered by the callers' tests)
        status = 1
        try:
            os.close(read_fd)
            signal.signal(signal.SIGINT, signal.SIG_DFL)
            die_with_parent(parent)
            try:
                reply = {"value": work()}
            except RuntimeError as exc:
                reply = {"runtime_error": str(exc)}
            except BaseException as exc:  # noqa: BLE001 - reported to the parent
                reply = {"error": f"{type(exc).__name__}: {exc}"}
            data = memoryview(json.dumps(reply).encode())
            while data:
                data = data[os.write(write_fd, data):]
            status = 0
        finally:
            os._exit(status)
    os.close(write_fd)
    chunks = []
    try:
        while chunk := os.read(read_fd, 1 << 16):
            chunks.append(chunk)
    finally:
        os.close(read_fd)
        _, status = os.waitpid(pid, 0)
    if not chunks:
        how = (f"was killed by signal {os.WTERMSIG(status)}" if os.WIFSIGNALED(status)
               else f"exited with status {os.waitstatus_to_exitcode(status)}")
        raise DataError(f"the child process of a long computation {how} without an answer")
    reply = json.loads(b"".join(chunks))
    if "runtime_error" in reply:
        raise ChildFailed(reply["runtime_error"])
    if "error" in reply:
        raise DataError(f"the child process of a long computation failed: {reply['error']}")
    return reply["value"]


def worker_initializer(parent: int, threads: int | None = None) -> None:
    """Initializer of every worker process: ignore Ctrl-C, end with the parent, and
    (with ``threads``) limit the native thread pools to that many threads."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    die_with_parent(parent)
    if threads is not None:
        limit_threads(threads)


def end_workers(processes: Iterable[multiprocessing.Process]) -> None:
    """Terminate processes, wait a little, kill those still alive, and reap them all."""
    processes = [p for p in processes if p.is_alive()]
    for p in processes:
        with contextlib.suppress(OSError, ValueError):
            p.terminate()
    for p in processes:
        with contextlib.suppress(OSError, ValueError, AssertionError):
            p.join(TERMINATE_GRACE_S)
            if p.is_alive():
                p.kill()
                p.join(TERMINATE_GRACE_S)


def map_in_processes(
    func: Callable, jobs: Sequence, *, workers: int, chunksize: int = 1,
    progress: Callable[[Iterator], Iterable] | None = None,
) -> list:
    """``[func(j) for j in jobs]`` in ``workers`` spawned processes, in order.

    Parameters
    ----------
    func : callable
        A module-level function (it is pickled to the workers).
    jobs : sequence
        Its arguments, one per call.
    workers : int
        Number of processes.
    chunksize : int
        Jobs sent to a worker at once.
    progress : callable, optional
        Wraps the iterator of results (e.g. a progress bar).

    Returns
    -------
    list
        The results, in the order of ``jobs``.

    Notes
    -----
    On any exception (``KeyboardInterrupt`` included) the workers are ended at once and
    the exception propagates; no job is left running.
    """
    _quiet_resource_tracker()
    compile_shared_kernels()
    ctx = multiprocessing.get_context("spawn")
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=ctx,
                               initializer=worker_initializer,
                               initargs=(os.getpid(), threads_per_worker(workers)))
    try:
        # pool.map submits every job, and the pool spawns its workers then: each is
        # started ignoring SIGINT, or a Ctrl-C while a worker is still importing (before
        # its initializer runs) printed that worker's KeyboardInterrupt traceback.
        with sigint_ignored_by_children():
            results = pool.map(func, jobs, chunksize=chunksize)
        done = list(progress(results) if progress else results)
    except BaseException:
        _abandon(pool)
        raise
    pool.shutdown(wait=True)
    return done


@functools.cache  # once a process: after the first call the kernels load from the cache
def compile_shared_kernels() -> None:
    """Compile librosa's numba gufuncs that clip preparation calls (``yin``'s parabolic
    interpolation and local minima, ``zero_crossing_rate``) into numba's on-disk cache
    here, before parallel workers start.

    numba writes a gufunc's cache as two files without a lock (numba/numba#10128): two
    processes compiling the same gufunc at once, as the workers of a fresh install do, can
    leave a cache that crashes every later call with a segmentation fault. Compiled once
    here, the workers only read it. Call it in the parent of processes that share this
    installation (a process pool, a local Dask cluster, test workers).
    """
    import numpy as np

    with contextlib.suppress(ImportError):
        import librosa

        tone = np.sin(np.arange(8000, dtype=np.float32) * (2 * np.pi * 150 / 16000))
        librosa.yin(tone, fmin=60.0, fmax=400.0, sr=16000)
        librosa.feature.zero_crossing_rate(tone)


#: The warnings filter that quiets multiprocessing's resource tracker (below).
_TRACKER_QUIET = "ignore::UserWarning:multiprocessing.resource_tracker"


def _quiet_resource_tracker() -> None:
    """Quiet the resource tracker's report of what ended workers left behind.

    Workers ended at a Ctrl-C (:func:`_abandon`) leave named semaphores (their libraries'
    own) that multiprocessing's resource tracker, a process beside the pool, unlinks once
    the program is gone: that clean-up is its job here, but it also warned of each
    "leaked" one on the terminal, after the program had said it was interrupted. The
    tracker is a process of its own, started with this environment, so the filter goes
    in ``PYTHONWARNINGS`` (narrowly: that module's ``UserWarning`` only)."""
    current = os.environ.get("PYTHONWARNINGS", "")
    if _TRACKER_QUIET not in current.split(","):
        os.environ["PYTHONWARNINGS"] = ",".join(filter(None, [current, _TRACKER_QUIET]))


def _abandon(pool: ProcessPoolExecutor) -> None:
    """End a pool's workers now; a Ctrl-C meanwhile does not cut this short."""
    restore = None
    if threading.current_thread() is threading.main_thread():
        restore = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        processes = list((getattr(pool, "_processes", None) or {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
        end_workers(processes)
    finally:
        if restore is not None:
            signal.signal(signal.SIGINT, restore)


@contextlib.contextmanager
def sigint_ignored_by_children() -> Iterator[None]:
    """Ignore SIGINT while worker processes are started by code we do not control.

    An ignored signal stays ignored across ``fork`` and ``exec`` (Python keeps it so),
    whichever thread starts the process, so workers started meanwhile (e.g. by a Dask
    cluster's own threads) never see the terminal's Ctrl-C, which is sent to the whole
    process group: their parent decides and ends them. (A blocked signal would not do:
    the cluster's threads exist before the block and start the processes.) The price: a
    Ctrl-C during these seconds is not seen; the next one is. Only in the main thread.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
