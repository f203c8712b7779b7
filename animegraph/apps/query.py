"""Finding expressive pieces in a database and exporting them for other tools.

A query is SQL over the database's DuckDB views (:mod:`db.sql`), written out by
:func:`build_sql` so that ``animegraph sql`` runs exactly the same thing
(``animegraph query --show-sql`` prints it). Hits are anime nodes (phoneme instances)
or, with ``clips=True``, whole utterances.

:func:`export_hits` writes each hit as a motion snippet with context around it (C3D for
marker databases, ``frame,time,<channel>`` CSV otherwise), its speech (WAV), a PNG
preview, and an ``index.csv``, and the phones over the snippet (``.phones.csv``, times from the
snippet's start); the folder is built aside and renamed into place.
"""

from __future__ import annotations

import csv
import io
import re
import secrets
import shutil
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from animegraph.apps.query_fields import ANIME_FIELDS, CLIP_FIELDS
from animegraph.emotion.control import AUTO, check_names
from db.errors import DataError, ParameterError
from db.sql import query as run_sql
from db.store import Database
from ingest.speech.g2p import split_words
from ingest.speech.phones import PHONE_SET


@dataclass(frozen=True)
class QuerySpec:
    """What to look for. Every field left None matches everything."""

    phoneme: str | None = None
    emotion: str | None = None
    text: str | None = None
    speaker: str | None = None
    min_dur: float | None = None
    order_by: str | None = None
    descending: bool = False
    limit: int | None = 20
    clips: bool = False


def _literal(value: str) -> str:
    return "'" + value.replace("'", "''") + "'"


def build_sql(spec: QuerySpec) -> str:
    """The SELECT that answers ``spec`` (runs as it is under ``animegraph sql``).

    Raises
    ------
    ParameterError
        On an unknown phoneme or order field, a bad word, a negative duration or limit.
    """
    from ingest.speech.phones import PHONE_SET

    where = []
    if spec.phoneme is not None:
        phone = spec.phoneme.strip().upper()
        if phone not in PHONE_SET:
            raise ParameterError(f"--phoneme {spec.phoneme!r} is not an ARPAbet phone "
                                 "(e.g. AA, B, CH, SIL)")
    if spec.min_dur is not None and not spec.min_dur >= 0:
        raise ParameterError(f"--min-dur must be >= 0 seconds, got {spec.min_dur}")
    if spec.limit is not None and spec.limit < 1:
        raise ParameterError(f"--limit must be >= 1, got {spec.limit}")
    # as a transcript is read: "boat," is the word boat (a token is letters and digits
    # joined by ' or -, safe inside the regular expression below)
    words = split_words(spec.text or "")
    if spec.text is not None and spec.text.strip() and not words:
        raise ParameterError(f"--text {spec.text!r} holds no word (letters or digits)")
    fields = CLIP_FIELDS if spec.clips else ANIME_FIELDS
    order = spec.order_by or ("clip_id" if spec.clips else "node_id")
    if order not in fields:
        raise ParameterError(f"--order-by must be one of {', '.join(fields)}; got {order!r}")
    c = "c." if spec.clips else "a."
    if spec.emotion is not None:
        where.append(f"{c}emotion = {_literal(spec.emotion)}")
    if spec.speaker is not None:
        where.append(f"{c}speaker = {_literal(spec.speaker)}")
    for word in words:
        # a transcript may spell its apostrophes typographically
        pattern = _literal(r"(?i)\b" + word.replace("'", "['\u2019]") + r"\b")
        where.append(f"regexp_matches(c.text, {pattern})")
    if spec.clips:
        if spec.phoneme is not None:
            where.append("EXISTS (SELECT 1 FROM animes AS a WHERE a.corpus = c.corpus AND "
                         f"a.clip_id = c.clip_id AND a.phoneme = {_literal(phone)})")
        duration = "round(c.duration, 3)"
        select = ("SELECT c.corpus, c.clip_id, c.emotion, c.speaker, "
                  f"{duration} AS duration, c.n_animes, c.text\nFROM clips AS c")
        ties = ["c.corpus", "c.clip_id"]
    else:
        if spec.phoneme is not None:
            where.append(f"a.phoneme = {_literal(phone)}")
        duration = "round(a.end_time - a.start_time, 4)"
        select = ("SELECT a.node_id, a.corpus, a.clip_id, a.phoneme, a.emotion, a.speaker, "
                  "round(a.start_time, 4) AS start_time, round(a.end_time, 4) AS end_time, "
                  f"{duration} AS duration, a.position, c.text\n"
                  "FROM animes AS a JOIN clips AS c ON c.corpus = a.corpus "
                  "AND c.clip_id = a.clip_id")
        ties = ["a.node_id"]
    if spec.min_dur is not None:
        # On the duration as shown: a hit listed as 0.46 s is at least 0.46 s long (the raw
        # 0.4599999999 of 91.39 - 90.93 was not).
        where.append(f"{duration} >= {spec.min_dur!r}")
    sql = select
    if where:
        sql += "\nWHERE " + "\n  AND ".join(where)
    # Ties break in recording order, so the result is the same on every run.
    keys = [f"{order}{' DESC' if spec.descending else ''}"]
    keys += [t for t in ties if t.split(".")[1] != order]
    sql += f"\nORDER BY {', '.join(keys)}"
    if spec.limit is not None:
        sql += f"\nLIMIT {int(spec.limit)}"
    return sql


def run_query(db: Database, spec: QuerySpec) -> pa.Table:
    """Run :func:`build_sql` on ``db`` (the spec in the database's spelling,
    :func:`in_database`)."""
    return run_sql(db, build_sql(in_database(db, spec)))


def in_database(db: Database, spec: QuerySpec) -> QuerySpec:
    """``spec`` with its emotion and speaker as ``db`` spells them, so that its SQL
    (``--show-sql``) finds what the query finds.

    Raises
    ------
    ParameterError
        For an emotion or a speaker the database does not have (naming the ones it has),
        or words to find in a database whose clips carry no transcript.
    """
    if spec.emotion is not None:  # in the database's spelling, whatever its case
        if spec.emotion.lower() == AUTO:
            raise ParameterError("query: --emotion takes an emotion's name, not auto")
        known = db.table("clips", columns=["emotion"]).column("emotion").to_pylist()
        spec = replace(spec, emotion=check_names(spec.emotion, None, known))
    if spec.speaker is not None:
        known = db.table("clips", columns=["speaker"]).column("speaker").to_pylist()
        spec = replace(spec, speaker=find_speaker(spec.speaker, known))
    if split_words(spec.text or ""):
        # Recognised phones leave a clip without words: no hit would not mean no match.
        texts = db.table("clips", columns=["text"]).column("text")
        if texts.null_count == len(texts):
            raise ParameterError(f"--text {spec.text!r}: the database's clips carry no "
                                 "transcript")
    return spec


def find_speaker(name: str, known: Sequence[str | None]) -> str:
    """``name`` as the database spells its speaker: the same whatever its case, else the
    one speaker whose name holds it (``obama`` for ``Barack Obama (as named in file)``:
    a speaker's label may carry a note).

    Raises
    ------
    ParameterError
        No speaker, or more than one, answers to ``name`` (naming them): a filter that
        matches nothing would list nothing without saying why.
    """
    speakers = sorted({k for k in known if k is not None})
    for match in (lambda k: k == name, lambda k: k.casefold() == name.casefold(),
                  lambda k: name.casefold() in k.casefold()):
        found = [k for k in speakers if match(k)]
        if len(found) == 1:
            return found[0]
        if found:
            raise ParameterError(f"--speaker {name!r} names {len(found)} speakers: "
                                 f"{'; '.join(found)}")
    if not speakers:
        raise ParameterError(f"--speaker {name!r}: the database's clips name no speaker")
    shown = "; ".join(speakers[:10]) + (f"; ... ({len(speakers)} in all)"
                                        if len(speakers) > 10 else "")
    raise ParameterError(f"unknown speaker {name!r}: the database has {shown}")


@dataclass(frozen=True)
class ClipData:
    """A clip's motion (world coordinates for a head group) and speech, from the database."""

    motion: np.ndarray  # (n_frames, n_channels)
    names: tuple[str, ...]
    groups: tuple[str, ...]
    kind: str
    fps: float
    audio: np.ndarray  # (n_samples,) int16
    sample_rate: int
    phones: list[dict]
    #: (first frame's timecode as frames since midnight, timecode rate) of an iPhone take
    #: (its ``extra``), None for other clips
    timecode: tuple[float, float] | None = None


def load_clip(db: Database, corpus: str, clip_id: str, *, speech: bool = True) -> ClipData:
    """Read one clip back from the database.

    ``speech=False`` leaves the speech unread (``audio`` empty, ``sample_rate`` 0): the
    studio sends it apart, and reading it took a third of a clip's load.

    Raises
    ------
    DataError
        If the clip is not in the database.
    """
    from animegraph.synthesis import to_world

    channels = db.table("channels").to_pylist()
    names = tuple(ch["name"] for ch in channels)
    groups = tuple(ch["group"] for ch in channels)
    mask = (pc.field("corpus") == corpus) & (pc.field("clip_id") == clip_id)
    clip = db.table("clips", filter=mask).to_pylist()
    if not clip:
        raise DataError(f"clip {clip_id!r} of corpus {corpus!r} is not in the database")
    clip = clip[0]
    # The frames are partitioned by emotion: naming the clip's skips the other folders
    # (a clip of the demo's database loaded three times faster).
    in_part = mask if clip.get("emotion") is None else \
        mask & (pc.field("emotion") == clip["emotion"])
    frames = db.table("frames", columns=["frame", *names], filter=in_part).sort_by("frame")
    motion = np.stack([frames.column(n).to_numpy() for n in names], axis=1).astype(np.float64)
    motion = to_world(motion, groups, db.arrays().get("head_reference"))
    sound = (db.table("audio", filter=mask).to_pylist() if speech
             else [{"pcm16": b"", "sample_rate": 0}])
    # The database may come from someone else: what an export divides by, counts or
    # pairs up is checked, for one line naming the clip rather than a traceback.
    damaged = f"database {db.root} is damaged: clip {clip_id!r}"
    fps, phone_list = clip["fps"], (clip["phones"] or "").split()
    starts, ends = clip["phone_starts"] or [], clip["phone_ends"] or []
    if speech and (not sound or len(sound[0]["pcm16"] or b"") % 2
                   or not (sound[0]["sample_rate"] or 0) > 0):
        raise DataError(f"{damaged} has no usable speech")
    if not (fps is not None and np.isfinite(fps) and fps > 0):
        raise DataError(f"{damaged} has frame rate {fps}")
    if not len(phone_list) == len(starts) == len(ends):
        raise DataError(f"{damaged} has {len(phone_list)} phones but {len(starts)} starts "
                        f"and {len(ends)} ends")
    phones = [{"phone": p, "start": s, "end": e, "clip_id": clip_id, "jump": False}
              for p, s, e in zip(phone_list, starts, ends, strict=True)]
    return ClipData(motion=motion, names=names, groups=groups, kind=channels[0]["kind"],
                    fps=float(fps), audio=np.frombuffer(sound[0]["pcm16"], dtype=np.int16),
                    sample_rate=int(sound[0]["sample_rate"]), phones=phones,
                    timecode=_take_timecode(clip.get("extra"), damaged))


def _take_timecode(extra: str | None, damaged: str) -> tuple[float, float] | None:
    """An iPhone take's first timecode (frames since midnight) and timecode rate, from a
    clip's ``extra`` (None if it has none: not a take, or ingested before it was kept).

    Raises
    ------
    DataError
        If ``extra`` is not JSON or holds a timecode that does not read.
    """
    import json

    from ingest.readers.livelink import take_timecode

    try:
        return take_timecode(json.loads(extra) if extra else {})
    except (ValueError, TypeError, AttributeError) as exc:
        raise DataError(f"{damaged} has a take timecode that does not read: {exc}") from None


def check_export(out: Path, *, context: float, force: bool) -> None:
    """Refuse an export that cannot be written, before the query runs and its table is
    printed (a bad --context was said after the table, as if the query had failed).

    Raises
    ------
    ParameterError
        A negative ``context``.
    DataError
        ``out`` exists (without ``force``) or is a file, or its folder does not exist.
    """
    from db.atomic import check_folder

    if not context >= 0:
        raise ParameterError(f"--context must be >= 0 seconds, got {context}")
    if out.exists() and (not force or not out.is_dir()):
        raise DataError(f"export folder {out} exists (use --force to replace it)"
                        if out.is_dir() else f"{out} exists and is not a folder")
    check_folder(out)


def export_hits(db: Database, hits: pa.Table, out: Path, *, context: float = 0.25,
                force: bool = False, progress=None) -> list[dict]:
    """Write every hit as motion + speech + preview, and ``index.csv``, into ``out``.

    Parameters
    ----------
    hits : pyarrow.Table
        Rows of :func:`run_query` (anime or clip mode).
    out : Path
        A folder to create; an existing one is replaced only with ``force``.
    context : float
        Seconds kept before and after each anime (clipped to its recording).
    progress : callable, optional
        ``progress(total)`` returns a wrapper for the iterable of hits (a bar).

    Returns
    -------
    list of dict
        The index rows.

    Raises
    ------
    DataError
        If ``out`` exists (without ``force``) or is a file, or nothing matched.
    """
    from db.atomic import replace_dir

    out = Path(out)
    check_export(out, context=context, force=force)
    if hits.num_rows == 0:
        raise DataError("nothing matched the query: no export written")
    staging = out.parent / f".{out.name}.partial-{secrets.token_hex(4)}"
    staging.mkdir()
    try:
        rows = _export_into(db, hits, staging, context, progress)
        replace_dir(staging, out)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return rows


def _export_into(db: Database, hits: pa.Table, folder: Path, context: float,
                 progress=None) -> list[dict]:
    from ingest.formats.phones_csv import write_phones_csv
    from ingest.formats.wav import write_wav

    cache: dict[tuple[str, str], ClipData] = {}
    # One deformer for every hit: building it (RBF systems per face region) took most of
    # each landmark hit's export.
    deformers: dict[tuple[str, ...], object] = {}
    index = []
    anime_mode = "node_id" in hits.column_names
    rows = hits.to_pylist()
    for n, hit in enumerate(progress(len(rows))(rows) if progress else rows):
        key = (hit["corpus"], hit["clip_id"])
        if key not in cache:
            cache[key] = load_clip(db, *key)
        clip = cache[key]
        duration = len(clip.motion) / clip.fps
        if anime_mode:
            a0, a1 = float(hit["start_time"]), float(hit["end_time"])
            t0, t1 = max(0.0, a0 - context), min(duration, a1 + context)
            if not (np.isfinite(a0) and np.isfinite(a1)):
                raise DataError(f"database {db.root} is damaged: anime {hit['node_id']} of "
                                f"{hit['clip_id']!r} has times {a0} to {a1}")
            if hit["phoneme"] not in PHONE_SET:  # it goes into a name, a CSV and a title
                raise DataError(f"database {db.root} is damaged: anime {hit['node_id']} of "
                                f"{hit['clip_id']!r} has phoneme {hit['phoneme']!r}, not a "
                                "phone")
            stem = (f"{n:03d}_{_safe(hit['clip_id'])}_{_safe(str(hit['phoneme']))}_"
                    f"{int(hit['node_id'])}")
        else:
            a0, a1 = 0.0, duration
            t0, t1 = 0.0, duration
            stem = f"{n:03d}_{_safe(hit['clip_id'])}"
        f0 = int(np.floor(t0 * clip.fps + 1e-9))
        f1 = max(f0 + 1, min(len(clip.motion), int(np.ceil(t1 * clip.fps - 1e-9))))
        motion_name = _write_snippet(clip, f0, f1, folder / stem)
        s0 = int(round(f0 / clip.fps * clip.sample_rate))
        s1 = min(len(clip.audio), int(round(f1 / clip.fps * clip.sample_rate)))
        write_wav(folder / f"{stem}.wav", clip.audio[s0:s1], clip.sample_rate)
        span_s = (f1 - f0) / clip.fps
        phones = [{**p, "start": max(0.0, p["start"] - f0 / clip.fps),
                   "end": min(span_s, p["end"] - f0 / clip.fps)}
                  for p in clip.phones if p["end"] > f0 / clip.fps and p["start"] < f1 / clip.fps]
        phones = [p for p in phones if p["end"] - p["start"] > 1e-4]
        write_phones_csv(folder / f"{stem}.phones.csv",
                         [(p["phone"], p["start"], p["end"]) for p in phones])
        _preview(clip, f0, f1, (a0 - f0 / clip.fps, a1 - f0 / clip.fps), phones,
                 folder / f"{stem}.png", title=f"{hit['clip_id']} ({hit['emotion']})"
                 + (f": {hit['phoneme']}" if anime_mode else ""), deformers=deformers)
        index.append({
            "n": n, "node_id": hit.get("node_id"), "corpus": hit["corpus"],
            "clip_id": hit["clip_id"], "phoneme": hit.get("phoneme"), "emotion": hit["emotion"],
            "speaker": hit["speaker"], "start_time": round(a0, 4), "end_time": round(a1, 4),
            "snippet_start": round(f0 / clip.fps, 4), "snippet_end": round(f1 / clip.fps, 4),
            "fps": clip.fps, "motion": motion_name, "audio": f"{stem}.wav",
            "phones": f"{stem}.phones.csv", "preview": f"{stem}.png",
        })
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(index[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows(index)
    (folder / "index.csv").write_text(buffer.getvalue())
    return index


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name)


def _write_snippet(clip: ClipData, f0: int, f1: int, stem: Path) -> str:
    """C3D for marker databases, Live Link Face CSV for ARKit
    databases (timecode = the take's at the snippet's start, or the time from the
    recording's start for a clip that is not an iPhone take), else channel CSV; the
    file name."""
    from animegraph.motion.files import (
        LIVELINK_SUFFIX,
        motion_suffix,
        point_labels,
        write_channel_csv,
    )
    from ingest.formats.c3d import MarkerData, write_c3d
    from ingest.formats.livelink import LIVELINK_FPS, format_timecode, write_livelink

    part = clip.motion[f0:f1]
    suffix = motion_suffix(clip.names, clip.kind)
    if suffix == LIVELINK_SUFFIX:
        path = stem.with_name(stem.name + LIVELINK_SUFFIX)
        first, rate = clip.timecode or (0.0, LIVELINK_FPS)
        write_livelink(path, part, clip.names, clip.fps,
                       start=format_timecode(first + f0 / clip.fps * rate, rate),
                       timecode_rate=rate)
    elif suffix == ".c3d":
        path = stem.with_suffix(".c3d")
        write_c3d(path, MarkerData(points=part.reshape(len(part), -1, 3),
                                   labels=point_labels(clip.names), rate=clip.fps))
    else:
        path = stem.with_suffix(".csv")
        write_channel_csv(path, part, clip.names, clip.fps, start_frame=0)
    return path.name


def _preview(clip: ClipData, f0: int, f1: int, span: tuple[float, float], phones, path: Path,
             *, title: str, deformers: dict | None = None) -> None:
    """PNG: the face at the anime's middle (point and ARKit databases) and its main
    measure. ``deformers`` keeps the face's deformer by channel names between calls."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from animegraph.motion.measures import measure

    part = clip.motion[f0:f1]
    t = np.arange(len(part)) / clip.fps
    face = _face_image(clip, part, int(round(0.5 * (span[0] + span[1]) * clip.fps)),
                       {} if deformers is None else deformers)
    fig = plt.figure(figsize=(9, 3.2))
    if face is not None:
        ax_img = fig.add_axes((0.0, 0.0, 0.28, 1.0))
        ax_img.imshow(face)
        ax_img.set_axis_off()
        ax = fig.add_axes((0.36, 0.17, 0.6, 0.7))
    else:
        ax = fig.add_axes((0.08, 0.17, 0.88, 0.7))
    label, values = measure(part, clip.names, clip.kind)
    if values.ndim == 1:
        ax.plot(t, values, "k", lw=1.5)
    else:
        ax.plot(t, values, lw=1)
    ax.set_ylabel(label)
    ax.set_xlabel("time in snippet (s)")
    ax.axvspan(*span, color="C1", alpha=0.18, lw=0)
    for k, p in enumerate(phones):
        mid = 0.5 * (p["start"] + p["end"])
        if p["phone"] != "SIL" and 0 <= mid <= t[-1]:
            ax.text(mid, 0.02 if k % 2 else 0.08, p["phone"],
                    ha="center", fontsize=7, transform=ax.get_xaxis_transform())
    ax.set_xlim(0, max(t[-1], 1e-3))
    ax.set_title(title, fontsize=9)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _face_image(clip: ClipData, part: np.ndarray, frame: int,
                deformers: dict) -> np.ndarray | None:
    from animegraph.face.animation import animate, animation_bounds
    from animegraph.face.arkit import arkit_animation
    from animegraph.face.render import FaceRenderer, deformer_for
    from animegraph.motion.files import Motion
    from ingest.formats.livelink import is_arkit

    motion = Motion(values=part, names=clip.names, fps=clip.fps)
    if clip.names not in deformers:
        try:
            deformers[clip.names] = deformer_for(clip.names)
        except DataError:  # markers the canonical mesh lacks: no face, only the measure
            deformers[clip.names] = None
    deformer = deformers[clip.names]
    if deformer is None and not is_arkit(clip.names):
        return None
    animation = (arkit_animation(motion) if deformer is None else animate(motion, deformer))
    frame = min(max(frame, 0), animation.n_frames - 1)
    renderer = FaceRenderer(animation.mesh, animation_bounds(animation), (240, 270))
    try:
        return renderer.frame(animation.vertices[frame])
    finally:
        renderer.close()
