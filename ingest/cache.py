"""The user's cache folder (``$ANIMEGRAPH_CACHE`` if set): the default corpus and database,
and face tracking of videos (:mod:`ingest.readers.video`)."""

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
