"""A clip as read from disk: motion, speech, text and labels, whatever the source kind.

Readers of every corpus kind (marker, animation-curve, landmark) return a
:class:`RawClip`; everything after reading works on its generic
``(n_frames, n_channels)`` motion and its :class:`ChannelSchema`, never on the kind.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from db.errors import DataError
from ingest.formats.livelink import ROTATIONS
from ingest.formats.phones_csv import Segment
from ingest.formats.words import WordSegment

#: Kinds of motion a clip can carry.
KINDS = ("markers", "curves", "landmarks")


#: Channels of a removed rigid head pose (group ``"pose"``) and their units, as
#: :func:`ingest.readers.landmarks.pose_motion` makes them: rotation in hundredths of a
#: radian (the arc, in mm, of a point 100 mm from the head's centre), position in mm,
#: scale change in per cent.
POSE_UNITS: dict[str, str] = {
    "pose.rx": "0.01 rad", "pose.ry": "0.01 rad", "pose.rz": "0.01 rad",
    "pose.tx": "mm", "pose.ty": "mm", "pose.tz": "mm", "pose.scale": "%",
}

#: An iPhone capture's head and eye rotations among its blendshape weights: angles in
#: radians, as Live Link Face exports them (:data:`ingest.formats.livelink.ROTATIONS`).
ROTATION_UNITS: dict[str, str] = {name: "rad" for name in ROTATIONS}


@dataclass(frozen=True)
class ChannelSchema:
    """What each motion channel is.

    Attributes
    ----------
    kind : str
        ``"markers"`` (3D marker x/y/z triples), ``"curves"`` (named animation
        curves, e.g. blendshape weights) or ``"landmarks"`` (3D points tracked from
        video, head pose removed).
    names : tuple of str
        One name per channel: ``"<marker>.x"``/``.y``/``.z`` for point kinds, the curve
        name for curves.
    groups : tuple of str
        Motion group of each channel (Cao et al. §3.2: ``"head"``, ``"upper_face"``,
        ``"lips"``; ``"pose"`` for a removed rigid head pose; ``"other"`` if unknown).
    units : str
        ``"mm"`` for markers and landmarks, ``"unit"`` for curves; a head pose
        channel's are its own (:attr:`channel_units`).
    """

    kind: str
    names: tuple[str, ...]
    groups: tuple[str, ...]
    units: str

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise DataError(f"channel kind must be one of {KINDS}, got {self.kind!r}")
        if len(self.names) != len(self.groups):
            raise DataError(f"{len(self.names)} channel names but {len(self.groups)} groups")
        if len(set(self.names)) != len(self.names):
            raise DataError("channel names must be unique")

    @property
    def n_channels(self) -> int:
        return len(self.names)

    @property
    def channel_units(self) -> tuple[str, ...]:
        """Each channel's units: the schema's, but a head pose channel's its own
        (:data:`POSE_UNITS`), and an ARKit rotation's among curves radians
        (:data:`ROTATION_UNITS`: the channels table said "unit" of headYaw)."""
        own = ROTATION_UNITS if self.kind == "curves" else {}
        return tuple(POSE_UNITS.get(name, self.units) if group == "pose"
                     else own.get(name, self.units)
                     for name, group in zip(self.names, self.groups, strict=True))

    def difference(self, other: ChannelSchema) -> str:
        """What differs from ``other``, in words ("" if nothing), for a rejection."""
        if self.kind != other.kind:
            return f"its motion is {self.kind}, the database's {other.kind}"
        if self.n_channels != other.n_channels:
            return (f"it has {self.n_channels} {self.kind} channels, the database "
                    f"{other.n_channels}")
        if self.names != other.names:
            pairs = [(a, b) for a, b in zip(self.names, other.names, strict=True) if a != b]
            if set(self.names) == set(other.names):
                return "its channels are the database's in another order"
            return (f"{len(pairs)} of its channel names differ from the database's (first: "
                    f"{pairs[0][0]} where the database has {pairs[0][1]})")
        if self.groups != other.groups:
            k = next(i for i, (a, b) in enumerate(zip(self.groups, other.groups, strict=True))
                     if a != b)
            hint = (" (is its markers.csv, which gives the motion groups, missing?)"
                    if "other" in (self.groups[k], other.groups[k]) else "")
            return (f"its motion groups differ from the database's (first: {self.names[k]} "
                    f"is {self.groups[k]}, in the database {other.groups[k]}){hint}")
        if self.units != other.units:
            return f"its units are {self.units}, the database's {other.units}"
        return ""

    @classmethod
    def for_points(cls, kind: str, labels, groups, units: str) -> ChannelSchema:
        """Schema of x/y/z triples of named points (markers or landmarks)."""
        names = tuple(f"{label}.{axis}" for label in labels for axis in "xyz")
        return cls(kind=kind, names=names, groups=tuple(g for g in groups for _ in "xyz"),
                   units=units)


@dataclass(frozen=True, eq=False)
class RawClip:
    """One utterance as read from its files.

    Attributes
    ----------
    clip_id : str
        Unique within its corpus (file stem by default).
    corpus : str
        Name of the corpus (folder name by default).
    source : Path
        The motion file (or clip folder) it was read from.
    motion : np.ndarray, shape (n_frames, n_channels)
        Motion, float64; NaN where a channel is missing (marker dropouts).
    fps : float
        Frames per second of ``motion``.
    schema : ChannelSchema
        What the channels are.
    audio : np.ndarray, shape (n_samples,)
        Mono speech, float32 in [-1, 1].
    sample_rate : int
        Audio sample rate in Hz.
    text : str or None
        Transcript, if any.
    phones : tuple of ingest.formats.phones_csv.Segment, or None
        Phone labels (ARPAbet, seconds) shipped with the clip, if any.
    words : tuple of ingest.formats.words.WordSegment, or None
        A word alignment shipped with the clip (GRID ``.align``, a TextGrid word tier),
        if any: phones are then aligned inside each word.
    emotion, speaker, sentence_id : str or None
        Metadata, if known.
    checksum : str
        SHA-256 over the clip's source files: re-ingesting an unchanged clip is a no-op.
    extra : dict
        Reader-specific facts worth keeping (e.g. an estimated lip-audio lag).
    """

    clip_id: str
    corpus: str
    source: Path
    motion: np.ndarray
    fps: float
    schema: ChannelSchema
    audio: np.ndarray
    sample_rate: int
    checksum: str
    text: str | None = None
    phones: tuple[Segment, ...] | None = None
    words: tuple[WordSegment, ...] | None = None
    emotion: str | None = None
    speaker: str | None = None
    sentence_id: str | None = None
    extra: dict = field(default_factory=dict)

    @property
    def n_frames(self) -> int:
        return int(self.motion.shape[0])

    @property
    def duration(self) -> float:
        """Audio duration in seconds."""
        return len(self.audio) / self.sample_rate


def checksum_files(paths) -> str:
    """SHA-256 (hex) over the bytes of ``paths`` in the given order, names excluded."""
    digest = hashlib.sha256()
    for path in paths:
        with open(path, "rb") as handle:
            for block in iter(lambda: handle.read(1 << 20), b""):
                digest.update(block)
    return digest.hexdigest()


def checksum_bytes(parts) -> str:
    """:func:`checksum_files` of files holding ``parts`` (bytes), in that order: for a
    clip's files already read (those that travel to a Dask worker)."""
    digest = hashlib.sha256()
    for part in parts:
        digest.update(part)
    return digest.hexdigest()


def stored_schema(db, channels: list[dict] | None = None) -> ChannelSchema:
    """The channels of ``db``'s motion (its ``channels`` table, or its rows ``channels``
    if already read), as its clips had them; the database's damage (DataError naming the
    table) if they do not hold up: a database is shared between people."""
    rows = db.table("channels").to_pylist() if channels is None else channels
    try:
        return ChannelSchema(kind=str(rows[0]["kind"]), names=tuple(str(c["name"]) for c in rows),
                             groups=tuple(str(c["group"]) for c in rows),
                             units=str(rows[0]["units"]))
    except (KeyError, IndexError, TypeError, DataError) as exc:
        raise db.damaged("channels", f"{type(exc).__name__}: {exc}") from None
