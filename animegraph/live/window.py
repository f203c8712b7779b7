"""A live window synthesized as offline, each phone's choice of animes made once.

A stream re-synthesizes its window (:mod:`animegraph.live.stream`) every hop, and most of
the window's phones were in the previous one: their labels and boundaries have not
moved. Offline synthesis (:func:`animegraph.synthesis.synthesize`) would score every
candidate anime of every phone by DTW again, search, rank the k best and time-warp them
onto the phone. :func:`window_motion` runs the same steps, but :class:`PhoneMemory` keeps,
for each phone it has ranked (its label, start and end in the stream's clock, the
emotion), the k best animes, their audio costs and their time-warps. A phone found again
is not scored or warped again: its candidates are its kept animes (the search still
runs over the whole window, so its neighbours are joined to it as before) and its
ranking is the kept one, so the motion of a settled phone does not change from one
update to the next. Only new phones (the newest ones, and the window's first, which the
window's start cuts) are scored and warped.

The rest is as offline: the k-best blend over the window (cross-fades between phones,
low-pass), the emotion mapping, the guide's prediction for the window, blended 50/50.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

#: Phones kept (by their end) this long (s) before the window's start: a phone that
#: the window has left is never found again.
KEEP_S = 1.0
#: A phone is the one kept when its label and emotion are the same and its start and
#: end moved by at most this (s) between windows: boundaries refined on each window's
#: audio move by a few ms as the window's start moves (measured: 1-3 ms, eSpeak NG).
TOLERANCE_S = 0.02


@dataclass(frozen=True)
class Kept:
    """One phone's choice: its ranked animes (best first), their audio costs and
    time-warps (``positions``, shape (k, n_prosody) or None), its label, emotion, start
    and end (s, the stream's clock)."""

    ranked: np.ndarray
    costs: np.ndarray
    positions: np.ndarray | None
    phone: str
    emotion: object
    start_s: float
    end_s: float


class PhoneMemory:
    """The choice of animes of each phone a stream has ranked.

    Attributes
    ----------
    hits, misses : int
        Phones found again (not scored again), and phones scored.
    """

    def __init__(self) -> None:
        self._kept: list[Kept] = []
        self.hits = 0
        self.misses = 0

    def find(self, phone: str, emotion, start_s: float, end_s: float, *,
             cut: bool) -> Kept | None:
        """The phone kept with this label and emotion and (within :data:`TOLERANCE_S`)
        these boundaries; with ``cut`` (the window's start cuts the phone) its end only."""
        for k in self._kept:
            if (k.phone == phone and k.emotion == emotion
                    and abs(k.end_s - end_s) <= TOLERANCE_S
                    and (abs(k.start_s - start_s) <= TOLERANCE_S
                         or cut and k.start_s < start_s)):
                return k
        return None

    def put(self, kept: Kept) -> None:
        self._kept.append(kept)

    def forget(self, before_s: float) -> None:
        """Drop the phones that ended before ``before_s``."""
        self._kept = [k for k in self._kept if k.end_s >= before_s]

    def __len__(self) -> int:
        return len(self._kept)


def _resampled(positions: np.ndarray | None, n: int) -> np.ndarray | None:
    """Kept time-warps (k, m) for a phone now of ``n`` prosody frames: each row stretched
    linearly (the boundaries moved by a few ms)."""
    if positions is None or positions.shape[1] == n:
        return positions
    u = np.linspace(0.0, 1.0, n)
    v = np.linspace(0.0, 1.0, positions.shape[1])
    return np.stack([np.interp(u, v, row) for row in positions])


def window_motion(model, audio: np.ndarray, sample_rate: int, segments, offset_s: float, *,
                  memory: PhoneMemory, k_best: int, emotion=None, context: bool = False,
                  guide=None, shortlist: int | str | None = "default",
                  guide_share: float | None = None
                  ) -> tuple[np.ndarray, list[str]]:
    """The window's motion, shape (n_frames, n_channels), and warnings on its input.

    Parameters
    ----------
    model : animegraph.synthesis.Model
    audio : np.ndarray, shape (n_samples,)
        The window's audio.
    sample_rate : int
    segments : list of Segment
        Its phones (times from the window's start), as ``synthesize(labels=...)`` takes.
    offset_s : float
        The window's start in the stream's clock (phones are kept by their place there).
    memory : PhoneMemory
        The phones ranked before; the new ones are added.
    k_best, emotion, context, guide, shortlist
        As :func:`animegraph.synthesis.synthesize` (``emotion`` a name, a mix or None;
        a new phone's candidates cut to its first ``max(shortlist, k_best)`` by k-best's
        order, :func:`animegraph.search.shortlist.shortlist`; ``"default"``: offline's
        default, :data:`animegraph.search.shortlist.SHORTLIST`, read when called so that
        importing the stream does not load the search's kernels; None: every candidate).
        A kept phone's candidates are its kept animes.
    guide_share : float in [0, 1] or None
        The guide's share of the blended motion
        (:func:`animegraph.synthesis.guide.blend_guide`); None: offline's
        (:data:`animegraph.synthesis.guide.GUIDE_BLEND`).
    """
    from animegraph.emotion.control import resolve_emotion
    from animegraph.search import SearchWeights, candidates, search
    from animegraph.search import k_best as ranked_candidates
    from animegraph.search.problem import Candidates
    from animegraph.search.shortlist import SHORTLIST
    from animegraph.search.shortlist import shortlist as cut_candidates
    from animegraph.synthesis import blend_k_best, map_emotion, query_phones, recentres
    from animegraph.synthesis.assemble import PostOptions, blend_positions
    from animegraph.synthesis.audio import candidate_costs
    from animegraph.synthesis.guide import GUIDE_BLEND, blend_guide, guide_trajectory
    from animegraph.synthesis.pipeline import input_warnings

    graph = model.graph
    choice = resolve_emotion(emotion, model.emotion_model, graph.emotions, audio, sample_rate,
                             timeline=True)
    wanted = choice.search
    phones, _ = query_phones(audio, sample_rate, labels=segments, silence=True)  # a pause too
    warnings = input_warnings(audio, sample_rate, False, phones_heard=False)  # as labels
    kept = [memory.find(p.phone, wanted, p.start + offset_s, p.end + offset_s,
                        cut=i == 0 and p.start == 0.0) for i, p in enumerate(phones)]
    cands = candidates(graph, [p.phone for p in phones], emotion=wanted)
    new = [i for i, k in enumerate(kept) if k is None]
    memory.hits += len(phones) - len(new)
    memory.misses += len(new)
    weights = SearchWeights()
    nodes, costs = list(cands.nodes), [None] * len(phones)
    shortlist = SHORTLIST if shortlist == "default" else shortlist
    if shortlist is None:
        scored = candidate_costs(graph, [phones[i] for i in new], [cands.nodes[i] for i in new])
    else:  # the new phones' shortlists, ranked in their place (the window's phones
        # around them give the context); a kept phone is not scored again here
        sub = Candidates(nodes=tuple(cands.nodes[i] if i in new else cands.nodes[i][:0]
                                     for i in range(len(phones))),
                         backoff=cands.backoff, phones=cands.phones, emotion=cands.emotion)
        cut = cut_candidates(graph, sub, max(shortlist, k_best), weights=weights,
                             emotion=wanted, context=context,
                             curves=[p.prosody.astype(np.float32) for p in phones])
        scored = [cut.audio[i] for i in new]
        for i in new:
            nodes[i] = cut.cands.nodes[i]
    for i, c in zip(new, scored, strict=True):
        costs[i] = c
    for i, k in enumerate(kept):
        if k is not None:  # its candidates: the animes it was given (ascending, as kept)
            order = np.argsort(k.ranked)
            nodes[i], costs[i] = k.ranked[order], k.costs[order]
    cands = Candidates(nodes=tuple(nodes), backoff=cands.backoff, phones=cands.phones,
                       emotion=cands.emotion)
    result = search(graph, cands, costs, weights=weights, emotion=wanted)
    ranked = list(ranked_candidates(graph, cands, costs, result.nodes, k_best, weights=weights,
                                    emotion=wanted, context=context))
    for i, k in enumerate(kept):
        if k is not None:
            ranked[i] = k.ranked
    # Warped again: new phones, and kept ones whose start the window cuts.
    warp = [i for i, k in enumerate(kept)
            if k is None or abs(k.start_s - phones[i].start - offset_s) > TOLERANCE_S]
    fresh = blend_positions(graph, [ranked[i] for i in warp], [phones[i] for i in warp])
    positions: list = [None if k is None else _resampled(k.positions, len(phones[i].prosody))
                       for i, k in enumerate(kept)]
    for i, pos in zip(warp, fresh, strict=True):
        positions[i] = pos
    for i in new:
        # Each ranked anime's place among the phone's candidates (unique node ids).
        order = np.argsort(cands.nodes[i])
        rank_costs = costs[i][order[np.searchsorted(cands.nodes[i], ranked[i], sorter=order)]]
        p = phones[i]
        memory.put(Kept(np.asarray(ranked[i]), rank_costs, positions[i], p.phone, wanted,
                        p.start + offset_s, p.end + offset_s))
    options = replace(PostOptions(), recentre=recentres(model))
    ics = blend_k_best(graph, ranked, phones, cutoffs=model.cutoffs, options=options,
                       positions=positions)
    if choice.target is not None and model.emotion_model is not None:
        ics, _ = map_emotion(model, phones, result.nodes, ics, choice.target,
                             timeline=choice.timeline)
    if guide is not None:
        guide_ics = guide_trajectory(model, guide, audio, sample_rate, phones, emotion=wanted)
        ics = blend_guide(ics, guide_ics, GUIDE_BLEND if guide_share is None else guide_share)
    memory.forget(offset_s - KEEP_S)
    return model.to_channels(ics), warnings
