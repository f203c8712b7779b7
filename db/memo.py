"""What this process has already checked of a database's files, by file identity.

A version's files are written once (:mod:`db.store`), so the checks of a file that has
not changed need not be redone at every read: hashing the model arrays and reading a
table's footers were 0.4 s and 0.1 s of every clip the studio loaded from the demo
database, and ``batch``, ``live`` and every ``Model.load`` pay them again. A check is
remembered under the identity of the files it read (:func:`identity`: device, inode,
size, modification and status-change times), so a file replaced (a new inode), rewritten
(new times, which a user cannot set back: the status-change time is the kernel's) or
grown is checked again.

A file changed within :data:`SETTLE_NS` of being checked is not remembered: file times
have the granularity of the kernel's clock tick, and a file changed twice in one tick
would keep its times (git's "racily clean" index entries, ``Documentation/technical/
racy-git.txt``, are the same problem and the same answer).
"""

from __future__ import annotations

import os
import threading
import time
from collections import OrderedDict

__all__ = ["Memo", "identities", "identity"]

#: Nanoseconds a file must be left unchanged before a check of it is remembered.
SETTLE_NS = 2_000_000_000


def identity(path: str | os.PathLike) -> tuple:
    """What tells one state of the file at ``path`` from another: its path, device,
    inode, size and modification and status-change times (OSError if it is gone)."""
    st = os.stat(path)
    return (os.fspath(path), st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns,
            st.st_ctime_ns)


def identities(paths) -> tuple | None:
    """The :func:`identity` of each file of ``paths``, or None if one is gone (the check
    that follows then says so, and nothing is remembered)."""
    try:
        return tuple(identity(p) for p in paths)
    except OSError:
        return None


def settled(ids: tuple) -> bool:
    """True if every file of ``ids`` (:func:`identity` tuples) was last changed at least
    :data:`SETTLE_NS` ago."""
    now = time.time_ns()
    return all(now - max(i[4], i[5]) >= SETTLE_NS for i in ids)


class Memo:
    """A bounded, thread-safe map from a key (holding file identities) to what was found
    (the least recently used entry goes first)."""

    def __init__(self, size: int) -> None:
        self.size = size
        self._lock = threading.Lock()
        self._entries: OrderedDict = OrderedDict()

    def get(self, key):
        """What was remembered under ``key``, or None."""
        with self._lock:
            value = self._entries.get(key)
            if value is not None:
                self._entries.move_to_end(key)
            return value

    def put(self, key, value, ids: tuple) -> None:
        """Remember ``value`` under ``key`` if the files of ``ids`` have settled."""
        if not settled(ids):
            return
        with self._lock:
            self._entries[key] = value
            self._entries.move_to_end(key)
            while len(self._entries) > self.size:
                self._entries.popitem(last=False)

    def clear(self) -> None:
        with self._lock:
            self._entries.clear()
