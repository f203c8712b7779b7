"""Whether the search's numba kernels are compiled yet (they are cached on disk once).

The first synthesis in a fresh environment compiles every kernel of the search (28 CPU-s
for synth's default path, the exact and the paper's search, ``scripts/bench_startup.py
--kernels``; NumPy is no substitute: its DTW, a vectorised row recurrence, is 14 times slower
there); later runs load them from numba's cache (:func:`animegraph.search.jit.cache_folder`)
in a few seconds. ``animegraph ingest`` and ``animegraph warmup`` compile them
ahead (:mod:`animegraph.apps.prepare`); a command that meets them uncompiled says so
before that half minute instead of going silent.
"""

from __future__ import annotations

from importlib import import_module
from pathlib import Path

#: Modules of this room holding cached numba kernels, by the search method using them.
KERNEL_MODULES = {"exact": ("dtw", "problem", "exact", "kdtree", "shortlist"),
                  "paper": ("dtw", "problem", "paper"),
                  "window": ("dtw", "problem"), "dp": ("dtw", "problem")}
#: Kernels of those modules that synthesis never calls: ``dtw.dtw``'s path, for scripts
#: and tests (synthesis warps every anime in one compiled pass). Counted, they were never
#: cached by a synthesis, and every ``synth`` announced a minute's compilation.
NOT_IN_SYNTHESIS = frozenset({"dtw._dtw_path"})
#: What the one-off compilation takes, for the message (28 CPU-s, measured by
#: ``scripts/bench_startup.py --kernels``; a loaded machine takes longer).
COMPILE_NOTE = "about half a minute on a quiet machine"


def kernel_caches(method: str = "exact") -> list[tuple[str, Path]]:
    """(``module.function``, its numba cache index file) for each kernel ``method`` runs.

    Numba's cache layout is not public API: kernels whose index cannot be found are
    left out (so nothing is announced rather than something false).
    """
    from numba.core.dispatcher import Dispatcher

    found = []
    for name in KERNEL_MODULES.get(method, KERNEL_MODULES["exact"]):
        module = import_module(f"animegraph.search.{name}")
        for attr, value in vars(module).items():
            if not isinstance(value, Dispatcher) or value.__module__ != module.__name__:
                continue
            index = getattr(getattr(getattr(value, "_cache", None), "_cache_file", None),
                            "_index_path", None)
            if index is not None and f"{name}.{attr}" not in NOT_IN_SYNTHESIS:
                found.append((f"{name}.{attr}", Path(index)))
    return found


def uncompiled_kernels(method: str = "exact") -> list[str]:
    """Names of ``method``'s kernels not compiled and cached on disk yet.

    Numba names an index by the kernel's line (``problem.row_dist-501.py311.nbi``). An
    index for the same kernel at another line counts as cached: the kernel moved in an
    edited file, and a helper such as ``row_dist``, compiled into its callers' cached
    kernels, is not compiled again on its own (so its new index never appears).
    """
    def cached(index: Path) -> bool:
        stem, _, rest = index.name.partition("-")
        tail = rest.partition(".")[2]
        return index.is_file() or any(index.parent.glob(f"{stem}-*.{tail}"))

    return [name for name, index in kernel_caches(method) if not cached(index)]


def compile_notice(method: str = "exact") -> str | None:
    """A line announcing the one-off compilation, or None if the kernels are cached."""
    missing = uncompiled_kernels(method)
    if not missing:
        return None
    return (f"compiling the search kernels once ({len(missing)} to go, {COMPILE_NOTE}; "
            "cached for later runs) ...")

