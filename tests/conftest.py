"""Shared fixtures: a seeded rng, a tiny synthetic corpus and its database built once per
run (once for all pytest-xdist workers, see :func:`_built_once`)."""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
#: ``shutil.copytree``'s ``ignore`` for a copy of ``tiny_db`` as ingest left it: tests that
#: synthesize from speech alone store guides in a worker's ``tiny_db``, and which of them ran
#: before depends on how the files were shared out to the workers.
AS_INGESTED = shutil.ignore_patterns("baselines")


def pytest_configure(config):
    # In the controller, before pytest-xdist starts its workers: numba writes a gufunc's
    # on-disk cache without a lock, and two workers compiling librosa's at once in a
    # fresh environment left a cache that crashed every later call (numba/numba#10128).
    if not hasattr(config, "workerinput"):
        from ingest.workers import compile_shared_kernels

        compile_shared_kernels()


#: The test files that take longest, slowest first (docs/results/speed.md, "The test
#: suite"). pytest-xdist hands files to its workers in the order collected
#: (``--no-loadscope-reorder`` in pyproject.toml; by default it orders them by their number
#: of tests, which put the demo's two long tests last): started first, a long file no
#: longer runs alone at the end while the other workers have finished.
SLOW_FILES = (
    "test_examples.py", "test_docs.py", "test_demo.py", "test_batch.py", "test_workers.py",
    "test_interrupt.py", "test_ingest.py", "test_live.py", "test_studio.py",
    "test_ingest_dask.py", "test_fuzz.py", "test_invariants.py", "test_emotion_fit.py",
    "test_baselines.py", "test_guide.py", "test_writer_lock.py", "test_search.py",
    "test_emotion_cli.py", "test_posteriorgram.py", "test_lag.py", "test_render.py",
)


def pytest_collection_modifyitems(config, items):
    # A stable sort: a file's tests keep their order, the other files theirs.
    rank = {name: i for i, name in enumerate(SLOW_FILES)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


@pytest.fixture(scope="session")
def tiny_config():
    from ingest.corpus.synthetic import CorpusConfig

    # 3 sentences in all five emotions and 2 in one, 2 takes each: 34 clips.
    return CorpusConfig(sentences=5, parallel=3, variations=2, seed=7)


def _built_once(tmp_path_factory, name: str, build: Callable[[Path], None]) -> Path:
    """The folder ``name``, filled by ``build(folder)`` once for the whole run.

    Under pytest-xdist the workers' temporary folders share a parent (the run's): the
    first worker that needs the folder builds it there under a lock while the others
    wait, then all use it (the xdist documentation's recipe for session fixtures). A
    folder left by a worker that failed while building has no ``built`` mark and is built
    again. In one process (``-n 0``) it is an ordinary temporary folder.
    """
    if os.environ.get("PYTEST_XDIST_WORKER") is None:
        folder = tmp_path_factory.mktemp(name)
        build(folder)
        return folder
    from db.lock import writer_lock

    shared = tmp_path_factory.getbasetemp().parent / "built-once"
    folder = shared / name
    mark = shared / f"{name}.built"
    with writer_lock(shared / f"{name}.lock", wait=3600.0, what="test fixture folder"):
        if not mark.exists():
            shutil.rmtree(folder, ignore_errors=True)
            folder.mkdir(parents=True)
            build(folder)
            mark.touch()
    return folder


@pytest.fixture(scope="session")
def tiny_corpus(tmp_path_factory, tiny_config) -> Path:
    """A small synthetic corpus on disk, generated once for the whole run: read-only (a
    test that changes it works on a copy)."""
    from ingest.corpus.synthetic import generate_corpus

    def build(folder: Path) -> None:
        generate_corpus(folder / "tiny", tiny_config, workers=2)

    return _built_once(tmp_path_factory, "corpus", build) / "tiny"


def _report_to_json(report) -> str:
    from dataclasses import asdict

    return json.dumps({**asdict(report), "db": None})


def _report_from_json(text: str, db: Path):
    from ingest.pipeline import ClipReport, IngestReport

    fields = json.loads(text)
    clips = [ClipReport(**clip) for clip in fields.pop("clips")]
    return IngestReport(**{**fields, "db": db, "clips": clips})


@pytest.fixture(scope="session")
def tiny_db(tiny_corpus, tmp_path_factory, _isolated_cache):
    """The tiny corpus ingested into a database (path, ingest report). The ingest runs once
    for the run; each worker gets its own copy of the database (tests store models in it)
    and, in its cache folder, what the ingest kept there (the phones it heard)."""
    from ingest.cache import CACHE_ENV, cache_dir
    from ingest.pipeline import IngestConfig, ingest

    def build(folder: Path) -> None:
        with pytest.MonkeyPatch.context() as patch:
            patch.setenv(CACHE_ENV, str(folder / "cache"))
            # With posteriorgrams (not the default) so that the tests see every stored
            # column.
            report = ingest([tiny_corpus], folder / "tiny.db",
                            IngestConfig(posteriorgrams=True), workers=2)
        (folder / "report.json").write_text(_report_to_json(report))

    built = _built_once(tmp_path_factory, "db", build)
    path = tmp_path_factory.mktemp("db") / "tiny.db"
    shutil.copytree(built / "tiny.db", path, symlinks=True)
    if (built / "cache").is_dir():
        shutil.copytree(built / "cache", cache_dir(), symlinks=True, dirs_exist_ok=True)
    return path, _report_from_json((built / "report.json").read_text(), path)


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
