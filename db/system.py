"""What this process may use of the machine (shared by every layer)."""

from __future__ import annotations

import os

__all__ = ["thread_budget", "usable_cpus"]


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
