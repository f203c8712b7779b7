"""From prepared clips and the corpus-wide model to the database's tables.

Each utterance becomes a sequence of anime nodes a = <P, C, M, E> (Cao et al. 2005,
§4.1, Eq. 1): phoneme label P, prosody curve C (the RASTA-PLP frames inside the
phone), motion M (the phone's frames in independent-component space) and emotion E,
linked to the previous and next node of the same recording — the Anime Graph.
"""

from __future__ import annotations

import itertools
import json
from collections.abc import Sequence

import numpy as np
import pyarrow as pa

from db.errors import DataError, ParameterError
from db.store import arrays_to_table
from ingest.clip import stored_schema
from ingest.decompose import MotionDecomposer, pcs_of_clips
from ingest.plausible import Limits, check_labels, check_stored_motion
from ingest.prepare import PreparedClip
from ingest.speech.features import RastaPlpConfig, slice_frames
from ingest.speech.posteriorgram import HOP_S as POSTERIOR_HOP_S

_F32 = pa.list_(pa.float32())
_F64 = pa.list_(pa.float64())
_F16 = pa.list_(pa.float16())

#: Types of the animes table's scalar columns (explicit, so that a database whose clips
#: name no speaker has a text column of nulls, not a column of SQL type NULL).
ANIME_SCALARS = {
    "node_id": pa.int64(), "clip_id": pa.string(), "corpus": pa.string(),
    "speaker": pa.string(), "emotion": pa.string(), "position": pa.int64(),
    "phoneme": pa.string(), "start_time": pa.float64(), "end_time": pa.float64(),
    "start_frame": pa.int64(), "end_frame": pa.int64(), "n_frames": pa.int64(),
    "prosody_frames": pa.int64(),
}
#: Column types of the clips table (explicit, so all-null columns keep their type).
CLIPS_SCHEMA = pa.schema([
    ("clip_id", pa.string()), ("corpus", pa.string()), ("kind", pa.string()),
    ("speaker", pa.string()), ("emotion", pa.string()), ("sentence_id", pa.string()),
    ("text", pa.string()), ("fps", pa.float64()), ("source_fps", pa.float64()),
    ("n_frames", pa.int32()), ("duration", pa.float64()), ("sample_rate", pa.int32()),
    ("n_animes", pa.int32()), ("segmentation", pa.string()), ("phones", pa.string()),
    ("phone_starts", _F64), ("phone_ends", _F64), ("prosody_frames", pa.int32()),
    ("prosody", _F32), ("lip_audio_lag_s", pa.float64()), ("source", pa.string()),
    ("checksum", pa.string()), ("extra", pa.string()),
    ("posterior_frames", pa.int32()), ("posteriors", _F16), ("posterior_blank", _F16),
])


def anime_frames(start: float, end: float, fps: float, n_frames: int) -> tuple[int, int]:
    """Frame range [first, stop) of a phone from ``start`` to ``end`` seconds.

    Every phone gets at least one frame, even one shorter than a frame period.
    """
    first = min(int(np.floor(start * fps + 1e-9)), n_frames - 1)
    stop = min(max(int(np.ceil(end * fps - 1e-9)), first + 1), n_frames)
    return first, stop


def build_tables(
    clips: Sequence[PreparedClip],
    model: MotionDecomposer,
    cutoffs: np.ndarray,
    *,
    prosody_config: RastaPlpConfig | None = None,
    arrays: dict[str, np.ndarray] | None = None,
    component_columns: dict[str, list] | None = None,
    pcs: Sequence[np.ndarray] | None = None,
) -> dict[str, pa.Table]:
    """Every table of the database for ``clips`` (sorted by corpus and clip id).

    ``arrays`` are stored with the model's (e.g. the head reference); ``component_columns``
    (one value per independent component) are added to the ``components`` table (e.g. the
    speech/emotion split, :mod:`ingest.emotion`). ``pcs``: each clip's principal-component
    scores (n_frames_k, n_pcs), in the order of ``clips``, if already computed
    (:func:`ingest.decompose.pcs_of_clips`).
    """
    cfg = prosody_config or RastaPlpConfig()
    if pcs is None:
        pcs = pcs_of_clips(model, [c.motion for c in clips])
    order = sorted(range(len(clips)), key=lambda i: clips[i].key)
    clips, pcs = [clips[i] for i in order], [pcs[i] for i in order]
    schema = clips[0].schema
    clip_rows, anime_cols = [], _columns()
    audio_rows = []
    node = 0
    sources_all = []
    # Posteriorgrams (beyond the paper) are stored only when every clip has one.
    with_posteriors = all(c.posteriors is not None and len(c.posteriors) for c in clips)
    for clip, scores in zip(clips, pcs, strict=True):
        ics = model.sources_from_pcs(scores).astype(np.float32)
        sources_all.append(ics)
        n_phones = len(clip.phones)
        for pos, seg in enumerate(clip.phones):
            first, stop = anime_frames(seg.start, seg.end, clip.fps, len(clip.motion))
            prosody = slice_frames(clip.prosody, seg.start, seg.end, hop_s=cfg.hop_s)
            a = anime_cols
            a["node_id"].append(node)
            a["clip_id"].append(clip.clip_id)
            a["corpus"].append(clip.corpus)
            a["speaker"].append(clip.speaker)
            a["emotion"].append(clip.emotion)
            a["position"].append(pos)
            a["phoneme"].append(seg.phone)
            a["start_time"].append(seg.start)
            a["end_time"].append(seg.end)
            a["start_frame"].append(first)
            a["end_frame"].append(stop)
            a["n_frames"].append(stop - first)
            a["prosody_frames"].append(len(prosody))
            a["prosody"].append(prosody.ravel())
            if with_posteriors:
                post = slice_frames(clip.posteriors, seg.start, seg.end, hop_s=POSTERIOR_HOP_S)
                a["posterior_frames"].append(len(post))
                a["posteriors"].append(post.astype(np.float16).ravel())
            a["motion"].append(ics[first:stop].ravel())
            a["first_pcs"].append(scores[first].astype(np.float32))
            a["last_pcs"].append(scores[stop - 1].astype(np.float32))
            a["prev_node"].append(node - 1 if pos > 0 else None)
            a["next_node"].append(node + 1 if pos < n_phones - 1 else None)
            node += 1
        clip_rows.append(_clip_row(clip, n_phones))
        audio_rows.append((clip.clip_id, clip.corpus, clip.sample_rate, clip.audio.tobytes()))

    animes = pa.table({
        **{k: pa.array(anime_cols[k], kind) for k, kind in ANIME_SCALARS.items()},
        "prosody": pa.array(anime_cols["prosody"], _F32),
        "motion": pa.array(anime_cols["motion"], _F32),
        "first_pcs": pa.array(anime_cols["first_pcs"], _F32),
        "last_pcs": pa.array(anime_cols["last_pcs"], _F32),
        "prev_node": pa.array(anime_cols["prev_node"], pa.int64()),
        "next_node": pa.array(anime_cols["next_node"], pa.int64()),
    })
    if with_posteriors:
        animes = animes.append_column(
            "posterior_frames", pa.array(anime_cols["posterior_frames"], pa.int32())
        ).append_column("posteriors", pa.array(anime_cols["posteriors"], _F16))
    audio = pa.table({
        "clip_id": [r[0] for r in audio_rows], "corpus": [r[1] for r in audio_rows],
        "sample_rate": pa.array([r[2] for r in audio_rows], pa.int32()),
        "pcm16": pa.array([r[3] for r in audio_rows], pa.binary()),
    })
    channels = pa.table({
        "channel": pa.array(np.arange(schema.n_channels), pa.int32()),
        "name": list(schema.names), "group": list(schema.groups),
        "kind": [schema.kind] * schema.n_channels, "units": list(schema.channel_units),
        # The range of the stored frames: what the model's channel mean is checked
        # against when read (ingest.invariants), without reading a frame.
        "min": np.min([c.motion.min(axis=0) for c in clips], axis=0).astype(np.float64),
        "max": np.max([c.motion.max(axis=0) for c in clips], axis=0).astype(np.float64),
    })
    arrays = {**model.to_arrays(), "ic_cutoff_hz": cutoffs, **(arrays or {})}
    return {
        "clips": pa.Table.from_pylist(clip_rows, schema=CLIPS_SCHEMA),
        "animes": animes,
        "frames": _frames(clips),
        "audio": audio,
        "channels": channels,
        "model_arrays": arrays_to_table(arrays),
        "components": _components(model, sources_all, cutoffs, component_columns),
    }


def _columns() -> dict[str, list]:
    names = ("node_id clip_id corpus speaker emotion position phoneme start_time end_time "
             "start_frame end_frame n_frames prosody_frames prosody motion first_pcs "
             "last_pcs prev_node next_node posterior_frames posteriors").split()
    return {n: [] for n in names}


def _clip_row(clip: PreparedClip, n_animes: int) -> dict:
    return {
        "clip_id": clip.clip_id, "corpus": clip.corpus, "kind": clip.schema.kind,
        "speaker": clip.speaker, "emotion": clip.emotion, "sentence_id": clip.sentence_id,
        "text": clip.text, "fps": float(clip.fps), "source_fps": float(clip.source_fps),
        "n_frames": int(len(clip.motion)), "duration": float(clip.duration),
        "sample_rate": int(clip.sample_rate), "n_animes": n_animes,
        "segmentation": clip.segmentation, "phones": " ".join(p.phone for p in clip.phones),
        "phone_starts": [float(p.start) for p in clip.phones],
        "phone_ends": [float(p.end) for p in clip.phones],
        "prosody_frames": int(len(clip.prosody)),
        "prosody": clip.prosody.ravel().tolist(),
        "lip_audio_lag_s": clip.extra.get("lip_audio_lag_s"),
        "source": clip.source, "checksum": clip.checksum,
        "extra": json.dumps(clip.extra, default=float, sort_keys=True),
        "posterior_frames": None if clip.posteriors is None else int(len(clip.posteriors)),
        "posteriors": None if clip.posteriors is None else clip.posteriors.astype(
            np.float16).ravel(),
        "posterior_blank": (None if clip.posteriors is None or clip.posterior_blank is None
                            else clip.posterior_blank.astype(np.float16)),
    }


def _frames(clips: Sequence[PreparedClip]) -> pa.Table:
    """The frames table of ``clips``, in their order: one row a frame, one column a
    channel, and ``missing`` (the channels filled as gaps in that frame).

    Built for all clips at once, each column one array (not one small table a clip:
    1,400 columns x 800 clips made 1.1 million arrays to build and to write).
    """
    lengths = np.array([len(c.motion) for c in clips])
    keys = {name: np.repeat(np.array([getattr(c, name) for c in clips], dtype=object), lengths)
            for name in ("clip_id", "corpus", "emotion")}
    cols = {name: pa.array(values, pa.string()) for name, values in keys.items()}
    cols["frame"] = pa.array(np.concatenate([np.arange(n, dtype=np.int32) for n in lengths]))
    cols["time"] = pa.array(np.concatenate([(np.arange(len(c.motion)) / c.fps).astype(
        np.float32) for c in clips]))
    motion = np.concatenate([c.motion for c in clips]).astype(clips[0].motion.dtype,
                                                              copy=False).T.copy()
    for c, name in enumerate(clips[0].schema.names):
        cols[name] = pa.array(motion[c])
    del motion
    missing = np.concatenate([c.missing for c in clips])
    rows, chans = np.nonzero(missing)
    offsets = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=len(missing)))])
    cols["missing"] = pa.ListArray.from_arrays(pa.array(offsets.astype(np.int32)),
                                               pa.array(chans.astype(np.int16)))
    return pa.table(cols)


def _components(model: MotionDecomposer, sources: list[np.ndarray],
                cutoffs: np.ndarray, extra: dict[str, list] | None = None) -> pa.Table:
    """One row per independent component: its share of the motion, its cutoff, ``extra``."""
    u = np.concatenate(sources).astype(np.float64)
    u = u - u.mean(axis=0)
    # Eq. 9: the motion one component alone reconstructs, in principal-component space
    # (orthonormal, so its power there is its power in the original channels).
    power = (u.var(axis=0) * (model.mixing_**2).sum(axis=0))
    share = power / power.sum()
    return pa.table({
        "component": pa.array(np.arange(len(cutoffs)), pa.int32()),
        "cutoff_hz": pa.array(cutoffs, pa.float64()),
        "motion_share": pa.array(share, pa.float64()),
        **{name: pa.array(values) for name, values in (extra or {}).items()},
    })


def stored_limits(db, unrecorded: Limits | None = None) -> Limits:
    """The plausibility limits the clips of database ``db`` were added with: its
    manifest's ``limits`` or, for a database written before they were kept,
    ``unrecorded`` (default: the defaults).

    Raises
    ------
    DataError
        If the manifest's entry is not limits.
    """
    entry = db.manifest.get("limits")
    if entry is None:
        return unrecorded or Limits()
    try:
        return Limits.from_entry(entry)
    except ParameterError as exc:
        raise db.damaged("manifest.json", f"limits: {exc}") from None


def prepared_from_database(db, limits: Limits | None = None) -> list[PreparedClip]:
    """The clips of a database as :class:`PreparedClip` (to refit the model with more, or
    to fit a baseline on it).

    Every clip's labels and motion are checked as a new clip's are before anything is
    fitted to it (:func:`ingest.plausible.check_labels`,
    :func:`ingest.plausible.check_stored_motion`, with the limits the clips were added
    with, :func:`stored_limits`): a database is someone else's data; a label such as
    ``../../pwn`` would be carried into the next version, and one clip of damaged frames
    (a marker at 500 m, NaN) would silently ruin the model refitted over all of them.

    Parameters
    ----------
    db : db.store.Database
    limits : ingest.plausible.Limits, optional
        The limits its clips are checked with (default: :func:`stored_limits`).

    Raises
    ------
    DataError
        One line naming the database, when a clip's row does not hold up (a list whose
        length does not fit its frame count, a missing column), or naming the database
        and the clip, when its stored motion is implausible, NaN or infinite.
    """
    limits = limits or stored_limits(db)
    try:
        clips = _read_prepared(db)
    except (KeyError, IndexError, TypeError, ValueError) as exc:
        raise db.damaged("clips", f"{type(exc).__name__}: {exc}") from None
    for clip in clips:
        try:  # its labels first: they are folder and file names, and named below
            check_labels(clip)
        except DataError as exc:
            raise db.damaged("clips", f"a stored clip's label: {exc}") from None
        try:
            check_stored_motion(clip.motion, clip.schema, clip.fps, limits)
        except DataError as exc:
            raise db.damaged("frames", f"clip {clip.corpus}/{clip.clip_id}: {exc}") from None
    return clips


def _read_prepared(db) -> list[PreparedClip]:
    from ingest.formats.phones_csv import Segment

    schema = stored_schema(db)
    audio = {(r["corpus"], r["clip_id"]): r for r in db.table("audio").to_pylist()}
    # Row groups of about 64 MB (db.store.rows_per_group): read whole, without the
    # per-clip row groups of older databases that made the scanner hold 12.6 GB for GRID.
    frames = db.table("frames", ["corpus", "clip_id", "frame", *schema.names, "missing"]).sort_by(
        [("corpus", "ascending"), ("clip_id", "ascending"), ("frame", "ascending")])
    keys = list(zip(frames.column("corpus").to_pylist(), frames.column("clip_id").to_pylist(),
                    strict=True))
    motion_all = np.stack([frames.column(n).to_numpy() for n in schema.names], axis=1)
    missing_lists = frames.column("missing").to_pylist()
    ranges, start = {}, 0
    for key, group in itertools.groupby(keys):
        stop = start + sum(1 for _ in group)
        ranges[key] = slice(start, stop)
        start = stop
    out = []
    for row in db.table("clips").to_pylist():
        idx = ranges[(row["corpus"], row["clip_id"])]
        missing = np.zeros((idx.stop - idx.start, schema.n_channels), dtype=bool)
        for r, chans in enumerate(missing_lists[idx]):
            if chans:
                missing[r, chans] = True
        sound = audio[(row["corpus"], row["clip_id"])]
        phones = tuple(Segment(p, s, e) for p, s, e in zip(
            row["phones"].split(), row["phone_starts"], row["phone_ends"], strict=True))
        out.append(PreparedClip(
            clip_id=row["clip_id"], corpus=row["corpus"], source=row["source"],
            checksum=row["checksum"], schema=schema, fps=row["fps"],
            source_fps=row["source_fps"], motion=motion_all[idx].astype(np.float32),
            missing=missing, audio=np.frombuffer(sound["pcm16"], dtype=np.int16),
            sample_rate=sound["sample_rate"], phones=phones,
            segmentation=row["segmentation"],
            prosody=np.asarray(row["prosody"], dtype=np.float32).reshape(
                row["prosody_frames"], -1),
            emotion=row["emotion"], speaker=row["speaker"], sentence_id=row["sentence_id"],
            text=row["text"], extra=json.loads(row["extra"]),
            posteriors=_posteriors(row), posterior_blank=_posterior_blank(row),
        ))
    return out


def _posterior_blank(row: dict) -> np.ndarray | None:
    """A clips row's CTC blank (float16), or None (not stored, a database built before
    it was, or not one value per posteriorgram frame)."""
    values, n = row.get("posterior_blank"), row.get("posterior_frames")
    if values is None or not n or len(values) != n:
        return None
    return np.asarray(values, dtype=np.float16)


def _posteriors(row: dict) -> np.ndarray | None:
    """A clips row's posteriorgram (float16), or None (not stored, or a database built
    before posteriorgrams)."""
    values, n = row.get("posteriors"), row.get("posterior_frames")
    if values is None or not n:
        return None
    return np.asarray(values, dtype=np.float16).reshape(n, -1)
