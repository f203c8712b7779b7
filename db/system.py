"""What this process may use of the machine (shared by every layer)."""

from __future__ import annotations

import os

__all__ = ["usable_cpus"]


def usable_cpus(cap: int = 8) -> int:
    """The CPUs this process may run on (its affinity, where the system says), 1 to ``cap``."""
    try:
        n = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        n = os.cpu_count() or 1
    return max(1, min(cap, n))
