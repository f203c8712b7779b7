"""Held-out evaluation of lip-sync: synthesize a clip the database does not hold, score it.

The naive rows show what the search adds: a random anime of the right phoneme for every
phone, and phoneme matching that ignores every cost (always the first anime of the
phoneme). Used by ``scripts/eval_lipsync.py`` and the plots of :mod:`.plots`.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np

from animegraph.motion.measures import lip_channels, motion_scores, paper_scores
from animegraph.search import search
from animegraph.search.shortlist import SHORTLIST, shortlist
from animegraph.synthesis import (
    HELPER_MODES,
    PostOptions,
    query_phones,
    render_k_best,
    render_nodes,
    score_candidates,
)
from animegraph.synthesis.audio import candidate_costs, likely_candidates
from animegraph.synthesis.guide import blend_guide, guide_trajectory, guided_costs, target_costs


def baseline_nodes(candidate_nodes: Sequence[np.ndarray], kind: str,
                   rng: np.random.Generator | None = None) -> np.ndarray:
    """A naive anime sequence: ``"random"`` candidate per phone, or the ``"first"``."""
    if kind == "random":
        rng = rng or np.random.default_rng(0)
        return np.array([int(rng.choice(c)) for c in candidate_nodes], dtype=np.int64)
    if kind == "first":
        return np.array([int(c[0]) for c in candidate_nodes], dtype=np.int64)
    raise ValueError(f"unknown baseline {kind!r}")


#: Methods compared: exact search, the paper's look-ahead, the two baselines, and (beyond
#: the paper) the exact search's motion averaged over the 20 best animes of each phone
#: (``synthesize(..., k_best=20)``; docs/results/lipsync.md, "Choices inside the default"). A
#: suffix picks another
#: audio cost than the paper's RASTA-PLP (:data:`COST_SUFFIXES`): ``kbest20-pg`` ranks by
#: posteriorgram DTW, ``kbest20-mix`` by both (``synthesize(..., audio_cost=...)``).
METHODS = ("exact", "window3", "window6", "random", "first", "kbest20", "exact-pg",
           "kbest20-pg", "kbest20-mix", "kbest20-pg-likely", "kbest20-mix-likely",
           "kbest20-guided", "kbest20-guided-blend", "kbest20-blend", "kbest20-ctx",
           "kbest20-ctx-blend", "kbest20-raw", "kbest20-ctx-raw", "kbest20-raw-blend",
           "kbest20-ctx-raw-blend", "kbest20-rc", "kbest20-ctx-rc", "kbest20-rc-blend",
           "kbest20-ctx-rc-blend", "kbest20-cut", "kbest20-ctx-cut", "kbest20-cut-blend",
           "kbest20-rc-cut-blend", "kbest20-ctx-all", "kbest20-all-blend", "kbest20-all")
#: The methods scored unless others are asked for (those of the paper's audio cost;
#: ``kbest20-ctx`` is ``synth``'s default with known phones).
DEFAULT_METHODS = ("exact", "window3", "window6", "random", "first", "kbest20", "kbest20-ctx")
#: ``kbest<K>[-ctx]-raw``: the K animes averaged as recorded, never relative to their
#: recordings' mean poses (``PostOptions(recentre=False)``; the k-best rows recentre as
#: ``synth`` does by default: with more than one speaker or session in the database).
RAW_SUFFIX = "-raw"
#: ``kbest<K>[-ctx]-rc``: always recentred (``PostOptions(recentre=True)``), whatever the
#: number of speakers or sessions.
RECENTRE_SUFFIX = "-rc"
RECENTRE_SUFFIXES = {RAW_SUFFIX: False, RECENTRE_SUFFIX: True}
#: ``kbest<K>[-ctx][-rc|-raw]-cut``: each phone's mean cut at its boundaries, not
#: cross-faded into its neighbours' through the recorded transitions
#: (``PostOptions(blend=False)``).
CUT_SUFFIX = "-cut"
#: ``kbest<K>[...]-all``: the search over every candidate of each phone, not over the
#: first ``max(SHORTLIST, K)`` by the ranking's order as ``synth`` does
#: (:func:`animegraph.search.shortlist.shortlist`, docs/results/speed.md, "A database of
#: 100 hours").
ALL_SUFFIX = "-all"
#: ``kbest<K>-ctx``: the K animes ranked by phonetic context first
#: (``animegraph.search.k_best(..., context=True)``; beyond the paper).
CONTEXT_SUFFIX = "-ctx"
#: Method-name suffix -> audio cost (:data:`animegraph.synthesis.audio.AUDIO_COSTS`).
COST_SUFFIXES = {"-pg": "posteriorgram", "-mix": "plp+posteriorgram"}
#: Guide suffixes (:mod:`animegraph.synthesis.guide`; need ``score_heldout(guide=...)``):
#: ``-guided`` adds the guide's target cost to C_audio (trajectory-guided selection),
#: ``-blend`` averages the output with the guide's motion (``GUIDE_BLEND``), both: both.
GUIDE_SUFFIXES = ("-guided-blend", "-guided", "-blend")
#: Rows only on request (``eval_lipsync.py --graph-methods``): the exact search with the
#: helper pairs of §4.3 blended one way or another (``exact-<mode>``: ``PostOptions(helper=
#: mode)``, e.g. ``exact-paper``, ``exact-anchored``).
OPTIONAL_METHODS = tuple(f"exact-{mode}" for mode in HELPER_MODES)


#: GRID's within-speaker split (docs/results/lipsync.md, "GRID s1"): in clip-id order every
#: GRID_HOLDOUT-th clip
#: is held out (index % 5 == 4), the others are the database.
GRID_HOLDOUT = 5


def grid_split(clips: Sequence) -> tuple[list, list]:
    """``(database, held out)`` of GRID clips by :data:`GRID_HOLDOUT`, in clip-id order."""
    ordered = sorted(clips, key=lambda c: c.clip_id)
    held = [k % GRID_HOLDOUT == GRID_HOLDOUT - 1 for k in range(len(ordered))]
    return ([c for c, h in zip(ordered, held, strict=True) if not h],
            [c for c, h in zip(ordered, held, strict=True) if h])


def split_method(method: str) -> tuple[str, str, str]:
    """``"kbest20-pg-likely"`` -> ``("kbest20", "posteriorgram", "likely")``; no suffix: the
    paper's ``"plp"`` cost over the ``"label"`` candidates."""
    source = "label"
    if method.endswith("-likely"):
        method, source = method[: -len("-likely")], "likely"
    for suffix, cost in COST_SUFFIXES.items():
        if method.endswith(suffix):
            return method[: -len(suffix)], cost, source
    return method, "plp", source


def split_guide(method: str) -> tuple[str, bool, bool]:
    """``"kbest20-guided-blend"`` -> ``("kbest20", True, True)``: the method without its
    guide suffix (:data:`GUIDE_SUFFIXES`), guided ranking, blending with the guide."""
    for suffix in GUIDE_SUFFIXES:
        if method.endswith(suffix):
            return method[: -len(suffix)], "guided" in suffix, "blend" in suffix
    return method, False, False


def heldout_query(model, clip, *, posteriorgram: bool = False):
    """The search input of a held-out prepared clip, from its audio and its phones.

    With ``posteriorgram`` the phones also get their posteriorgrams (the clip's own if it
    has one, else computed).

    Returns
    -------
    (phones, emotion or None, candidates, audio costs)
    """
    audio = clip.audio.astype(np.float32) / 32767.0
    emotion = clip.emotion if clip.emotion in model.graph.emotions else None
    phones, _ = query_phones(audio, clip.sample_rate, labels=list(clip.phones),
                             posteriorgram=posteriorgram,
                             posteriors=getattr(clip, "posteriors", None))
    cands, audio_cost = score_candidates(model, phones, emotion=emotion)
    return phones, emotion, cands, audio_cost


def method_nodes(model, cands, audio_cost, method: str, *, emotion: str | None = None,
                 rng: np.random.Generator | None = None) -> tuple[np.ndarray, int]:
    """The anime sequence one of :data:`METHODS` picks, and its number of jump matches.

    ``"kbest<K>"`` picks the exact search's sequence (its motion averages K animes a phone:
    :func:`method_motion`).
    """
    if method in ("random", "first"):
        nodes = baseline_nodes(cands.nodes, method, rng)
        return nodes, int(np.sum(model.graph.next_node[nodes[:-1]] != nodes[1:]))
    window = int(method[len("window"):]) if method.startswith("window") else None
    result = search(model.graph, cands, audio_cost, emotion=emotion,
                    method="window" if window else "exact", window=window)
    return result.nodes, result.n_jumps


def method_motion(model, phones, cands, audio_cost, method: str, *,
                  emotion: str | None = None,
                  rng: np.random.Generator | None = None) -> tuple[np.ndarray, int]:
    """The motion (independent components) one of :data:`METHODS` synthesizes from the
    search input of :func:`heldout_query`, and its number of jump matches."""
    if method.startswith("kbest"):
        every = method.endswith(ALL_SUFFIX)
        method = method.removesuffix(ALL_SUFFIX)
        blend = not method.endswith(CUT_SUFFIX)
        method = method.removesuffix(CUT_SUFFIX)
        recentre = None  # synth's default
        for suffix, on in RECENTRE_SUFFIXES.items():
            if method.endswith(suffix):
                recentre, method = on, method.removesuffix(suffix)
        context = method.endswith(CONTEXT_SUFFIX)
        k = int(method[len("kbest"):len(method) - len(CONTEXT_SUFFIX) * context])
        if not every:  # synth's cut of the candidates before the search (the same costs)
            cut = shortlist(model.graph, cands, max(SHORTLIST, k), costs=audio_cost,
                            emotion=emotion, context=context)
            cands, audio_cost = cut.cands, cut.audio
        nodes, jumps = method_nodes(model, cands, audio_cost, "exact", emotion=emotion)
        return render_k_best(model, phones, cands, audio_cost, nodes, k, emotion=emotion,
                             context=context,
                             options=PostOptions(recentre=recentre, blend=blend))[0], jumps
    nodes, jumps = method_nodes(model, cands, audio_cost, method, emotion=emotion, rng=rng)
    options = (PostOptions(helper=method[len("exact-"):]) if method in OPTIONAL_METHODS
               else None)
    return render_nodes(model, phones, nodes, emotion=emotion, options=options)[0], jumps


def score_heldout(model, clip, *, methods: Sequence[str] = DEFAULT_METHODS,
                  estimators: dict | None = None,
                  norm: tuple[np.ndarray, np.ndarray] | None = None,
                  rng: np.random.Generator | None = None,
                  predictions: dict | None = None, guide=None) -> dict:
    """Synthesize a held-out prepared clip from its audio and phones; score every method.

    Parameters
    ----------
    model : animegraph.synthesis.Model
        A database that does not contain the clip.
    clip : ingest.prepare.PreparedClip
        The clip (its motion, in the database's space, is the ground truth).
    methods : sequence of str
        Anime Graph search methods (:data:`METHODS`) to score.
    estimators : dict of str to BaselineModel, optional
        Fitted baselines (:mod:`animegraph.baselines`), scored on the clip's audio alone.
    norm : (center, scale), optional
        :func:`displacement_scale` of the training motion; with it every row also has
        :func:`paper_scores`.
    predictions : dict, optional
        Filled with each method's motion, shape (n_frames, n_channels).
    guide : BaselineModel, optional
        Fitted on the same training clips: the guide of the methods with a guide suffix
        (:data:`GUIDE_SUFFIXES`, :mod:`animegraph.synthesis.guide`).

    Only the frames whose truth was observed are scored (``frames_scored`` of ``frames``):
    frames filled across a gap in the capture (``clip.missing``) are left out.

    Every row has ``synth_s`` (seconds to synthesize the clip: the prosody query, search
    and rendering for the Anime Graph, ``predict`` for a baseline; phone labels given)
    and ``rtf`` (``synth_s`` over the clip's duration).
    """
    rng = rng or np.random.default_rng(0)
    t0 = time.perf_counter()
    wanted = {split_method(split_guide(m)[0])[1:] for m in methods} - {("plp", "label")}
    phones, emotion, cands, audio_cost = heldout_query(model, clip, posteriorgram=bool(wanted))
    pools = {"label": cands}
    if any(source == "likely" for _, source in wanted):
        pools["likely"] = likely_candidates(model.graph, phones, cands)
    costs = {("plp", "label"): audio_cost}
    for name, source in wanted:
        costs[name, source] = candidate_costs(model.graph, phones, pools[source].nodes, name)
    query_s = time.perf_counter() - t0
    guide_ics, guide_s, guided = None, 0.0, {}
    if any(split_guide(m)[1] or split_guide(m)[2] for m in methods):
        if guide is None:
            raise ValueError("a guided method needs score_heldout(guide=...)")
        t0 = time.perf_counter()
        guide_ics = guide_trajectory(model, guide, clip.audio.astype(np.float32) / 32767.0,
                                     clip.sample_rate, phones, emotion=emotion)
        guide_s = time.perf_counter() - t0
    truth = clip.motion.astype(np.float64)
    # Channels that move: their share of the database's motion variance (from the PCA).
    share = (model.decomposer.components_**2).T @ model.decomposer.explained_variance_ratio_
    active = np.flatnonzero(share > 1e-4 * share.max())
    lips = lip_channels(model.names, model.groups)
    rows = {}

    # Only frames whose truth was observed are scored: a frame filled across a gap (a
    # video frame without a face, a dropped marker) is the filler's guess, not the actor.
    observed = ~np.asarray(clip.missing, dtype=bool).any(axis=1)

    def record(name, pred, extra):
        n = min(len(pred), len(truth))
        keep = observed[:n]
        p, t = pred[:n][keep], truth[:n][keep]
        row = {**motion_scores(p, t, model.names, model.groups, model.kind, active), **extra}
        if norm is not None:
            row |= paper_scores(p, t, active, lips, norm)
        row["rtf"] = row["synth_s"] / clip.duration
        rows[name] = row
        if predictions is not None:
            predictions[name] = pred

    for method in methods:
        t0 = time.perf_counter()
        plain, guided_rank, blend = split_guide(method)
        base, cost, source = split_method(plain)
        unary = costs[cost, source]
        if guided_rank:
            if (cost, source) not in guided:
                guided[cost, source] = guided_costs(unary, target_costs(
                    model.graph, model.decomposer.mixing_, phones, pools[source].nodes,
                    guide_ics))
            unary = guided[cost, source]
        ics, jumps = method_motion(model, phones, pools[source], unary, base,
                                   emotion=emotion, rng=rng)
        if blend:
            ics = blend_guide(ics, guide_ics)
        pred = model.decomposer.inverse_transform(ics)  # the database's (stabilised) space
        extra_s = guide_s if (guided_rank or blend) else 0.0
        record(method, pred, {"jumps": jumps,
                              "synth_s": query_s + extra_s + time.perf_counter() - t0})
    for name, est in (estimators or {}).items():
        t0 = time.perf_counter()
        pred = est.predict(clip.audio, clip.sample_rate, n_frames=len(truth),
                           emotion=clip.emotion if clip.emotion in est.emotions_ else None)
        record(name, pred, {"synth_s": time.perf_counter() - t0})
    return {"clip": clip.clip_id, "emotion": clip.emotion, "n_phones": len(phones),
            "seconds": round(clip.duration, 2), "frames_scored": int(observed.sum()),
            "frames": len(truth), "methods": rows}
