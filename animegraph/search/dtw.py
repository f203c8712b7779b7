"""Dynamic time warping of prosody curves (Cao et al. 2005, §4.2 Eq. 5 and §4.3).

The search scores each candidate anime node by how well its prosody curve C (RASTA-PLP,
one 9-vector per 10 ms frame) matches the input phone's curve once warped onto it
(Eq. 5)::

    C_audio = (1/n) * sum_k || C_input(k) - L(C_anime)(k) ||,    k = 1..n

where ``n`` is the number of input frames (the paper's ``m``), ``||.||`` the Euclidean norm
and ``L`` the DTW operator warping the anime's curve onto the input's timeline.
Post-processing (§4.3) reuses the same alignment to time-warp each anime's motion onto the
input phone.

Conventions
-----------
* Curves are ``(n_frames, n_features)``; ``x`` (the input, n frames) is the reference
  timeline and ``y`` (the anime, m frames) is warped onto it.
* Local cost: Euclidean distance between frames (``metric="euclidean"``, the ``||.||`` of
  Eq. 5). For posteriorgrams the Eq. 5 functions also take ``metric="neglog-dot"``,
  ``-log(x . y)`` (:data:`AUDIO_METRICS`; with it ``L``'s mean of posterior vectors is
  again a posterior vector). ``metric="sqeuclidean"`` (squared distance) is offered for
  :func:`dtw` only; it is tslearn's convention (``tslearn.metrics.dtw`` returns the
  square root of that accumulated cost).
* Steps (1, 0), (0, 1), (1, 1), all with weight 1; the path runs from (0, 0) to
  (n-1, m-1). Ties while backtracking go to the diagonal, then to (i-1, j), then to
  (i, j-1) (tslearn's order), so paths agree with tslearn's.
* ``L``: where several anime frames are matched to one input frame, ``L`` takes their
  mean (where one anime frame is matched to several input frames it is repeated). The
  mean keeps every matched frame's contribution and is what :func:`warp_onto` returns.
* ``band``: a Sakoe-Chiba radius with tslearn's meaning (``global_constraint=
  "sakoe_chiba"``): around the diagonal, widened by ``|n - m|`` so that the corner is
  always reachable. ``None`` (the default, and the paper's setting) leaves the warp free.

The kernels are compiled with numba on first use (about 3 s per kernel) and cached on
disk in the room's kernel cache (:mod:`animegraph.search.jit`: keyed by the kernels'
sources); with no writable place they are compiled in every process, silently. They
assume valid input: every public function validates its arguments first.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numba
import numpy as np

from animegraph.search.dtw_args import band_radius as _band
from animegraph.search.dtw_args import count as _count
from animegraph.search.dtw_args import curve_array as _curve
from animegraph.search.dtw_args import int_vector as _int_vector
from animegraph.search.dtw_args import known_finite as _known_finite
from animegraph.search.dtw_args import mark_finite
from animegraph.search.dtw_args import path_array as _path
from animegraph.search.dtw_args import same_width as _same_width
from animegraph.search.dtw_args import values_array as _values
from animegraph.search.jit import kernel
from animegraph.search.threads import in_chunks
from db.errors import ParameterError

__all__ = ["AUDIO_METRICS", "DTWResult", "audio_cost", "audio_costs", "audio_costs_many", "dtw",
           "mark_finite", "warp_indices", "warp_indices_many", "warp_onto"]

_METRICS = {"euclidean": 0, "sqeuclidean": 1}
#: Local distances of Eq. 5's audio cost: the paper's Euclidean norm between RASTA-PLP
#: frames, or (beyond the paper) -log of the inner product of two posterior vectors, the
#: distance of posteriorgram DTW (Hazen, Shen & White 2009, "Query-by-example spoken term
#: detection using phonetic posteriorgram templates", ASRU; Zhang & Glass 2009, ASRU).
AUDIO_METRICS = {"euclidean": 0, "neglog-dot": 2}
#: Inner products below this count as this (-log: at most 23 nats), so that two
#: posteriorgram frames with no phone in common still have a finite distance.
_DOT_FLOOR = 1e-10

#: ``audio_costs_many`` runs in parallel (threads) from this many nodes on, when numba
#: has more than one thread (``numba.get_num_threads()``, which ingest's workers divide).
#: On 2 cores parallel broke even at ~10 nodes and was 1.6-1.8x faster from ~50 on
#: (``scripts/bench_dtw.py``); the margin keeps tiny batches serial.
#: (Pairs: an utterance's phones x candidates.)
_PARALLEL_MIN_NODES = 64


#: The room's cached kernel decorator (:mod:`animegraph.search.jit`).
_jit = kernel


# --------------------------------------------------------------------------- kernels
# Private: valid input assumed (finite, non-empty, matching widths, band >= 0 or -1).
# Layout: the input x is passed transposed, ``xt`` of shape (d, n), and the accumulated
# cost is stored as ``acc[j, i]`` (one row per frame j of y): the n local costs of a
# frame of y are then computed with unit-stride inner loops that vectorise, and the
# recurrence runs down contiguous rows. About 1.5x faster than the (i, j) layout.


@_jit()
def _band_limits(n, m, band, i):
    """First and last j of row i of an (n, m) grid inside tslearn's Sakoe-Chiba band."""
    if band < 0:
        return 0, m - 1
    if n <= m:
        lo = i - band
        hi = i + (m - n) + band
    else:
        lo = i - (n - m) - band
        hi = i + band
    return max(lo, 0), min(hi, m - 1)


@_jit()
def _accumulate(xt, y, band, metric, acc, c):
    """Fill ``acc[:m, :n]``: acc[j, i] is the least cost of aligning x[:i+1] with y[:j+1].

    ``c`` (n,) is workspace for one frame's local costs.
    """
    # The constant -1 lets LLVM specialise the unconstrained case (2-3x faster than
    # passing a run-time band through).
    if band < 0:
        _accumulate_band(xt, y, -1, metric, acc, c)
    else:
        _accumulate_band(xt, y, band, metric, acc, c)


@_jit()
def _accumulate_band(xt, y, band, metric, acc, c):
    d, n = xt.shape
    m = y.shape[0]
    for j in range(m):
        lo, hi = _band_limits(m, n, band, j)
        for i in range(lo, hi + 1):
            c[i] = 0.0
        if metric == 2:  # -log of the inner product (posteriorgrams)
            for k in range(d):
                yk = np.float64(y[j, k])
                for i in range(lo, hi + 1):
                    c[i] += xt[k, i] * yk
            for i in range(lo, hi + 1):
                c[i] = -np.log(max(c[i], _DOT_FLOOR))
        else:
            for k in range(d):
                yk = np.float64(y[j, k])
                for i in range(lo, hi + 1):
                    diff = xt[k, i] - yk
                    c[i] += diff * diff
        if metric == 0:
            for i in range(lo, hi + 1):
                c[i] = np.sqrt(c[i])
        for i in range(lo):
            acc[j, i] = np.inf
        for i in range(hi + 1, n):
            acc[j, i] = np.inf
        if j == 0:  # lo == 0: only steps along x
            run = 0.0
            for i in range(hi + 1):
                run += c[i]
                acc[0, i] = run
            continue
        up = np.inf  # acc[j, i - 1]
        start = lo
        if lo == 0:
            up = acc[j - 1, 0] + c[0]
            acc[j, 0] = up
            start = 1
        for i in range(start, hi + 1):
            up = c[i] + min(min(acc[j - 1, i - 1], acc[j - 1, i]), up)
            acc[j, i] = up


@_jit()
def _step_back(acc, i, j):
    """Predecessor of (i, j) on the optimal path: diagonal, then (i-1, j), then (i, j-1)."""
    if i == 0:
        return 0, j - 1
    if j == 0:
        return i - 1, 0
    diag = acc[j - 1, i - 1]
    up = acc[j, i - 1]
    left = acc[j - 1, i]
    if diag <= up and diag <= left:
        return i - 1, j - 1
    if up <= left:
        return i - 1, j
    return i, j - 1


@_jit()
def _dtw_path(xt, y, band, metric):
    """Accumulated cost and optimal path, (L, 2) int64 from (0, 0) to (n-1, m-1)."""
    n = xt.shape[1]
    m = y.shape[0]
    acc = np.empty((m, n))
    _accumulate(xt, y, band, metric, acc, np.empty(n))
    path = np.empty((n + m - 1, 2), dtype=np.int64)
    k = n + m - 2
    i = n - 1
    j = m - 1
    path[k, 0] = i
    path[k, 1] = j
    while i > 0 or j > 0:
        i, j = _step_back(acc, i, j)
        k -= 1
        path[k, 0] = i
        path[k, 1] = j
    return acc[m - 1, n - 1], path[k:].copy()


@_jit()
def _row_error(xt, i, total, count, metric):
    """One term of Eq. 5: || x[i] - total / count ||, or with ``metric`` 2
    -log(x[i] . total / count)."""
    s = 0.0
    if metric == 2:
        for k in range(xt.shape[0]):
            s += xt[k, i] * total[k] / count
        return -np.log(max(s, _DOT_FLOOR))
    for k in range(xt.shape[0]):
        diff = xt[k, i] - total[k] / count
        s += diff * diff
    return np.sqrt(s)


@_jit()
def _audio_cost_one(xt, y, band, metric, acc, c, total):
    """Eq. 5 for one anime curve ``y``; ``acc`` (>= m, n), ``c`` (n,), ``total`` (d,) are
    workspace; ``metric`` 0 (Euclidean) or 2 (-log inner product).

    Backtracks the optimal path from (n-1, m-1) and, since the cells of one input frame
    i are consecutive on it, averages their anime frames on the fly: no path is kept.
    """
    d, n = xt.shape
    m = y.shape[0]
    _accumulate(xt, y, band, metric, acc, c)
    for k in range(d):
        total[k] = 0.0
    count = 0
    cost = 0.0
    i = n - 1
    j = m - 1
    while True:
        for k in range(d):
            total[k] += y[j, k]
        count += 1
        if i == 0 and j == 0:
            break
        pi, pj = _step_back(acc, i, j)
        if pi != i:
            cost += _row_error(xt, i, total, count, metric)
            for k in range(d):
                total[k] = 0.0
            count = 0
        i = pi
        j = pj
    cost += _row_error(xt, 0, total, count, metric)
    return cost / n


@_jit()
def _warp_one(xt, y, band, acc, c, out):
    """The mean frame j of ``y`` matched to each frame i of x on the optimal path of
    Euclidean DTW, into ``out[:n]`` (:func:`warp_indices` of :func:`dtw`'s path);
    ``acc`` (>= m, n) and ``c`` (n,) are workspace."""
    n = xt.shape[1]
    m = y.shape[0]
    _accumulate(xt, y, band, 0, acc, c)
    total = 0.0
    count = 0
    i = n - 1
    j = m - 1
    while True:
        total += j
        count += 1
        if i == 0 and j == 0:
            break
        pi, pj = _step_back(acc, i, j)
        if pi != i:
            out[i] = total / count
            total = 0.0
            count = 0
        i = pi
        j = pj
    out[0] = total / count


@_jit()
def _pairs_range(xs, x_off, values, offsets, inputs, nodes, max_len, band, metric, lo, hi,
                 out, warps):
    """Pairs [lo, hi): input ``inputs[t]`` (columns ``x_off[k]:x_off[k+1]`` of ``xs``,
    shape (d, total input frames)) against node ``nodes[t]``. With ``metric`` >= 0,
    Eq. 5 into ``out[t]``; with -1, the warp (:func:`_warp_one`) into ``warps[t]``'s
    first n_k entries.

    Pairs of one input are expected together: its workspace is made once per run of them.
    """
    d = xs.shape[0]
    total = np.empty(d)
    current = -1
    xt = np.empty((d, 1))
    acc = np.empty((1, 1))
    c = np.empty(1)
    for t in range(lo, hi):
        k = inputs[t]
        if k != current:
            xt = np.ascontiguousarray(xs[:, x_off[k]:x_off[k + 1]])
            acc = np.empty((max_len, xt.shape[1]))
            c = np.empty(xt.shape[1])
            current = k
        a = nodes[t]
        y = values[offsets[a]:offsets[a + 1]]
        if metric < 0:
            _warp_one(xt, y, band, acc, c, warps[t])
        else:
            out[t] = _audio_cost_one(xt, y, band, metric, acc, c, total)


@_jit()
def _first_nonfinite(values, offsets, nodes):
    """Index into ``nodes`` of the first node whose curve is not finite, else -1."""
    for t in range(nodes.shape[0]):
        a = nodes[t]
        for r in range(offsets[a], offsets[a + 1]):
            for k in range(values.shape[1]):
                if not np.isfinite(values[r, k]):
                    return t
    return -1


# --------------------------------------------------------------------------- public API


@dataclass(frozen=True, eq=False)
class DTWResult:
    """An optimal alignment of two curves.

    Attributes
    ----------
    cost : float
        Accumulated local cost along ``path`` (Euclidean distances by default, see
        :func:`dtw`'s ``metric``).
    path : np.ndarray of int64, shape (L, 2)
        Pairs (i, j) of aligned frames of x and y, from (0, 0) to (n-1, m-1), each step
        (1, 0), (0, 1) or (1, 1); ``max(n, m) <= L <= n + m - 1``.
    """

    cost: float
    path: np.ndarray


def dtw(x: np.ndarray, y: np.ndarray, *, band: int | None = None,
        metric: str = "euclidean") -> DTWResult:
    """Dynamic time warping of ``y`` onto ``x`` (Cao et al. 2005 §4.2 Eq. 5, §4.3).

    Parameters
    ----------
    x : np.ndarray, shape (n, d)
        The reference curve (the input phone's prosody C_input).
    y : np.ndarray, shape (m, d)
        The curve to warp (an anime's prosody C_anime).
    band : int or None, optional
        Sakoe-Chiba radius (tslearn's ``sakoe_chiba_radius``): frame i of x may only
        match frames j of y with ``i - band <= j <= i + (m - n) + band`` when n <= m
        (symmetrically when n > m). None: no constraint.
    metric : {"euclidean", "sqeuclidean"}, optional
        Local cost between frames: the Euclidean distance (Eq. 5's norm) or its square
        (tslearn's convention: ``tslearn.metrics.dtw(x, y) ** 2`` equals the cost).

    Returns
    -------
    DTWResult
        ``cost``: the minimal accumulated local cost; ``path``: an optimal path.

    Raises
    ------
    ParameterError
        ``x`` or ``y`` not a non-empty finite 2-D array, different numbers of features,
        bad ``band`` or ``metric``.
    """
    x = _curve("x", x, np.float64)
    y = _curve("y", y, np.float64)
    _same_width("y", y, "x", x)
    if metric not in _METRICS:
        raise ParameterError(f"metric must be 'euclidean' or 'sqeuclidean', got {metric!r}")
    cost, path = _dtw_path(np.ascontiguousarray(x.T), y, _band(band), _METRICS[metric])
    return DTWResult(cost=float(cost), path=path)


def warp_onto(y: np.ndarray, path: np.ndarray, n: int) -> np.ndarray:
    """The DTW operator L of Eq. 5: ``y``'s frames carried onto x's ``n`` frames.

    Output frame i is the mean of the frames y[j] matched to i along ``path`` (usually
    one; several when y is longer or slower there). Also warps any per-frame data that
    shares y's timeline, such as the anime's motion resampled to its prosody frames (§4.3).

    Parameters
    ----------
    y : np.ndarray, shape (m, d)
        The curve to warp.
    path : np.ndarray of int, shape (L, 2)
        An alignment from (0, 0) to (n-1, m-1), e.g. ``dtw(x, y).path``.
    n : int
        Number of frames of the reference curve x.

    Returns
    -------
    np.ndarray of float64, shape (n, d)

    Raises
    ------
    ParameterError
        ``y`` not a non-empty finite 2-D array, ``n`` not a positive integer, or ``path``
        not a monotone path of unit steps from (0, 0) to (n-1, m-1).
    """
    n = _count("n", n)
    y = _curve("y", y, np.float64)
    path = _path(path, n, len(y))
    starts = _row_starts(path)
    sums = np.add.reduceat(y[path[:, 1]], starts, axis=0)
    counts = np.diff(np.append(starts, len(path)))
    return sums / counts[:, None]


def warp_indices(n_out: int, path: np.ndarray) -> np.ndarray:
    """Fractional frame of y to show at each of x's ``n_out`` frames (§4.3 time-warping).

    Output frame i gets the mean of the frames j of y matched to it along ``path``:
    sampling y (e.g. an anime's motion on its prosody timeline) at these positions, by
    linear interpolation, plays it with the input phone's timing.

    Parameters
    ----------
    n_out : int
        Number of frames of the reference curve x (the input phone).
    path : np.ndarray of int, shape (L, 2)
        An alignment from (0, 0) to (n_out-1, m-1), e.g. ``dtw(x, y).path``.

    Returns
    -------
    np.ndarray of float64, shape (n_out,)
        Non-decreasing, within [0, m-1]; the first value is 0 and the last m-1 unless
        several frames of y are matched to the first or last frame of x.

    Raises
    ------
    ParameterError
        ``n_out`` not a positive integer or ``path`` not a monotone path of unit steps
        from (0, 0) to (n_out-1, m-1).
    """
    n_out = _count("n_out", n_out)
    path = _path(path, n_out, None)
    starts = _row_starts(path)
    sums = np.add.reduceat(path[:, 1].astype(np.float64), starts)
    return sums / np.diff(np.append(starts, len(path)))


def audio_cost(c_input: np.ndarray, c_anime: np.ndarray, *, band: int | None = None,
               metric: str = "euclidean") -> float:
    """Audio cost of Eq. 5 (Cao et al. 2005 §4.2) for one anime node.

    ``(1/n) * sum_k || c_input[k] - L(c_anime)[k] ||`` with L the DTW operator of
    :func:`warp_onto` (Euclidean local cost; frames of ``c_anime`` matched to one input
    frame are averaged).

    Parameters
    ----------
    c_input : np.ndarray, shape (n, d)
        The input phone's prosody curve.
    c_anime : np.ndarray, shape (m, d)
        The anime node's prosody curve.
    band : int or None, optional
        Sakoe-Chiba radius, as in :func:`dtw`.
    metric : {"euclidean", "neglog-dot"}, optional
        The local distance (:data:`AUDIO_METRICS`): Eq. 5's Euclidean norm, or
        ``-log(x . y)`` between posteriorgram frames (rows summing to 1).

    Returns
    -------
    float
        The mean local distance per input frame; equal to the matching entry of
        :func:`audio_costs`.

    Raises
    ------
    ParameterError
        A curve not a non-empty finite 2-D array, different numbers of features, bad
        ``band``.
    """
    x = _curve("c_input", c_input, np.float64)
    y = _curve("c_anime", c_anime, None)
    _same_width("c_anime", y, "c_input", x)
    out = np.empty(1)
    zero = np.zeros(1, dtype=np.int64)
    _pairs_range(np.ascontiguousarray(x.T), np.array([0, len(x)], dtype=np.int64), y,
                 np.array([0, len(y)], dtype=np.int64), zero, zero, len(y), _band(band),
                 _audio_metric(metric), 0, 1, out, np.empty((0, 0)))
    return float(out[0])


def audio_costs(c_input: np.ndarray, values: np.ndarray, offsets: np.ndarray,
                nodes: np.ndarray, *, band: int | None = None,
                metric: str = "euclidean") -> np.ndarray:
    """Audio cost of Eq. 5 (Cao et al. 2005 §4.2) for many anime nodes at once.

    Eq. 5 depends only on the input phone and the anime node, not on the rest of the
    sequence, so one call per input phone over its candidates (``graph.by_phone[p]``)
    serves the whole search; :func:`audio_costs_many` does every phone of an utterance
    in one call.

    Parameters
    ----------
    c_input : np.ndarray, shape (n, d)
        The input phone's prosody curve.
    values : np.ndarray of float32 or float64, shape (n_frames, d)
        Every node's curve, end to end
        (:attr:`animegraph.search.graph.AnimeGraph.prosody_values`).
    offsets : np.ndarray of int, shape (n_nodes + 1,)
        Node ``a``'s curve is ``values[offsets[a]:offsets[a + 1]]``.
    nodes : np.ndarray of int, shape (k,)
        The nodes to score (may be empty).
    band : int or None, optional
        Sakoe-Chiba radius, as in :func:`dtw`.

    Returns
    -------
    np.ndarray of float64, shape (k,)
        ``out[t] == audio_cost(c_input, values[offsets[a]:offsets[a + 1]])`` for
        ``a = nodes[t]``, exactly.

    Raises
    ------
    ParameterError
        As :func:`audio_costs_many`.
    """
    return audio_costs_many([c_input], values, offsets, [nodes], band=band, metric=metric)[0]


def audio_costs_many(c_inputs: Sequence[np.ndarray], values: np.ndarray, offsets: np.ndarray,
                     nodes: Sequence[np.ndarray], *, band: int | None = None,
                     metric: str = "euclidean") -> list[np.ndarray]:
    """Audio costs of Eq. 5 for every input phone against its candidate nodes.

    The search's hot path: one compiled loop over all (phone, node) pairs of an
    utterance, in parallel (threads) from ``_PARALLEL_MIN_NODES`` pairs on, with
    the curves in the graph's ragged layout. Only the curves of ``nodes`` are read (and
    checked for NaN/inf).

    Parameters
    ----------
    c_inputs : sequence of np.ndarray, each shape (n_i, d)
        The input phones' prosody curves.
    values : np.ndarray of float32 or float64, shape (n_frames, d)
        Every node's curve, end to end.
    offsets : np.ndarray of int, shape (n_nodes + 1,)
        Node ``a``'s curve is ``values[offsets[a]:offsets[a + 1]]``.
    nodes : sequence of np.ndarray of int, each shape (k_i,)
        ``nodes[i]``: the nodes to score against input ``i`` (may be empty).
    band : int or None, optional
        Sakoe-Chiba radius, as in :func:`dtw`.
    metric : {"euclidean", "neglog-dot"}, optional
        The local distance, as in :func:`audio_cost`.

    Returns
    -------
    list of np.ndarray of float64, shapes (k_i,)
        ``out[i][t] == audio_cost(c_inputs[i], curve of nodes[i][t])``, exactly.

    Raises
    ------
    ParameterError
        An input curve not a non-empty finite 2-D array; ``values``, ``offsets`` or
        ``nodes`` malformed; a node out of range, with an empty curve or with non-finite
        values; different numbers of features; bad ``band``; different numbers of inputs
        and node lists.
    """
    sizes, out, _ = _run_pairs(c_inputs, values, offsets, nodes, band, _audio_metric(metric))
    return _split(out, sizes)


def warp_indices_many(c_inputs: Sequence[np.ndarray], values: np.ndarray, offsets: np.ndarray,
                      nodes: Sequence[np.ndarray], *, band: int | None = None
                      ) -> list[np.ndarray]:
    """§4.3's time-warps of every input phone's candidate nodes at once.

    :func:`warp_indices` of :func:`dtw`'s path for each (input curve, node curve) pair, in
    one compiled loop over an utterance's pairs as :func:`audio_costs_many` scores them
    (k-best averages several animes per phone, each warped onto it).

    Parameters
    ----------
    c_inputs : sequence of np.ndarray, each shape (n_i, d)
        The input phones' prosody curves.
    values, offsets, band
        As :func:`audio_costs_many`.
    nodes : sequence of np.ndarray of int, each shape (k_i,)
        ``nodes[i]``: the nodes to warp onto input ``i`` (may be empty).

    Returns
    -------
    list of np.ndarray of float64, shapes (k_i, n_i)
        Row t of ``out[i]`` equals ``warp_indices(n_i, dtw(c_inputs[i], curve of
        nodes[i][t]).path)``, exactly.

    Raises
    ------
    ParameterError
        As :func:`audio_costs_many`.
    """
    sizes, _, warps = _run_pairs(c_inputs, values, offsets, nodes, band, -1)
    return [w[:, :len(c)] for w, c in zip(_split(warps, sizes), c_inputs, strict=True)]


def _run_pairs(c_inputs, values, offsets, nodes, band, code):
    """Checked arguments of the pair functions through the kernels: ``sizes`` (k_i per
    input), Eq. 5's costs (``code`` >= 0) or warps (``code`` -1, one row per pair)."""
    if len(c_inputs) != len(nodes):
        raise ParameterError(f"need one node list per input curve, got {len(nodes)} lists "
                             f"for {len(c_inputs)} curves")
    values = _values(values)
    band = _band(band)
    offsets = _int_vector("offsets", offsets)
    if len(offsets) < 2:
        raise ParameterError(f"offsets must have n_nodes + 1 >= 2 entries, got {len(offsets)}")
    xs, lists = [], []
    for i, (c_input, node_list) in enumerate(zip(c_inputs, nodes, strict=True)):
        x = _curve("c_input" if len(c_inputs) == 1 else f"c_inputs[{i}]", c_input, np.float64)
        _same_width("values", values, "c_input", x)
        xs.append(x)
        lists.append(_int_vector("nodes", node_list))
    sizes = np.array([len(n) for n in lists], dtype=np.int64)
    flat = np.concatenate(lists) if lists else np.empty(0, dtype=np.int64)
    out = np.empty(len(flat) if code >= 0 else 0)
    warps = np.zeros((len(flat), max((len(x) for x in xs), default=0)) if code < 0
                     else (0, 0))
    if len(flat):
        _check_nodes(values, offsets, flat)
        x_off = np.concatenate([[0], np.cumsum([len(x) for x in xs])]).astype(np.int64)
        xs_all = np.ascontiguousarray(np.concatenate(xs).T)
        inputs = np.repeat(np.arange(len(xs), dtype=np.int64), sizes)
        max_len = int(np.diff(offsets)[flat].max())
        threads = numba.get_num_threads() if len(flat) >= _PARALLEL_MIN_NODES else 1
        # Chunks of pairs on Python threads (the kernel releases the GIL), each chunk
        # writing its own rows of ``out``/``warps``. Not numba's prange: a parallel kernel
        # took ~5 s CPU more to compile at first use (scripts/bench_startup.py --kernels).
        in_chunks(len(flat), threads, lambda a, b: _pairs_range(
            xs_all, x_off, values, offsets, inputs, flat, max_len, band, code, a, b, out,
            warps))
    return sizes, out, warps


def _split(a: np.ndarray, sizes: np.ndarray) -> list[np.ndarray]:
    """``a``'s rows in consecutive pieces of ``sizes`` rows (none for no sizes)."""
    return np.split(a, np.cumsum(sizes)[:-1]) if len(sizes) else []


def _check_nodes(values: np.ndarray, offsets: np.ndarray, nodes: np.ndarray) -> None:
    """Nodes in range, each with a non-empty finite curve within ``values``."""
    bad = np.flatnonzero((nodes < 0) | (nodes >= len(offsets) - 1))
    if len(bad):
        raise ParameterError(
            f"nodes must be in [0, {len(offsets) - 1}), got {nodes[bad[0]]} at index {bad[0]}"
        )
    starts = offsets[nodes]
    stops = offsets[nodes + 1]
    bad = np.flatnonzero((starts < 0) | (stops <= starts) | (stops > len(values)))
    if len(bad):
        a = nodes[bad[0]]
        raise ParameterError(
            f"offsets must give node {a} a curve within values' {len(values)} frames, "
            f"got [{starts[bad[0]]}, {stops[bad[0]]})"
        )
    if _known_finite(values):
        return
    t = _first_nonfinite(values, offsets, nodes)
    if t >= 0:
        raise ParameterError(f"values must be finite, got NaN or inf in node {nodes[t]}'s curve")


# --------------------------------------------------------------------------- validation


def _audio_metric(metric) -> int:
    if not isinstance(metric, str) or metric not in AUDIO_METRICS:
        raise ParameterError(f"metric must be one of {', '.join(AUDIO_METRICS)}, got {metric!r}")
    return AUDIO_METRICS[metric]


def _row_starts(path: np.ndarray) -> np.ndarray:
    """Index in ``path`` of the first cell of each frame i (a valid path visits every i)."""
    return np.flatnonzero(np.diff(path[:, 0], prepend=-1))
