"""Where the embedded default corpus and database live on a user's machine."""

from __future__ import annotations

from pathlib import Path

from ingest.cache import CACHE_ENV, cache_dir

__all__ = ["CACHE_ENV", "cache_dir", "default_corpus_dir", "default_db_dir"]


def default_corpus_dir() -> Path:
    """Folder of the default synthetic corpus, generated on first use."""
    return cache_dir() / "corpus-default"


def default_db_dir() -> Path:
    """Folder of the database built from the default corpus, on first use."""
    return cache_dir() / "db-default"
