"""The Anime Graph's loader reads the curves a batch at a time into their arrays: the
same arrays as converting each whole column at once, in node order whatever the order of
the rows, and the same refusals."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest

from animegraph.search import graph as G
from animegraph.search.graph import AnimeGraph
from db.errors import DataError
from db.store import Database, arrays_to_table, write_version


def _whole(column: pa.ChunkedArray) -> np.ndarray:
    """The values of a list column converted at once (the loader's former way)."""
    return column.combine_chunks().flatten().to_numpy(zero_copy_only=False).astype(np.float32)


def _curves_db(path, rng, rows: np.ndarray, width: int, *, lists=None):
    """A database whose animes (shuffled, in two emotion partitions) carry a ``curve``
    list column of rows[i] x width values for node i and one fixed ``pcs`` of 4."""
    n = len(rows)
    if lists is None:
        lists = [rng.standard_normal(int(r) * width).astype(np.float32) for r in rows]
    pcs = [rng.standard_normal(4).astype(np.float32) for _ in range(n)]
    order = rng.permutation(n)
    emotions = np.where(np.arange(n) % 3 == 0, "happy", "sad")
    animes = pa.table({
        "node_id": pa.array(order, pa.int64()),
        "emotion": pa.array(emotions[order]),
        "clip_id": pa.array([f"c{i}" for i in order]),
        "curve": pa.array([lists[i] for i in order], pa.list_(pa.float32())),
        "pcs": pa.array([pcs[i] for i in order], pa.list_(pa.float32())),
    })
    tables = {
        "clips": pa.table({"clip_id": ["c0"], "emotion": ["happy"]}), "animes": animes,
        "frames": pa.table({"clip_id": ["c0"], "emotion": ["happy"],
                            "frame": pa.array([0], pa.int32()), "jaw": [0.0]}),
        "audio": pa.table({"clip_id": ["c0"], "pcm16": [b"\x00\x01"]}),
        "channels": pa.table({"channel": [0], "name": ["jaw"]}),
        "model_arrays": arrays_to_table({"m": np.zeros(1)}),
        "components": pa.table({"component": [0], "cutoff_hz": [3.5]}),
    }
    write_version(path, tables, {"fps": 30.0})
    return Database.open(path), lists, pcs


@pytest.mark.parametrize("batch", [2, 5, 1000])
def test_curves_read_in_batches_equal_the_whole_columns_in_node_order(tmp_path, monkeypatch,
                                                                       batch):
    monkeypatch.setattr(G, "CURVE_BATCH_ROWS", batch)
    rng = np.random.default_rng(batch)
    rows = rng.integers(1, 6, size=13)
    db, lists, pcs = _curves_db(tmp_path / "db", rng, rows, width=3)
    curves = G._read_curves(db, {"curve": rows, "pcs": np.ones(13, np.int64)})
    values, offsets = curves["curve"]
    assert values.dtype == np.float32 and values.shape == (rows.sum(), 3)
    assert np.array_equal(values.ravel(), np.concatenate(lists))
    assert np.array_equal(offsets, np.concatenate(([0], np.cumsum(rows))))
    assert np.array_equal(curves["pcs"][0], np.stack(pcs))


def test_curve_refusals_are_kept(tmp_path, monkeypatch):
    monkeypatch.setattr(G, "CURVE_BATCH_ROWS", 2)
    rng = np.random.default_rng(1)
    rows = np.array([2, 1, 3, 1, 2])
    db, _, _ = _curves_db(tmp_path / "db", rng, rows, width=2)
    with pytest.raises(ValueError, match="does not hold its frames"):
        G._read_curves(db, {"curve": np.array([1, 2, 3, 2, 1])})  # same total, other rows
    with pytest.raises(ValueError, match="does not hold its frames"):
        G._read_curves(db, {"curve": rows + 1})
    with pytest.raises(ValueError, match="no frames"):
        G._read_curves(db, {"curve": np.array([2, 0, 3, 1, 2])})
    with pytest.raises(ValueError, match="out of range"):
        G._read_curves(db, {"curve": rows[:4]})  # a node id beyond the nodes
    with pytest.raises(TypeError, match="list column"):
        G._read_curves(db, {"clip_id": rows})
    nulls = [np.ones(2, np.float32), None, np.ones(2, np.float32)]
    db, _, _ = _curves_db(tmp_path / "nulls", rng, np.ones(3, np.int64), width=2,
                          lists=nulls)
    with pytest.raises(ValueError, match="nulls"):
        G._read_curves(db, {"curve": np.ones(3, np.int64)})


def test_a_damaged_curve_file_is_refused_when_read(tmp_path):
    """A page of the animes' curves damaged on disk is refused by its checksum, as the
    whole-table read refuses it, in one line naming the table."""
    db, _, _ = _curves_db(tmp_path / "db", np.random.default_rng(2),
                          np.full(200, 3), width=8)
    part = sorted(db.table_path("animes").rglob("*.parquet"))[-1]
    data = bytearray(part.read_bytes())
    data[len(data) // 3] ^= 0xFF
    part.write_bytes(bytes(data))
    with pytest.raises(DataError, match="animes"):
        G._read_curves(db, {"curve": np.full(200, 3), "pcs": np.ones(200, np.int64)})


@pytest.mark.parametrize("batch", [7, G.CURVE_BATCH_ROWS])
def test_loaded_graph_equals_the_stored_columns(tiny_db, monkeypatch, batch):
    # A real database: its columns, converted whole, are the graph's arrays.
    monkeypatch.setattr(G, "CURVE_BATCH_ROWS", batch)
    db = Database.open(tiny_db[0])
    graph = AnimeGraph.from_database(db)
    t = db.table("animes", columns=["node_id", "motion", "prosody", "posteriors",
                                    "first_pcs", "last_pcs", "next_node"]).sort_by("node_id")
    assert np.array_equal(graph.motion_values.ravel(), _whole(t.column("motion")))
    assert np.array_equal(graph.prosody_values.ravel(), _whole(t.column("prosody")))
    assert np.array_equal(graph.posterior_values.ravel(), _whole(t.column("posteriors")))
    assert np.array_equal(graph.first_pcs.ravel(), _whole(t.column("first_pcs")))
    assert np.array_equal(graph.last_pcs.ravel(), _whole(t.column("last_pcs")))
    assert np.array_equal(graph.next_node, t.column("next_node").fill_null(-1).to_numpy())


def test_batches_read_what_the_whole_table_reads(tmp_path):
    """Database.batches gives the rows and emotions (percent-decoded partition names, as
    pyarrow.dataset decodes them) of Database.table, in pieces."""
    tables = {name: t for name, t in zip(
        ("clips", "frames", "audio", "channels", "model_arrays", "components"),
        (pa.table({"clip_id": ["c0"], "emotion": ["a b"]}),
         pa.table({"clip_id": ["c0"], "emotion": ["a b"], "frame": pa.array([0], pa.int32()),
                   "jaw": [0.0]}),
         pa.table({"clip_id": ["c0"], "pcm16": [b"\x00\x01"]}),
         pa.table({"channel": [0], "name": ["jaw"]}),
         arrays_to_table({"m": np.zeros(1)}),
         pa.table({"component": [0], "cutoff_hz": [3.5]})), strict=True)}
    tables["animes"] = pa.table({"node_id": pa.array(range(9), pa.int64()),
                                 "emotion": ["très", "a b", "x/y"] * 3,
                                 "clip_id": [f"c{i}" for i in range(9)]})
    write_version(tmp_path / "db", tables, {"fps": 30.0})
    db = Database.open(tmp_path / "db")
    whole = db.table("animes", columns=["node_id", "emotion"])
    pieces = pa.concat_tables(db.batches("animes", ["node_id", "emotion"], 2))
    assert sorted(pieces.to_pylist(), key=str) == sorted(whole.to_pylist(), key=str)
    assert set(pieces.column("emotion").to_pylist()) == {"très", "a b", "x/y"}
