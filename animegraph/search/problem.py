"""The search problem of §4.2: weights, candidates, the cost of a sequence, flat arrays.

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
  (:data:`ingest.speech.phones.VISEME_OF`) at ``w_backoff`` per input, and when the class
  is empty too by any node at ``w_backoff_any``. Every candidate of one input pays the
  same back-off, so it never changes which sequence is best; it makes costs of inputs
  with and without back-off comparable and is reported.

:class:`Problem` holds one search as flat arrays, the form every solver works on.
"""

from __future__ import annotations

import logging
import math
import numbers
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from animegraph.search.graph import PHONE_INDEX, AnimeGraph
from animegraph.search.jit import kernel
from db.errors import DataError, ParameterError
from ingest.speech.phones import PHONES, SILENCE, VISEME_CLASSES, VISEME_OF

log = logging.getLogger(__name__)

METHODS = ("exact", "paper", "window", "dp")

#: :func:`k_best` with ``context``: what a recorded neighbour scores when it is the input
#: neighbour's phone, and when it is only of the same viseme class (a phone that looks
#: alike on the lips, :data:`ingest.speech.phones.VISEME_CLASSES`). Set a priori, not
#: fitted: a half match for a class-mate (its lips look alike, its tongue may not), so
#: both neighbours' visemes (1.0) tie one neighbour's exact phone with no match on the
#: other side.
CONTEXT_SAME_PHONE = 1.0
CONTEXT_SAME_VISEME = 0.5



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
    # synthetic sentences (docs/results/lipsync.md, "Choices inside the default"): with 10, a
    # quarter of the nodes came from
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
        ARPAbet phones of :data:`ingest.speech.phones.PHONES`.
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
        emotion_code(graph, emotion)  # validates the type, logs an unknown emotion
    nodes: list[np.ndarray] = []
    backoff: list[str | None] = []
    every: np.ndarray | None = None
    for i, phone in enumerate(phones):
        if not isinstance(phone, str) or phone not in PHONE_INDEX:
            raise ParameterError(f"phones[{i}] must be one of the {len(PHONES)} ARPAbet phones "
                                 f"of ingest.speech.phones.PHONES, got {phone!r}")
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
    problem = Problem.build(graph, cands, audio, weights, emotion)
    if (indices is None) == (nodes is None):
        raise ParameterError("path_cost needs exactly one of indices and nodes, got "
                             f"{'both' if indices is not None else 'neither'}")
    n = len(cands)
    if nodes is not None:
        idx = node_indices(cands, nodes)
    else:
        idx = np.asarray(indices, dtype=np.int64).reshape(-1)
        if len(idx) != n:
            raise ParameterError(f"indices must have one entry per input ({n}), got {len(idx)}")
        sizes = cands.sizes
        if np.any(idx < 0) or np.any(idx >= sizes):
            i = int(np.flatnonzero((idx < 0) | (idx >= sizes))[0])
            raise ParameterError(f"indices[{i}] must be in [0, {sizes[i]}), got {idx[i]}")
    return problem.breakdown(idx)


def node_indices(cands: Candidates, nodes) -> np.ndarray:
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
           emotion: str | None = None, context: bool = False) -> tuple[np.ndarray, ...]:
    """Per input, its matched node followed by the ``k - 1`` best other candidates
    (beyond the paper: the animes :func:`animegraph.synthesis.blend_k_best` averages).

    Without ``context`` the others are ranked by unary cost, the part of Eq. (2) that
    depends on one node only: ``w3 C_audio`` plus the emotion and back-off terms.

    With ``context`` (beyond the paper) they are ranked lexicographically: first animes
    of the input's emotion (the emotion term, as in the unary cost), then by
    :func:`context_match`, the phonetic context of the anime in its recording against
    the input's (left and right neighbour phones), then by unary cost. This is the
    target cost on phonetic context of unit-selection speech synthesis (Hunt & Black
    1996, "Unit selection in a concatenative speech synthesis system using a large
    speech database", ICASSP, §2-3): by coarticulation a unit recorded in the context
    it is needed in is the better exemplar; the lips of a phone are shaped by its
    neighbours (Taylor et al. 2012, "Dynamic units of visual speech", SCA). Context
    ranks above the audio cost for the reason Cao et al. give the jump match the
    largest weight and the audio cost the smallest (§4.2, w1 >> w3): consecutive
    recorded motion carries the coarticulation, the prosody distance is the tie-break.
    The order is set a priori, not fitted to an evaluation set.

    Ties keep the candidates' order.

    Parameters
    ----------
    graph : AnimeGraph
    cands : Candidates
        n inputs (``cands.phones`` is needed for ``context``).
    audio : sequence of np.ndarray
        ``audio[i]``, shape (len(cands.nodes[i]),): C_audio (Eq. 5), as for :func:`search`.
    nodes : array-like of int, shape (n,)
        The matched sequence (e.g. ``search(...).nodes``); each a candidate of its input.
    k : int
        Nodes per input, >= 1 (fewer where an input has fewer candidates).
    weights : SearchWeights, optional
    emotion : str, optional
        The input's emotion; None uses ``cands.emotion``.
    context : bool, optional
        Rank by phonetic context before the audio cost (see above).

    Returns
    -------
    tuple of np.ndarray of int64
        ``ranked[i]``, shape (min(k, len(cands.nodes[i])),), starting with ``nodes[i]``.

    Raises
    ------
    ParameterError
        If ``k`` is not an int >= 1, on malformed inputs (as :func:`search`), if a
        node is not a candidate of its input, or if ``context`` is asked of candidates
        without their phones.
    """
    if isinstance(k, bool) or not isinstance(k, int | np.integer) or k < 1:
        raise ParameterError(f"k must be an int >= 1, got {k!r}")
    problem = Problem.build(graph, cands, audio, weights or SearchWeights(), emotion)
    match = context_match(graph, cands, problem.cn, problem.off) if context else None
    ranked = []
    for i, pick in enumerate(node_indices(cands, nodes)):
        lo, hi = problem.off[i], problem.off[i + 1]
        if match is None:
            order = np.argsort(problem.u[lo:hi], kind="stable")
        else:  # np.lexsort: the last key is the first; stable
            order = np.lexsort((problem.u[lo:hi], -match[lo:hi], problem.mismatch[lo:hi]))
        order = np.concatenate([[pick], order[order != pick][:k - 1]])
        ranked.append(problem.cn[lo + order])
    return tuple(ranked)


def concatenated(cands: Candidates) -> tuple[np.ndarray, np.ndarray]:
    """Every input's candidates in one array, shape (N,) int64, and the layer offsets,
    shape (n + 1,) int64 (input ``i``'s are ``[off[i], off[i + 1])``)."""
    off = np.zeros(len(cands.nodes) + 1, dtype=np.int64)
    np.cumsum([len(c) for c in cands.nodes], out=off[1:])
    cn = (np.concatenate([np.asarray(c, dtype=np.int64) for c in cands.nodes])
          if cands.nodes else np.zeros(0, dtype=np.int64))
    return cn, off


#: Viseme class of each phone index of :data:`ingest.speech.phones.PHONES`.
_VISEME_INDEX = np.array([sorted(VISEME_CLASSES).index(VISEME_OF[p]) for p in PHONES],
                         dtype=np.int16)


def context_match(graph: AnimeGraph, cands: Candidates, cn: np.ndarray | None = None,
                  off: np.ndarray | None = None) -> np.ndarray:
    """How well each candidate's recorded neighbours match the input's (beyond the paper).

    For input ``i`` with neighbours ``cands.phones[i - 1]`` and ``cands.phones[i + 1]``
    (``SIL`` past either end of the utterance), a candidate anime scores, on each side,
    :data:`CONTEXT_SAME_PHONE` when the anime next to it in its recording has that
    phone, :data:`CONTEXT_SAME_VISEME` when it has another phone of the same viseme
    class, else 0 (a recording's ends count as ``SIL``). Used by :func:`k_best`.

    Parameters
    ----------
    graph : AnimeGraph
    cands : Candidates
        n inputs, with ``phones``.
    cn, off : np.ndarray of int64, optional
        The candidates concatenated, shape (N,), and the layer offsets, shape (n + 1,),
        as :class:`Problem` holds them (built from ``cands`` when not given).

    Returns
    -------
    np.ndarray of float64, shape (N,)
        The sum of the two sides, in [0, 2 * CONTEXT_SAME_PHONE].

    Raises
    ------
    ParameterError
        If ``cands`` has no phones or not one per input.
    """
    n = len(cands)
    if len(cands.phones) != n:
        raise ParameterError(f"context needs the input phones, one per input ({n}), got "
                             f"{len(cands.phones)}")
    if cn is None or off is None:
        cn, off = concatenated(cands)
    sil = PHONE_INDEX[SILENCE]
    want = np.array([sil] + [PHONE_INDEX[p] for p in cands.phones] + [sil], dtype=np.int64)
    sizes = np.diff(off)
    score = np.zeros(len(cn), dtype=np.float64)
    for link, shift in ((graph.prev_node, 0), (graph.next_node, 2)):
        other = link[cn]
        got = np.where(other >= 0, graph.node_phone[np.maximum(other, 0)], sil)
        need = np.repeat(want[shift:shift + n], sizes)
        same_viseme = _VISEME_INDEX[got] == _VISEME_INDEX[need]
        score += np.where(got == need, CONTEXT_SAME_PHONE,
                          np.where(same_viseme, CONTEXT_SAME_VISEME, 0.0))
    return score


def emotion_code(graph: AnimeGraph, emotion: str) -> int:
    if not isinstance(emotion, str):
        raise ParameterError(f"emotion must be a string or None, got {emotion!r}")
    if emotion in graph.emotions:
        return graph.emotions.index(emotion)
    log.warning("emotion %r is not in the graph (%s): every node pays w_emotion", emotion,
                ", ".join(graph.emotions))
    return -1


@dataclass(frozen=True, eq=False)
class Problem:
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
              weights: SearchWeights, emotion: str | None) -> Problem:
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
        cn, off = concatenated(cands)
        sizes = np.diff(off)
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
            code = emotion_code(graph, emotion)
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



@kernel()
def row_dist(x: np.ndarray, a: int, y: np.ndarray, b: int) -> float:  # pragma: no cover
    s = 0.0
    for j in range(x.shape[1]):
        t = np.float64(x[a, j]) - np.float64(y[b, j])
        s += t * t
    return np.sqrt(s)

