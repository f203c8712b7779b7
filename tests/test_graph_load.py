"""The Anime Graph's loader copies list columns chunk by chunk: the same arrays as
converting each whole column at once, and the same refusals."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest

from animegraph.search import graph as G
from animegraph.search.graph import AnimeGraph
from db.store import Database


def _whole(column: pa.ChunkedArray) -> np.ndarray:
    """The values of a list column converted at once (the loader's former way)."""
    return column.combine_chunks().flatten().to_numpy(zero_copy_only=False).astype(np.float32)


def _chunked(rng, rows: np.ndarray, width: int) -> pa.ChunkedArray:
    """A list<float> column of rows[i] x width values a row, in chunks of uneven sizes,
    one of them a slice of a larger array (its values start after the slice's first)."""
    lists = [rng.standard_normal(int(r) * width).astype(np.float32) for r in rows]
    padded = pa.array([[0.5] * width] + lists[:3] + [[9.0]], pa.list_(pa.float32()))
    chunks = [padded.slice(1, 3)]  # rows 0-2, sliced out of a larger array
    chunks += [pa.array(lists[3:4], pa.list_(pa.float32())),
               pa.array(lists[4:], pa.list_(pa.float32()))]
    return pa.chunked_array(chunks)


def test_ragged_chunk_by_chunk_equals_whole_column():
    rng = np.random.default_rng(0)
    rows = rng.integers(1, 6, size=11)
    column = _chunked(rng, rows, width=3)
    values, offsets = G._ragged(column, rows)
    assert values.dtype == np.float32 and values.shape == (rows.sum(), 3)
    assert np.array_equal(values.ravel(), _whole(column))
    assert np.array_equal(offsets, np.concatenate(([0], np.cumsum(rows))))
    fixed = _chunked(rng, np.ones(7, dtype=np.int64), width=4)
    assert np.array_equal(G._fixed(fixed, 7), _whole(fixed).reshape(7, 4))


def test_ragged_refusals_are_kept():
    rng = np.random.default_rng(1)
    rows = np.array([2, 1, 3, 1, 2])
    column = _chunked(rng, rows, width=2)
    with pytest.raises(ValueError, match="does not hold its frames"):
        G._ragged(column, np.array([1, 2, 3, 2, 1]))  # the same total, other rows
    with pytest.raises(ValueError, match="do not fill"):
        G._ragged(column, rows + 1)
    with pytest.raises(ValueError, match="no frames"):
        G._ragged(column, np.array([2, 0, 3, 1, 2]))
    nulls = pa.chunked_array([pa.array([[1.0, 2.0], None], pa.list_(pa.float32()))])
    with pytest.raises(ValueError, match="nulls"):
        G._ragged(nulls, np.array([1, 1]))
    with pytest.raises(TypeError, match="list column"):
        G._ragged(pa.chunked_array([pa.array([1.0, 2.0])]), np.array([1, 1]))
    uneven = pa.chunked_array([pa.array([[1.0, 2.0], [3.0]], pa.list_(pa.float32()))])
    with pytest.raises(ValueError, match="unequal"):
        G._fixed(uneven, 2)


def test_loaded_graph_equals_the_stored_columns(tiny_db):
    # A real database: its columns, converted whole, are the graph's arrays.
    db = Database.open(tiny_db[0])
    graph = AnimeGraph.from_database(db)
    t = db.table("animes", columns=["node_id", "motion", "prosody", "posteriors",
                                    "first_pcs", "last_pcs"]).sort_by("node_id")
    assert np.array_equal(graph.motion_values.ravel(), _whole(t.column("motion")))
    assert np.array_equal(graph.prosody_values.ravel(), _whole(t.column("prosody")))
    assert np.array_equal(graph.posterior_values.ravel(), _whole(t.column("posteriors")))
    assert np.array_equal(graph.first_pcs.ravel(), _whole(t.column("first_pcs")))
    assert np.array_equal(graph.last_pcs.ravel(), _whole(t.column("last_pcs")))
