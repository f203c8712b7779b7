"""Speech in, facial motion out: the lip-sync pipeline of Cao et al. (2005, §4.2-4.3).

1. The input speech is segmented into phones by the same code as ingest (given labels,
   forced alignment of a transcript, or phone recognition) and each phone gets its
   prosody curve (RASTA-PLP): the search nodes sn = <P, C, E>.
2. Candidates (animes with the same phoneme, a viseme class-mate when the database
   lacks it) are scored against each search node with DTW on the prosody curves
   (C_audio, Eq. 5), and the Anime Graph is searched for the sequence of least cost
   (Eq. 2): exactly by default, or with the paper's bounded look-ahead.
3. The chosen animes are time-warped, blended at jumps and smoothed (§4.3), and brought
   back from independent components to the database's channels.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from animegraph.dtw import audio_costs
from animegraph.graph import AnimeGraph
from animegraph.search import SearchResult, SearchWeights, candidates, search
from animegraph.synthesis import Phone, PostOptions, assemble
from db.errors import DataError, ParameterError
from db.store import Database
from ingest.decompose import MotionDecomposer
from ingest.features import RastaPlpConfig, rasta_plp, slice_frames
from ingest.formats.phones_csv import Segment
from ingest.motion import head_points, unstabilize_points
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

    @classmethod
    def load(cls, path) -> Model:
        db = Database.open(path)
        arrays = db.arrays()
        channels = db.table("channels").to_pylist()
        return cls(
            db=db, graph=AnimeGraph.from_database(db),
            decomposer=MotionDecomposer.from_arrays(arrays), cutoffs=arrays["ic_cutoff_hz"],
            names=tuple(c["name"] for c in channels), groups=tuple(c["group"] for c in channels),
            kind=channels[0]["kind"], head_reference=arrays.get("head_reference"),
        )

    def to_channels(self, ics: np.ndarray) -> np.ndarray:
        """Motion in the database's channels (world coordinates for a head group)."""
        return to_world(self.decomposer.inverse_transform(ics), self.groups,
                        self.head_reference)


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


def synthesize(
    model: Model, audio: np.ndarray, sample_rate: int, *, text: str | None = None,
    labels: list[Segment] | None = None, emotion: str | None = None, method: str = "exact",
    window: int | None = None, weights: SearchWeights | None = None,
    options: PostOptions | None = None, prosody_config: RastaPlpConfig | None = None,
) -> Synthesis:
    """Facial motion for speech ``audio`` (shape (n_samples,)) from the database ``model``.

    Raises
    ------
    ParameterError
        On an unknown emotion or search method.
    DataError
        If the audio holds no speech.
    """
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    if emotion is not None and emotion not in model.graph.emotions:
        known = ", ".join(model.graph.emotions)
        raise ParameterError(f"emotion {emotion!r} is not in the database (it has {known})")
    phones, method_used = query_phones(audio, sample_rate, text=text, labels=labels,
                                       prosody_config=prosody_config)
    timings["segment_s"] = time.perf_counter() - t0

    t1 = time.perf_counter()
    cands, audio_cost = score_candidates(model, phones, emotion=emotion)
    timings["audio_cost_s"] = time.perf_counter() - t1
    t2 = time.perf_counter()
    result = search(model.graph, cands, audio_cost, weights=weights or SearchWeights(),
                    emotion=emotion, method=method, window=window)
    timings["search_s"] = time.perf_counter() - t2

    t3 = time.perf_counter()
    ics, joins = render_nodes(model, phones, result.nodes, options=options, emotion=emotion)
    motion = model.to_channels(ics)
    timings["post_s"] = time.perf_counter() - t3
    timings["total_s"] = time.perf_counter() - t0
    explain = _explain(model, phones, result, cands, audio_cost)
    return Synthesis(motion=motion, ics=ics, fps=model.graph.fps, phones=phones,
                     segmentation=method_used, result=result, joins=joins, explain=explain,
                     timings=timings)


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
    audio_cost = [audio_costs(p.prosody.astype(np.float32), graph.prosody_values,
                              graph.prosody_offsets, nodes)
                  for p, nodes in zip(phones, cands.nodes, strict=True)]
    return cands, audio_cost


def render_nodes(model: Model, phones, nodes, *, options: PostOptions | None = None,
                 emotion: str | None = None) -> tuple[np.ndarray, list[dict]]:
    """Post-processed motion (independent components) of an anime sequence, §4.3."""
    graph = model.graph
    emotion_index = graph.emotions.index(emotion) if emotion is not None else None
    return assemble(graph, nodes, phones, cutoffs=model.cutoffs, options=options,
                    emotion=emotion_index)


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

    names = tuple(names)
    suffix = path.suffix.lower()
    if suffix == ".c3d":
        if kind not in ("markers", "landmarks"):
            raise ParameterError(f"C3D holds 3D points; this database has {kind} "
                                 "(write .csv or .npz)")
        from ingest.formats.c3d import MarkerData, write_c3d

        point_cols = [i for i, n in enumerate(names) if n.endswith((".x", ".y", ".z"))]
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
