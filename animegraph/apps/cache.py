"""Where the embedded default corpus and database live on a user's machine."""

from __future__ import annotations

import os
from pathlib import Path

from ingest.cache import CACHE_ENV, cache_dir

__all__ = ["CACHE_ENV", "DB_ENV", "cache_dir", "default_corpus_dir", "default_database",
           "default_db_dir"]


def default_corpus_dir() -> Path:
    """Folder of the default synthetic corpus, generated on first use."""
    return cache_dir() / "corpus-default"


def default_db_dir() -> Path:
    """Folder of the database built from the default corpus, on first use."""
    return cache_dir() / "db-default"


#: Names the database a command uses when ``--db`` is left out.
DB_ENV = "ANIMEGRAPH_DB"


def default_database() -> tuple[Path, str]:
    """The database used without ``--db``: ``$ANIMEGRAPH_DB`` if set, else the demo's.

    Returns
    -------
    (path, where the choice came from, for messages)
    """
    if os.environ.get(DB_ENV):
        return Path(os.environ[DB_ENV]), f"${DB_ENV}"
    return default_db_dir(), "the demo's database"
