"""One writer at a time: an OS lock on a folder, released when its process dies.

:func:`writer_lock` takes an exclusive ``fcntl.flock`` on a hidden lock file in the
folder (a database, a batch output folder). The kernel drops the lock when the
holding process exits however it exits (``kill -9`` included), so a crash never leaves
a stale lock behind; the file itself stays and is harmless. A second writer waits up to
``wait`` seconds, then fails with one line naming the holder's process id. Within one
process the lock is re-entrant (an ingest holds it and :func:`db.store.write_version`
takes it again).
"""

from __future__ import annotations

import errno
import os
import stat
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from db.errors import BusyError, DataError

#: Name of the lock file inside the locked folder.
LOCK_NAME = ".animegraph.lock"
#: Seconds between attempts while waiting for another writer.
POLL_S = 0.2

_held: dict[str, list] = {}  # resolved folder -> [fd, depth]
_guard = threading.Lock()

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows: no flock, no lock (single-user tool)
    fcntl = None


def lock_path(folder: str | os.PathLike) -> Path:
    """The lock file of ``folder``."""
    return Path(folder) / LOCK_NAME


@contextmanager
def writer_lock(folder: str | os.PathLike, *, wait: float = 0.0, what: str = "folder",
                on_wait: Callable[[str], object] | None = None) -> Iterator[None]:
    """Hold the exclusive writer lock of ``folder`` (created if absent) for a block.

    Parameters
    ----------
    folder : path
        The folder to lock.
    wait : float
        Seconds to wait for another writer to finish before giving up (0: fail at once).
    what : str
        What the folder is, for the message (``"database"``, ``"output folder"``).
    on_wait : callable, optional
        Called once, with the holder (``" (process 123)"`` or ``""``), when the lock is
        found held and is about to be waited for: a wait of minutes is said, not silent.

    Raises
    ------
    BusyError
        If another process holds the lock after ``wait`` seconds.
    DataError
        If the lock file cannot be created.
    """
    root = Path(folder)
    try:
        root.mkdir(parents=True, exist_ok=True)
        key = str(root.resolve())
    except OSError as exc:
        raise DataError(f"cannot lock {what} {root}: {exc.strerror or exc}") from None
    with _guard:
        entry = _held.get(key)
        if entry is not None:
            entry[1] += 1
    if entry is not None:
        try:
            yield
        finally:
            with _guard:
                entry[1] -= 1
        return
    fd = _acquire(root, wait, what, on_wait)
    with _guard:
        _held[key] = [fd, 1]
    try:
        yield
    finally:
        with _guard:
            del _held[key]
        os.close(fd)  # closing the descriptor releases the flock


def _acquire(root: Path, wait: float, what: str,
             on_wait: Callable[[str], object] | None = None) -> int:
    # The folder may come from someone else: a lock file that is a symbolic link (to a
    # file of the user's elsewhere) is not followed, and anything but a regular file is
    # refused, since the lock file is truncated and written.
    flags = os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0)
    try:
        fd = os.open(lock_path(root), flags, 0o666)
    except OSError as exc:
        why = ("its lock file is a symbolic link" if exc.errno == errno.ELOOP
               else exc.strerror or str(exc))
        raise DataError(f"cannot lock {what} {root}: {why}") from None
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise DataError(f"cannot lock {what} {root}: its lock file "
                        f"{lock_path(root).name} is not a regular file")
    if fcntl is None:  # pragma: no cover
        return fd
    deadline = time.monotonic() + max(0.0, wait)
    while True:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            break
        except OSError as exc:
            if exc.errno not in (errno.EAGAIN, errno.EACCES, errno.EWOULDBLOCK):
                os.close(fd)
                raise DataError(f"cannot lock {what} {root}: {exc.strerror or exc}") from None
            if time.monotonic() >= deadline:
                holder = _holder(fd)
                os.close(fd)
                waited = f" after waiting {wait:g} s" if wait > 0 else ""
                raise BusyError(f"{what} {root} is being written by another process"
                                f"{holder}{waited}; try again when it has finished") from None
            if on_wait is not None:
                on_wait(_holder(fd))
                on_wait = None
            time.sleep(POLL_S)
    os.ftruncate(fd, 0)
    os.pwrite(fd, str(os.getpid()).encode(), 0)
    return fd


def _holder(fd: int) -> str:
    try:
        text = os.pread(fd, 32, 0).decode("ascii").strip()
    except (OSError, UnicodeDecodeError):
        return ""
    return f" (process {text})" if text.isdigit() else ""


def pid_alive(pid: int) -> bool:
    """True if a process with id ``pid`` exists (it may belong to another user)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True
