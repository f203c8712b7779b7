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
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from animegraph.dtw import audio_costs_many
from animegraph.emotion.control import EmotionChoice, map_frames, resolve_emotion
from animegraph.graph import AnimeGraph
from animegraph.search import SearchResult, SearchWeights, candidates, search
from animegraph.search import k_best as ranked_candidates
from animegraph.synthesis import (
    Phone,
    PostOptions,
    assemble,
    blend_k_best,
    output_frames,
    rank_weights,
    smooth,
)
from db.errors import DataError, ParameterError
from db.store import Database
from ingest.decompose import MotionDecomposer
from ingest.emotion.model import EmotionModel
from ingest.features import RastaPlpConfig, rasta_plp, slice_frames
from ingest.formats.phones_csv import Segment
from ingest.motion import fill_gaps, head_points, stabilize_points, unstabilize_points
from ingest.segment import segment


@dataclass(frozen=True, eq=False)
class Model:
    """Everything synthesis needs from a database, loaded once."""

    db: Database
    graph: AnimeGraph
    decomposer: MotionDecomposer
    cutoffs: np.ndarray
    names: tuple[str, ...]
    groups: tuple[str, ...]
    kind: str
    head_reference: np.ndarray | None
    emotion_model: EmotionModel | None = None  # None: a database built before emotion models

    @classmethod
    def load(cls, path) -> Model:
        db = Database.open(path)
        arrays = db.arrays()
        channels = db.table("channels").to_pylist()
        try:
            emotion_model = EmotionModel.from_database(db)
        except DataError:
            emotion_model = None
        return cls(
            db=db, graph=AnimeGraph.from_database(db),
            decomposer=MotionDecomposer.from_arrays(arrays), cutoffs=arrays["ic_cutoff_hz"],
            names=tuple(c["name"] for c in channels), groups=tuple(c["group"] for c in channels),
            kind=channels[0]["kind"], head_reference=arrays.get("head_reference"),
            emotion_model=emotion_model,
        )

    def to_channels(self, ics: np.ndarray) -> np.ndarray:
        """Motion in the database's channels (world coordinates for a head group)."""
        return to_world(self.decomposer.inverse_transform(ics), self.groups,
                        self.head_reference)

    @property
    def rigid_head(self) -> bool:
        """True if the database stores motion head-stabilised (a rigid head group)."""
        return self.head_reference is not None and head_points(self.groups) >= 3

    def to_local(self, motion: np.ndarray) -> np.ndarray:
        """Motion (n_frames, n_channels) in the database's channels, gaps filled, in the
        stored (head-stabilised) space that its PCA/ICA model describes: the inverse of
        :meth:`to_channels` before the decomposition."""
        filled, _ = fill_gaps(np.asarray(motion, dtype=np.float64), self.names)
        if self.rigid_head:
            return stabilize_points(filled, self.groups, self.head_reference)
        return filled


def to_world(motion: np.ndarray, groups, head_reference: np.ndarray | None) -> np.ndarray:
    """Motion (n_frames, n_channels) in the database's stored, head-stabilised space back
    in world coordinates (unchanged when the database has no rigid head group)."""
    if head_reference is not None and head_points(groups) >= 3:
        motion = unstabilize_points(motion, groups, head_reference)
    return motion


@dataclass(frozen=True, eq=False)
class Synthesis:
    """A synthesized utterance.

    Attributes
    ----------
    motion : np.ndarray, shape (n_frames, n_channels)
        In the database's channels, at ``fps``.
    ics : np.ndarray, shape (n_frames, n_ics)
        The same motion in independent components.
    blended : tuple of list of dict
        With ``k_best``: per phone the animes its motion averages (node, clip_id,
        position, weight), the search's pick first; empty otherwise.
    """

    motion: np.ndarray
    ics: np.ndarray
    fps: float
    phones: tuple[Phone, ...]
    segmentation: str
    result: SearchResult
    joins: list[dict]
    explain: list[dict]
    timings: dict = field(default_factory=dict)
    emotion: EmotionChoice = field(default_factory=lambda: EmotionChoice(None, None))
    notes: tuple[str, ...] = ()
    blended: tuple[list[dict], ...] = ()


def synthesize(
    model: Model, audio: np.ndarray, sample_rate: int, *, text: str | None = None,
    labels: list[Segment] | None = None, emotion: str | dict | None = None,
    method: str = "exact", window: int | None = None, tolerance: float = 0.0,
    weights: SearchWeights | None = None, options: PostOptions | None = None,
    prosody_config: RastaPlpConfig | None = None, k_best: int | None = None,
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
        an older animegraph) only steer the search.
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
        (docs/results.md). ``joins`` is then empty.

    Returns
    -------
    Synthesis
        ``emotion`` says what was chosen; ``notes`` what could not be mapped.

    Raises
    ------
    ParameterError
        On an unknown emotion, a malformed mix, or an unknown search method.
    DataError
        If the audio holds no speech; for ``"auto"``, if the database has no classifier or
        the audio is too short to classify (< 0.25 s); for a mix, if the database cannot
        map into one of its emotions.
    """
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    choice = resolve_emotion(emotion, model.emotion_model, model.graph.emotions, audio,
                             sample_rate)
    emotion = choice.search
    phones, method_used = query_phones(audio, sample_rate, text=text, labels=labels,
                                       prosody_config=prosody_config)
    timings["segment_s"] = time.perf_counter() - t0

    t1 = time.perf_counter()
    cands, audio_cost = score_candidates(model, phones, emotion=emotion)
    timings["audio_cost_s"] = time.perf_counter() - t1
    t2 = time.perf_counter()
    result = search(model.graph, cands, audio_cost, weights=weights or SearchWeights(),
                    emotion=emotion, method=method, window=window, tolerance=tolerance)
    timings["search_s"] = time.perf_counter() - t2

    t3 = time.perf_counter()
    ranked = ()
    if k_best is None:
        ics, joins = render_nodes(model, phones, result.nodes, options=options, emotion=emotion)
    else:
        ics, ranked = render_k_best(model, phones, cands, audio_cost, result.nodes, k_best,
                                    weights=weights, options=options, emotion=emotion)
        joins = []
    notes: list[str] = []
    if choice.target is not None and model.emotion_model is not None:
        ics, notes = map_emotion(model, phones, result.nodes, ics, choice.target,
                                 options=options)
    motion = model.to_channels(ics)
    timings["post_s"] = time.perf_counter() - t3
    timings["total_s"] = time.perf_counter() - t0
    explain = _explain(model, phones, result, cands, audio_cost)
    blended = tuple(_blended(model.graph, r) for r in ranked)
    for row, animes in zip(explain, blended, strict=False):
        row["k_best"], row["pick_weight"] = len(animes), animes[0]["weight"]
    return Synthesis(motion=motion, ics=ics, fps=model.graph.fps, phones=phones,
                     segmentation=method_used, result=result, joins=joins, explain=explain,
                     timings=timings, emotion=choice, notes=tuple(notes), blended=blended)


def map_emotion(model: Model, phones, nodes, ics: np.ndarray, target, *,
                options: PostOptions | None = None) -> tuple[np.ndarray, list[str]]:
    """Map the frames of each anime whose emotion is not ``target`` into it (Fig. 6).

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
    mapped, notes = map_frames(model.emotion_model, ics, frame_emotion.astype(str), target)
    e = model.emotion_model.split.emotion_components
    if (options is None or options.smooth) and e.size and not np.array_equal(mapped, ics):
        mapped[:, e] = smooth(mapped[:, e], model.cutoffs[e], graph.fps)
    return mapped, notes


def query_phones(audio: np.ndarray, sample_rate: int, *, text: str | None = None,
                 labels: list[Segment] | None = None,
                 prosody_config: RastaPlpConfig | None = None) -> tuple[tuple[Phone, ...], str]:
    """The search nodes of an utterance: its phones with their prosody curves.

    Returns the phones and how they were found (``labels``, ``aligned``, ``recognized``).
    """
    audio = np.asarray(audio, dtype=np.float32)
    if audio.ndim != 1:
        raise ParameterError(f"audio must be mono (n_samples,), got shape {audio.shape}")
    if not np.any(np.abs(audio) > 1e-4):
        raise DataError("the audio is silent: there is no speech to animate")
    segments, method = segment(audio, sample_rate, text=text, labels=labels)
    if all(s.phone == "SIL" for s in segments):
        raise DataError("no speech found in the audio (every phone is silence)")
    cfg = prosody_config or RastaPlpConfig()
    curve = rasta_plp(audio, sample_rate, config=cfg)
    phones = tuple(Phone(s.phone, s.start, s.end,
                         np.ascontiguousarray(slice_frames(curve, s.start, s.end, hop_s=cfg.hop_s)))
                   for s in segments)
    return phones, method


def score_candidates(model: Model, phones, *, emotion: str | None = None):
    """Candidate animes of every input phone and their audio costs (Eq. 5)."""
    graph = model.graph
    cands = candidates(graph, [p.phone for p in phones], emotion=emotion)
    audio_cost = audio_costs_many([p.prosody.astype(np.float32) for p in phones],
                                  graph.prosody_values,
                                  graph.prosody_offsets, cands.nodes)
    return cands, audio_cost


def render_nodes(model: Model, phones, nodes, *, options: PostOptions | None = None,
                 emotion: str | None = None) -> tuple[np.ndarray, list[dict]]:
    """Post-processed motion (independent components) of an anime sequence, §4.3."""
    graph = model.graph
    emotion_index = graph.emotions.index(emotion) if emotion is not None else None
    return assemble(graph, nodes, phones, cutoffs=model.cutoffs, options=options,
                    emotion=emotion_index)


def render_k_best(model: Model, phones, cands, audio_cost, nodes, k: int, *,
                  weights: SearchWeights | None = None, options: PostOptions | None = None,
                  emotion: str | None = None) -> tuple[np.ndarray, tuple[np.ndarray, ...]]:
    """Motion (independent components) averaging the ``k`` best animes of each phone around
    the matched ``nodes`` (beyond the paper; :func:`animegraph.search.k_best`), and those
    animes per phone, best first."""
    ranked = ranked_candidates(model.graph, cands, audio_cost, nodes, k, weights=weights,
                               emotion=emotion)
    return blend_k_best(model.graph, ranked, phones, cutoffs=model.cutoffs,
                        options=options), ranked


def _blended(graph: AnimeGraph, ranked: np.ndarray) -> list[dict]:
    """The animes one phone's k-best motion averages: where each came from, its weight."""
    return [{"node": int(a), "clip_id": graph.clip_ids[graph.node_clip[a]],
             "position": int(graph.position[a]), "weight": round(float(w), 4)}
            for a, w in zip(ranked, rank_weights(len(ranked)), strict=True)]


def _explain(model, phones, result, cands, audio_cost) -> list[dict]:
    """One row per input phone: where its motion came from and what it cost."""
    g = model.graph
    rows = []
    for i, (p, node) in enumerate(zip(phones, result.nodes, strict=True)):
        node = int(node)
        k = int(np.flatnonzero(cands.nodes[i] == node)[0])
        row = {
            "index": i, "phone": p.phone, "start": round(p.start, 4), "end": round(p.end, 4),
            "node": node, "clip_id": g.clip_ids[g.node_clip[node]],
            "anime_phone": _phone_name(g, node), "position": int(g.position[node]),
            "emotion": g.emotions[g.node_emotion[node]],
            "audio_cost": float(audio_cost[i][k]),
            "backoff": cands.backoff[i],
        }
        if i > 0:
            prev = int(result.nodes[i - 1])
            row["jump"] = bool(g.next_node[prev] != node)
            dist = np.linalg.norm(g.last_pcs[prev] - g.first_pcs[node]) / np.sqrt(g.n_channels)
            row["jump_cost"] = float(dist)
        else:
            row["jump"], row["jump_cost"] = False, 0.0
        rows.append(row)
    return rows


def _phone_name(graph: AnimeGraph, node: int) -> str:
    from ingest.phones import PHONES

    return PHONES[int(graph.node_phone[node])]


def explain_record(synth: Synthesis) -> dict:
    """The ``--explain`` record of a synthesis: every phone's source and costs, the joins,
    the search result and the timings (what ``synth --explain-json`` and ``batch`` write)."""
    r = synth.result
    record = {"phones": synth.explain, "joins": synth.joins, "cost": r.cost,
              "n_jumps": r.n_jumps, "method": r.method, "segmentation": synth.segmentation,
              "timings": synth.timings}
    if synth.blended:
        record["k_best"] = list(synth.blended)
    return record


def backoffs(synth: Synthesis) -> list[str]:
    """Phones the database lacks and the phone used instead, e.g. ``["ZH->SH"]``."""
    return sorted({f"{e['phone']}->{e['anime_phone']}" for e in synth.explain if e["backoff"]})


def write_explain(synth: Synthesis, path: Path, **extra) -> Path:
    """Write :func:`explain_record` (plus ``extra`` keys) as JSON, atomically."""
    import json

    from db.atomic import atomic_write

    record = {**extra, **explain_record(synth)}
    with atomic_write(path) as handle:
        handle.write(json.dumps(record, indent=1, default=_jsonable).encode())
    return path


def _jsonable(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, tuple):
        return list(value)
    return str(value)


def write_motion(synth: Synthesis, model: Model, path: Path) -> Path:
    """Write the motion as C3D (point databases), CSV or NPZ, by ``path``'s extension."""
    return write_channels(synth.motion, synth.fps, model.names, model.kind, path,
                          extra={"ics": synth.ics, "nodes": synth.result.nodes})


def write_channels(motion: np.ndarray, fps: float, names, kind: str, path: Path, *,
                   extra: dict | None = None) -> Path:
    """Write motion (n_frames, n_channels) as C3D (point databases), CSV or NPZ.

    ``extra`` arrays go into an NPZ beside ``motion``, ``fps`` and ``channels``.
    """
    from db.atomic import atomic_write

    path = Path(path)
    motion = np.asarray(motion, dtype=np.float64)
    names = tuple(names)
    suffix = path.suffix.lower()
    if suffix == ".c3d":
        if kind not in ("markers", "landmarks"):
            raise ParameterError(f"C3D holds 3D points; this database has {kind} "
                                 "(write .csv or .npz)")
        from ingest.formats.c3d import MarkerData, write_c3d

        point_cols = _point_columns(names)
        labels = tuple(names[i][:-2] for i in point_cols[::3])
        points = motion[:, point_cols].reshape(len(motion), -1, 3)
        write_c3d(path, MarkerData(points=points, labels=labels, rate=fps))
    elif suffix == ".csv":
        header = "frame,time," + ",".join(names)
        n = len(motion)
        table = np.column_stack([np.arange(n), np.arange(n) / fps, motion])
        with atomic_write(path) as handle:
            np.savetxt(handle, table, delimiter=",", header=header, comments="",
                       fmt=["%d", "%.5f"] + ["%.6g"] * len(names))
    elif suffix == ".npz":
        with atomic_write(path) as handle:
            np.savez(handle, motion=motion, fps=fps, channels=np.array(names),
                     **(extra or {}))
    else:
        raise ParameterError(f"output must end in .c3d, .csv or .npz, got {path.name!r}")
    return path


def _point_columns(names) -> list[int]:
    return [i for i, n in enumerate(names) if n.endswith((".x", ".y", ".z"))]


def read_motion(path: Path, model: Model) -> tuple[np.ndarray, float]:
    """Read a motion file (.c3d, .csv, .npz; :func:`animegraph.motionio.read_motion`) in
    ``model``'s channels: (motion of shape (n_frames, n_channels), frames per second).

    A C3D holds the point channels only: any other channel of the database is set to its
    mean over the database.

    Raises
    ------
    DataError
        Unreadable file, or channels that are not the database's.
    """
    from animegraph.motionio import read_motion as read_file

    path = Path(path)
    motion = read_file(path)
    names = list(model.names)
    index = {c: i for i, c in enumerate(motion.names)}
    points = _point_columns(names)
    only_points = path.suffix.lower() == ".c3d"
    wanted = [names[i] for i in points] if only_points else names
    missing = [c for c in wanted if c not in index]
    if missing:
        raise DataError(f"{path.name} lacks {len(missing)} of the database's channels "
                        f"(first: {missing[0]}): it is not motion of this database")
    values = np.asarray(motion.values, dtype=np.float64)
    if only_points:
        out = np.tile(model.decomposer.mean_, (len(values), 1))
        for i in points:
            out[:, i] = values[:, index[names[i]]]
        return out, motion.fps
    return values[:, [index[c] for c in names]], motion.fps
