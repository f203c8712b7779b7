"""The search's kept thread pools, one per thread count, shared by its kernels' callers.

The DTW pairs (:mod:`animegraph.search.dtw`), the exact search's layer queries
(:mod:`animegraph.search.exact`) and the shortlist's bounds
(:mod:`animegraph.search.shortlist`) run numba kernels that release the GIL on Python
threads. A pool is made when first needed and kept: starting its threads on every call
was most of a small batch's time (a live stream's window: docs/results/live.md, "What is
computed once, what is not"). Callers on several threads may share a pool: each waits
only for its own work. A forked child (ingest's workers) has none of its parent's threads,
so work given to the parent's pools would wait for ever: the child makes its own.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

import numpy as np

__all__ = ["in_chunks", "thread_pool"]

_POOLS: dict[int, ThreadPoolExecutor] = {}
_LOCK = threading.Lock()


def thread_pool(threads: int) -> ThreadPoolExecutor:
    """The kept pool of ``threads`` threads (made on first use)."""
    with _LOCK:
        pool = _POOLS.get(threads)
        if pool is None:
            pool = _POOLS[threads] = ThreadPoolExecutor(threads, thread_name_prefix="search")
        return pool


def in_chunks(n: int, threads: int, run: Callable[[int, int], None]) -> None:
    """``run(start, stop)`` over ``[0, n)``: in one call on one thread, else in about four
    chunks a thread on the kept pool (several a thread even out items of unequal cost).
    Each chunk must write only its own items."""
    if threads <= 1:
        run(0, n)
        return
    cuts = np.linspace(0, n, min(n, 4 * threads) + 1).astype(np.int64)
    list(thread_pool(threads).map(lambda k: run(cuts[k], cuts[k + 1]), range(len(cuts) - 1)))


def _forget_pools() -> None:
    """In a forked child: the parent's pools have no threads here (a fork copies only
    the calling thread); new ones are made when needed."""
    global _LOCK
    _POOLS.clear()
    _LOCK = threading.Lock()  # another thread may have held it at the fork


if hasattr(os, "register_at_fork"):  # not on Windows, which does not fork
    os.register_at_fork(after_in_child=_forget_pools)
