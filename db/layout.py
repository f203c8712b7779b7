"""The one fact of a database folder's layout that the lowest layer needs: a database
is a folder with a ``CURRENT`` pointer (:mod:`db.store` writes and reads it;
:mod:`db.atomic` refuses to write into such a folder)."""

from __future__ import annotations

import os
from pathlib import Path

#: The file naming a database's live version.
CURRENT = "CURRENT"


def is_database(path: str | os.PathLike) -> bool:
    """True if ``path`` is a database folder (it has a ``CURRENT`` pointer)."""
    return (Path(path) / CURRENT).is_file()
