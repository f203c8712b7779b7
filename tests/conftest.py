"""Shared fixtures: a seeded rng, a tiny synthetic corpus built once per session."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def pytest_configure(config):
    # In the controller, before pytest-xdist starts its workers: numba writes a gufunc's
    # on-disk cache without a lock, and two workers compiling librosa's at once in a
    # fresh environment left a cache that crashed every later call (numba/numba#10128).
    if not hasattr(config, "workerinput"):
        from ingest.workers import compile_shared_kernels

        compile_shared_kernels()


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


@pytest.fixture(scope="session")
def tiny_config():
    from ingest.corpus.synthetic import CorpusConfig

    # 3 sentences in all five emotions and 2 in one, 2 takes each: 34 clips.
    return CorpusConfig(sentences=5, parallel=3, variations=2, seed=7)


@pytest.fixture(scope="session")
def tiny_corpus(tmp_path_factory, tiny_config) -> Path:
    """A small synthetic corpus on disk, generated once for the whole session."""
    from ingest.corpus.synthetic import generate_corpus

    out = tmp_path_factory.mktemp("corpus") / "tiny"
    generate_corpus(out, tiny_config, workers=2)
    return out


@pytest.fixture(scope="session")
def tiny_db(tiny_corpus, tmp_path_factory):
    """The tiny corpus ingested into a database (path, ingest report), once per session."""
    from ingest.pipeline import IngestConfig, ingest

    path = tmp_path_factory.mktemp("db") / "tiny.db"
    # With posteriorgrams (not the default) so that the tests see every stored column.
    report = ingest([tiny_corpus], path, IngestConfig(posteriorgrams=True), workers=2)
    return path, report


@pytest.fixture(scope="session")
def unlabelled_db(tiny_db, tmp_path_factory):
    """The tiny database's clips of two sentences without their emotion labels (as GRID's
    come): a database whose clips carry no emotion labels."""
    from dataclasses import replace

    from db.store import Database
    from ingest.pipeline import build_database
    from ingest.tables import prepared_from_database

    clips = [replace(c, emotion="unknown") for c in prepared_from_database(
        Database.open(tiny_db[0])) if c.sentence_id in ("s0001", "s0002")]
    path = tmp_path_factory.mktemp("unlabelled") / "db"
    build_database(path, clips)
    return path


@pytest.fixture(scope="session", autouse=True)
def _isolated_cache(tmp_path_factory):
    """Keep every test's cache (the demo's default corpus, the phone posteriors ingest
    keeps) out of the user's home: session-wide, so that session fixtures such as
    ``tiny_db``, set up before any test's own fixtures, use it too."""
    from animegraph.apps.cache import CACHE_ENV

    with pytest.MonkeyPatch.context() as patch:
        patch.setenv(CACHE_ENV, str(tmp_path_factory.getbasetemp() / "cache"))
        yield


def require_shared(*parts: str) -> Path:
    """Path under ../shared/data, or skip the test with the reason it is missing."""
    path = SHARED_DATA.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"needs {path} (the shared data beside the project), which is absent")
    return path
