"""Plausibility checks on one clip, before anything is fitted to it (issue #18).

A clip's files are untrusted: one flipped byte in a C3D (a marker at 4.4e6 mm for one
frame), a coordinate of 3e38, a dead (all-zero) marker or a phone file of a million
4 µs phones is accepted by every file format, and once in the corpus it wrecks the
PCA/ICA model every other clip shares (Cao et al. §4.1, §5.1.2 fit one decomposition
to the whole database). So each clip is checked on its own, as it is read:

- **labels** (emotion, speaker, sentence id, clip id, corpus): at most
  :data:`MAX_LABEL_CHARS` printable characters (:data:`MAX_EMOTION_CHARS` for the
  emotion), no control character (NUL included), no path separator, not ``.``/``..``,
  nothing starting ``__``; the emotion, which names a partition folder of the store,
  also not a value the store reads back as missing (:data:`RESERVED_EMOTIONS`:
  ``__HIVE_DEFAULT_PARTITION__``, ``NULL`` ...) and only letters, digits, ``_``, ``-``,
  ``.``, ``+`` and spaces, and lowercased (``Happy`` and ``happy`` are one emotion: two
  folders differing only in case are one on macOS and Windows);
  the transcript at most :data:`MAX_TEXT_CHARS`, no NUL;
- **phones**: at most :data:`MAX_SHORT_PHONE_SHARE` of them shorter than one analysis
  frame (:data:`MIN_PHONE_S`, the 10 ms hop of the prosody features, §4.1), none
  shorter than :data:`MIN_PHONE_FLOOR_S`, at most :data:`MAX_PHONE_RATE` per second;
- **motion**: values finite; point coordinates within :data:`MAX_COORDINATE_MM` of the
  origin (animation curves within :data:`MAX_CURVE_VALUE`); no point moving faster than
  :data:`MAX_SPEED_MM_S` between two valid samples (a physical limit, configurable); no
  point that never moves (a constant or all-zero track), and not a motion that never
  moves at all.

Implausible samples of a point (out of range, or cut off from the rest of its track by
an impossible jump) become dropouts, filled like any other
(:func:`ingest.motion.fill_gaps`), as long as each run of them is at most
:data:`MAX_DROPOUT_S` long and they are at most :data:`MAX_DROPOUT_SHARE` of the clip's
frames; otherwise the clip is rejected with its reason. The note says which.
"""

from __future__ import annotations

import functools
import re
import unicodedata
import warnings
from dataclasses import asdict, dataclass, fields, replace

import numpy as np

from db.errors import DataError, ParameterError
from ingest.clip import RawClip

#: Longest label (speaker, sentence id, clip id, corpus), in characters (the shared
#: talking-face clips describe speakers in up to 99).
MAX_LABEL_CHARS = 200
#: Longest emotion, in characters: it names a partition folder of the store.
MAX_EMOTION_CHARS = 64
#: Longest transcript, in characters.
MAX_TEXT_CHARS = 10_000
#: Emotions the storage layout reads back as missing (a hive partition value of
#: ``__HIVE_DEFAULT_PARTITION__`` or ``NULL``); every label starting ``__`` is refused too.
RESERVED_EMOTIONS = frozenset({"__hive_default_partition__", "null", "none", "nan"})
#: One analysis frame of the prosody features (10 ms hop, §4.1): at most
#: :data:`MAX_SHORT_PHONE_SHARE` of a clip's phones may be shorter (eSpeak NG itself
#: makes an occasional 5.5-6.5 ms phone: 6 of the default corpus' 240 clips have one).
MIN_PHONE_S = 0.010
MAX_SHORT_PHONE_SHARE = 0.10
#: No phone may be shorter than this (no articulation is; a 4 µs phone is an attack).
MIN_PHONE_FLOOR_S = 0.001
#: Most phones per second of speech (fast read speech has 12-15).
MAX_PHONE_RATE = 40.0
#: Fastest plausible motion of a face or head marker, mm/s (a fast head shake moves the
#: forehead at about 1 m/s; speech articulators at well under 0.5 m/s).
MAX_SPEED_MM_S = 5_000.0
#: Farthest plausible coordinate from the capture volume's origin, mm.
MAX_COORDINATE_MM = 10_000.0
#: Largest plausible animation-curve value (blendshape weights are 0-1 or 0-100).
MAX_CURVE_VALUE = 1_000.0
#: Longest run of implausible samples filled as a dropout (the corpus' dropouts are
#: at most 0.25 s).
MAX_DROPOUT_S = 0.25
#: Largest share of a point's frames that may be filled as dropouts.
MAX_DROPOUT_SHARE = 0.05
#: Smallest range (mm, or curve units) of a moving track.
MIN_RANGE = 1e-6

# Ceilings of the limits above: the loosest a user (``--max-speed``) or a database's
# manifest (``limits``, someone else's data) may set them. Beyond them a check passes
# what no recording of a face holds, and a database could wave its own damaged clips
# (a marker 1 km away) into the model every clip shares.
#: Fastest any limit may allow, mm/s: no part of a body moves at 100 m/s (a pitcher's
#: hand reaches 40 m/s; a face's markers measure at most 0.5 m/s here).
MAX_SPEED_CEILING_MM_S = 100_000.0
#: Farthest any limit may allow, mm: 100 m, beyond the largest capture stage.
MAX_COORDINATE_CEILING_MM = 100_000.0
#: Largest curve value any limit may allow: ten times the default's 1000 (blendshape
#: weights are 0-1 or 0-100, angles within a turn, 360 degrees).
MAX_CURVE_CEILING = 10_000.0
#: Longest dropout any limit may fill, s: a second of speech is 12-15 phones, whose
#: motion a filled gap would invent and the database offer as recorded.
MAX_DROPOUT_CEILING_S = 1.0
#: Largest share of a track any limit may fill: past half it is invented, not recorded.
MAX_DROPOUT_SHARE_CEILING = 0.5

_EMOTION = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.+ -]*$")
_SEPARATORS = ("/", "\\")


@dataclass(frozen=True)
class Limits:
    """The physical limits of the motion checks (``animegraph ingest --max-speed``).

    A database keeps the limits its clips were added with (its manifest's ``limits``,
    :meth:`to_entry`): its stored clips are checked with them again before a refit.
    Each is above 0 (the dropout share may be 0) and at most its ceiling
    (:data:`MAX_SPEED_CEILING_MM_S` ...), whoever sets it: a limit beyond is
    ParameterError.
    """

    max_speed_mm_s: float = MAX_SPEED_MM_S
    max_coordinate_mm: float = MAX_COORDINATE_MM
    max_curve_value: float = MAX_CURVE_VALUE
    max_dropout_s: float = MAX_DROPOUT_S
    max_dropout_share: float = MAX_DROPOUT_SHARE

    def __post_init__(self):
        for name, ceiling in _CEILINGS.items():
            value = getattr(self, name)
            share = name == "max_dropout_share"  # the only one that may be 0
            if not (isinstance(value, int | float) and (0 <= value if share else 0 < value)
                    and value <= ceiling):
                raise ParameterError(f"{name} must be a number {'>=' if share else '>'} 0 "
                                     f"and at most {ceiling:g} (no face recording needs "
                                     f"more), got {value!r}")

    def loosest(self, other: Limits) -> Limits:
        """The limits passing what either of ``self`` and ``other`` passes (every limit
        is a most: the larger of the two)."""
        return Limits(**{f.name: max(getattr(self, f.name), getattr(other, f.name))
                         for f in fields(self)})

    def to_entry(self) -> dict[str, float]:
        """The limits as a manifest keeps them (:meth:`from_entry` reads them back)."""
        return asdict(self)

    @classmethod
    def from_entry(cls, entry) -> Limits:
        """Limits from a manifest's entry (the defaults for the limits it lacks; one this
        version does not know is left out).

        Raises
        ------
        ParameterError
            If the entry is not an object of numbers in range.
        """
        if not isinstance(entry, dict):
            raise ParameterError(f"limits must be an object, got {type(entry).__name__}")
        known = {f.name for f in fields(cls)}
        values = {k: v for k, v in entry.items() if k in known}
        for name, value in values.items():
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ParameterError(f"{name} must be a number, got {type(value).__name__}")
        return cls(**values)


#: Each limit's ceiling (:class:`Limits`, in its fields' order).
_CEILINGS = {"max_speed_mm_s": MAX_SPEED_CEILING_MM_S,
             "max_coordinate_mm": MAX_COORDINATE_CEILING_MM,
             "max_curve_value": MAX_CURVE_CEILING,
             "max_dropout_s": MAX_DROPOUT_CEILING_S,
             "max_dropout_share": MAX_DROPOUT_SHARE_CEILING}


def check_label(value: str | None, what: str, *, emotion: bool = False) -> None:
    """Raise DataError (one line, the value shortened) unless ``value`` is a safe label."""
    if value is None:
        return
    shown = repr(value[:20] + ("..." if len(value) > 20 else ""))
    longest = MAX_EMOTION_CHARS if emotion else MAX_LABEL_CHARS
    if len(value) > longest:
        raise DataError(f"{what} {shown} is {len(value)} characters long (at most {longest})")
    if any(unicodedata.category(c)[0] == "C" for c in value):
        raise DataError(f"{what} {shown} holds a control character (NUL, newline ...)")
    if any(s in value for s in _SEPARATORS) or value.strip() in ("", ".", ".."):
        raise DataError(f"{what} {shown} is empty or holds a path separator")
    if value.startswith("__") or (emotion and value.strip().lower() in RESERVED_EMOTIONS):
        raise DataError(f"{what} {shown} is a name the database storage reserves")
    if emotion and not _EMOTION.match(value):
        raise DataError(f"{what} {shown} may only hold letters, digits, spaces and _ - . +")


def check_labels(clip) -> None:
    """:func:`check_label` on the labels of a clip, new (a RawClip) or read back from a
    database (a PreparedClip): corpus, clip id, emotion, speaker, sentence id."""
    check_label(clip.corpus, "corpus name")
    check_label(clip.clip_id, "clip id")
    check_label(clip.emotion, "emotion", emotion=True)
    check_label(clip.speaker, "speaker")
    check_label(clip.sentence_id, "sentence id")


def check_clip_labels(clip: RawClip) -> None:
    """Check every label and the transcript of ``clip``; DataError naming the first bad one."""
    where = clip.source
    try:
        check_labels(clip)
    except DataError as exc:
        raise DataError(f"{where}: {exc}") from None
    if clip.text is not None:
        if len(clip.text) > MAX_TEXT_CHARS:
            raise DataError(f"{where}: transcript of {len(clip.text)} characters (at most "
                            f"{MAX_TEXT_CHARS})")
        if "\x00" in clip.text:
            raise DataError(f"{where}: transcript holds a NUL character")


def check_phones(clip: RawClip) -> None:
    """Reject absurd phone labels: too short (see the module doc), or too many a second."""
    if not clip.phones:
        return
    starts = np.array([p.start for p in clip.phones])
    ends = np.array([p.end for p in clip.phones])
    durations = ends - starts
    short = np.flatnonzero(~(durations >= MIN_PHONE_S - 1e-6))
    absurd = np.flatnonzero(~(durations >= MIN_PHONE_FLOOR_S))
    if absurd.size or short.size > MAX_SHORT_PHONE_SHARE * len(durations):
        p = clip.phones[(absurd if absurd.size else short)[0]]
        raise DataError(f"{clip.source}: {short.size} of {len(durations)} phone labels "
                        f"shorter than one analysis frame ({1000 * MIN_PHONE_S:g} ms), first "
                        f"{p.phone} at {p.start:.6f} s lasting {1000 * (p.end - p.start):.3f} "
                        f"ms")
    seconds = max(float(ends.max() - starts.min()), MIN_PHONE_S)
    if len(clip.phones) > MAX_PHONE_RATE * max(seconds, clip.duration):
        raise DataError(f"{clip.source}: {len(clip.phones)} phone labels in {seconds:.2f} s "
                        f"(at most {MAX_PHONE_RATE:g} per second)")


def check_motion(clip: RawClip, limits: Limits) -> tuple[RawClip, str]:
    """Implausible samples as dropouts, or DataError; returns (clip, note for the report).

    Parameters
    ----------
    clip : RawClip
        Motion ``(n_frames, n_channels)`` with NaN for dropouts. Channels named
        ``<p>.x``, ``<p>.y``, ``<p>.z`` in a row are a point (speed and range checked);
        any other channel is checked for its range only.
    limits : Limits

    Returns
    -------
    (RawClip, str)
        The clip with implausible samples set to NaN (unchanged if there were none) and a
        note saying how many were (empty if none).
    """
    motion = np.array(clip.motion, dtype=np.float64)
    try:
        if motion.ndim != 2 or not np.isfinite(motion[~np.isnan(motion)]).all():
            raise DataError("motion has infinite values")
        checked = _implausible(motion, clip.schema, clip.fps, limits)
        n = len(motion)
        budget = max(int(limits.max_dropout_share * n), 0)
        longest = int(round(limits.max_dropout_s * clip.fps))
        for j in checked.tracks:
            count, run = int(checked.bad[:, j].sum()), _longest_run(checked.bad[:, j])
            if count > budget or run > longest:
                raise DataError(f"{checked.describe(j, run / clip.fps)}; rejected, more "
                                f"than a dropout")
        for j in checked.tracks:
            motion[np.ix_(checked.bad[:, j], checked.columns[j])] = np.nan
        _check_moves(motion, checked)
    except DataError as exc:
        raise DataError(f"{clip.source}: {exc}") from None
    if not checked.tracks.size:
        return clip, ""
    first = checked.tracks[0]
    note = (f"{int(checked.bad.sum())} implausible sample(s) of {len(checked.tracks)} "
            f"track(s) (first: {checked.names[first]}, {checked.reason(first)}) filled as "
            f"dropouts")
    return replace(clip, motion=motion), note


def check_stored_motion(motion: np.ndarray, schema, fps: float,
                        limits: Limits | None = None) -> None:
    """The motion checks of :func:`check_motion` on a clip's motion as a database stores
    it (checked and gap-filled when it was ingested, :mod:`ingest.prepare`): no sample
    may be implausible any more, nor missing (NaN), nor infinite; no track constant.

    Parameters
    ----------
    motion : np.ndarray, shape (n_frames, n_channels)
    schema : ingest.clip.ChannelSchema
    fps : float
    limits : Limits, optional

    Raises
    ------
    DataError
        One line saying what is wrong (without naming the clip: the caller does).
    """
    motion = np.asarray(motion)
    if motion.ndim != 2 or motion.shape[1] != schema.n_channels or not len(motion):
        raise DataError(f"motion of shape {motion.shape}, not (frames, {schema.n_channels})")
    if not (np.isfinite(fps) and fps > 0):
        raise DataError(f"frame rate {fps}")
    finite = np.isfinite(motion)
    if not finite.all():
        j = int(np.flatnonzero(~finite.all(axis=0))[0])
        raise DataError(f"motion has {motion.size - int(finite.sum())} NaN or infinite "
                        f"value(s) (first: {schema.names[j]}, frame "
                        f"{int(np.flatnonzero(~finite[:, j])[0])}); stored motion is filled")
    checked = _implausible(motion.astype(np.float64, copy=False), schema, fps,
                           limits or Limits())
    if checked.tracks.size:
        j = checked.tracks[0]
        raise DataError(checked.describe(j, _longest_run(checked.bad[:, j]) / fps))
    _check_moves(motion, checked)


@dataclass(frozen=True)
class _Checked:
    """Implausible samples of a motion: ``bad`` (n_frames, n_tracks), the tracks' names
    and columns, and why each bad sample is (kept for the tracks that have one)."""

    bad: np.ndarray
    names: tuple[str, ...]
    columns: tuple[np.ndarray, ...]
    is_point: np.ndarray
    why: dict[int, np.ndarray]

    @property
    def tracks(self) -> np.ndarray:
        """The tracks with an implausible sample, in channel order."""
        return np.flatnonzero(self.bad.any(axis=0))

    def reason(self, j: int) -> str:
        """Why the first bad sample of track ``j`` is."""
        return str(self.why[j][np.flatnonzero(self.bad[:, j])[0]])

    def describe(self, j: int, run_s: float) -> str:
        first = int(np.flatnonzero(self.bad[:, j])[0])
        return (f"{self.names[j]} implausible in {int(self.bad[:, j].sum())} frame(s) "
                f"(longest run {run_s:.3f} s, first at frame {first}: {self.reason(j)})")


def _implausible(motion: np.ndarray, schema, fps: float, limits: Limits) -> _Checked:
    """Every implausible sample of ``motion`` (float64, NaN for dropouts) by the limits."""
    n = len(motion)
    names, columns = _tracks_of(tuple(schema.names))
    is_point = np.array([len(c) == 3 for c in columns], bool)
    bad = np.zeros((n, len(columns)), bool)
    why: dict[int, np.ndarray] = {}
    if is_point.any():
        cols = np.concatenate([columns[j] for j in np.flatnonzero(is_point)])
        point_bad, point_why = _implausible_points(motion[:, cols], fps, limits)
        bad[:, is_point] = point_bad
        tracks = np.flatnonzero(is_point)
        why.update({int(tracks[k]): r for k, r in point_why.items()})
    single = np.flatnonzero(~is_point)
    if single.size:
        limit = limits.max_coordinate_mm if schema.units == "mm" else limits.max_curve_value
        chans = np.array([columns[j][0] for j in single])
        with np.errstate(invalid="ignore"):
            far = np.abs(motion[:, chans]) > limit
        bad[:, single] = far
        for k in np.flatnonzero(far.any(axis=0)):
            why[int(single[k])] = np.where(far[:, k], f"beyond {limit:g} {schema.units}",
                                           "").astype(object)
    return _Checked(bad, names, columns, is_point, why)


@functools.lru_cache(maxsize=8)
def _tracks_of(channel_names: tuple[str, ...]) -> tuple[tuple[str, ...], tuple[np.ndarray, ...]]:
    """Points (``p.x, p.y, p.z`` in a row) and single channels: (names, column indices,
    read-only: they are shared)."""
    names, columns, i = [], [], 0
    channel_names = list(channel_names)
    while i < len(channel_names):
        stem = channel_names[i].removesuffix(".x")
        if (channel_names[i].endswith(".x") and channel_names[i + 1:i + 3]
                == [f"{stem}.y", f"{stem}.z"]):
            names.append(stem)
            columns.append(np.arange(i, i + 3))
            i += 3
        else:
            names.append(channel_names[i])
            columns.append(np.array([i]))
            i += 1
    for c in columns:
        c.setflags(write=False)
    return tuple(names), tuple(columns)


def _implausible_points(motion: np.ndarray, fps: float, limits: Limits):
    """(bad (n_frames, n_points), {point: reason per frame}) of x/y/z point tracks.

    A point's valid samples are cut into segments wherever it moves faster than the
    limit from one sample to the next. The longest segment is trusted; going outwards
    from it, a segment is trusted too if the point could have travelled to it from the
    trusted samples within the limit, and is implausible otherwise (a spike, a plateau
    of a few frames, the far side of a step).
    """
    n = len(motion)
    pts = motion.reshape(n, -1, 3)
    with np.errstate(invalid="ignore", over="ignore"):
        far = np.abs(pts).max(axis=2) > limits.max_coordinate_mm
    far &= ~np.isnan(pts).any(axis=2)
    bad = far.copy()
    why = {int(j): np.where(far[:, j], f"beyond {limits.max_coordinate_mm:g} mm",
                            "").astype(object) for j in np.flatnonzero(far.any(axis=0))}
    for j in map(int, _points_to_check(pts, bad, fps, limits)):
        p = pts[:, j]
        idx = np.flatnonzero(~np.isnan(p).any(axis=1) & ~bad[:, j])
        if len(idx) < 2:
            continue
        speed = _speeds(p, idx[:-1], idx[1:], fps)
        cuts = np.flatnonzero(~(speed <= limits.max_speed_mm_s)) + 1
        if not cuts.size:
            continue
        segments = np.split(np.arange(len(idx)), cuts)
        k = int(np.argmax([len(seg) for seg in segments]))
        for order, edge in ((range(k - 1, -1, -1), 0), (range(k + 1, len(segments)), -1)):
            anchor = idx[segments[k][edge]]
            for i in order:
                near = idx[segments[i][-1 - edge]]  # the segment's end facing the anchor
                step = float(_speeds(p, np.array([near]), np.array([anchor]), fps)[0])
                if step <= limits.max_speed_mm_s:
                    anchor = idx[segments[i][edge]]
                    continue
                frames = idx[segments[i]]
                bad[frames, j] = True
                if j not in why:
                    why[j] = np.full(n, "", dtype=object)
                why[j][frames] = (f"moves at {step:.3g} mm/s, above "
                                  f"{limits.max_speed_mm_s:g} mm/s")
    return bad, why


def _points_to_check(pts: np.ndarray, bad: np.ndarray, fps: float, limits: Limits
                     ) -> np.ndarray:
    """Points that may have an implausible sample: all but those whose valid frames are
    the frames where any point is valid and which never move faster than the limit
    between two of them (checked for all such points at once: a tracked video's points
    are missing together, in the frames without a face)."""
    valid = ~np.isnan(pts).any(axis=2) & ~bad
    frames = valid.any(axis=1)
    shared = (valid == frames[:, None]).all(axis=0)
    idx = np.flatnonzero(frames)
    if len(idx) < 2 or not shared.any():
        return np.arange(pts.shape[1])
    # Squared steps against the squared farthest step allowed (no square root: this is
    # every frame of every point, of every stored clip at each ingest too).
    p = pts if len(idx) == len(pts) and shared.all() else pts[idx][:, shared]
    step = p[1:] - p[:-1]
    with np.errstate(over="ignore", invalid="ignore"):
        squared = np.einsum("ijk,ijk->ij", step, step)
        farthest = (limits.max_speed_mm_s / fps * np.diff(idx).astype(np.float64)) ** 2
        moves_fine = (squared <= farthest[:, None]).all(axis=0)
    fine = np.zeros(pts.shape[1], bool)
    fine[np.flatnonzero(shared)] = moves_fine
    return np.flatnonzero(~fine)


def _speeds(p: np.ndarray, a: np.ndarray, b: np.ndarray, fps: float) -> np.ndarray:
    with np.errstate(over="ignore", invalid="ignore"):
        return np.linalg.norm(p[b] - p[a], axis=1) * fps / np.abs(b - a)


def _longest_run(flags: np.ndarray) -> int:
    if not flags.any():
        return 0
    edges = np.diff(np.concatenate([[0], flags.astype(np.int8), [0]]))
    return int((np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)).max())


def _check_moves(motion: np.ndarray, checked: _Checked) -> None:
    """DataError unless every point, and the motion as a whole, moves."""
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # an all-NaN column
        span = np.nanmax(motion, axis=0) - np.nanmin(motion, axis=0)
    if not (span > MIN_RANGE).any():
        raise DataError("the motion never moves (every channel constant)")
    points = np.flatnonzero(checked.is_point)
    if not points.size:
        return
    cols = np.stack([checked.columns[j] for j in points])
    dead = ~(span[cols] > MIN_RANGE).any(axis=1)
    if dead.any():
        raise DataError(f"{checked.names[points[np.argmax(dead)]]} never moves (a constant "
                        f"or all-zero track: a dead marker)")


def check_clip(clip: RawClip, limits: Limits | None = None) -> tuple[RawClip, str]:
    """Every check of this module on one clip: (the clip, a note for the report).

    The clip comes back with its emotion lowercased and implausible samples made gaps
    and filled (the note says how many).

    Raises
    ------
    DataError
        The clip is rejected; the message says why.
    """
    check_clip_labels(clip)
    if clip.emotion is not None and clip.emotion != clip.emotion.lower():
        clip = replace(clip, emotion=clip.emotion.lower())
    check_phones(clip)
    return check_motion(clip, limits or Limits())
