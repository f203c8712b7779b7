"""A large database's anime graph mapped from its cache (:mod:`animegraph.search.mapped`)
equals the graph converted from its Parquet files, and a cache or database file changed
after the cache was written is not trusted."""

from __future__ import annotations

import json
import mmap
import shutil
from dataclasses import replace

import numpy as np
import pytest

from animegraph.search import mapped
from animegraph.search.graph import AnimeGraph, clip_motion_means
from db import memo
from db.errors import DataError
from db.store import Database


@pytest.fixture
def cached(monkeypatch):
    """Cache every database's graph, however small or freshly written."""
    monkeypatch.setattr(mapped, "MIN_ANIMES", 0)
    monkeypatch.setattr(memo, "SETTLE_NS", 0)


def _is_mapped(array: np.ndarray) -> bool:
    base = array
    while base is not None and not isinstance(base, mmap.mmap):
        base = getattr(base, "base", None)
    return base is not None


def _folder(db: Database):
    return next((mapped.cache_dir() / "graphs").glob("[!.]*"))


def assert_same_graph(graph: AnimeGraph, eager: AnimeGraph) -> None:
    for name, value in vars(eager).items():
        other = getattr(graph, name)
        if name == "clip_means":
            continue
        if isinstance(value, np.ndarray):
            assert other.dtype == value.dtype and np.array_equal(other, value), name
        elif name == "by_phone":
            assert len(other) == len(value)
            assert all(np.array_equal(a, b) for a, b in zip(other, value, strict=True))
        else:
            assert other == value, name
    assert graph.clip_means is not None
    assert np.array_equal(graph.clip_means, clip_motion_means(eager))


@pytest.fixture
def copy_db(tiny_db, tmp_path, monkeypatch):
    """A copy of the tiny database (with posteriorgrams) and a cache folder of its own."""
    monkeypatch.setenv("ANIMEGRAPH_CACHE", str(tmp_path / "cache"))
    path = tmp_path / "db"
    shutil.copytree(tiny_db[0], path, symlinks=True)
    return path


def test_the_mapped_graph_is_the_converted_graph(copy_db, cached):
    db = Database.open(copy_db)
    eager = AnimeGraph.from_database(db)
    written = mapped.load_graph(db)  # converted into the cache's files
    again = mapped.load_graph(Database.open(copy_db))  # mapped from them
    assert eager.posterior_values is not None
    for graph in (written, again):
        assert_same_graph(graph, eager)
        assert _is_mapped(graph.motion_values) and _is_mapped(graph.prosody_values)
        # Copy-on-write: a caller may write as it could into the converted arrays.
        assert graph.motion_values.flags.writeable
    again.motion_values[0] += 1.0
    assert_same_graph(mapped.load_graph(db), eager)  # the file is unchanged


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_mapped_graph_of_any_database_is_its_converted_graph(tiny_db, tmp_path,
                                                                 monkeypatch, cached, seed):
    """Random databases from the tiny corpus's clips: some clips, emotions relabelled,
    with or without posteriorgrams."""
    from ingest.pipeline import build_database
    from ingest.tables import prepared_from_database

    monkeypatch.setenv("ANIMEGRAPH_CACHE", str(tmp_path / "cache"))
    rng = np.random.default_rng(seed)
    clips = prepared_from_database(Database.open(tiny_db[0]))
    keep = rng.choice(len(clips), size=rng.integers(2, len(clips) + 1), replace=False)
    chosen = [replace(clips[i], emotion=str(rng.choice(["a", "b", clips[i].emotion])))
              for i in sorted(keep)]
    if seed == 1:
        chosen = [replace(c, posteriors=None, posterior_blank=None) for c in chosen]
    build_database(tmp_path / "db", chosen)
    db = Database.open(tmp_path / "db")
    eager = AnimeGraph.from_database(db)
    mapped.load_graph(db)
    graph = mapped.load_graph(db)
    assert _is_mapped(graph.motion_values)
    assert_same_graph(graph, eager)


def test_a_changed_cache_file_is_not_used(copy_db, cached):
    db = Database.open(copy_db)
    eager = AnimeGraph.from_database(db)
    mapped.load_graph(db)
    folder = _folder(db)
    # Other values of the same shape: a new identity, so converted again.
    np.save(folder / "motion_values.npy", np.zeros_like(eager.motion_values))
    assert_same_graph(mapped.load_graph(db), eager)
    assert np.array_equal(np.load(folder / "motion_values.npy"), eager.motion_values)
    # Truncated, and an index that is not JSON.
    data = (folder / "prosody_values.npy").read_bytes()
    (folder / "prosody_values.npy").write_bytes(data[:len(data) // 2])
    assert_same_graph(mapped.load_graph(db), eager)
    (folder / "index.json").write_text("{not json")
    assert_same_graph(mapped.load_graph(db), eager)


def test_a_crafted_cache_is_checked_before_the_kernels_index_with_it(copy_db, cached):
    """An edit that records the new identities too (not an accident) still cannot give
    the search links or offsets outside the arrays."""
    db = Database.open(copy_db)
    eager = AnimeGraph.from_database(db)
    mapped.load_graph(db)
    folder = _folder(db)
    for name, value in (("next_node", lambda a: a + 10**6),
                        ("motion_offsets", lambda a: a * 2),
                        ("node_phone", lambda a: a + 500),
                        ("first_pcs", lambda a: a[:, :2].copy())):
        index = json.loads((folder / "index.json").read_text())
        original = np.load(folder / f"{name}.npy")
        np.save(folder / f"{name}.npy", value(original))
        index["files"][name] = mapped._file_id(folder / f"{name}.npy")
        (folder / "index.json").write_text(json.dumps(index))
        assert mapped._open(folder, mapped._key(db)) is None, name
        assert_same_graph(mapped.load_graph(db), eager)  # converted again


def test_a_database_file_changed_after_caching_is_refused(copy_db, cached):
    db = Database.open(copy_db)
    mapped.load_graph(db)
    part = sorted(db.table_path("animes").rglob("*.parquet"))[-1]
    data = bytearray(part.read_bytes())
    data[len(data) // 3] ^= 0xFF
    part.write_bytes(bytes(data))
    with pytest.raises(DataError, match="animes"):
        mapped.load_graph(Database.open(copy_db))


def test_small_fresh_or_uncachable_databases_are_converted(copy_db, monkeypatch, tmp_path):
    db = Database.open(copy_db)
    eager = AnimeGraph.from_database(db)
    graphs = mapped.cache_dir() / "graphs"
    graph = mapped.load_graph(db)  # below MIN_ANIMES
    assert not _is_mapped(graph.motion_values) and not graphs.exists()
    monkeypatch.setattr(mapped, "MIN_ANIMES", 0)
    part = sorted(db.table_path("animes").rglob("*.parquet"))[0]
    part.touch()  # just changed: its times cannot tell a change within their tick
    graph = mapped.load_graph(Database.open(copy_db))
    assert not _is_mapped(graph.motion_values) and not any(graphs.glob("[!.]*"))
    monkeypatch.setattr(memo, "SETTLE_NS", 0)
    (tmp_path / "file").write_text("")
    monkeypatch.setenv("ANIMEGRAPH_CACHE", str(tmp_path / "file"))  # not a folder
    graph = mapped.load_graph(Database.open(copy_db))
    assert_same_graph(replace(graph, clip_means=clip_motion_means(graph)), eager)
    assert not _is_mapped(graph.motion_values)


def test_synthesis_from_the_mapped_graph_is_synthesis_from_the_converted(copy_db, monkeypatch,
                                                                       cached):
    from animegraph.synthesis import Model, PostOptions, synthesize
    from ingest.formats.phones_csv import Segment
    from ingest.speech.espeak import speak

    utt = speak("Bob moved the warm vase away.")
    labels = [Segment(p.phone, p.start, p.end) for p in utt.phones]
    lazy = Model.load(copy_db)
    lazy = Model.load(copy_db)  # mapped
    assert _is_mapped(lazy.graph.motion_values)
    monkeypatch.setattr(mapped, "MIN_ANIMES", 2**62)
    eager = Model.load(copy_db)
    assert not _is_mapped(eager.graph.motion_values)
    for kwargs in ({"k_best": 4, "options": PostOptions(recentre=True)}, {}):
        a = synthesize(lazy, utt.audio, utt.sample_rate, labels=labels, **kwargs)
        b = synthesize(eager, utt.audio, utt.sample_rate, labels=labels, **kwargs)
        assert np.array_equal(a.ics, b.ics)


def test_the_cache_of_a_database_that_is_gone_is_removed(tiny_db, tmp_path, monkeypatch,
                                                          cached):
    monkeypatch.setenv("ANIMEGRAPH_CACHE", str(tmp_path / "cache"))
    for name in ("a", "b"):
        shutil.copytree(tiny_db[0], tmp_path / name, symlinks=True)
    mapped.load_graph(Database.open(tmp_path / "a"))
    shutil.rmtree(tmp_path / "a")
    (mapped.cache_dir() / "graphs" / ".x.partial-999999999-00").mkdir()  # a dead writer's
    mapped.load_graph(Database.open(tmp_path / "b"))  # writes its own, removes the others
    left = list((mapped.cache_dir() / "graphs").iterdir())
    assert len(left) == 1
    assert json.loads((left[0] / "index.json").read_text())["key"][1] == str(
        (tmp_path / "b").resolve())
