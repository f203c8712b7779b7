"""The search's numba kernels and their on-disk cache, keyed by the kernels' sources.

numba checks a cached kernel against its own file only: a kernel that calls one from
another file (``exact.py``'s search calls ``kdtree.py``'s tree) has that callee compiled
into it, and an edit to ``kdtree.py`` left ``exact.py``'s cached kernels running the old
code. So every kernel of this room is cached in one folder named after the package's
version and a hash of the sources of all files holding kernels: an edit to any of them,
or an upgrade that replaced some files and not others, opens a fresh folder, and the
kernels compile once again instead of running stale code.

The folder is ``numba-<key>`` inside the first writable of ``$NUMBA_CACHE_DIR``,
``__pycache__`` beside this module (numba's own default place), and the user's
animegraph cache (``~/.cache/animegraph/numba``, for an install that cannot be written).
With none writable the kernels compile in every process. When a new folder is made, the
others older than a day in the same place are removed (another install of another
version sharing ``$NUMBA_CACHE_DIR`` keeps the one it used within the day).
"""

from __future__ import annotations

import functools
import hashlib
import os
import shutil
import time
from pathlib import Path

import numba

__all__ = ["KERNEL_FILES", "cache_folder", "cache_key", "kernel", "kernel_sources"]

#: The files of this room that hold kernels (and this one, which decides their cache):
#: their sources make the cache's key. ``tests/test_search_jit.py`` checks it is complete.
KERNEL_FILES = ("dtw.py", "exact.py", "jit.py", "kdtree.py", "paper.py", "problem.py",
                "shortlist.py")
#: Cache folders of other keys unused for this long are removed when a new one is made.
_STALE_SECONDS = 24 * 3600
_PREFIX = "numba-"


def kernel_sources(folder: Path | None = None) -> list[Path]:
    """The :data:`KERNEL_FILES` of ``folder`` (this room by default)."""
    folder = Path(__file__).parent if folder is None else folder
    return [folder / name for name in KERNEL_FILES]


def cache_key(folder: Path | None = None) -> str:
    """The package's version and a hash of the kernels' sources (16 hex digits).

    Hashing the seven files takes well under a millisecond, once a process.
    """
    from animegraph import __version__

    digest = hashlib.sha256(__version__.encode())
    for path in kernel_sources(folder):
        digest.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    return f"{__version__}-{digest.hexdigest()[:16]}"


def _bases() -> list[Path]:
    from ingest.cache import cache_dir

    bases = [Path(os.environ["NUMBA_CACHE_DIR"])] if os.environ.get("NUMBA_CACHE_DIR") else []
    return [*bases, Path(__file__).parent / "__pycache__", cache_dir() / "numba"]


def _prune(base: Path, keep: Path) -> None:
    """Remove the other keys' folders in ``base`` unused for a day (best effort)."""
    now = time.time()
    for old in base.glob(f"{_PREFIX}*"):
        try:
            if old != keep and old.is_dir() and now - old.stat().st_mtime > _STALE_SECONDS:
                shutil.rmtree(old, ignore_errors=True)
        except OSError:
            continue


@functools.cache
def cache_folder() -> Path | None:
    """This version's kernel cache folder (made if new), or None if none is writable."""
    key = cache_key()
    for base in _bases():
        folder = base / f"{_PREFIX}{key}"
        try:
            new = not folder.is_dir()
            folder.mkdir(parents=True, exist_ok=True)
            if not os.access(folder, os.W_OK):
                continue
            os.utime(folder)  # marks it in use, for _prune
        except OSError:
            continue
        if new:
            _prune(base, folder)
        return folder
    return None


def kernel(**options):
    """``numba.njit(nogil=True)`` cached in :func:`cache_folder` (uncached without one).

    numba picks a kernel's cache folder when the function is decorated, from
    ``numba.config.CACHE_DIR`` (what ``$NUMBA_CACHE_DIR`` sets); it is pointed at this
    version's folder for that moment only, so that other libraries' kernels (librosa's)
    keep their own cache.
    """

    def wrap(func):
        folder = cache_folder()
        if folder is None:
            return numba.njit(cache=False, nogil=True, **options)(func)
        saved = numba.config.CACHE_DIR
        numba.config.CACHE_DIR = str(folder)
        try:
            return numba.njit(cache=True, nogil=True, **options)(func)
        except RuntimeError:  # numba found no writable place after all
            return numba.njit(cache=False, nogil=True, **options)(func)
        finally:
            numba.config.CACHE_DIR = saved

    return wrap
