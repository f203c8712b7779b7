"""Each input phone's candidates cut to the few that k-best blending can use (beyond the paper).

With k-best blending (:func:`animegraph.search.k_best`) the motion of a phone is a mean
of the search's pick and the ``k - 1`` candidates ranked next by one fixed order (the
emotion term, with ``context`` the phonetic context, then the unary cost). On a large
database every phone has hundreds of thousands of candidates and the exact search over
all of them, and the audio cost (Eq. 5) of each, grow with the database. Unit-selection
speech synthesis faces the same growth and answers it the same way: the candidates of
each target are *pre-selected* by their target cost before the Viterbi search over
joins (Black & Taylor 1997, "Automatically clustering similar units for unit selection
in speech synthesis", Eurospeech; Conkie 1999, "Robust unit selection system for speech
synthesis", Joint ASA/EAA/DEGA meeting; Taylor 2009, *Text-to-Speech Synthesis*, §16.3).
:func:`shortlist` keeps each input's first ``size`` candidates by the k-best order, so
that the search and the ranking work on at most ``size`` candidates a phone whatever
the database holds.

What it changes and what it does not: the ``k - 1`` animes ranked next to the pick are
the same as over all candidates (they are among the first ``k <= size``); the pick is
the best sequence over the shortlist, which on a database with more than ``size``
candidates a phone may differ from the one over all of them.

The audio cost is computed only where the order needs it. The emotion and context keys
need no audio; within the group of equal keys that the cut falls in, candidates are
taken by a lower bound of C_audio (:func:`box_bounds`) and the exact cost is computed
for a candidate only while its bound does not exceed the ``size``-th exact cost found:
the selection is the one the full computation gives (``tests/test_shortlist.py``).
"""

from __future__ import annotations

import threading
import weakref
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numba
import numpy as np

from animegraph.search.dtw import audio_costs_many
from animegraph.search.graph import AnimeGraph
from animegraph.search.jit import kernel
from animegraph.search.problem import (
    Candidates,
    SearchWeights,
    concatenated,
    context_match,
    emotion_code,
)
from animegraph.search.threads import in_chunks
from db.errors import ParameterError

#: Candidates kept per input phone (``synth --shortlist``): five times k-best's default 20.
#: Measured against the search over every candidate in docs/results/speed.md, "A
#: database of 100 hours" (lip sync on GRID s1 and the time at 4M animes).
SHORTLIST = 100

#: The lower bound is shrunk by this fraction so that rounding never lifts it above the
#: exact cost of a curve whose frames all lie on its bounding box (one-frame animes).
_SAFETY = 1e-9

#: Candidate bounds computed on threads (the kernel releases the GIL) from this many on.
_PARALLEL_MIN = 4096


@dataclass(frozen=True, eq=False)
class Shortlist:
    """Candidates cut to the first ``size`` of each input by the k-best order.

    Attributes
    ----------
    cands : Candidates
        As given, each ``nodes[i]`` cut to at most ``size`` nodes (ascending).
    audio : list of np.ndarray of float64
        ``audio[i]``, shape (len(cands.nodes[i]),): C_audio of each kept candidate.
    n_all : int
        Candidates before the cut, over every input.
    n_costs : int
        Audio costs (DTWs) computed to make the cut.
    """

    cands: Candidates
    audio: list[np.ndarray]
    n_all: int
    n_costs: int


def shortlist(graph: AnimeGraph, cands: Candidates, size: int, *,
              curves: Sequence[np.ndarray] | None = None,
              costs: Sequence[np.ndarray] | None = None,
              weights: SearchWeights | None = None, emotion: str | None = None,
              context: bool = False) -> Shortlist:
    """The first ``size`` candidates of each input by :func:`animegraph.search.k_best`'s order.

    The order: with ``context``, candidates of the input's emotion first, then by
    :func:`animegraph.search.problem.context_match` (larger first), then by unary cost
    (w3 C_audio + emotion + back-off); without it by unary cost alone; ties in
    candidate order. An input with at most ``size`` candidates keeps them all.

    Parameters
    ----------
    graph : AnimeGraph
    cands : Candidates
        n inputs (with ``phones`` for ``context``).
    size : int
        Candidates kept per input, >= 1.
    curves : sequence of np.ndarray, optional
        ``curves[i]``, shape (n_frames_i, n_prosody): input ``i``'s RASTA-PLP curve; C_audio
        (Eq. 5, the paper's Euclidean DTW with a free warp) is then computed here, only
        for the candidates the cut needs.
    costs : sequence of np.ndarray, optional
        ``costs[i]``, shape (len(cands.nodes[i]),): C_audio already computed for every
        candidate (any audio cost); exactly one of ``curves`` and ``costs`` is given.
    weights : SearchWeights, optional
    emotion : str, optional
        The input's emotion; None uses ``cands.emotion``.
    context : bool, optional
        Rank by phonetic context before the audio cost, as k-best does with it.

    Returns
    -------
    Shortlist

    Raises
    ------
    ParameterError
        If ``size`` is not an int >= 1, if not exactly one of ``curves`` and ``costs``
        is given or they do not hold one entry per input, or as
        :func:`animegraph.search.dtw.audio_costs_many` on malformed curves.
    """
    if isinstance(size, bool) or not isinstance(size, int | np.integer) or size < 1:
        raise ParameterError(f"shortlist size must be an int >= 1, got {size!r}")
    if (curves is None) == (costs is None):
        raise ParameterError("shortlist needs exactly one of curves and costs")
    given = curves if curves is not None else costs
    if len(given) != len(cands):
        raise ParameterError(f"need one curve or cost array per input ({len(cands)}), "
                             f"got {len(given)}")
    weights = weights or SearchWeights()
    cn, off = concatenated(cands)
    emotion = emotion if emotion is not None else cands.emotion
    if emotion is not None:
        mismatch = graph.node_emotion[cn] != emotion_code(graph, emotion)
    else:
        mismatch = np.zeros(len(cn), dtype=bool)
    # The keys before the audio cost, as one number (smaller first): the context score
    # is at most 2, so the emotion flag dominates it.
    group = mismatch * 1000.0 - context_match(graph, cands, cn, off) if context else None
    backoff = [0.0 if b is None else weights.w_backoff_any if b == "any" else weights.w_backoff
               for b in cands.backoff]
    if costs is not None:
        exact = [np.asarray(c, dtype=np.float64).reshape(-1) for c in costs]
        for i, c in enumerate(exact):
            if len(c) != len(cands.nodes[i]):
                raise ParameterError(f"costs[{i}] must have shape ({len(cands.nodes[i])},), "
                                     f"got {c.shape}")

        def compute(lists: list[np.ndarray]) -> list[np.ndarray]:
            return [exact[i][pos] for i, pos in enumerate(lists)]

        bound = compute
    else:
        xs = [np.asarray(c, dtype=np.float64) for c in curves]

        def bound(lists: list[np.ndarray]) -> list[np.ndarray]:
            return box_bounds(graph, xs, [cands.nodes[i][pos] for i, pos in enumerate(lists)])

        def compute(lists: list[np.ndarray]) -> list[np.ndarray]:
            return audio_costs_many(xs, graph.prosody_values, graph.prosody_offsets,
                                    [cands.nodes[i][pos] for i, pos in enumerate(lists)])

    def unary(i: int, audio: np.ndarray, pos: np.ndarray) -> np.ndarray:
        # Problem.build's sum, term by term, so that the values are the same to the bit.
        u = weights.w_audio * audio + weights.w_emotion * mismatch[off[i] + pos]
        return u + backoff[i]

    # First every candidate surely kept and, of the group the cut falls in, the ``need``
    # of least bound; then, best bound first in batches that double, those of the group
    # whose bound does not exceed the need-th least exact cost found so far (a candidate
    # whose bound exceeds it cannot be kept; the cost found only falls).
    plan = [_plan(len(c), None if group is None else group[off[i]:off[i + 1]], size)
            for i, c in enumerate(cands.nodes)]
    # Bounds only where the cut falls inside a group (elsewhere every candidate is kept).
    cut = [tied if need < len(tied) else tied[:0] for _, tied, need in plan]
    lbs = [unary(i, b, cut[i]) for i, b in enumerate(bound(cut))]
    first = [np.argpartition(lb, need - 1)[:need] if need < len(tied) else np.arange(len(tied))
             for (_, tied, need), lb in zip(plan, lbs, strict=True)]  # places in ``tied``
    got = compute([np.concatenate([sure, tied[f]]) for (sure, tied, _), f in zip(plan, first,
                                                                                strict=True)])
    sure_audio = [a[:len(p[0])] for a, p in zip(got, plan, strict=True)]
    tied_audio = [np.full(len(p[1]), np.nan) for p in plan]  # NaN: not computed
    for i, f in enumerate(first):
        tied_audio[i][f] = got[i][len(plan[i][0]):]
    n_costs = sum(len(a) for a in got)
    pending = [np.zeros(0, dtype=np.int64)] * len(plan)  # places in ``tied``, by bound
    for i, ((_, tied, need), lb) in enumerate(zip(plan, lbs, strict=True)):
        if need < len(tied):
            tau = np.partition(unary(i, tied_audio[i][first[i]], tied[first[i]]), need - 1)[
                need - 1]
            rest = np.flatnonzero((lb <= tau) & np.isnan(tied_audio[i]))
            pending[i] = rest[np.argsort(lb[rest], kind="stable")]
    batch = [max(p[2], 1) for p in plan]
    while any(len(p) for p in pending):
        take = []
        for i, (_, tied, need) in enumerate(plan):
            if len(pending[i]):
                done = ~np.isnan(tied_audio[i])
                u = unary(i, tied_audio[i][done], tied[done])
                tau = np.partition(u, need - 1)[need - 1]
                pending[i] = pending[i][:np.searchsorted(lbs[i][pending[i]], tau, "right")]
            take.append(pending[i][:batch[i]])
            pending[i] = pending[i][batch[i]:]
            batch[i] *= 2
        got = compute([tied[t] for (_, tied, _), t in zip(plan, take, strict=True)])
        for i, t in enumerate(take):
            tied_audio[i][t] = got[i]
        n_costs += sum(len(t) for t in take)
    nodes, audio = [], []
    for i, (sure, tied, need) in enumerate(plan):
        done = np.flatnonzero(~np.isnan(tied_audio[i]))  # ascending: ties by place
        pick = done[np.argsort(unary(i, tied_audio[i][done], tied[done]), kind="stable")[:need]]
        keep = np.concatenate([sure, tied[pick]])
        values = np.concatenate([sure_audio[i], tied_audio[i][pick]])
        order = np.argsort(keep)
        nodes.append(cands.nodes[i][keep[order]])
        audio.append(values[order])
    return Shortlist(cands=replace(cands, nodes=tuple(nodes)), audio=audio, n_all=int(off[-1]),
                     n_costs=n_costs)


def _plan(n: int, group: np.ndarray | None, size: int) -> tuple[np.ndarray, np.ndarray, int]:
    """For one input of ``n`` candidates: positions surely kept (keys before the cut's),
    positions of the group the cut falls in, and how many of that group are kept."""
    if n <= size:
        return np.arange(n), np.zeros(0, dtype=np.int64), 0
    if group is None:  # no keys before the audio cost: one group
        return np.zeros(0, dtype=np.int64), np.arange(n), size
    cut = np.partition(group, size - 1)[size - 1]  # the key of the size-th candidate
    sure = np.flatnonzero(group < cut)
    tied = np.flatnonzero(group == cut)
    return sure, tied, size - len(sure)


# ------------------------------------------------------------------- the lower bound

_boxes: dict[int, tuple[weakref.ref, np.ndarray, np.ndarray]] = {}
_boxes_lock = threading.Lock()


def prosody_boxes(graph: AnimeGraph) -> tuple[np.ndarray, np.ndarray]:
    """Per-feature minimum and maximum of every anime's prosody curve, each shape
    (n_nodes, n_prosody) float32 (exact: minima and maxima of float32 values), computed
    once per graph (72 bytes an anime with the paper's 9 coefficients; an empty curve
    gets (-inf, inf), a bound of 0)."""
    with _boxes_lock:
        hit = _boxes.get(id(graph))
        if hit is not None and hit[0]() is graph:
            return hit[1], hit[2]
        values, offsets = graph.prosody_values, np.asarray(graph.prosody_offsets)
        d = values.shape[1]
        lo = np.full((graph.n_nodes, d), -np.inf, dtype=np.float32)
        hi = np.full((graph.n_nodes, d), np.inf, dtype=np.float32)
        full = np.flatnonzero(np.diff(offsets) > 0)
        if len(full):
            starts = offsets[full]
            # reduceat over the non-empty curves: each segment ends where the next
            # non-empty one starts (empty ones in between add no frames).
            lo[full] = np.minimum.reduceat(values[:offsets[full[-1] + 1]], starts, axis=0)
            hi[full] = np.maximum.reduceat(values[:offsets[full[-1] + 1]], starts, axis=0)
        for key in [k for k, v in _boxes.items() if v[0]() is None]:
            del _boxes[key]
        _boxes[id(graph)] = (weakref.ref(graph), lo, hi)
        return lo, hi


def box_bounds(graph: AnimeGraph, curves: Sequence[np.ndarray],
               nodes: Sequence[np.ndarray]) -> list[np.ndarray]:
    """A lower bound of C_audio (Eq. 5, Euclidean) of each input against each candidate.

    Eq. 5 charges input frame k the distance to ``L(C_anime)(k)``, the mean of the anime
    frames the warp matches to it; a mean of frames lies in their convex hull, inside
    the box spanned by the per-feature minimum and maximum of the whole anime curve.
    So the distance from the input frame to that box, averaged over the input's frames,
    is at most C_audio, for any warp (a band only narrows the frames a mean may take).

    Parameters
    ----------
    graph : AnimeGraph
    curves : sequence of np.ndarray
        ``curves[i]``, shape (n_frames_i >= 1, n_prosody).
    nodes : sequence of np.ndarray of int
        ``nodes[i]``: the candidates of input ``i``.

    Returns
    -------
    list of np.ndarray of float64, shapes (len(nodes[i]),)
    """
    lo, hi = prosody_boxes(graph)
    xs = [np.ascontiguousarray(c, dtype=np.float64) for c in curves]
    if any(x.ndim != 2 or len(x) == 0 or x.shape[1] != lo.shape[1] for x in xs):
        raise ParameterError(f"curves must be non-empty (n_frames, {lo.shape[1]}) arrays")
    sizes = np.array([len(n) for n in nodes], dtype=np.int64)
    flat = (np.concatenate([np.asarray(n, dtype=np.int64) for n in nodes]) if len(nodes)
            else np.zeros(0, dtype=np.int64))
    x_off = np.concatenate([[0], np.cumsum([len(x) for x in xs])]).astype(np.int64)
    x_all = np.concatenate(xs) if xs else np.zeros((0, lo.shape[1]))
    inputs = np.repeat(np.arange(len(xs), dtype=np.int64), sizes)
    out = np.empty(len(flat))
    threads = numba.get_num_threads() if len(flat) >= _PARALLEL_MIN else 1
    in_chunks(len(flat), threads,
              lambda a, b: _box_range(x_all, x_off, inputs, flat, lo, hi, a, b, out))
    out *= 1.0 - _SAFETY
    return np.split(out, np.cumsum(sizes)[:-1]) if len(sizes) else []


@kernel()
def _box_range(x_all, x_off, inputs, nodes, lo, hi, start, stop, out):
    d = x_all.shape[1]
    for t in range(start, stop):
        i = inputs[t]
        a = nodes[t]
        total = 0.0
        for f in range(x_off[i], x_off[i + 1]):
            s = 0.0
            for k in range(d):
                v = x_all[f, k]
                if v < lo[a, k]:
                    e = lo[a, k] - v
                elif v > hi[a, k]:
                    e = v - hi[a, k]
                else:
                    e = 0.0
                s += e * e
            total += np.sqrt(s)
        out[t] = total / (x_off[i + 1] - x_off[i])
