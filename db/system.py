"""What this process may use of the machine (shared by every layer)."""

from __future__ import annotations

import contextvars
import os
import threading
import time

__all__ = ["StillRunning", "in_worker_thread", "interrupt_awaited", "thread_budget",
           "usable_cpus"]


def thread_budget() -> int:
    """Threads this process should run at once: ``OMP_NUM_THREADS`` where it is set to a
    whole number (a user's limit, or the share of the cores a worker process was given,
    :func:`ingest.workers.limit_threads`), else :func:`usable_cpus`."""
    given = os.environ.get("OMP_NUM_THREADS", "")
    return max(1, int(given)) if given.strip().isdigit() else usable_cpus()


def usable_cpus(cap: int = 8) -> int:
    """The CPUs this process may run on (its affinity, where the system says), 1 to ``cap``."""
    try:
        n = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        n = os.cpu_count() or 1
    return max(1, min(cap, n))


#: True in the work :func:`in_worker_thread` runs (its context): see :func:`interrupt_awaited`.
_AWAITED = contextvars.ContextVar("animegraph_interrupt_awaited", default=False)


def interrupt_awaited() -> bool:
    """True inside work that :func:`in_worker_thread` runs, where the main thread waits to
    end the command at a Ctrl-C.

    That wait needs Python's lock: a long compiled call that keeps it (PocketSphinx's
    decoder does) delays the Ctrl-C until it returns. Such a call asks this and, when
    true, runs where it can be killed (:func:`ingest.workers.in_forked_child`).
    """
    return _AWAITED.get()


class StillRunning(Exception):
    """A Ctrl-C came, and the interrupted work had not stopped within its grace."""


def in_worker_thread(work, *, timeout: float | None = None, on_timeout=None,
                     on_interrupt=None, grace: float | None = None, poll: float = 0.05):
    """``work()`` in a daemon thread while this thread waits for it; its value, or its
    exception.

    Python runs a Ctrl-C's handler in the main thread only between its own instructions:
    inside a long compiled call (DuckDB's execution, numba's kernels, the phone model) the
    ``KeyboardInterrupt`` waited for the call to end. Waiting here, it arrives within
    ``poll`` seconds. The work runs in a copy of the caller's context variables.

    Parameters
    ----------
    work : callable
        Called with no argument.
    timeout : float, optional
        Seconds after which ``on_timeout()`` is called (at every look until the work ends).
    on_timeout, on_interrupt : callable, optional
        What stops the work: called past ``timeout``, and at a Ctrl-C.
    grace : float, optional
        Seconds a Ctrl-C'd work gets to stop before :class:`StillRunning` is raised
        instead of ``KeyboardInterrupt``; without, ``KeyboardInterrupt`` at once.
    poll : float
        Seconds between two looks at the work (and at Ctrl-C).
    """
    outcome: dict = {}
    # Waited for through an Event, not Thread.join: a join cut short by Ctrl-C marks the
    # thread as ended while it still runs (CPython releases its lock, bpo-45274).
    done = threading.Event()
    context = contextvars.copy_context()
    context.run(_AWAITED.set, True)

    def target() -> None:
        try:
            outcome["value"] = context.run(work)
        except BaseException as exc:  # noqa: BLE001 - handed to the waiting thread
            outcome["error"] = exc
        finally:
            done.set()

    # A daemon: work that ignores its interruption must not keep the process alive.
    thread = threading.Thread(target=target, name="animegraph-work", daemon=True)
    deadline = None if timeout is None else time.monotonic() + timeout
    thread.start()
    try:
        while not done.wait(poll):
            if deadline is not None and time.monotonic() > deadline and on_timeout:
                on_timeout()
    except KeyboardInterrupt:
        if on_interrupt is not None:
            on_interrupt()
        if grace is not None and not done.wait(grace):
            raise StillRunning from None
        raise
    if "error" in outcome:
        raise outcome["error"]
    return outcome["value"]
