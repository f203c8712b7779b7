"""Writes that either complete or leave the previous state untouched.

:func:`atomic_write` replaces one file through a temporary file and a rename;
:func:`replace_dir` swaps a fully built staging folder in for a target folder.
"""

from __future__ import annotations

import errno
import logging
import os
import secrets
import shutil
import stat
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import BinaryIO

from db.errors import DataError
from db.layout import is_database

logger = logging.getLogger(__name__)


def write_error(path: str | os.PathLike[str], exc: OSError) -> DataError:
    """The one line for a write to ``path`` that failed with ``exc``: the file named, and a
    full disk said as such (pyarrow's own error, "Error writing bytes to file. Detail:
    [errno 28] ...", named neither the file nor the cause in words)."""
    full = exc.errno == errno.ENOSPC or f"[errno {errno.ENOSPC}]" in str(exc)
    quota = exc.errno == errno.EDQUOT or f"[errno {errno.EDQUOT}]" in str(exc)
    why = ("the disk is full" if full else "the disk quota is used up" if quota
           else exc.strerror or str(exc).strip().splitlines()[0] or type(exc).__name__)
    return DataError(f"cannot write {path}: {why}")


#: What an existing path is, by its file type (``os.lstat``), when it is not a regular file
#: or a folder: never replaced by an output.
_KINDS = ((stat.S_ISLNK, "a symbolic link"), (stat.S_ISCHR, "a device"),
          (stat.S_ISBLK, "a device"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
          (stat.S_ISSOCK, "a socket"), (stat.S_ISDIR, "a folder"), (stat.S_ISREG, "a file"))


def check_output_path(path: str | os.PathLike[str], *, folder: bool | None = False) -> Path:
    """Refuse a place a command's output may not go; return it as a Path.

    An output (``sql -o``, ``synth -o``, ``render -o``, ``query --export`` ...) is written
    beside its target and renamed onto it, which replaces whatever the name held: a device
    node (``/dev/full``, as root), a FIFO, a symbolic link (not what it points to), a
    database's own ``CURRENT``. So an output must be a new path or an existing regular file
    (``folder=True``: an existing folder; ``folder=None``: either), the path itself not a
    symbolic link, and it must not be inside a database folder, nor be one.

    Raises
    ------
    DataError
        One line naming the path and what it is.
    """
    target = Path(path)
    try:
        mode = os.lstat(target).st_mode
    except (FileNotFoundError, NotADirectoryError):  # a new path (its folder: the writer's)
        mode = None
    except OSError as exc:
        raise DataError(f"cannot write {target}: {exc.strerror or exc}") from None
    # The folder as it really is (``..`` and symbolic links followed): ``-o DB/x/../CURRENT``
    # and a link to a database's folder name a place inside it.
    where = target.parent.resolve() / target.name
    if mode is not None and stat.S_ISDIR(mode) and is_database(where):
        raise DataError(f"cannot write {target}: it is a database folder; write outputs "
                        "outside a database")
    for place in where.parents:
        if is_database(place):
            raise DataError(f"cannot write {target}: it is inside the database {place}; "
                            "write outputs outside a database")
    if mode is not None:
        wanted = {False: (stat.S_ISREG,), True: (stat.S_ISDIR,),
                  None: (stat.S_ISREG, stat.S_ISDIR)}[folder]
        if not any(test(mode) for test in wanted):
            what = next((name for test, name in _KINDS if test(mode)), "a special file")
            expected = {False: "a regular file", True: "a folder",
                        None: "a regular file or a folder"}[folder]
            raise DataError(f"cannot write {target}: it is {what}, not {expected}; "
                            f"give a new path or {expected}")
    return target


def check_folder(path: str | os.PathLike[str]) -> None:
    """DataError unless ``path``'s folder exists: an output that cannot be written, said
    before the work that makes it rather than after."""
    target = Path(path)
    if not target.parent.is_dir():
        raise DataError(f"cannot write {target}: folder {target.parent} does not exist")


@contextmanager
def atomic_write(path: str | os.PathLike[str]) -> Iterator[BinaryIO]:
    """Open a temporary file beside ``path`` for binary writing, then move it onto ``path``.

    The temporary file is created in the target's folder (so the final
    :func:`os.replace` is atomic), flushed and fsynced when the ``with`` block ends
    normally, then renamed onto ``path``. If the block, the flush or the rename fails
    the temporary file is removed and an existing ``path`` is left untouched.

    Parameters
    ----------
    path : str or os.PathLike
        The file to create or replace.

    Yields
    ------
    BinaryIO
        The open temporary file.

    Raises
    ------
    DataError
        If the folder is missing or the file cannot be written (wraps the ``OSError``).
    """
    target = Path(path)
    folder = target.parent
    check_folder(target)
    _replaceable(target)
    tmp = folder / f".{target.name}.{secrets.token_hex(6)}.tmp"
    try:
        # os.open with mode 0o666 honours the umask, as a plain open() of the target would.
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), 0o666)
    except OSError as exc:
        raise DataError(f"cannot write {target}: {exc.strerror or exc}") from exc
    try:
        with os.fdopen(fd, "wb") as handle:
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        _replaceable(target)  # again: the name may have changed during the write
        os.replace(tmp, target)
    except BaseException as exc:
        try:
            tmp.unlink(missing_ok=True)
        except OSError:  # pragma: no cover - nothing more can be done
            logger.warning("could not remove temporary file %s", tmp)
        if isinstance(exc, OSError):
            raise write_error(target, exc) from exc
        raise


def _replaceable(target: Path) -> None:
    """DataError unless ``target`` is absent or a regular file: the rename would replace a
    device, a FIFO, a symbolic link or a socket by a regular file."""
    try:
        mode = os.lstat(target).st_mode
    except (FileNotFoundError, NotADirectoryError):
        return
    except OSError as exc:
        raise DataError(f"cannot write {target}: {exc.strerror or exc}") from None
    if not stat.S_ISREG(mode):
        check_output_path(target)  # says what it is


def replace_dir(staging: str | os.PathLike[str], target: str | os.PathLike[str]) -> None:
    """Move the finished folder ``staging`` to ``target``, replacing any folder there.

    The old ``target`` is renamed aside first and deleted only once ``staging`` is in
    place; if the swap fails, the old folder is put back. Both must be on one file system.
    """
    staging, target = Path(staging), Path(target)
    old = None
    if target.exists():
        old = target.parent / f".{target.name}.old-{secrets.token_hex(4)}"
        target.rename(old)
    try:
        staging.rename(target)
    except BaseException:
        if old is not None:
            old.rename(target)
        raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
