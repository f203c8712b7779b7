"""Speech in, facial motion out: the lip-sync pipeline of Cao et al. (2005, §4.2-4.3).

1. The input speech is segmented into phones by the same code as ingest (given labels,
   forced alignment of a transcript, or phone recognition) and each phone gets its
   prosody curve (RASTA-PLP): the search nodes sn = <P, C, E>.
2. Candidates (animes with the same phoneme, a viseme class-mate when the database
   lacks it) are scored against each search node with DTW on the prosody curves
   (C_audio, Eq. 5), and the Anime Graph is searched for the sequence of least cost
   (Eq. 2): exactly by default, or with the paper's bounded look-ahead.
3. The chosen animes are time-warped, blended at jumps and smoothed (§4.3), and brought
   back from independent components to the database's channels. Beyond the paper, with
   ``k_best`` each phone's motion is instead a weighted mean of its k best-matching animes.
4. With an emotion asked for (a name, ``"auto"`` to classify the speech (§6), or a mix),
   the frames that came from animes of another emotion get their emotion components
   mapped into it (§5.2, Fig. 6; :mod:`animegraph.emotion.control`).
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from animegraph.emotion.control import map_frames, map_frames_over_time, resolve_emotion
from animegraph.search import SearchWeights, candidates, search
from animegraph.search import k_best as ranked_candidates
from animegraph.search.shortlist import SHORTLIST
from animegraph.search.shortlist import shortlist as cut_candidates
from animegraph.synthesis.assemble import (
    Phone,
    PostOptions,
    assemble,
    blend_k_best,
    output_frames,
)
from animegraph.synthesis.audio import (
    CANDIDATE_SOURCES,
    candidate_costs,
    likely_candidates,
    needs_posteriorgram,
    require_posteriorgrams,
)
from animegraph.synthesis.explain import blended_sources, explain_rows
from animegraph.synthesis.guide import (
    GUIDE_BLEND,
    blend_guide,
    check_guide_use,
    guide_names,
    guide_trajectory,
    guided_costs,
    target_costs,
)
from animegraph.synthesis.model import Model
from animegraph.synthesis.path import KNOWN_PHONES_CONTEXT
from animegraph.synthesis.result import Synthesis
from db.errors import DataError, ParameterError
from ingest.formats.phones_csv import Segment
from ingest.lowpass import smooth
from ingest.speech import ctc
from ingest.speech.features import RastaPlpConfig, rasta_plp, slice_frames
from ingest.speech.heard import segment_once
from ingest.speech.posteriorgram import HOP_S as POSTERIOR_HOP_S
from ingest.speech.posteriorgram import compute as compute_posteriorgram
from ingest.speech.quality import assess, is_silent, warnings_for
from ingest.speech.segment import segment


def synthesize(
    model: Model, audio: np.ndarray, sample_rate: int, *, text: str | None = None,
    labels: list[Segment] | None = None, emotion: str | dict | None = None,
    method: str = "exact", window: int | None = None, tolerance: float = 0.0,
    weights: SearchWeights | None = None, options: PostOptions | None = None,
    prosody_config: RastaPlpConfig | None = None, k_best: int | None = None,
    phones_engine: str | None = None, audio_cost: str = "plp", candidates_from: str = "label",
    guide=None, guide_blend: float = GUIDE_BLEND, guide_rank: bool = False,
    context: bool | None = None, recognized_guide=None, shortlist: int | None = SHORTLIST,
) -> Synthesis:
    """Facial motion for speech ``audio`` (shape (n_samples,)) from the database ``model``.

    Parameters
    ----------
    emotion : None, str or dict of str to float
        ``None``: no preference (the search's emotion cost is off, nothing is mapped).
        An emotion name (``"happy"``): the search prefers its animes (§4.2) and the frames
        that came from animes of other emotions get their emotion components mapped into
        it (§5.2, Fig. 6). ``"auto"``: the emotion the database's classifier finds in the
        speech (§6; ``result.emotion.probabilities`` holds its output). A mix, as a dict
        ``{"happy": 0.7, "neutral": 0.3}`` or the text ``"happy=0.7,neutral=0.3"``
        (:func:`animegraph.emotion.control.parse_emotion`): the search prefers the
        heaviest emotion's animes and every frame's emotion components are the weighted
        blend of their mappings into each emotion (beyond the paper). When the database
        has no animes of the wanted emotion, the search prefers the nearest emotion it has
        and the motion is mapped from there. Databases without an emotion model (built by
        an older animegraph) only steer the search. ``"auto"`` on speech longer than a
        window follows the emotion over time (``result.emotion.timeline``,
        :func:`animegraph.emotion.control.map_frames_over_time`); an
        :class:`~animegraph.emotion.control.EmotionChoice` already resolved is used as is.
    method, window, tolerance
        The search (:func:`animegraph.search.search`): ``"exact"`` (default), ``"window"``
        with ``window`` K (the paper's look-ahead), ``"paper"`` or ``"dp"``; ``tolerance``
        t > 0 lets the exact search stop at a sequence certified within (1 + t) × the
        optimum's cost.
    k_best : int, optional
        Beyond the paper: each phone's motion is a rank-weighted mean of ``k_best`` animes, the
        search's pick and the other candidates of least unary cost (audio, emotion;
        :func:`animegraph.search.k_best`, :func:`animegraph.synthesis.blend_k_best`),
        instead of the single picked anime joined at jumps (§4.3). None (default): the
        paper's synthesis. On real data with recognized phones 20 measured best; with
        exact phone labels (the synthetic corpus) the paper's synthesis is better
        (docs/results/lipsync.md, "Synthetic corpus"). ``joins`` is then empty.
        ``options.recentre`` says whether each
        anime is averaged relative to its recording's mean pose (None: when the database
        holds more than one speaker or session, :func:`recentres`).
    phones_engine : str, optional
        The phone engine without labels (:data:`ingest.speech.engines.ENGINES`; None: its
        default, PocketSphinx alignment of a transcript, hama recognition without one).
    audio_cost : str, optional
        C_audio of Eq. 5 (:data:`animegraph.synthesis.audio.AUDIO_COSTS`): ``"plp"`` (the
        paper's RASTA-PLP DTW, default), ``"posteriorgram"`` (DTW of phone posteriorgrams,
        beyond the paper; the database must hold them) or ``"plp+posteriorgram"``.
    candidates_from : str, optional
        ``"label"`` (the paper: animes of the input's phone) or ``"likely"`` (also those of
        the phones its posteriorgram makes likely,
        :func:`animegraph.synthesis.audio.likely_candidates`; needs posteriorgrams).
    guide : animegraph.baselines.base.BaselineModel, or a tuple of them, optional
        Beyond the paper (:mod:`animegraph.synthesis.guide`): a baseline fitted on this
        database whose predicted motion for the audio is averaged with the synthesized
        motion (``guide_blend``) and, with ``guide_rank``, guides the choice of animes.
    guide_blend : float, optional
        With ``guide``: the guide's share of the output motion, in [0, 1]
        (:data:`animegraph.synthesis.guide.GUIDE_BLEND` = 0.5, the mean of the two).
    guide_rank : bool, optional
        With ``guide``: add each candidate's distance to the guide's motion to C_audio
        (trajectory-guided selection); off by default (it did not hold across speakers,
        docs/results/lipsync.md, "Options measured against the default").
    context : bool, optional
        With ``k_best``, beyond the paper: rank each phone's animes by phonetic context
        (their recorded neighbour phones against the input's) before the audio cost
        (:func:`animegraph.search.k_best`). None (default): as
        :data:`animegraph.synthesis.path.KNOWN_PHONES_CONTEXT` says when the phones are
        known (labels, or a transcript aligned), off when they are recognised.
    shortlist : int or None, optional
        With ``k_best``, beyond the paper: the search and the ranking see only the first
        ``max(shortlist, k_best)`` candidates of each phone by the ranking's own order
        (:func:`animegraph.search.shortlist.shortlist`: the emotion term, the context with
        ``context``, then the unary cost), so that their cost does not grow with the
        database; the ``k_best - 1`` animes ranked next to the pick are the same, the pick
        is the best sequence over the shortlist. Default
        :data:`animegraph.search.shortlist.SHORTLIST`; None: every candidate (as with
        ``guide_rank``, whose ranking includes the guide's target cost).
    recognized_guide : guide, or a callable returning one (or None), optional
        With ``text`` and no ``guide``: the guide used when the transcript does not fit
        the speech and the phones are recognised instead, so that a wrong transcript
        gives what the speech alone would (``synth`` and ``batch`` pass the audio-only
        path's guide, :data:`animegraph.synthesis.path.AUDIO_ONLY_GUIDE`). A callable is
        called only then (a first use may fit the guide).

    Returns
    -------
    Synthesis
        ``emotion`` says what was chosen; ``notes`` what could not be mapped.

    Raises
    ------
    ParameterError
        On an unknown emotion, a malformed mix, or an unknown search method.
    DataError
        If the audio holds no speech; if a posteriorgram cost is asked of a database
        without posteriorgrams; for ``"auto"``, if the database has no classifier or
        the audio is too short to classify (< 0.25 s); for a mix, if the database cannot
        map into one of its emotions.
    """
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    if guide is not None:
        check_guide_use(guide_blend, guide_rank)
    check_shortlist(shortlist)
    if candidates_from not in CANDIDATE_SOURCES:
        raise ParameterError(f"candidates_from must be one of {', '.join(CANDIDATE_SOURCES)}, "
                             f"got {candidates_from!r}")
    posteriorgram = needs_posteriorgram(audio_cost) or candidates_from == "likely"
    if posteriorgram:
        require_posteriorgrams(model.graph, model.db.root)
    choice = resolve_emotion(emotion, model.emotion_model, model.graph.emotions, audio,
                             sample_rate, timeline=True)
    emotion = choice.search
    fallback: list[str] = []  # why a transcript was not aligned: the first warning
    with ctc.doubts() as doubted:  # ... or why it was, with doubt
        phones, method_used = query_phones(audio, sample_rate, text=text, labels=labels,
                                           prosody_config=prosody_config, engine=phones_engine,
                                           posteriorgram=posteriorgram,
                                           on_fallback=fallback.append)
    warnings = fallback + doubted + input_warnings(audio, sample_rate,
                                         method_used == "recognized" or posteriorgram,
                                         phones_heard=method_used != "labels")
    if (guide is None and text is not None and method_used == "recognized"
            and recognized_guide is not None):
        guide = recognized_guide() if callable(recognized_guide) else recognized_guide
        if guide is not None:
            check_guide_use(guide_blend, guide_rank)
    timings["segment_s"] = time.perf_counter() - t0

    t1 = time.perf_counter()
    cost_name = audio_cost
    if k_best is not None and context is None:
        context = KNOWN_PHONES_CONTEXT and method_used in ("labels", "aligned")
    cut = (max(shortlist, k_best) if k_best is not None and shortlist is not None
           and not (guide is not None and guide_rank) else None)
    cands, audio_cost = score_candidates(model, phones, emotion=emotion, audio_cost=cost_name,
                                         candidates_from=candidates_from, shortlist=cut,
                                         weights=weights, context=bool(context))
    guide_ics, target, unary = None, None, audio_cost
    if guide is not None:
        t_guide = time.perf_counter()
        guide_ics = guide_trajectory(model, guide, audio, sample_rate, phones, emotion=emotion)
        timings["guide_s"] = time.perf_counter() - t_guide
    if guide is not None and guide_rank:  # trajectory-guided: C_audio plus the target cost
        target = target_costs(model.graph, model.decomposer.mixing_, phones, cands.nodes,
                              guide_ics)
        unary = guided_costs(audio_cost, target)
    timings["audio_cost_s"] = time.perf_counter() - t1 - timings.get("guide_s", 0.0)
    t2 = time.perf_counter()
    result = search(model.graph, cands, unary, weights=weights or SearchWeights(),
                    emotion=emotion, method=method, window=window, tolerance=tolerance)
    timings["search_s"] = time.perf_counter() - t2

    t3 = time.perf_counter()
    ranked = ()
    if k_best is None:
        ics, joins = render_nodes(model, phones, result.nodes, options=options, emotion=emotion)
    else:
        ics, ranked = render_k_best(model, phones, cands, unary, result.nodes, k_best,
                                    weights=weights, options=options, emotion=emotion,
                                    context=context)
        joins = []
    notes: list[str] = []
    if choice.target is not None and model.emotion_model is not None:
        ics, notes = map_emotion(model, phones, result.nodes, ics, choice.target,
                                 options=options, timeline=choice.timeline)
    if guide_ics is not None and guide_blend > 0:
        ics = blend_guide(ics, guide_ics, guide_blend)
    motion = model.to_channels(ics)
    timings["post_s"] = time.perf_counter() - t3
    timings["total_s"] = time.perf_counter() - t0
    explain = explain_rows(model, phones, result, cands, audio_cost, target)
    blended = tuple(blended_sources(model.graph, r) for r in ranked)
    for row, animes in zip(explain, blended, strict=False):
        row["k_best"], row["pick_weight"] = len(animes), animes[0]["weight"]
    return Synthesis(motion=motion, ics=ics, fps=model.graph.fps, phones=phones,
                     segmentation=method_used, result=result, joins=joins, explain=explain,
                     timings=timings, emotion=choice, notes=tuple(notes), blended=blended,
                     warnings=tuple(warnings), context_ranked=bool(k_best and context),
                     recentred=k_best is not None and recentres(model, options),
                     cross_faded=k_best is not None and (options or PostOptions()).blend,
                     guided=guide_names(guide))


def input_warnings(audio: np.ndarray, sample_rate: int, phone_rate: bool, *,
                   phones_heard: bool = True) -> list[str]:
    """Lines on what may be wrong with the input speech (:mod:`ingest.speech.quality`);
    with ``phone_rate`` (hama has heard the audio already) also music or an unmodelled
    language. Without ``phones_heard`` (the phones were given as labels, e.g. by the
    synthesizer that spoke a batch line) a narrow band is not said: it matters to
    finding phones in the audio, and eSpeak NG's own speech has little above 4 kHz."""
    probs = None
    if phone_rate and ctc.available():
        try:
            probs = ctc.posteriors(np.asarray(audio, dtype=np.float32), sample_rate)
        except DataError:
            probs = None
    return warnings_for(assess(np.asarray(audio, dtype=np.float32), sample_rate, probs,
                               band=phones_heard))


def map_emotion(model: Model, phones, nodes, ics: np.ndarray, target, *,
                options: PostOptions | None = None, timeline=None
                ) -> tuple[np.ndarray, list[str]]:
    """Map the frames of each anime whose emotion is not ``target`` into it (Fig. 6), or,
    given an :class:`~animegraph.emotion.control.EmotionTimeline`, into the emotion its
    windows find at each frame's time.

    ``ics`` (n_frames, n_ics) is the rendered motion of ``nodes`` over ``phones``. The
    mapped emotion components are low-passed again (with the learned cutoffs, when
    smoothing is on) so that animes mapped from different emotions join smoothly.
    Returns the components and notes on frames left unmapped.
    """
    graph = model.graph
    n, ranges = output_frames(phones, graph.fps)
    frame_emotion = np.empty(len(ics), dtype=object)
    for node, (a, b) in zip(nodes, ranges, strict=True):
        frame_emotion[a:b] = graph.emotions[graph.node_emotion[int(node)]]
    if timeline is None:
        mapped, notes = map_frames(model.emotion_model, ics, frame_emotion.astype(str), target)
    else:
        names, weights = timeline.weights(np.arange(len(ics)) / graph.fps)
        mapped, notes = map_frames_over_time(model.emotion_model, ics,
                                             frame_emotion.astype(str), names, weights)
    e = model.emotion_model.split.emotion_components
    if (options is None or options.smooth) and e.size and not np.array_equal(mapped, ics):
        mapped[:, e] = smooth(mapped[:, e], model.cutoffs[e], graph.fps)
    return mapped, notes


def check_not_silent(audio: np.ndarray) -> None:
    """Raise :class:`~db.errors.DataError` if ``audio`` (shape (n_samples,) or
    (n_samples, n_channels), float in [-1, 1]) is silent
    (:func:`ingest.speech.quality.is_silent`, under -80 dBFS): nothing to
    animate, whatever a transcript says (``synth`` asks before checking one)."""
    if is_silent(audio):
        raise DataError("the audio is silent: there is no speech to animate")


def query_phones(audio: np.ndarray, sample_rate: int, *, text: str | None = None,
                 labels: list[Segment] | None = None,
                 prosody_config: RastaPlpConfig | None = None,
                 engine: str | None = None, posteriorgram: bool = False,
                 posteriors: np.ndarray | None = None,
                 on_fallback=None, silence: bool = False) -> tuple[tuple[Phone, ...], str]:
    """The search nodes of an utterance: its phones with their prosody curves.

    With ``posteriorgram`` each phone also gets its part of the utterance's phone
    posteriorgram (:mod:`ingest.speech.posteriorgram`; ``posteriors``, shape
    (n_frames, 39), if already computed). Returns the phones and how they were found
    (``labels``, ``aligned``, ``recognized``); a failed alignment of ``text`` is said to
    ``on_fallback`` (:func:`ingest.speech.segment.segment`). Audio whose phones are all
    silence is refused (DataError), unless ``silence`` (a live window within a pause,
    synthesized as a silence of an utterance is).
    """
    audio = np.asarray(audio, dtype=np.float32)
    if audio.ndim != 1:
        raise ParameterError(f"audio must be mono (n_samples,), got shape {audio.shape}")
    check_not_silent(audio)
    if labels is None:  # heard once within heard.remembered() (a command's synthesis)
        segments, method, _ = segment_once(audio, sample_rate, text=text, engine=engine,
                                           on_fallback=on_fallback)
    else:
        segments, method = segment(audio, sample_rate, labels=labels, engine=engine)
    if not silence and all(s.phone == "SIL" for s in segments):
        raise DataError("no speech found in the audio (every phone is silence)")
    cfg = prosody_config or RastaPlpConfig()
    curve = rasta_plp(audio, sample_rate, config=cfg)
    post = None
    if posteriorgram:
        post = posteriors if posteriors is not None else compute_posteriorgram(audio,
                                                                               sample_rate)
        post = np.asarray(post, dtype=np.float32)
    phones = tuple(Phone(s.phone, s.start, s.end,
                         np.ascontiguousarray(slice_frames(curve, s.start, s.end, hop_s=cfg.hop_s)),
                         None if post is None else np.ascontiguousarray(
                             slice_frames(post, s.start, s.end, hop_s=POSTERIOR_HOP_S)))
                   for s in segments)
    return phones, method


def score_candidates(model: Model, phones, *, emotion: str | None = None,
                     audio_cost: str = "plp", candidates_from: str = "label",
                     shortlist: int | None = None, weights: SearchWeights | None = None,
                     context: bool = False):
    """Candidate animes of every input phone and their audio costs (Eq. 5; ``audio_cost``
    one of :data:`animegraph.synthesis.audio.AUDIO_COSTS`, ``candidates_from`` one of
    :data:`animegraph.synthesis.audio.CANDIDATE_SOURCES`); with ``shortlist``, each
    phone's first ``shortlist`` by k-best's order (``weights``, ``context``;
    :func:`animegraph.search.shortlist.shortlist`), the paper's cost computed only where
    that order needs it."""
    cands = candidates(model.graph, [p.phone for p in phones], emotion=emotion)
    if candidates_from == "likely":
        cands = likely_candidates(model.graph, phones, cands)
    if shortlist is None:
        return cands, candidate_costs(model.graph, phones, cands.nodes, audio_cost)
    if audio_cost == "plp":  # the paper's cost: bounded from below, computed where needed
        cut = cut_candidates(model.graph, cands, shortlist, weights=weights, emotion=emotion,
                             context=context,
                             curves=[p.prosody.astype(np.float32) for p in phones])
    else:  # the others (a median over all candidates, posteriors): all of them first
        cut = cut_candidates(model.graph, cands, shortlist, weights=weights, emotion=emotion,
                             context=context,
                             costs=candidate_costs(model.graph, phones, cands.nodes, audio_cost))
    return cut.cands, cut.audio


def check_shortlist(shortlist) -> None:
    """ParameterError unless ``shortlist`` is None or an int >= 1."""
    if shortlist is not None and (isinstance(shortlist, bool)
                                  or not isinstance(shortlist, int | np.integer)
                                  or shortlist < 1):
        raise ParameterError(f"shortlist must be None or an int >= 1, got {shortlist!r}")


def render_nodes(model: Model, phones, nodes, *, options: PostOptions | None = None,
                 emotion: str | None = None) -> tuple[np.ndarray, list[dict]]:
    """Post-processed motion (independent components) of an anime sequence, §4.3."""
    graph = model.graph
    emotion_index = graph.emotions.index(emotion) if emotion is not None else None
    split = model.emotion_model.split if model.emotion_model is not None else None
    return assemble(graph, nodes, phones, cutoffs=model.cutoffs, options=options,
                    emotion=emotion_index,
                    speech=split.speech_components if split is not None else None)


def render_k_best(model: Model, phones, cands, audio_cost, nodes, k: int, *,
                  weights: SearchWeights | None = None, options: PostOptions | None = None,
                  emotion: str | None = None,
                  context: bool = False) -> tuple[np.ndarray, tuple[np.ndarray, ...]]:
    """Motion (independent components) averaging the ``k`` best animes of each phone around
    the matched ``nodes`` (beyond the paper; :func:`animegraph.search.k_best`, ranked by
    phonetic context first with ``context``), and those animes per phone, best first.
    ``options.recentre`` None is decided by :func:`recentres`."""
    ranked = ranked_candidates(model.graph, cands, audio_cost, nodes, k, weights=weights,
                               emotion=emotion, context=context)
    options = options or PostOptions()
    options = replace(options, recentre=recentres(model, options))
    return blend_k_best(model.graph, ranked, phones, cutoffs=model.cutoffs,
                        options=options), ranked


def recentres(model: Model, options: PostOptions | None = None) -> bool:
    """Whether k-best recentres each anime on its recording (``PostOptions.recentre``):
    as asked, else when the database's clips come from more than one recording session
    (:attr:`Model.sessions`: speakers, or corpus folders). Rest poses differ between
    speakers and their sessions; within one session a short recording's mean pose is
    mostly what it says, and subtracting it costs a little (docs/results/lipsync.md,
    "Options measured against the default": ``--no-recentre``)."""
    asked = (options or PostOptions()).recentre
    return len(model.sessions) > 1 if asked is None else bool(asked)
