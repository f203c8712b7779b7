"""Writes that either complete or leave the previous state untouched.

:func:`atomic_write` replaces one file through a temporary file and a rename;
:func:`replace_dir` swaps a fully built staging folder in for a target folder.
"""

from __future__ import annotations

import logging
import os
import secrets
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import BinaryIO

from db.errors import DataError

logger = logging.getLogger(__name__)


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
        os.replace(tmp, target)
    except BaseException as exc:
        try:
            tmp.unlink(missing_ok=True)
        except OSError:  # pragma: no cover - nothing more can be done
            logger.warning("could not remove temporary file %s", tmp)
        if isinstance(exc, OSError):
            raise DataError(f"cannot write {target}: {exc.strerror or exc}") from exc
        raise


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
