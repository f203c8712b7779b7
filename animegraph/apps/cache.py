"""Where the embedded default corpus and database live on a user's machine."""

from __future__ import annotations

import os
from pathlib import Path

#: Overrides the cache folder (tests and CI point it at a temporary folder).
CACHE_ENV = "ANIMEGRAPH_CACHE"


def cache_dir() -> Path:
    """The user's cache folder for animegraph (``$ANIMEGRAPH_CACHE`` if set)."""
    if os.environ.get(CACHE_ENV):
        return Path(os.environ[CACHE_ENV])
    from platformdirs import user_cache_dir

    return Path(user_cache_dir("animegraph"))


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
    return default_db_dir(), "the demo's default database"
