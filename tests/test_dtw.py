"""Dynamic time warping (animegraph.search.dtw): known answers; tslearn, librosa as references."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import animegraph.search.dtw as dtw_module
import animegraph.search.threads as threads_module
from animegraph.search.dtw import (
    audio_cost,
    audio_costs,
    audio_costs_many,
    dtw,
    mark_finite,
    warp_indices,
    warp_indices_many,
    warp_onto,
)
from db.errors import ParameterError


def _col(*values: float) -> np.ndarray:
    return np.array(values, dtype=np.float64)[:, None]


def _ragged(curves: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    offsets = np.zeros(len(curves) + 1, dtype=np.int64)
    np.cumsum([len(c) for c in curves], out=offsets[1:])
    return np.concatenate(curves), offsets


def _brute_force(x: np.ndarray, y: np.ndarray, sq: bool) -> float:
    """Least cost over every monotone path (exhaustive; tiny inputs only)."""
    local = ((x[:, None, :] - y[None, :, :]) ** 2).sum(-1)
    if not sq:
        local = np.sqrt(local)
    n, m = local.shape

    def best(i: int, j: int) -> float:
        if (i, j) == (n - 1, m - 1):
            return local[i, j]
        steps = [(i + a, j + b) for a, b in ((1, 0), (0, 1), (1, 1)) if i + a < n and j + b < m]
        return local[i, j] + min(best(*s) for s in steps)

    return best(0, 0)


# --------------------------------------------------------------------------- known answers


def test_unique_path_hand_computed():
    # |x_i - y_j|:  [[0, 3], [1, 2], [2, 1], [3, 0]]: the first half of x goes to y[0].
    x, y = _col(0, 1, 2, 3), _col(0, 3)
    result = dtw(x, y)
    assert result.cost == 2.0
    assert result.path.tolist() == [[0, 0], [1, 0], [2, 1], [3, 1]]
    assert result.path.dtype == np.int64
    np.testing.assert_array_equal(warp_onto(y, result.path, 4), _col(0, 0, 3, 3))
    np.testing.assert_array_equal(warp_indices(4, result.path), [0, 0, 1, 1])
    assert audio_cost(x, y) == (0 + 1 + 1 + 0) / 4


def test_many_to_one_frames_are_averaged():
    # y[0] and y[1] both match x[0]; L averages them (Eq. 5's warp, documented choice).
    x, y = _col(0, 10), _col(0, 1, 9, 11)
    result = dtw(x, y)
    assert result.cost == 3.0
    assert result.path.tolist() == [[0, 0], [0, 1], [1, 2], [1, 3]]
    np.testing.assert_array_equal(warp_onto(y, result.path, 2), _col(0.5, 10))
    np.testing.assert_array_equal(warp_indices(2, result.path), [0.5, 2.5])
    assert audio_cost(x, y) == (0.5 + 0.0) / 2


def test_identical_sequences_give_the_diagonal(rng):
    x = rng.standard_normal((7, 9))
    result = dtw(x, x)
    assert result.cost == 0.0
    np.testing.assert_array_equal(result.path, np.repeat(np.arange(7)[:, None], 2, axis=1))
    assert audio_cost(x, x) == 0.0
    np.testing.assert_array_equal(warp_indices(7, result.path), np.arange(7))


@pytest.mark.parametrize("repeats", [[2, 1, 2, 2, 1, 1], [1, 3, 1, 4, 2, 1]])
def test_time_stretched_copy_is_recovered(rng, repeats):
    # Dyadic values, so means of repeated frames are exact whatever the count.
    x = rng.integers(-64, 64, size=(6, 9)) / 8.0
    y = np.repeat(x, repeats, axis=0)
    result = dtw(x, y)
    assert result.cost == 0.0
    np.testing.assert_array_equal(warp_onto(y, result.path, len(x)), x)
    assert audio_cost(x, y) == 0.0
    # and the other way round: x is y slowed down, each frame of y shown once per copy
    back = dtw(y, x)
    assert back.cost == 0.0
    np.testing.assert_array_equal(warp_onto(x, back.path, len(y)), y)
    starts = np.concatenate([[0], np.cumsum(repeats)[:-1]])
    idx = warp_indices(len(y), back.path)
    np.testing.assert_array_equal(idx[starts], np.arange(len(x)))


def test_one_frame_against_forty(rng):
    one, forty = rng.standard_normal((1, 9)), rng.standard_normal((40, 9))
    result = dtw(one, forty)
    assert result.path.tolist() == [[0, j] for j in range(40)]
    np.testing.assert_allclose(result.cost, np.linalg.norm(forty - one, axis=1).sum())
    np.testing.assert_allclose(warp_onto(forty, result.path, 1), forty.mean(0, keepdims=True))
    np.testing.assert_allclose(audio_cost(one, forty), np.linalg.norm(one[0] - forty.mean(0)))
    np.testing.assert_array_equal(warp_indices(1, result.path), [19.5])
    # a 40-frame input against a 1-frame anime: the anime frame is repeated
    back = dtw(forty, one)
    assert back.path.tolist() == [[i, 0] for i in range(40)]
    np.testing.assert_array_equal(warp_onto(one, back.path, 40), np.repeat(one, 40, axis=0))
    np.testing.assert_allclose(audio_cost(forty, one), np.linalg.norm(forty - one, axis=1).mean())
    np.testing.assert_array_equal(warp_indices(40, back.path), np.zeros(40))


def test_one_frame_each():
    result = dtw([[3.0, 4.0]], [[0.0, 0.0]])
    assert result.cost == 5.0 and result.path.tolist() == [[0, 0]]
    assert dtw([[3.0, 4.0]], [[0.0, 0.0]], metric="sqeuclidean").cost == 25.0


def test_band_zero_on_equal_lengths_forces_the_diagonal():
    x, y = _col(0, 0, 5, 5), _col(0, 5, 5, 5)
    assert dtw(x, y).cost == 0.0
    banded = dtw(x, y, band=0)
    np.testing.assert_array_equal(banded.path, [[0, 0], [1, 1], [2, 2], [3, 3]])
    assert banded.cost == 5.0
    assert audio_cost(x, y, band=0) == 5.0 / 4


def test_matches_exhaustive_search(rng):
    for n, m in itertools.product(range(1, 5), repeat=2):
        x, y = rng.standard_normal((n, 2)), rng.standard_normal((m, 2))
        for metric, sq in (("euclidean", False), ("sqeuclidean", True)):
            assert dtw(x, y, metric=metric).cost == pytest.approx(_brute_force(x, y, sq),
                                                                  rel=1e-12)


# --------------------------------------------------------------------------- references


def _random_pairs(rng, count: int):
    for t in range(count):
        n, m = rng.integers(1, 41, size=2)
        d = 9 if t % 3 else 1
        yield rng.standard_normal((n, d)), rng.standard_normal((m, d))


def _tslearn_path(acc: np.ndarray) -> np.ndarray | None:
    """tslearn's own backtracking, run as plain Python (compiling it takes ~7 s)."""
    try:
        from tslearn.metrics.utils import _njit_compute_path
    except ImportError:  # private; moved in another tslearn version
        return None
    return np.asarray(_njit_compute_path.py_func(acc))


def test_sqeuclidean_matches_tslearn_on_200_pairs(rng):
    # tslearn.metrics.dtw(x, y) is sqrt(accumulated squared distance); its accumulated
    # matrix (public, and quick to compile unlike dtw/dtw_path) gives the cost itself.
    from tslearn.metrics import dtw_accumulated_matrix

    for x, y in _random_pairs(rng, 200):
        acc = dtw_accumulated_matrix(x, y, np.ones((len(x), len(y)), bool), be="numpy")
        result = dtw(x, y, metric="sqeuclidean")
        assert result.cost == pytest.approx(acc[-1, -1], rel=1e-9, abs=1e-12)
        ref_path = _tslearn_path(acc)
        if ref_path is not None:
            np.testing.assert_array_equal(result.path, ref_path)  # same tie order


def test_band_matches_tslearn_sakoe_chiba(rng):
    from tslearn.metrics import dtw_accumulated_matrix, sakoe_chiba_mask

    for t, (x, y) in enumerate(_random_pairs(rng, 60)):
        band = t % 4
        mask = sakoe_chiba_mask(len(x), len(y), radius=band)
        acc = dtw_accumulated_matrix(x, y, mask, be="numpy")
        result = dtw(x, y, band=band, metric="sqeuclidean")
        assert result.cost == pytest.approx(acc[-1, -1], rel=1e-9, abs=1e-12)
        assert mask[result.path[:, 0], result.path[:, 1]].all()
        ref_path = _tslearn_path(acc)
        if ref_path is not None:
            np.testing.assert_array_equal(result.path, ref_path)


def test_euclidean_matches_librosa(rng):
    import librosa

    for x, y in _random_pairs(rng, 60):
        acc, wp = librosa.sequence.dtw(x.T, y.T, metric="euclidean")
        result = dtw(x, y)
        assert result.cost == pytest.approx(acc[-1, -1], rel=1e-9, abs=1e-9)
        # librosa breaks ties the other way: compare the cost along its path instead
        ref = wp[::-1]
        along = np.linalg.norm(x[ref[:, 0]] - y[ref[:, 1]], axis=1).sum()
        assert result.cost == pytest.approx(along, rel=1e-9, abs=1e-9)


def test_path_is_a_valid_warp_and_costs_what_it_says(rng):
    for x, y in _random_pairs(rng, 50):
        result = dtw(x, y)
        path = result.path
        assert path[0].tolist() == [0, 0] and path[-1].tolist() == [len(x) - 1, len(y) - 1]
        steps = {tuple(s) for s in np.diff(path, axis=0).tolist()}
        assert steps <= {(1, 0), (0, 1), (1, 1)}
        along = np.linalg.norm(x[path[:, 0]] - y[path[:, 1]], axis=1).sum()
        assert result.cost == pytest.approx(along, rel=1e-12)


def test_audio_cost_is_eq5_on_the_warped_curve(rng):
    for x, y in _random_pairs(rng, 50):
        warped = warp_onto(y, dtw(x, y).path, len(x))
        expected = np.linalg.norm(x - warped, axis=1).mean()
        assert audio_cost(x, y) == pytest.approx(expected, rel=1e-12)


# --------------------------------------------------------------------------- many nodes


def _graph_like(rng, n_nodes: int):
    curves = [rng.standard_normal((int(k), 9)).astype(np.float32)
              for k in rng.integers(1, 41, size=n_nodes)]
    values, offsets = _ragged(curves)
    return curves, values, offsets


@pytest.mark.parametrize("parallel", [False, True])
def test_audio_costs_equal_a_loop_of_audio_cost(rng, monkeypatch, parallel):
    monkeypatch.setattr(dtw_module, "_PARALLEL_MIN_NODES", 1 if parallel else 10**9)
    curves, values, offsets = _graph_like(rng, 300)
    nodes = rng.permutation(300)[:250]
    for c_input in (rng.standard_normal((12, 9)).astype(np.float32),
                    rng.standard_normal((1, 9)), rng.standard_normal((30, 9))):
        costs = audio_costs(c_input, values, offsets, nodes)
        assert costs.dtype == np.float64 and costs.shape == (250,)
        expected = [audio_cost(c_input, curves[a]) for a in nodes]
        np.testing.assert_array_equal(costs, expected)  # bit for bit


def _one_cost(x, curve):
    return audio_cost(x, curve)


def _one_warp(x, curve):
    return warp_indices(len(x), dtw(x, curve).path)


@pytest.mark.parametrize("parallel", [False, True])
@pytest.mark.parametrize("many_of, one, shape", [
    (audio_costs_many, _one_cost, lambda k, n: (k,)),
    (warp_indices_many, _one_warp, lambda k, n: (k, n)),
])
def test_pairs_of_an_utterance_equal_one_call_per_pair(rng, monkeypatch, parallel, many_of,
                                                       one, shape):
    # Eq. 5's costs and §4.3's warps of every (input phone, candidate) pair in one call.
    monkeypatch.setattr(dtw_module, "_PARALLEL_MIN_NODES", 1 if parallel else 10**9)
    curves, values, offsets = _graph_like(rng, 200)
    inputs = [rng.standard_normal((k, 9)) for k in (12, 1, 30, 5)]
    lists = [rng.permutation(200)[:k] for k in (150, 0, 7, 200)]
    many = many_of(inputs, values, offsets, lists)
    assert [m.shape for m in many] == [shape(len(n), len(x)) for x, n in zip(inputs, lists,
                                                                           strict=True)]
    for x, nodes, got in zip(inputs, lists, many, strict=True):
        for a, value in zip(nodes, got, strict=True):  # bit for bit
            np.testing.assert_array_equal(value, one(x, curves[a]))
    assert many_of([], values, offsets, []) == []
    with pytest.raises(ParameterError, match="one node list per input"):
        many_of(inputs, values, offsets, lists[:2])
    with pytest.raises(ParameterError, match=r"c_inputs\[1\]"):
        many_of([inputs[0], np.full((3, 9), np.nan)], values, offsets, lists[:2])
    with pytest.raises(ParameterError, match="nodes must be in"):
        many_of(inputs[:1], values, offsets, [np.array([200])])


def _parallel_costs(values, offsets, inputs, lists):
    return [c.tolist() for c in audio_costs_many(inputs, values, offsets, lists)]


def test_the_kept_pool_gives_the_serial_costs_and_survives_fork(rng, monkeypatch):
    # One pool of threads, kept from call to call (not started on each), gives the costs
    # of a serial run bit for bit, and a forked child (which has none of the parent's
    # threads) makes a pool of its own instead of waiting for ever on the parent's.
    import numba

    from ingest.workers import in_forked_child

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("numba has one thread here: the pool is never used")
    monkeypatch.setattr(dtw_module, "_PARALLEL_MIN_NODES", 1)
    numba.set_num_threads(2)
    curves, values, offsets = _graph_like(rng, 120)
    inputs = [rng.standard_normal((k, 9)) for k in (12, 30, 5)]
    lists = [rng.permutation(120)[:k] for k in (100, 60, 120)]
    serial = [[audio_cost(x, curves[a]) for a in nodes]
              for x, nodes in zip(inputs, lists, strict=True)]
    assert _parallel_costs(values, offsets, inputs, lists) == serial
    pool = threads_module._POOLS[2]
    assert _parallel_costs(values, offsets, inputs, lists) == serial
    assert threads_module._POOLS[2] is pool  # kept, not started again
    child = in_forked_child(lambda: (
        _parallel_costs(values, offsets, inputs, lists),
        2 in threads_module._POOLS and threads_module._POOLS[2] is not pool))
    assert child == [serial, True]
    assert _parallel_costs(values, offsets, inputs, lists) == serial  # the parent's still works


def test_a_marked_array_is_not_scanned_again_and_others_still_are(rng, monkeypatch):
    # A graph's curves, checked once when loaded (mark_finite), are not scanned for NaN on
    # every call; an unmarked array, or a marked one made writeable again, still is.
    curves, values, offsets = _graph_like(rng, 30)
    x, nodes = rng.standard_normal((6, 9)), np.arange(30)
    expected = audio_costs(x, values, offsets, nodes)
    scans = []
    real = dtw_module._first_nonfinite
    monkeypatch.setattr(dtw_module, "_first_nonfinite",
                        lambda *a: scans.append(1) or real(*a))
    mark_finite(values)
    assert not values.flags.writeable
    np.testing.assert_array_equal(audio_costs(x, values, offsets, nodes), expected)
    assert scans == []
    audio_costs(x, values.copy(), offsets, nodes)  # an equal array, not the one checked
    assert scans == [1]
    bad = values.copy()
    bad[offsets[3]] = np.nan
    with pytest.raises(ParameterError, match="NaN or inf"):
        mark_finite(bad)
    assert bad.flags.writeable  # refused, not marked
    with pytest.raises(ParameterError, match="NaN or inf in node 3"):
        audio_costs(x, bad, offsets, nodes)
    values.flags.writeable = True  # writeable again: checked again
    values[offsets[5]] = np.inf
    with pytest.raises(ParameterError, match="NaN or inf in node 5"):
        audio_costs(x, values, offsets, nodes)
    base = np.zeros((8, 9))
    view = base[2:6]
    mark_finite(view)  # the array it views made read-only too
    assert dtw_module._known_finite(view) and not base.flags.writeable
    base.flags.writeable = True  # the array viewed writeable again: checked again
    assert not dtw_module._known_finite(view)


def test_audio_costs_float64_values_and_band(rng):
    curves, values, offsets = _graph_like(rng, 40)
    c_input = rng.standard_normal((8, 9))
    nodes = np.arange(40)
    np.testing.assert_array_equal(
        audio_costs(c_input, values.astype(np.float64), offsets, nodes),
        audio_costs(c_input, values, offsets, nodes))
    np.testing.assert_array_equal(
        audio_costs(c_input, values, offsets, nodes, band=1),
        [audio_cost(c_input, c, band=1) for c in curves])


def test_audio_costs_of_no_nodes_is_empty(rng):
    _, values, offsets = _graph_like(rng, 3)
    out = audio_costs(rng.standard_normal((4, 9)), values, offsets, np.array([], np.int64))
    assert out.shape == (0,) and out.dtype == np.float64


def test_warp_indices_monotone_within_range(rng):
    for x, y in _random_pairs(rng, 50):
        idx = warp_indices(len(x), dtw(x, y).path)
        assert idx.shape == (len(x),) and idx.dtype == np.float64
        assert np.all(np.diff(idx) >= 0)
        assert idx[0] >= 0 and idx[-1] <= len(y) - 1


def test_warp_indices_span_when_the_ends_match_one_to_one():
    path = np.array([[0, 0], [1, 1], [1, 2], [2, 3], [3, 3], [4, 4]])
    np.testing.assert_array_equal(warp_indices(5, path), [0, 1.5, 3, 3, 4])


def test_kernels_compile_without_a_cache_folder(monkeypatch):
    # numba raises RuntimeError ("no locator available") when no cache folder is writable.
    import numba

    real_njit = numba.njit

    def njit(**options):
        if options.get("cache"):
            raise RuntimeError("cannot cache function 'twice': no locator available")
        return real_njit(**options)

    monkeypatch.setattr(dtw_module.numba, "njit", njit)

    def twice(a):
        return 2 * a

    assert dtw_module._jit()(twice)(21) == 42


# --------------------------------------------------------------------------- errors


@pytest.mark.parametrize("bad, match", [
    (np.zeros((0, 9)), "x must not be empty"),
    (np.zeros((3, 0)), "x must not be empty"),
    (np.zeros(9), r"x must be a \(n_frames, n_features\) array, got shape \(9,\)"),
    (np.zeros((2, 3, 9)), "got shape"),
    (np.array([[0.0, np.nan]]), "x must be finite, got nan in frame 0"),
    (np.array([[0.0], [np.inf]]), "x must be finite, got inf in frame 1"),
    (np.array([["a"]]), "x must hold real numbers"),
    ([[1.0, 2.0], [3.0]], "x must be a"),
])
def test_bad_curves(bad, match):
    with pytest.raises(ParameterError, match=match):
        dtw(bad, np.zeros((2, 1)))


def test_bad_options_and_mismatches():
    x, y = np.zeros((3, 9)), np.zeros((4, 9))
    with pytest.raises(ParameterError, match="y must have 9 features like x, got 8"):
        dtw(x, np.zeros((4, 8)))
    with pytest.raises(ParameterError, match="c_anime must have 9 features like c_input, got 2"):
        audio_cost(x, np.zeros((4, 2)))
    with pytest.raises(ParameterError, match="c_anime must be finite"):
        audio_cost(x, np.full((4, 9), np.nan))
    with pytest.raises(ParameterError, match="c_input must not be empty"):
        audio_cost(np.zeros((0, 9)), y)
    for band in (-1, 1.5, True, "2"):
        with pytest.raises(ParameterError, match=f"band must be None or a non-negative "
                                                 f"integer, got {band!r}"):
            dtw(x, y, band=band)
    with pytest.raises(ParameterError, match="metric must be 'euclidean' or 'sqeuclidean', "
                                             "got 'cosine'"):
        dtw(x, y, metric="cosine")


def test_bad_ragged_arguments(rng):
    _, values, offsets = _graph_like(rng, 5)
    c = rng.standard_normal((4, 9))
    nodes = np.arange(5)
    with pytest.raises(ParameterError, match=r"nodes must be in \[0, 5\), got 5 at index 1"):
        audio_costs(c, values, offsets, np.array([0, 5]))
    with pytest.raises(ParameterError, match="nodes must be in"):
        audio_costs(c, values, offsets, np.array([-1]))
    with pytest.raises(ParameterError, match="nodes must be a 1-D integer array"):
        audio_costs(c, values, offsets, nodes.astype(float))
    with pytest.raises(ParameterError, match="offsets must be a 1-D integer array"):
        audio_costs(c, values, offsets[:, None], nodes)
    with pytest.raises(ParameterError, match="offsets must have n_nodes"):
        audio_costs(c, values, offsets[:1], np.array([], np.int64))
    empty = offsets.copy()
    empty[3] = empty[2]
    with pytest.raises(ParameterError, match="offsets must give node 2 a curve"):
        audio_costs(c, values, empty, nodes)
    beyond = offsets.copy()
    beyond[-1] += 1
    with pytest.raises(ParameterError, match="offsets must give node 4 a curve within "
                                             f"values' {len(values)} frames"):
        audio_costs(c, values, beyond, nodes)
    with pytest.raises(ParameterError, match="values must have 9 features like c_input"):
        audio_costs(c, values[:, :4], offsets, nodes)
    with pytest.raises(ParameterError, match="values must be a"):
        audio_costs(c, values.ravel(), offsets, nodes)
    poisoned = values.copy()
    poisoned[offsets[3] + 0] = np.nan
    with pytest.raises(ParameterError, match="values must be finite, got NaN or inf in node 3"):
        audio_costs(c, poisoned, offsets, nodes)
    # a non-finite frame outside the nodes asked for is not looked at
    assert np.isfinite(audio_costs(c, poisoned, offsets, np.array([0, 4]))).all()


def test_bad_paths():
    y = np.zeros((3, 2))
    good = np.array([[0, 0], [1, 1], [1, 2]])
    assert warp_onto(y, good, 2).shape == (2, 2)
    with pytest.raises(ParameterError, match=r"path must run from \(0, 0\) to \(2, 2\)"):
        warp_onto(y, good, 3)
    with pytest.raises(ParameterError, match=r"path must run from \(0, 0\) to \(1, 2\)"):
        warp_onto(y, good[1:], 2)
    with pytest.raises(ParameterError, match=r"path must move by .*got \(0, 0\) -> \(1, 2\)"):
        warp_onto(y, good[[0, 2]], 2)
    with pytest.raises(ParameterError, match="path must move by"):
        warp_indices(2, np.array([[0, 0], [1, 1], [1, 1], [1, 2]]))
    with pytest.raises(ParameterError, match="path must be a non-empty"):
        warp_indices(2, good.astype(float))
    with pytest.raises(ParameterError, match="path must be a non-empty"):
        warp_indices(2, np.zeros((0, 2), np.int64))
    with pytest.raises(ParameterError, match="n must be a positive integer, got 0"):
        warp_onto(y, good, 0)
    with pytest.raises(ParameterError, match="n_out must be a positive integer, got 2.0"):
        warp_indices(2.0, good)
