"""Search of the Anime Graph for the anime sequence that best matches an input (§4.2).

Cao et al. (2005, §4.2) turn an input utterance into search nodes sn_i = <P_i, C_i, E>
and look for a matching sequence of anime nodes a_1 .. a_n (one per input phone, with
a_i.P = sn_i.P) that minimises Eq. (2)::

    C = w1 Σ_{i<n} C_jump(a_i, a_i+1) + w2 Σ_{i<n} C_jumpcost(a_i, a_i+1) + w3 Σ_i C_audio(i, a_i)

* ``C_jump`` (Eq. 3) is 0 when a_i+1 follows a_i in its recording (``next_node``), else 1
  (a *jump match*).
* ``C_jumpcost`` (Eq. 4) is the RMS distance between the last motion frame of a_i and the
  first of a_i+1. Convention here: ``||last_pcs[a] - first_pcs[b]|| / sqrt(n_channels)``,
  i.e. the Euclidean distance in principal-component space (equal to the distance in
  the motion channels, up to what PCA left out) divided by the square root of the number
  of channels. It is charged for every pair, consecutive pairs included, as Eq. (4) is.
* ``C_audio`` (Eq. 5) is the DTW distance of prosody curves, computed by the caller:
  ``audio[i][k]`` is the cost of input ``i`` against its ``k``-th candidate node.

Two soft terms extend Eq. (2), both constant or zero unless the input asks for them:

* the input's emotion E (§4.2 uses it to choose the motion): ``w_emotion`` per node of
  another emotion;
* back-off: a phone with no node in the graph is matched by the nodes of its viseme class
  (:data:`ingest.phones.VISEME_OF`) at ``w_backoff`` per input, and when the class is
  empty too by any node at ``w_backoff_any``. Every candidate of one input pays the same
  back-off, so it never changes which sequence is best; it makes costs of inputs with and
  without back-off comparable and is reported.

Solvers (:func:`search`, ``method=``):

``"exact"`` (default)
    The global optimum, fast: a forward dynamic program over the chain of candidate
    layers, pruned with an admissible backward bound and an upper bound from a feasible
    sequence, with a k-d tree for the jump transitions (see :func:`_exact_layers`);
    provably equal to the optimum of ``"dp"``. Kernels are compiled by numba (cached on
    disk after the first call) and a large layer's queries run on several threads.
``"paper"``
    The paper's Priority-Queue (branch and bound) algorithm, steps (1)–(4), with an
    expansion cap.
``"window"``
    The paper's bounded look-ahead: optimise the current phone and ``window`` phones
    ahead, commit the current one, slide.
``"dp"``
    A plain Viterbi over all candidate pairs, O(Σ |C_i| |C_i+1|): the tests' oracle.
"""

from __future__ import annotations

import logging
import math
import numbers
import os
import threading
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numba
import numpy as np
from scipy.spatial.distance import cdist

from animegraph.graph import PHONE_INDEX, AnimeGraph
from db.errors import DataError, ParameterError
from ingest.phones import PHONES, VISEME_CLASSES, VISEME_OF

log = logging.getLogger(__name__)

METHODS = ("exact", "paper", "window", "dp")

#: The ``"dp"`` oracle refuses layers with more candidate pairs than this (memory ~8 B each).
DP_MAX_PAIRS = 4_000_000


@dataclass(frozen=True)
class SearchWeights:
    """Weights of the matching cost (Eq. 2 and its two soft extensions).

    Every weight must be finite and non-negative (the pruning of every solver relies on
    costs never decreasing along a sequence).
    """

    w_jump: float = 100.0  # w1 (§4.2, the paper's value): per jump match, highest priority
    w_jumpcost: float = 1.0  # w2 (§4.2): per unit of RMS distance between joined frames
    w_audio: float = 0.01  # w3 (§4.2): per unit of audio (prosody DTW) distance, lowest
    # Per node whose emotion differs from the input's: as much as a jump match, so the
    # search takes a jump rather than motion of the wrong emotion. Measured on held-out
    # synthetic sentences (docs/results.md): with 10, a quarter of the nodes came from
    # other emotions and face RMSE was 0.629 mm; with 100, none did, RMSE 0.557 mm, lip
    # vertex error 2.31 -> 1.99 mm, mouth-opening R 0.685 -> 0.715, for ~4 more jumps.
    w_emotion: float = 100.0
    # Per input phone matched by a class-mate of its viseme (the phone has no node).
    w_backoff: float = 50.0
    # Per input phone matched by any node (neither the phone nor its class has a node).
    w_backoff_any: float = 200.0

    def __post_init__(self) -> None:
        for name in ("w_jump", "w_jumpcost", "w_audio", "w_emotion", "w_backoff",
                     "w_backoff_any"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, numbers.Real) \
                    or not math.isfinite(value) or value < 0:
                raise ParameterError(f"{name} must be a finite number >= 0, got {value!r}")


@dataclass(frozen=True, eq=False)
class Candidates:
    """The anime nodes that may match each input phone (§4.2: a_i.P = sn_i.P).

    Attributes
    ----------
    nodes : tuple of np.ndarray of int64
        ``nodes[i]``, shape (n_candidates_i,), strictly ascending node ids for input ``i``.
    backoff : tuple of (str or None)
        Per input: None (the phone's own nodes), ``"viseme:<class>"`` (class-mates of the
        phone's viseme) or ``"any"`` (every node, the last resort).
    phones : tuple of str
        The input phones.
    emotion : str or None
        The input's emotion E, used by :func:`search` and :func:`path_cost` when they are
        not given one.
    """

    nodes: tuple[np.ndarray, ...]
    backoff: tuple[str | None, ...]
    phones: tuple[str, ...] = ()
    emotion: str | None = None

    def __len__(self) -> int:
        return len(self.nodes)

    @property
    def sizes(self) -> np.ndarray:
        """Number of candidates per input, shape (n,)."""
        return np.array([len(c) for c in self.nodes], dtype=np.int64)

    @property
    def backed_off(self) -> dict[int, str]:
        """``{input index: back-off}`` for the inputs that did not match their own phone."""
        return {i: b for i, b in enumerate(self.backoff) if b is not None}


@dataclass(frozen=True)
class PathCost:
    """Eq. (2) of one matching sequence, term by term (weighted; they sum to ``cost``).

    ``cost = w_jump * n_jumps + jump_cost + audio_cost + emotion_cost + backoff_cost``.
    """

    cost: float
    n_jumps: int
    jump_cost: float  # w2 Σ C_jumpcost (RMS frame distances, consecutive pairs included)
    audio_cost: float  # w3 Σ C_audio
    emotion_cost: float  # w_emotion * nodes of another emotion than the input's
    backoff_cost: float  # w_backoff / w_backoff_any per backed-off input


@dataclass(frozen=True, eq=False)
class SearchResult:
    """A matching anime sequence and how it was found.

    Attributes
    ----------
    nodes : np.ndarray of int64, shape (n,)
        The anime node matched to each input phone.
    cost : float
        Eq. (2) (plus the soft terms) as the solver computed it while searching; equal to
        ``path_cost(...).cost`` of ``nodes`` up to rounding.
    n_jumps, jump_cost, audio_cost, emotion_cost, backoff_cost
        The breakdown of :func:`path_cost`.
    n_expanded : int
        Search states worked on: ``"exact"`` (layer, node) states kept after pruning;
        ``"dp"`` every state; ``"paper"`` queue nodes expanded; ``"window"`` the sum over
        its windows.
    method : str
    optimal : bool
        True when the sequence is proven to be the global optimum.
    n_distances : int
        Frame distances (Eq. 4) evaluated.
    capped : bool
        ``"paper"`` only: the expansion or queue cap stopped the search.
    backoff : tuple of (str or None)
        Per input, as in :class:`Candidates`.
    """

    nodes: np.ndarray
    cost: float
    n_jumps: int
    jump_cost: float
    audio_cost: float
    emotion_cost: float
    backoff_cost: float
    n_expanded: int
    method: str
    optimal: bool
    n_distances: int = 0
    capped: bool = False
    backoff: tuple[str | None, ...] = field(default=())


# --------------------------------------------------------------------------------------
# Candidates and the cost of a sequence
# --------------------------------------------------------------------------------------


def candidates(graph: AnimeGraph, phones: Sequence[str], *,
               emotion: str | None = None) -> Candidates:
    """Candidate anime nodes of each input phone, with viseme and last-resort back-off.

    Implements the matching constraint a_i.P = sn_i.P of §4.2. A phone with no node in
    the graph backs off to the nodes of its viseme class, and when the class has none
    either, to every node of the graph ("any"). It never fails for a missing phone.

    Parameters
    ----------
    graph : AnimeGraph
    phones : sequence of str, length n >= 1
        ARPAbet phones of :data:`ingest.phones.PHONES`.
    emotion : str, optional
        The input's emotion E; stored in the result for :func:`search`. An emotion the
        graph lacks is allowed (every node then pays the same penalty) and logged.

    Returns
    -------
    Candidates

    Raises
    ------
    ParameterError
        If ``phones`` is empty, a string, or holds a label that is not a phone.
    DataError
        If the graph has no nodes.
    """
    if isinstance(phones, str) or not isinstance(phones, Sequence):
        raise ParameterError(f"phones must be a sequence of phone labels, got {phones!r:.60}")
    if len(phones) == 0:
        raise ParameterError("phones must hold at least one phone, got an empty sequence")
    if graph.n_nodes == 0:
        raise DataError("the anime graph has no nodes to search")
    if emotion is not None:
        _emotion_code(graph, emotion)  # validates the type, logs an unknown emotion
    nodes: list[np.ndarray] = []
    backoff: list[str | None] = []
    every: np.ndarray | None = None
    for i, phone in enumerate(phones):
        if not isinstance(phone, str) or phone not in PHONE_INDEX:
            raise ParameterError(f"phones[{i}] must be one of the {len(PHONES)} ARPAbet phones "
                                 f"of ingest.phones.PHONES, got {phone!r}")
        own = graph.by_phone[PHONE_INDEX[phone]]
        if len(own):
            nodes.append(own)
            backoff.append(None)
            continue
        viseme = VISEME_OF[phone]
        mates = [graph.by_phone[PHONE_INDEX[p]] for p in VISEME_CLASSES[viseme] if p != phone]
        mates = [m for m in mates if len(m)]
        if mates:
            nodes.append(np.sort(np.concatenate(mates)))
            backoff.append(f"viseme:{viseme}")
            log.info("phone %s (input %d) is not in the graph: backing off to its viseme "
                     "class %s (%d nodes)", phone, i, viseme, len(nodes[-1]))
            continue
        if every is None:
            every = np.arange(graph.n_nodes, dtype=np.int64)
        nodes.append(every)
        backoff.append("any")
        log.warning("neither phone %s (input %d) nor its viseme class %s is in the graph: "
                    "any node may match it", phone, i, viseme)
    return Candidates(nodes=tuple(nodes), backoff=tuple(backoff), phones=tuple(phones),
                      emotion=emotion)


def path_cost(graph: AnimeGraph, cands: Candidates, audio: Sequence[np.ndarray], *,
              indices: Sequence[int] | np.ndarray | None = None,
              nodes: Sequence[int] | np.ndarray | None = None,
              weights: SearchWeights | None = None,
              emotion: str | None = None) -> PathCost:
    """Eq. (2) of a matching sequence, given by candidate indices or by node ids (§4.2).

    The one definition of the cost: every solver's result is checked against it.

    Parameters
    ----------
    graph : AnimeGraph
    cands : Candidates
        n inputs.
    audio : sequence of np.ndarray
        ``audio[i]``, shape (len(cands.nodes[i]),): C_audio of input ``i`` per candidate.
    indices : array-like of int, shape (n,), optional
        ``indices[i]`` is the position of the matched node in ``cands.nodes[i]``.
    nodes : array-like of int, shape (n,), optional
        The matched node ids (each must be a candidate of its input). Exactly one of
        ``indices`` and ``nodes`` is given.
    weights : SearchWeights, optional
    emotion : str, optional
        The input's emotion; None uses ``cands.emotion`` (None there too: no preference).

    Returns
    -------
    PathCost

    Raises
    ------
    ParameterError
        On shapes that do not match or a node that is not a candidate of its input.
    """
    weights = weights or SearchWeights()
    problem = _Problem.build(graph, cands, audio, weights, emotion)
    if (indices is None) == (nodes is None):
        raise ParameterError("path_cost needs exactly one of indices and nodes, got "
                             f"{'both' if indices is not None else 'neither'}")
    n = len(cands)
    if nodes is not None:
        idx = _node_indices(cands, nodes)
    else:
        idx = np.asarray(indices, dtype=np.int64).reshape(-1)
        if len(idx) != n:
            raise ParameterError(f"indices must have one entry per input ({n}), got {len(idx)}")
        sizes = cands.sizes
        if np.any(idx < 0) or np.any(idx >= sizes):
            i = int(np.flatnonzero((idx < 0) | (idx >= sizes))[0])
            raise ParameterError(f"indices[{i}] must be in [0, {sizes[i]}), got {idx[i]}")
    return problem.breakdown(idx)


def _node_indices(cands: Candidates, nodes) -> np.ndarray:
    """Position of each matched node in its input's candidates, shape (n,); ParameterError
    if the count is wrong or a node is not a candidate of its input."""
    n = len(cands)
    nodes = np.asarray(nodes, dtype=np.int64).reshape(-1)
    if len(nodes) != n:
        raise ParameterError(f"nodes must have one node per input ({n}), got {len(nodes)}")
    idx = np.empty(n, dtype=np.int64)
    for i in range(n):
        k = int(np.searchsorted(cands.nodes[i], nodes[i]))
        if k >= len(cands.nodes[i]) or cands.nodes[i][k] != nodes[i]:
            raise ParameterError(f"nodes[{i}] = {int(nodes[i])} is not a candidate of input "
                                 f"{i} ({cands.phones[i] if cands.phones else '?'})")
        idx[i] = k
    return idx


def k_best(graph: AnimeGraph, cands: Candidates, audio: Sequence[np.ndarray],
           nodes: Sequence[int] | np.ndarray, k: int, *, weights: SearchWeights | None = None,
           emotion: str | None = None) -> tuple[np.ndarray, ...]:
    """Per input, its matched node followed by the ``k - 1`` other candidates of least
    unary cost (beyond the paper: the animes :func:`animegraph.synthesis.blend_k_best`
    averages).

    The unary cost is the part of Eq. (2) that depends on one node only:
    ``w3 C_audio`` plus the emotion and back-off terms. Ties keep the candidates' order.

    Parameters
    ----------
    graph : AnimeGraph
    cands : Candidates
        n inputs.
    audio : sequence of np.ndarray
        ``audio[i]``, shape (len(cands.nodes[i]),): C_audio (Eq. 5), as for :func:`search`.
    nodes : array-like of int, shape (n,)
        The matched sequence (e.g. ``search(...).nodes``); each a candidate of its input.
    k : int
        Nodes per input, >= 1 (fewer where an input has fewer candidates).
    weights : SearchWeights, optional
    emotion : str, optional
        The input's emotion; None uses ``cands.emotion``.

    Returns
    -------
    tuple of np.ndarray of int64
        ``ranked[i]``, shape (min(k, len(cands.nodes[i])),), starting with ``nodes[i]``.

    Raises
    ------
    ParameterError
        If ``k`` is not an int >= 1, on malformed inputs (as :func:`search`), or if a
        node is not a candidate of its input.
    """
    if isinstance(k, bool) or not isinstance(k, int | np.integer) or k < 1:
        raise ParameterError(f"k must be an int >= 1, got {k!r}")
    problem = _Problem.build(graph, cands, audio, weights or SearchWeights(), emotion)
    ranked = []
    for i, pick in enumerate(_node_indices(cands, nodes)):
        lo, hi = problem.off[i], problem.off[i + 1]
        order = np.argsort(problem.u[lo:hi], kind="stable")
        order = np.concatenate([[pick], order[order != pick][:k - 1]])
        ranked.append(problem.cn[lo + order])
    return tuple(ranked)


# --------------------------------------------------------------------------------------
# The search
# --------------------------------------------------------------------------------------


def search(graph: AnimeGraph, cands: Candidates, audio: Sequence[np.ndarray], *,
           weights: SearchWeights | None = None, emotion: str | None = None,
           method: str = "exact", window: int | None = None, tolerance: float = 0.0,
           max_expansions: int = 2_000_000, max_queue: int = 20_000_000) -> SearchResult:
    """Find the matching anime sequence of least cost (Eq. 2, §4.2).

    Parameters
    ----------
    graph : AnimeGraph
    cands : Candidates
        From :func:`candidates`, n >= 1 inputs.
    audio : sequence of np.ndarray
        ``audio[i]``, shape (len(cands.nodes[i]),), finite and >= 0: C_audio (Eq. 5) of
        input ``i`` against each of its candidates.
    weights : SearchWeights, optional
        Defaults to the paper's w1, w2, w3 = 100, 1, 0.01.
    emotion : str, optional
        The input's emotion E (soft preference); None uses ``cands.emotion``.
    method : {"exact", "paper", "window", "dp"}
        See the module docstring.
    window : int, optional
        ``method="window"`` only (required there): phones looked ahead of the current one
        (the paper: 3–6).
    tolerance : float, optional
        ``method="exact"`` only: accept a sequence whose cost is within this fraction of
        the optimum (0, the default: the optimum itself). The search then keeps only
        states that could beat the greedy upper bound by more than ``tolerance`` times
        a lower bound of the optimum, and returns the greedy sequence when none does; the
        result is certified: ``cost <= (1 + tolerance) * optimum``. Beyond the paper: on
        graphs of many near-identical recordings (near-ties the bounds cannot separate)
        it prunes most of the work.
    max_expansions : int
        ``method="paper"``: queue nodes expanded before the search stops (capped).
    max_queue : int
        ``method="paper"``: queue size (memory: 24 B a node) before the search stops.

    Returns
    -------
    SearchResult

    Raises
    ------
    ParameterError
        On an unknown method, a missing or invalid window, audio costs of the wrong shape
        or negative / non-finite, or a problem too large for ``method="dp"``.
    """
    weights = weights or SearchWeights()
    if method not in METHODS:
        raise ParameterError(f"method must be one of {METHODS}, got {method!r}")
    if method == "window":
        if window is None or isinstance(window, bool) or not isinstance(window, int | np.integer) \
                or window < 1:
            raise ParameterError(f"window must be an int >= 1 for method='window', got {window!r}")
    elif window is not None:
        raise ParameterError(f"window is only used by method='window', got window={window!r} "
                             f"with method={method!r}")
    if not isinstance(tolerance, int | float | np.floating) or not 0.0 <= tolerance < 1.0:
        raise ParameterError(f"tolerance must be a number in [0, 1), got {tolerance!r}")
    if tolerance and method != "exact":
        raise ParameterError(f"tolerance is only used by method='exact', got method={method!r}")
    for name, value in (("max_expansions", max_expansions), ("max_queue", max_queue)):
        if not isinstance(value, int | np.integer) or value < 1:
            raise ParameterError(f"{name} must be an int >= 1, got {value!r}")
    problem = _Problem.build(graph, cands, audio, weights, emotion)
    capped = False
    if method == "exact":
        idx, cost, n_exp, n_dist = _exact(problem, float(tolerance))
        optimal = tolerance == 0.0
    elif method == "dp":
        idx, cost, n_exp, n_dist = _dp(problem)
        optimal = True
    elif method == "window":
        idx, cost, n_exp, n_dist = _window(problem, int(window))
        optimal = window >= len(cands) - 1  # one window spans the input: the exact search
    else:
        idx, cost, n_exp, n_dist, capped, optimal = _paper(problem, int(max_expansions),
                                                           int(max_queue))
    br = problem.breakdown(idx)
    log.debug("search %s: n=%d cost=%.6f jumps=%d expanded=%d distances=%d", method,
              len(cands), cost, br.n_jumps, n_exp, n_dist)
    return SearchResult(
        nodes=problem.nodes_of(idx), cost=float(cost), n_jumps=br.n_jumps,
        jump_cost=br.jump_cost, audio_cost=br.audio_cost, emotion_cost=br.emotion_cost,
        backoff_cost=br.backoff_cost, n_expanded=int(n_exp), method=method, optimal=optimal,
        n_distances=int(n_dist), capped=capped, backoff=cands.backoff,
    )


# --------------------------------------------------------------------------------------
# The problem in flat arrays
# --------------------------------------------------------------------------------------


def _emotion_code(graph: AnimeGraph, emotion: str) -> int:
    if not isinstance(emotion, str):
        raise ParameterError(f"emotion must be a string or None, got {emotion!r}")
    if emotion in graph.emotions:
        return graph.emotions.index(emotion)
    log.warning("emotion %r is not in the graph (%s): every node pays w_emotion", emotion,
                ", ".join(graph.emotions))
    return -1


@dataclass(frozen=True, eq=False)
class _Problem:
    """A search problem as flat arrays over the concatenated candidate layers.

    ``cn[off[i]:off[i+1]]`` are the candidates of input ``i``; ``u`` the unary cost of each
    (w3 C_audio + emotion + back-off); ``scale`` = w2 / sqrt(n_channels) turns a PCA
    distance into the weighted jump cost.
    """

    graph: AnimeGraph
    weights: SearchWeights
    cn: np.ndarray  # int64 (N,)
    off: np.ndarray  # int64 (n + 1,)
    u: np.ndarray  # float64 (N,)
    audio: np.ndarray  # float64 (N,), unweighted
    mismatch: np.ndarray  # bool (N,), emotion differs
    backoff_cost: np.ndarray  # float64 (n,), per layer
    scale: float
    last: np.ndarray  # float32 (n_nodes, n_pcs), C-contiguous
    first: np.ndarray
    nxt: np.ndarray  # int64 (n_nodes,)
    prv: np.ndarray

    @classmethod
    def build(cls, graph: AnimeGraph, cands: Candidates, audio: Sequence[np.ndarray],
              weights: SearchWeights, emotion: str | None) -> _Problem:
        n = len(cands)
        if n == 0:
            raise ParameterError("cands must hold at least one input, got none")
        if len(cands.backoff) != n:
            raise ParameterError(f"cands.backoff must have {n} entries, got {len(cands.backoff)}")
        if audio is None or len(audio) != n:
            got = None if audio is None else len(audio)
            raise ParameterError(f"audio must hold one cost array per input ({n}), got {got}")
        if graph.n_channels < 1:
            raise DataError(f"the graph's n_channels must be >= 1, got {graph.n_channels}")
        sizes = np.array([len(c) for c in cands.nodes], dtype=np.int64)
        off = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(sizes, out=off[1:])
        cn = np.concatenate([np.asarray(c, dtype=np.int64) for c in cands.nodes])
        au = np.empty(off[-1], dtype=np.float64)
        for i in range(n):
            if sizes[i] == 0:
                raise ParameterError(f"cands.nodes[{i}] is empty: every input needs a candidate")
            c = cands.nodes[i]
            if np.any(np.diff(c) <= 0) or c[0] < 0 or c[-1] >= graph.n_nodes:
                raise ParameterError(f"cands.nodes[{i}] must be strictly ascending node ids in "
                                     f"[0, {graph.n_nodes}), got {np.asarray(c)[:5]}...")
            a = np.asarray(audio[i], dtype=np.float64).reshape(-1)
            if a.shape != (sizes[i],):
                raise ParameterError(f"audio[{i}] must have shape ({sizes[i]},), "
                                     f"got {np.shape(audio[i])}")
            if not np.all(np.isfinite(a)) or np.any(a < 0):
                raise ParameterError(f"audio[{i}] must be finite and >= 0, got min {a.min()!r}")
            au[off[i]:off[i + 1]] = a
        emotion = emotion if emotion is not None else cands.emotion
        if emotion is not None:
            code = _emotion_code(graph, emotion)
            mismatch = graph.node_emotion[cn] != code
        else:
            mismatch = np.zeros(len(cn), dtype=bool)
        layer_backoff = np.array([0.0 if b is None else weights.w_backoff_any if b == "any"
                                  else weights.w_backoff for b in cands.backoff])
        u = weights.w_audio * au + weights.w_emotion * mismatch
        u += np.repeat(layer_backoff, sizes)
        return cls(
            graph=graph, weights=weights, cn=cn, off=off, u=u, audio=au, mismatch=mismatch,
            backoff_cost=layer_backoff,
            scale=weights.w_jumpcost / math.sqrt(graph.n_channels),
            last=np.ascontiguousarray(graph.last_pcs, dtype=np.float32),
            first=np.ascontiguousarray(graph.first_pcs, dtype=np.float32),
            nxt=np.ascontiguousarray(graph.next_node, dtype=np.int64),
            prv=np.ascontiguousarray(graph.prev_node, dtype=np.int64),
        )

    @property
    def n(self) -> int:
        return len(self.off) - 1

    def nodes_of(self, idx: np.ndarray) -> np.ndarray:
        return self.cn[self.off[:-1] + np.asarray(idx, dtype=np.int64)].copy()

    def breakdown(self, idx: np.ndarray) -> PathCost:
        """Eq. (2) of the sequence whose candidate index in layer i is ``idx[i]``."""
        w = self.weights
        flat = self.off[:-1] + np.asarray(idx, dtype=np.int64)
        nodes = self.cn[flat]
        a, b = nodes[:-1], nodes[1:]
        n_jumps = int(np.count_nonzero(self.nxt[a] != b))
        diff = self.last[a].astype(np.float64) - self.first[b].astype(np.float64)
        dist = float(np.sqrt((diff * diff).sum(axis=1)).sum()) / math.sqrt(self.graph.n_channels)
        jump_cost = w.w_jumpcost * dist
        audio_cost = w.w_audio * float(self.audio[flat].sum())
        emotion_cost = w.w_emotion * int(np.count_nonzero(self.mismatch[flat]))
        backoff_cost = float(self.backoff_cost.sum())
        cost = w.w_jump * n_jumps + jump_cost + audio_cost + emotion_cost + backoff_cost
        return PathCost(cost=cost, n_jumps=n_jumps, jump_cost=jump_cost, audio_cost=audio_cost,
                        emotion_cost=emotion_cost, backoff_cost=backoff_cost)

    def sub(self, start: int, stop: int,
            prev_node: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Layers [start, stop) as (cn, off, u); the transition from ``prev_node`` (if >= 0)
        is added to the unary cost of the first layer."""
        lo, hi = self.off[start], self.off[stop]
        cn = self.cn[lo:hi]
        off = self.off[start:stop + 1] - lo
        u = self.u[lo:hi].copy()
        if prev_node >= 0:
            first_layer = cn[:off[1]]
            u[:off[1]] += self.transition(prev_node, first_layer)
        return cn, off, u

    def transition(self, a: int, b: np.ndarray) -> np.ndarray:
        """w1 C_jump + w2 C_jumpcost from node ``a`` to each node of ``b``."""
        diff = self.first[b].astype(np.float64) - self.last[a].astype(np.float64)
        d = np.sqrt((diff * diff).sum(axis=1))
        return self.weights.w_jump * (b != self.nxt[a]) + self.scale * d


# --------------------------------------------------------------------------------------
# method="exact": pruned forward dynamic programming
# --------------------------------------------------------------------------------------


def _exact(p: _Problem, tolerance: float = 0.0) -> tuple[np.ndarray, float, int, int]:
    return _exact_layers(p, p.cn, p.off, p.u, tolerance)


def _exact_layers(p: _Problem, cn: np.ndarray, off: np.ndarray, u: np.ndarray,
                  tolerance: float = 0.0) -> tuple[np.ndarray, float, int, int]:
    """Global optimum of the chain ``cn``/``off``/``u``: (indices, cost, states, distances).

    The problem is a shortest path through layers of candidates, with the transition
    ``T(a, b) = w1 [b != next(a)] + s ||last(a) - first(b)||`` (s = w2 / sqrt(n_channels))
    and the unary cost ``u(b)``. The plain Viterbi recursion
    ``D(b) = u(b) + min_a D(a) + T(a, b)`` costs |C_i| |C_i+1| distances a layer. Three
    steps avoid almost all of them without changing the result:

    1. **Lower bound** ``h(a)`` on the cost to go from ``a`` (a backward DP on a
       relaxation): ``h(a) = min(T(a, next a) + u(next a) + h(next a),
       w1 + min_b u(b) + h(b))``, the first term only when ``next a`` is a candidate of
       the next layer. It drops the distance of jump transitions only (>= 0), so by
       induction ``h <= H``, the true cost to go (admissible). O(N).
    2. **Upper bound** ``UB``: the cost of one feasible sequence, built greedily forward,
       each step taking the successor that minimises ``T + u + h`` with true distances.
       O(N) distances.
    3. **Pruned forward DP.** A state ``b`` is kept only if ``D(b) + h(b) <= UB``. For a
       kept ``b``, the consecutive predecessor ``prev b`` costs O(1). The jump part,
       ``w1 + min_a D(a) + s ||last(a) - first(b)||``, is an additively weighted
       nearest-neighbour query over the kept states ``a`` of the previous layer, answered
       by branch and bound in a k-d tree over their last frames whose nodes carry their
       bounding box and least ``D`` (lower bound of a subtree: ``w1 + min D + s *
       box distance``; leaves are scanned in ascending ``D``). A subtree or point is
       skipped only when its lower bound reaches the best value found or exceeds
       ``UB - h(b) - u(b)`` (it could neither improve ``b`` nor keep it); a point's
       distance is computed whole, without an early exit on its partial sum, so that
       the loop over the few components vectorises (~10-15 % less CPU time at 1M nodes
       than the early exit; the skip test is the same). With few queries the tree is a
       single leaf (a scan in ascending ``D``). Before the queries, states that can never
       be the best source are dropped: ``a`` is dominated by ``a'`` when
       ``D(a') + s ||x_a' - x_a|| < D(a)`` (by a 1e-9 relative margin), for then, by
       the triangle inequality, ``a'`` beats ``a`` for every target; dominance is
       checked among neighbours in the tree (subtrees of <= ``_DOMINANCE_RANGE``
       states), and the tree is rebuilt when many states go. Queries of a large layer
       run on several threads (numba releases the GIL).

    Exactness: let π be an optimal sequence, cost OPT <= UB. For each of its states,
    (prefix cost of π) + h <= (prefix cost) + H <= OPT <= UB. By induction over layers,
    each state of π is kept with ``D <= its prefix cost``: its predecessor on π is kept
    (or dominated by a kept state that does at least as well, following the chain of
    dominations to a state that stays), and the search skips only sources whose lower
    bound is not below the best value found or is above the keep threshold, which π's
    predecessor is not. Every computed ``D`` is the cost of a real prefix, so ``min D``
    over the last layer is both <= OPT and >= OPT: it equals the optimum of the full
    Viterbi recursion (the ``"dp"`` oracle), up to floating-point rounding (1e-12).
    Comparisons with UB carry a relative slack of 1e-9 so that rounding never prunes π.
    Cost: O(N) for the bounds plus, per kept state, one tree query; in the worst case
    (bounds that prune nothing) this is the Viterbi recursion with a spatial index.

    With ``tolerance`` t > 0 the keep threshold is ``UB - t * LB`` instead of UB, with
    ``LB = min(u + h)`` over the first layer (<= OPT). If ``OPT <= UB - t * LB``, the
    argument above keeps π and the result is optimal; otherwise the greedy sequence,
    returned when nothing is kept, costs ``UB < OPT + t * LB <= (1 + t) OPT``.
    """
    n = len(off) - 1
    pos = np.full(p.graph.n_nodes, -1, dtype=np.int64)
    w1 = float(p.weights.w_jump)
    h = _relaxed_backward(cn, off, u, p.nxt, p.last, p.first, w1, p.scale, pos)
    gpath, ub = _greedy(cn, off, u, h, p.nxt, p.last, p.first, w1, p.scale)
    if n == 1:
        return gpath - off[:-1], float(ub), len(cn), 0
    ub_eff = ub + 1e-9 * (1.0 + abs(ub))
    if tolerance > 0.0:
        ub_eff = ub - tolerance * float(np.min(u[:off[1]] + h[:off[1]]))
    path, cost, kept, n_dist = _forward(cn, off, u, h, p.nxt, p.prv, p.last, p.first, w1,
                                        p.scale, ub_eff, pos)
    if path[0] < 0:
        # With a tolerance: nothing beats the greedy sequence by more than it (see
        # above). Without one this cannot happen (the greedy sequence is kept).
        if tolerance == 0.0:
            log.warning("exact search kept no complete sequence; returning the greedy one")
        return gpath - off[:-1], float(ub), kept, n_dist
    return path - off[:-1], float(cost), kept, n_dist + len(cn)


@numba.njit(cache=True, nogil=True)
def _dist(x: np.ndarray, a: int, y: np.ndarray, b: int) -> float:  # pragma: no cover
    s = 0.0
    for j in range(x.shape[1]):
        t = np.float64(x[a, j]) - np.float64(y[b, j])
        s += t * t
    return np.sqrt(s)


@numba.njit(cache=True, nogil=True)
def _relaxed_backward(cn, off, u, nxt, last, first, w1, scale, pos):  # pragma: no cover
    n = len(off) - 1
    h = np.zeros(len(cn))
    for i in range(n - 2, -1, -1):
        lo1, hi1 = off[i + 1], off[i + 2]
        m = np.inf
        for q in range(lo1, hi1):
            v = u[q] + h[q]
            if v < m:
                m = v
            pos[cn[q]] = q
        for p in range(off[i], off[i + 1]):
            best = w1 + m
            j = nxt[cn[p]]
            if j >= 0:
                q = pos[j]
                if q >= 0:
                    v = scale * _dist(last, cn[p], first, j) + u[q] + h[q]
                    if v < best:
                        best = v
            h[p] = best
        for q in range(lo1, hi1):
            pos[cn[q]] = -1
    return h


@numba.njit(cache=True, nogil=True)
def _greedy(cn, off, u, h, nxt, last, first, w1, scale):  # pragma: no cover
    n = len(off) - 1
    path = np.empty(n, dtype=np.int64)
    best = np.inf
    qb = off[0]
    for q in range(off[0], off[1]):
        v = u[q] + h[q]
        if v < best:
            best = v
            qb = q
    path[0] = qb
    cost = u[qb]
    for i in range(n - 1):
        a = cn[path[i]]
        best = np.inf
        tb = 0.0
        qb = off[i + 1]
        for q in range(off[i + 1], off[i + 2]):
            b = cn[q]
            t = scale * _dist(last, a, first, b)
            if nxt[a] != b:
                t += w1
            v = t + u[q] + h[q]
            if v < best:
                best = v
                qb = q
                tb = t
        path[i + 1] = qb
        cost += tb + u[qb]
    return path, cost


#: Points per leaf of the k-d tree over the kept states of a layer.
_LEAF = 16
#: Dominated jump sources are looked for among at most this many neighbours.
_DOMINANCE_RANGE = 64
#: Rebuild the tree when dominance leaves fewer than this fraction of the states.
_REBUILD = 0.7
#: Queries of a layer below which one thread does them all.
_PARALLEL_MIN = 2048
_POOL: ThreadPoolExecutor | None = None
_POOL_LOCK = threading.Lock()


def _threads() -> int:
    """Threads for the queries of a layer: the CPUs this process may use, at most 8."""
    try:
        return max(1, min(8, len(os.sched_getaffinity(0))))
    except AttributeError:  # not on Linux
        return max(1, min(8, os.cpu_count() or 1))


def _pool(threads: int) -> ThreadPoolExecutor:
    global _POOL
    with _POOL_LOCK:
        if _POOL is None:
            _POOL = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="search")
        return _POOL


@numba.njit(cache=True, nogil=True)
def _select(perm, x, dim, s, e, kth):  # pragma: no cover
    """Reorder ``perm[s:e]`` so that ``perm[kth]`` holds the point of rank ``kth - s`` along
    ``dim``, smaller ones before it and larger ones after (quickselect)."""
    lo, hi = s, e - 1
    while hi > lo:
        mid = (lo + hi) // 2
        # Median of three as the pivot, moved to hi.
        a, b, c = x[perm[lo], dim], x[perm[mid], dim], x[perm[hi], dim]
        if (a <= b <= c) or (c <= b <= a):
            piv = mid
        elif (b <= a <= c) or (c <= a <= b):
            piv = lo
        else:
            piv = hi
        perm[piv], perm[hi] = perm[hi], perm[piv]
        pv = x[perm[hi], dim]
        store = lo
        for t in range(lo, hi):
            if x[perm[t], dim] < pv:
                perm[store], perm[t] = perm[t], perm[store]
                store += 1
        perm[store], perm[hi] = perm[hi], perm[store]
        if store == kth:
            return
        if store < kth:
            lo = store + 1
        else:
            hi = store - 1


@numba.njit(cache=True, nogil=True)
def _sort_by(perm, key, s, e):  # pragma: no cover
    """Sort ``perm[s:e]`` by ``key[perm]`` ascending (insertion sort for a leaf, else heap
    sort; numba compiles these far faster than ``np.argsort``)."""
    n = e - s
    if n <= 32:
        for i in range(s + 1, e):
            p = perm[i]
            k = key[p]
            j = i - 1
            while j >= s and key[perm[j]] > k:
                perm[j + 1] = perm[j]
                j -= 1
            perm[j + 1] = p
        return
    for root in range(n // 2 - 1, -1, -1):
        _sift(perm, key, s, root, n)
    for end in range(n - 1, 0, -1):
        perm[s], perm[s + end] = perm[s + end], perm[s]
        _sift(perm, key, s, 0, end)


@numba.njit(cache=True, nogil=True)
def _sift(perm, key, s, root, n):  # pragma: no cover
    while True:
        child = 2 * root + 1
        if child >= n:
            return
        if child + 1 < n and key[perm[s + child + 1]] > key[perm[s + child]]:
            child += 1
        if key[perm[s + child]] > key[perm[s + root]]:
            perm[s + root], perm[s + child] = perm[s + child], perm[s + root]
            root = child
        else:
            return


@numba.njit(cache=True, nogil=True)
def _build_tree(x, d, leaf):  # pragma: no cover
    """k-d tree over points ``x`` (m, k) weighted by ``d`` (m,); leaves sorted by ``d``.

    Returns the permutation of the points, and per tree node: [start, end) into the
    permuted points, children (-1 at a leaf), bounding box and least weight. With
    ``leaf >= m`` the tree is a single leaf: every point in ascending weight.
    """
    m, k = x.shape
    size = 4 * (m // leaf + 1) + 1
    perm = np.arange(m)
    start = np.empty(size, dtype=np.int64)
    end = np.empty(size, dtype=np.int64)
    left = np.full(size, -1, dtype=np.int64)
    right = np.full(size, -1, dtype=np.int64)
    lo = np.empty((size, k))
    hi = np.empty((size, k))
    mind = np.empty(size)
    stack = np.empty(size, dtype=np.int64)
    start[0], end[0] = 0, m
    nn = 1
    stack[0] = 0
    sp = 1
    while sp > 0:
        sp -= 1
        node = stack[sp]
        s, e = start[node], end[node]
        for j in range(k):
            lo[node, j] = np.inf
            hi[node, j] = -np.inf
        md = np.inf
        for t in range(s, e):
            i = perm[t]
            if d[i] < md:
                md = d[i]
            for j in range(k):
                v = x[i, j]
                if v < lo[node, j]:
                    lo[node, j] = v
                if v > hi[node, j]:
                    hi[node, j] = v
        mind[node] = md
        if e - s > leaf:
            dim = 0
            spread = -1.0
            for j in range(k):
                if hi[node, j] - lo[node, j] > spread:
                    spread = hi[node, j] - lo[node, j]
                    dim = j
            if spread > 0.0:
                mid = (s + e) // 2
                _select(perm, x, dim, s, e, mid)
                left[node], right[node] = nn, nn + 1
                start[nn], end[nn] = s, mid
                start[nn + 1], end[nn + 1] = mid, e
                stack[sp], stack[sp + 1] = nn, nn + 1
                sp += 2
                nn += 2
                continue
        _sort_by(perm, d, s, e)  # a leaf: by ascending weight
    return perm, start[:nn], end[:nn], left[:nn], right[:nn], lo[:nn], hi[:nn], mind[:nn]


@numba.njit(cache=True, nogil=True)
def _box_dist(lo, hi, node, y):  # pragma: no cover
    s = 0.0
    for j in range(y.shape[0]):
        t = max(lo[node, j] - y[j], 0.0) + max(y[j] - hi[node, j], 0.0)  # branch-free
        s += t * t
    return np.sqrt(s)


@numba.njit(cache=True, nogil=True)
def _query(xs, ds, start, end, left, right, lo, hi, mind, y, w1, scale, best, thr,
           stack, bounds):  # pragma: no cover
    """Least ``w1 + ds[r] + scale * ||xs[r] - y||`` below ``min(best, thr)``, branch and
    bound over the tree: (value, row or -1, distances evaluated)."""
    arg = -1
    n_dist = 0
    b0 = w1 + mind[0] + scale * _box_dist(lo, hi, 0, y)
    if b0 >= best or b0 > thr:
        return best, arg, n_dist
    stack[0] = 0
    bounds[0] = b0
    sp = 1
    npc = y.shape[0]
    while sp > 0:
        sp -= 1
        node = stack[sp]
        if bounds[sp] >= best or bounds[sp] > thr:
            continue
        if left[node] < 0:
            for r in range(start[node], end[node]):
                base = w1 + ds[r]
                if base >= best or base > thr:
                    break
                lim = best if best < thr else thr
                if scale > 0.0:
                    room = (lim - base) / scale
                    room2 = room * room
                    s = 0.0
                    for j in range(npc):
                        t = xs[r, j] - y[j]
                        s += t * t
                    n_dist += 1
                    if s > room2:
                        continue
                    v = base + scale * np.sqrt(s)
                else:
                    v = base
                if v < best:
                    best = v
                    arg = r
            continue
        l, rr = left[node], right[node]
        bl = w1 + mind[l] + scale * _box_dist(lo, hi, l, y)
        br = w1 + mind[rr] + scale * _box_dist(lo, hi, rr, y)
        if bl <= br:  # push the worse child first: the better one is explored first
            first_n, first_b, second_n, second_b = rr, br, l, bl
        else:
            first_n, first_b, second_n, second_b = l, bl, rr, br
        if first_b < best and first_b <= thr:
            stack[sp] = first_n
            bounds[sp] = first_b
            sp += 1
        if second_b < best and second_b <= thr:
            stack[sp] = second_n
            bounds[sp] = second_b
            sp += 1
    return best, arg, n_dist


@numba.njit(cache=True, nogil=True)
def _prepare_layer(cn, lo, hi, lo1, hi1, D, u, h, last, w1, scale, ub,
                   pos):  # pragma: no cover
    """The kept states of layer [lo, hi) as a k-d tree over their last frames, weighted
    by D; ``pos[node]`` set to each kept state (for the consecutive test)."""
    npc = last.shape[1]
    m = 0
    for q in range(lo, hi):
        if D[q] < np.inf:
            m += 1
    alive = np.empty(m, dtype=np.int64)
    xa = np.empty((m, npc))
    da = np.empty(m)
    k = 0
    dmin = np.inf
    for q in range(lo, hi):
        if D[q] < np.inf:
            alive[k] = q
            pos[cn[q]] = q
            da[k] = D[q]
            if D[q] < dmin:
                dmin = D[q]
            for j in range(npc):
                xa[k, j] = last[cn[q], j]
            k += 1
    n_query = 0
    for q in range(lo1, hi1):
        if w1 + dmin <= ub - h[q] - u[q]:
            n_query += 1
    # A k-d tree pays off when many states query it; else one leaf in ascending D.
    leaf = _LEAF if n_query > 8 * np.log2(m + 1) else max(m, 1)
    perm, start, end, left, right, tlo, thi, mind = _build_tree(xa, da, leaf)
    xs, ds, ids = xa[perm], da[perm], alive[perm]
    if leaf == _LEAF:
        n_kept = _drop_dominated(xs, ds, ids, start, end, left, right, tlo, thi, mind, scale)
        if n_kept < _REBUILD * m:  # a smaller tree over the states that remain
            sel = np.empty(n_kept, dtype=np.int64)
            k = 0
            for node in range(len(start)):
                if left[node] < 0:
                    for r in range(start[node], end[node]):
                        sel[k] = r
                        k += 1
            xs, ds, ids = xs[sel], ds[sel], ids[sel]
            perm, start, end, left, right, tlo, thi, mind = _build_tree(xs, ds, leaf)
            xs, ds, ids = xs[perm], ds[perm], ids[perm]
    return (alive, xs, ds, ids, start, end, left, right, tlo, thi, mind, n_query)


@numba.njit(cache=True, nogil=True)
def _drop_dominated(xs, ds, ids, start, end, left, right, lo, hi, mind,
                    scale):  # pragma: no cover
    """Remove from the tree's leaves the states that cannot be the best jump source.

    State r is dominated by a if ``D(a) + s ||x_a - x_r|| < D(r)`` (by a margin): by the
    triangle inequality ``D(a) + s ||x_a - y|| < D(r) + s ||x_r - y||`` for every y, so
    the least jump cost into any state is the same without r (a chain of dominations
    ends at a state that is kept). Checked among near neighbours only (subtrees of at
    most ``_DOMINANCE_RANGE`` points); leaves are compacted and bounds recomputed.
    """
    n_nodes = len(start)
    npc = xs.shape[1]
    keep = np.ones(len(ds), dtype=np.bool_)
    stack = np.empty(n_nodes + 1, dtype=np.int64)
    stack[0] = 0
    sp = 1
    while sp > 0:
        sp -= 1
        node = stack[sp]
        s, e = start[node], end[node]
        if e - s > _DOMINANCE_RANGE:
            if left[node] >= 0:
                stack[sp] = left[node]
                stack[sp + 1] = right[node]
                sp += 2
            continue
        for r in range(s, e):
            margin = 1e-9 * (1.0 + abs(ds[r]))
            for a in range(s, e):
                if a == r or not keep[a] or ds[a] >= ds[r] - margin:
                    continue
                room = (ds[r] - margin - ds[a]) / scale if scale > 0.0 else np.inf
                d2 = 0.0
                for j in range(npc):
                    t = xs[a, j] - xs[r, j]
                    d2 += t * t
                if d2 < room * room:
                    keep[r] = False
                    break
    for node in range(n_nodes - 1, -1, -1):
        if left[node] < 0:
            k = start[node]
            for r in range(start[node], end[node]):
                if keep[r]:
                    if k != r:
                        ds[k] = ds[r]
                        ids[k] = ids[r]
                        for j in range(npc):
                            xs[k, j] = xs[r, j]
                        keep[k] = True
                    k += 1
            end[node] = k
            for j in range(npc):
                lo[node, j] = np.inf
                hi[node, j] = -np.inf
            mind[node] = np.inf
            for r in range(start[node], end[node]):
                if ds[r] < mind[node]:
                    mind[node] = ds[r]
                for j in range(npc):
                    lo[node, j] = min(lo[node, j], xs[r, j])
                    hi[node, j] = max(hi[node, j], xs[r, j])
        else:
            l, rr = left[node], right[node]
            mind[node] = min(mind[l], mind[rr])
            for j in range(npc):
                lo[node, j] = min(lo[l, j], lo[rr, j])
                hi[node, j] = max(hi[l, j], hi[rr, j])
    n_kept = 0
    for node in range(n_nodes):
        if left[node] < 0:
            n_kept += end[node] - start[node]
    return n_kept


@numba.njit(cache=True, nogil=True)
def _query_layer(cn, q_from, q_to, D, pred, u, h, prv, last, first, w1, scale, ub, pos,
                 xs, ds, ids, start, end, left, right, tlo, thi, mind):  # pragma: no cover
    """D and pred of the states [q_from, q_to) of the next layer; returns distances."""
    npc = last.shape[1]
    y = np.empty(npc)
    stack = np.empty(256, dtype=np.int64)
    bounds = np.empty(256)
    n_dist = 0
    has_tree = len(ds) > 0
    for q in range(q_from, q_to):
        b = cn[q]
        thr = ub - h[q] - u[q]
        best = np.inf
        arg = -1
        pb = prv[b]
        if pb >= 0:
            qa = pos[pb]
            if qa >= 0:
                best = D[qa] + scale * _dist(last, pb, first, b)
                arg = qa
                n_dist += 1
        if has_tree and w1 + mind[0] < best and w1 + mind[0] <= thr:
            for j in range(npc):
                y[j] = first[b, j]
            v, r, nd = _query(xs, ds, start, end, left, right, tlo, thi, mind, y, w1, scale,
                              best, thr, stack, bounds)
            n_dist += nd
            if r >= 0:
                best = v
                arg = ids[r]
        if best <= thr:
            D[q] = best + u[q]
            pred[q] = arg
    return n_dist


def _forward(cn, off, u, h, nxt, prv, last, first, w1, scale, ub, pos):
    """Pruned forward DP (see :func:`_exact_layers`): (flat path, cost, kept, distances)."""
    n = len(off) - 1
    D = np.full(len(cn), np.inf)
    pred = np.full(len(cn), -1, dtype=np.int64)
    keep0 = u[:off[1]] + h[:off[1]] <= ub
    D[:off[1]][keep0] = u[:off[1]][keep0]
    kept = int(keep0.sum())
    n_dist = 0
    for i in range(n - 1):
        lo, hi, lo1, hi1 = off[i], off[i + 1], off[i + 1], off[i + 2]
        (alive, xs, ds, ids, start, end, left, right, tlo, thi, mind,
         n_query) = _prepare_layer(cn, lo, hi, lo1, hi1, D, u, h, last, w1, scale, ub,
                                    pos)
        if len(alive) == 0:
            break
        args = (D, pred, u, h, prv, last, first, w1, scale, ub, pos, xs, ds, ids, start, end,
                left, right, tlo, thi, mind)
        n_dist += _run_queries(cn, lo1, hi1, n_query, args)
        pos[cn[alive]] = -1
        kept += int(np.count_nonzero(D[lo1:hi1] < np.inf))
    last_layer = D[off[n - 1]:off[n]]
    q = int(np.argmin(last_layer))
    if not np.isfinite(last_layer[q]):
        return np.full(n, -1, dtype=np.int64), np.inf, kept, n_dist
    path = np.empty(n, dtype=np.int64)
    qb = off[n - 1] + q
    for i in range(n - 1, -1, -1):
        path[i] = qb
        qb = pred[qb]
    return path, float(last_layer[q]), kept, n_dist


def _run_queries(cn, lo1, hi1, n_query, args) -> int:
    """The queries of one layer, split over threads when there are many (numba releases
    the GIL)."""
    threads = _threads()
    if threads == 1 or n_query < _PARALLEL_MIN:
        return _query_layer(cn, lo1, hi1, *args)
    cuts = np.linspace(lo1, hi1, threads + 1).astype(np.int64)
    futures = [_pool(threads).submit(_query_layer, cn, int(a), int(b), *args)
               for a, b in zip(cuts[:-1], cuts[1:], strict=True)]
    return sum(f.result() for f in futures)


# --------------------------------------------------------------------------------------
# method="dp": the oracle
# --------------------------------------------------------------------------------------


def _dp(p: _Problem) -> tuple[np.ndarray, float, int, int]:
    """Viterbi over every pair of consecutive candidates: D(b) = u(b) + min_a D(a) + T(a, b)."""
    sizes = np.diff(p.off)
    pairs = sizes[:-1] * sizes[1:]
    if len(pairs) and pairs.max() > DP_MAX_PAIRS:
        i = int(pairs.argmax())
        raise ParameterError(f"method='dp' handles at most {DP_MAX_PAIRS} candidate pairs "
                             f"between two inputs, got {int(pairs[i])} (inputs {i}, {i + 1})")
    w1 = p.weights.w_jump
    layer = [p.cn[p.off[i]:p.off[i + 1]] for i in range(p.n)]
    unary = [p.u[p.off[i]:p.off[i + 1]] for i in range(p.n)]
    D = unary[0].copy()
    back = []
    for i in range(p.n - 1):
        a, b = layer[i], layer[i + 1]
        dist = cdist(p.last[a].astype(np.float64), p.first[b].astype(np.float64))
        total = D[:, None] + (w1 * (p.nxt[a][:, None] != b[None, :]) + p.scale * dist)
        arg = total.argmin(axis=0)
        D = total[arg, np.arange(len(b))] + unary[i + 1]
        back.append(arg)
    idx = np.empty(p.n, dtype=np.int64)
    idx[-1] = int(D.argmin())
    cost = float(D[idx[-1]])
    for i in range(p.n - 2, -1, -1):
        idx[i] = back[i][idx[i + 1]]
    return idx, cost, int(sizes.sum()), int(pairs.sum())


# --------------------------------------------------------------------------------------
# method="window": the paper's bounded look-ahead
# --------------------------------------------------------------------------------------


def _window(p: _Problem, window: int) -> tuple[np.ndarray, float, int, int]:
    """Receding horizon (§4.2: "consider only 3–6 phonemes ahead of the current phoneme").

    At input t, with a_0 .. a_t-1 committed, the sub-sequence t .. t+window (the current
    phone and ``window`` phones ahead) is optimised exactly, its first transition being
    the one from a_t-1; a_t is committed from that optimum and the window slides by one.
    The last window (reaching input n-1) is committed whole. The cost of each window is
    Eq. (2) restricted to it, so its optimum is the one the paper's Priority-Queue
    algorithm would return on it (both are exact; ties aside). The result is a local
    optimum made of optimal short sequences: never better than the global one.
    """
    n = p.n
    idx = np.empty(n, dtype=np.int64)
    cost = 0.0
    n_exp = n_dist = 0
    prev = -1
    for t in range(n):
        stop = min(t + window + 1, n)
        cn, off, u = p.sub(t, stop, prev)
        sub_idx, sub_cost, e, d = _exact_layers(p, cn, off, u)
        n_exp += e
        n_dist += d + (off[1] if prev >= 0 else 0)
        if stop == n:
            idx[t:] = sub_idx
            cost += sub_cost
            break
        idx[t] = sub_idx[0]
        cost += float(u[sub_idx[0]])  # u of the first layer includes the transition in
        prev = int(cn[sub_idx[0]])
    return idx, cost, n_exp, n_dist


# --------------------------------------------------------------------------------------
# method="paper": the Priority-Queue (branch and bound) algorithm, steps (1)-(4)
# --------------------------------------------------------------------------------------


def _paper(p: _Problem, max_expansions: int,
           max_queue: int) -> tuple[np.ndarray, float, int, int, bool, bool]:
    """Cao et al.'s Priority-Queue algorithm (§4.2), as steps (1)–(4) describe it.

    (1) A queue node <seq, c, index> for every candidate of sn_1, c its Eq. (2) cost.
    (2) Remove the node q_min of least c; unless it is complete, create a queue node for
        every candidate of sn_{index+1}, with ``seq + (a,)`` and its cost, and queue them.
    (3) If q_min is complete (index = n): delete every queued node costlier than q_min.c;
        if q_min.c < mincost, it becomes the answer S_a and mincost.
    (4) Stop when the queue is empty, else go to (2).

    Representation (no change to the algorithm): ``seq`` is a parent pointer to the
    expanded node it extends. Once a complete sequence is known, a new node costlier than
    mincost is not queued: step (3) would delete it at the next complete sequence and,
    costs never decreasing along a sequence, it cannot lead to a cheaper one. Costs are
    >= 0 increments, so the first complete sequence removed is optimal; the search still
    runs to an empty queue as step (4) says.

    Capped: after ``max_expansions`` expansions, or when queueing the children would pass
    ``max_queue`` nodes, the search stops. The answer is then the best complete sequence
    if one was found (still optimal, by the argument above), else the deepest expanded
    partial sequence completed greedily (each step the cheapest transition plus unary
    cost): ``optimal=False``.
    """
    idx, cost, n_exp, n_dist, capped, found = _paper_kernel(
        p.cn, p.off, p.u, p.nxt, p.last, p.first, float(p.weights.w_jump), p.scale,
        max_expansions, max_queue)
    if capped:
        log.info("paper search stopped at its cap after %d expansions (%s)", n_exp,
                 "a complete sequence was found" if found else "none complete")
    return idx - p.off[:-1], float(cost), int(n_exp), int(n_dist), bool(capped), bool(found)


@numba.njit(cache=True, nogil=True)
def _sift_down(hc, hr, hq, start, size):  # pragma: no cover
    i = start
    c, r, q = hc[i], hr[i], hq[i]
    while True:
        child = 2 * i + 1
        if child >= size:
            break
        if child + 1 < size and hc[child + 1] < hc[child]:
            child += 1
        if hc[child] < c:
            hc[i], hr[i], hq[i] = hc[child], hr[child], hq[child]
            i = child
        else:
            break
    hc[i], hr[i], hq[i] = c, r, q


@numba.njit(cache=True, nogil=True)
def _push(hc, hr, hq, size, c, r, q):  # pragma: no cover
    i = size
    while i > 0:
        parent = (i - 1) // 2
        if hc[parent] <= c:
            break
        hc[i], hr[i], hq[i] = hc[parent], hr[parent], hq[parent]
        i = parent
    hc[i], hr[i], hq[i] = c, r, q


@numba.njit(cache=True, nogil=True)
def _paper_kernel(cn, off, u, nxt, last, first, w1, scale, max_expansions,
                  max_queue):  # pragma: no cover
    n = len(off) - 1
    cap = max(min(max_queue, max(1024, 4 * (off[1] - off[0]))), off[1] - off[0])
    hc = np.empty(cap)  # queue: cost, expanded parent record (-1 for a root), flat candidate
    hr = np.empty(cap, dtype=np.int64)
    hq = np.empty(cap, dtype=np.int64)
    rcap = 1024
    rec_parent = np.empty(rcap, dtype=np.int64)  # expanded nodes: parent record, candidate
    rec_q = np.empty(rcap, dtype=np.int64)
    rec_layer = np.empty(rcap, dtype=np.int64)
    n_rec = 0
    size = 0
    n_dist = 0
    # (1) Initialisation.
    mincost = np.inf
    best_r = -2
    best_q = -1
    for q in range(off[0], off[1]):
        _push(hc, hr, hq, size, u[q], -1, q)
        size += 1
    capped = False
    deep_layer = -1
    deep_cost = np.inf
    deep_r = -1
    deep_q = -1
    while size > 0:  # (4)
        # (2) Remove q_min.
        c, r, q = hc[0], hr[0], hq[0]
        size -= 1
        if size > 0:
            hc[0], hr[0], hq[0] = hc[size], hr[size], hq[size]
            _sift_down(hc, hr, hq, 0, size)
        layer = 0 if r < 0 else rec_layer[r] + 1
        if layer == n - 1:
            # (3) Queue pruning: a complete matching sequence.
            k = 0
            for j in range(size):
                if hc[j] <= c:
                    hc[k], hr[k], hq[k] = hc[j], hr[j], hq[j]
                    k += 1
            size = k
            for j in range(size // 2 - 1, -1, -1):
                _sift_down(hc, hr, hq, j, size)
            if c < mincost:
                mincost = c
                best_r = r
                best_q = q
            continue
        if n_rec >= max_expansions or size + (off[layer + 2] - off[layer + 1]) > max_queue:
            capped = True
            if layer > deep_layer or (layer == deep_layer and c < deep_cost):
                deep_layer, deep_cost, deep_r, deep_q = layer, c, r, q
            break
        if layer > deep_layer or (layer == deep_layer and c < deep_cost):
            deep_layer, deep_cost, deep_r, deep_q = layer, c, r, q
        # (2) Expand q_min: one queue node per candidate of the next phone.
        if n_rec == rcap:
            rcap *= 2
            rec_parent = np.concatenate((rec_parent, np.empty(rcap - n_rec, dtype=np.int64)))
            rec_q = np.concatenate((rec_q, np.empty(rcap - n_rec, dtype=np.int64)))
            rec_layer = np.concatenate((rec_layer, np.empty(rcap - n_rec, dtype=np.int64)))
        rec_parent[n_rec] = r
        rec_q[n_rec] = q
        rec_layer[n_rec] = layer
        me = n_rec
        n_rec += 1
        a = cn[q]
        lo1, hi1 = off[layer + 1], off[layer + 2]
        if size + (hi1 - lo1) > cap:
            newcap = min(max_queue, max(2 * cap, size + (hi1 - lo1)))
            hc = np.concatenate((hc, np.empty(newcap - cap)))
            hr = np.concatenate((hr, np.empty(newcap - cap, dtype=np.int64)))
            hq = np.concatenate((hq, np.empty(newcap - cap, dtype=np.int64)))
            cap = newcap
        for q1 in range(lo1, hi1):
            b = cn[q1]
            t = scale * _dist(last, a, first, b)
            n_dist += 1
            if nxt[a] != b:
                t += w1
            c1 = c + t + u[q1]
            if c1 > mincost:
                continue
            _push(hc, hr, hq, size, c1, me, q1)
            size += 1
    path = np.empty(n, dtype=np.int64)
    found = best_r > -2
    if found:
        cost = mincost
        path[n - 1] = best_q
        r = best_r
        i = n - 2
        while r >= 0:
            path[i] = rec_q[r]
            r = rec_parent[r]
            i -= 1
        return path, cost, n_rec, n_dist, capped, True
    # Capped before any complete sequence: complete the deepest one greedily.
    r = deep_r
    path[deep_layer] = deep_q
    i = deep_layer - 1
    while r >= 0:
        path[i] = rec_q[r]
        r = rec_parent[r]
        i -= 1
    cost = deep_cost
    for layer in range(deep_layer, n - 1):
        a = cn[path[layer]]
        best = np.inf
        qb = off[layer + 1]
        for q1 in range(off[layer + 1], off[layer + 2]):
            b = cn[q1]
            t = scale * _dist(last, a, first, b)
            n_dist += 1
            if nxt[a] != b:
                t += w1
            if t + u[q1] < best:
                best = t + u[q1]
                qb = q1
        path[layer + 1] = qb
        cost += best
    return path, cost, n_rec, n_dist, capped, False


__all__ = [
    "METHODS", "Candidates", "PathCost", "SearchResult", "SearchWeights", "candidates",
    "k_best", "path_cost", "search",
]
