"""iPhone face captures: Live Link Face CSV (ARKit blendshapes) with their speech.

Layout: ``<take>.csv`` (Live Link Face's export, :mod:`ingest.formats.livelink`) with
``<take>.wav`` beside it (or, as the app saves a take, the video ``<take>.mov`` whose
sound track is read through ffmpeg), and optionally ``<take>.txt`` (transcript), phone labels
(``.phones.csv``/``.TextGrid``/``.lab``) and ``<take>.json`` (speaker, emotion, text), as
for every clip kind. The CSV is told from other tables by its header
(``Timecode,BlendshapeCount,...``).

The clip's channels are the 52 ARKit blendshapes and the 9 head and eye rotations, by
ARKit's names, in motion groups (Cao et al. 2005 §3.2 split the face into rigid head
motion, upper face and lips):

- ``"lips"`` (the speech group): ``jaw*``, ``mouth*``, ``tongueOut``;
- ``"upper_face"``: ``eye*`` blendshapes (blinks, squints, gaze), ``brow*``, ``cheek*``,
  ``nose*``;
- ``"head"`` (rigid): head yaw/pitch/roll and both eyes' yaw/pitch/roll.

Timing: each row's timecode gives its time. The frame rate is the rows' mean rate over the
take (:func:`frame_steps`); a row repeating or going back in time is an error; a step
longer than :data:`GAP_FACTOR` nominal frames is a gap of dropped frames, filled with NaN
rows here (and interpolated later, as marker dropouts are:
:func:`ingest.motion.fill_gaps`) and reported; a gap longer than :data:`MAX_GAP_S` is taken
for two takes run together and rejected. The lag between the lips and the speech is
estimated as for landmark clips (:func:`ingest.readers.sync.estimate_lag`), with the
mouth's opening and width read off the blendshapes (:func:`mouth_activity`); its evidence
is pooled per speaker at ingest, which decides whether it is applied (:mod:`ingest.lag`).
"""

from __future__ import annotations

import logging

import numpy as np

from db.errors import DataError
from ingest.clip import ChannelSchema, RawClip, checksum_files
from ingest.formats.livelink import (
    ARKIT_BLENDSHAPES,
    ROTATIONS,
    TIMECODE_RATES,
    format_timecode,
    read_livelink,
    timecode_frames,
)
from ingest.readers.common import (
    ClipSource,
    check_motion,
    read_json_object,
    speech_and_side_files,
)
from ingest.readers.sync import (
    audio_envelope,
    estimate_lag,
    lag_evidence,
    opening_width_activity,
)

logger = logging.getLogger(__name__)

#: A step this many nominal frame periods long (or longer) holds dropped frames.
GAP_FACTOR = 1.5
#: A gap longer than this (s) is not a dropout: the file holds more than one take.
MAX_GAP_S = 0.5
#: Name prefixes (ARKit spelling) -> motion group; the rotations are ``"head"``.
ARKIT_GROUP_PREFIXES: tuple[tuple[tuple[str, ...], str], ...] = (
    (("jaw", "mouth", "tongue"), "lips"),
    (("eye", "brow", "cheek", "nose"), "upper_face"),
)


def arkit_group(name: str) -> str:
    """Motion group of an ARKit channel (see the module docstring)."""
    if name in ROTATIONS:
        return "head"
    for prefixes, group in ARKIT_GROUP_PREFIXES:
        if name.startswith(prefixes):
            return group
    return "other"


def arkit_schema(names) -> ChannelSchema:
    """Schema of ARKit curves: ``kind="curves"``, units ``"unit"``, ARKit groups."""
    names = tuple(names)
    return ChannelSchema(kind="curves", names=names,
                         groups=tuple(arkit_group(n) for n in names), units="unit")


def frame_steps(frames: np.ndarray, rate: float, where) -> tuple[float, np.ndarray]:
    """Frame rate of a take and the frames dropped before each row.

    Parameters
    ----------
    frames : np.ndarray, shape (n_rows,)
        Each row's timecode as a frame count at ``rate``.
    rate : float
        Timecode frames per second.
    where : Path
        Named in errors.

    Returns
    -------
    fps : float
        Rows per second, dropped rows included: ``(n_rows + dropped - 1) / span``.
    dropped : np.ndarray of int, shape (n_rows,)
        Rows missing just before each row (0 for the first).

    Raises
    ------
    DataError
        If a timecode repeats or goes back, or a gap exceeds :data:`MAX_GAP_S`.
    """
    dropped = np.zeros(len(frames), dtype=np.int64)
    if len(frames) < 2:
        raise DataError(f"{where}: {len(frames)} row(s); a take needs at least 2")
    steps = np.diff(frames)
    bad = np.flatnonzero(steps <= 0)
    if len(bad):
        i = int(bad[0]) + 1
        what = "repeats" if steps[i - 1] == 0 else "goes back to"
        raise DataError(f"{where}: timecode {what} {format_timecode(frames[i], rate)} at row "
                        f"{i + 1} (after {format_timecode(frames[i - 1], rate)})")
    nominal = float(np.median(steps))
    ratio = steps / nominal
    gaps = ratio >= GAP_FACTOR
    dropped[1:][gaps] = np.round(ratio[gaps]).astype(np.int64) - 1
    longest = float(steps.max()) / rate
    if longest > MAX_GAP_S:
        i = int(np.argmax(steps)) + 1
        raise DataError(f"{where}: timecode jumps {longest:.2f} s at row {i + 1} "
                        f"({format_timecode(frames[i - 1], rate)} -> "
                        f"{format_timecode(frames[i], rate)}): more than one take?")
    span_s = float(frames[-1] - frames[0]) / rate
    fps = (len(frames) + int(dropped.sum()) - 1) / span_s
    return round(fps, 4), dropped


def insert_dropped(values: np.ndarray, dropped: np.ndarray) -> np.ndarray:
    """Rows with NaN rows put where frames were dropped: shape (n_rows + sum(dropped), c)."""
    if not dropped.any():
        return values
    out = np.full((len(values) + int(dropped.sum()), values.shape[1]), np.nan)
    out[np.arange(len(values)) + np.cumsum(dropped)] = values
    return out


def mouth_activity(motion: np.ndarray, names) -> np.ndarray:
    """How much the mouth moves at each frame, from ARKit weights.

    Opening = ``jawOpen - mouthClose`` + the means of ``mouthLowerDown*`` and
    ``mouthUpperUp*``; width = the means of ``mouthStretch*`` and ``mouthSmile*`` minus
    ``mouthPucker`` (all in blendshape weight); then ``|d opening| + |d width|`` as for
    landmark clips (:func:`ingest.readers.sync.opening_width_activity`).

    Parameters
    ----------
    motion : np.ndarray, shape (n_frames, n_channels)
    names : sequence of str
        ARKit channel names of ``motion``'s columns.

    Returns
    -------
    np.ndarray, shape (n_frames,)
    """
    index = {n: i for i, n in enumerate(names)}

    def col(name: str) -> np.ndarray:
        return motion[:, index[name]]

    def pair(stem: str) -> np.ndarray:
        return 0.5 * (col(stem + "Left") + col(stem + "Right"))

    opening = (col("jawOpen") - col("mouthClose") + pair("mouthLowerDown")
               + pair("mouthUpperUp"))
    width = pair("mouthStretch") + pair("mouthSmile") - col("mouthPucker")
    return opening_width_activity(opening, width)


def read_livelink_motion(path) -> tuple[np.ndarray, tuple[str, ...], float]:
    """A Live Link Face CSV as motion: (values (n_frames, n_channels), names, fps).

    Dropped frames are put back and interpolated (:func:`ingest.motion.fill_gaps`);
    channels are in :data:`ingest.formats.livelink.ARKIT_CHANNELS` order.

    Raises
    ------
    DataError
        As :func:`ingest.formats.livelink.read_livelink` and :func:`frame_steps`.
    """
    from ingest.motion import fill_gaps

    take = read_livelink(path)
    fps, dropped = frame_steps(take.frames, take.timecode_rate, path)
    names = tuple(n for n in ARKIT_BLENDSHAPES + ROTATIONS if n in take.names)
    motion = insert_dropped(take.values[:, [take.names.index(n) for n in names]], dropped)
    filled, _ = fill_gaps(motion, names)
    return filled, names, fps


def load_livelink(source: ClipSource) -> RawClip:
    """Read one Live Link Face take (see the module docstring).

    Raises
    ------
    DataError
        One line naming the file: not a Live Link Face CSV, missing ARKit columns, a bad
        or non-increasing timecode, NaN values, a gap longer than :data:`MAX_GAP_S`, no
        audio, bad side files, or a take whose duration at its frame rate disagrees with
        the audio's.
    """
    path = source.source
    audio_path = source.file("audio")
    if audio_path is None:
        raise DataError(f"{path}: no {path.stem}.wav or {path.stem}.mov beside it (the "
                        f"take's speech)")
    take = read_livelink(path)
    fps, dropped = frame_steps(take.frames, take.timecode_rate, path)
    names = tuple(n for n in ARKIT_BLENDSHAPES + ROTATIONS if n in take.names)
    order = [take.names.index(n) for n in names]
    motion = insert_dropped(take.values[:, order], dropped)
    motion = check_motion(motion, names, path, "curve")
    schema = arkit_schema(names)

    meta_path = source.file("metadata")
    meta = read_json_object(meta_path) if meta_path else {}
    audio, sample_rate, fields, phones, words = speech_and_side_files(
        source, len(motion), fps, path, meta, meta_path)
    audio_seconds = len(audio) / sample_rate

    filled = np.where(np.isnan(motion), np.nanmean(motion, axis=0), motion)
    loudness = audio_envelope(audio, sample_rate, fps, len(motion))
    activity = mouth_activity(filled, names)
    lag, confidence = estimate_lag(activity, loudness, fps)
    n_dropped = int(dropped.sum())
    extra = {
        "layout": source.layout,
        "timecode_start": format_timecode(take.frames[0], take.timecode_rate),
        "timecode_rate": take.timecode_rate,
        "dropped_frames": n_dropped,
        "gaps": int((dropped > 0).sum()),
        "lip_audio_lag_s": round(lag, 4),
        "lag_confidence": round(confidence, 4),
        # pooled per speaker at ingest (ingest.lag), which decides whether it is applied
        "lag_evidence": np.round(lag_evidence(activity, loudness, fps), 4).tolist(),
        "motion_audio_offset_s": round(len(motion) / fps - audio_seconds, 4),
    }
    if n_dropped:
        logger.warning("%s: %d dropped frame(s) in %d gap(s) (filled by interpolation)",
                       path, n_dropped, extra["gaps"])
    logger.info("%s: %d frames at %g fps from %s; lip-audio lag %+.3f s (r %.2f)", path,
                len(motion), fps, extra["timecode_start"], lag, confidence)
    return RawClip(
        clip_id=source.clip_id, corpus=source.corpus, source=path, motion=motion, fps=fps,
        schema=schema, audio=audio, sample_rate=sample_rate,
        checksum=checksum_files(source.paths), text=fields["text"], phones=phones,
        emotion=fields["emotion"], speaker=fields["speaker"],
        sentence_id=fields["sentence_id"], extra=extra,
    )


def take_timecode(extra: dict) -> tuple[float, float] | None:
    """A take's first timecode (frames since midnight) and timecode rate, as
    :func:`load_livelink` keeps them in a clip's ``extra`` (``timecode_start``,
    ``timecode_rate``); None for a clip that has none.

    Raises
    ------
    ValueError
        If they do not read (a database is shared between people).
    """
    start, rate = extra.get("timecode_start"), extra.get("timecode_rate")
    if start is None:
        return None
    if rate not in TIMECODE_RATES:
        raise ValueError(f"timecode rate {rate!r}")
    return timecode_frames(start, float(rate)), float(rate)
