"""What every reader shares: :class:`ClipSource`, side files, and the checks on a clip.

Checks made on every clip (each failure is one :class:`db.errors.DataError` line):

- motion is a 2-D ``(n_frames, n_channels)`` array of finite numbers or NaN, with at
  least one frame, and no channel (marker, curve, landmark) NaN in every frame;
- the motion's duration ``n_frames / fps`` and the audio's duration agree within
  :func:`duration_tolerance` = max(:data:`DURATION_TOLERANCE_S`,
  :data:`DURATION_TOLERANCE_REL` x audio duration), i.e. 0.2 s, or 2 % for clips
  longer than 10 s (video and audio tracks of real recordings commonly differ by a
  frame or two plus codec padding; a wrong frame rate or a clip cut from the wrong
  take is off by far more);
- phone labels end no later than the audio (within the same tolerance);
- a transcript file is not empty.
"""

from __future__ import annotations

import json
import logging
import math
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from db.errors import DataError
from db.npyfile import REAL_KINDS, check_npy, holds
from ingest.formats.htk_lab import read_htk_lab
from ingest.formats.phones_csv import Segment, read_phones_csv
from ingest.formats.text import MAX_SIDE_FILE_BYTES, read_bytes, read_utf8
from ingest.formats.textgrid import PHONE_TIER_NAMES, read_textgrid, read_tiers
from ingest.formats.words import WORD_TIER_NAMES, read_grid_align, read_textgrid_words

logger = logging.getLogger(__name__)

#: Roles of a clip's files, in the order their bytes enter the clip's checksum.
ROLES = (
    "motion",  # the motion file (c3d/trc/csv, npy/curves.csv, landmarks.npy)
    "audio",  # the speech (wav)
    "labels",  # phone labels (phones.csv, TextGrid, lab)
    "transcript",  # <stem>.txt
    "metadata",  # <stem>.json / meta.json
    "marker_table",  # markers.csv: marker -> motion group
    "channel_names",  # curve names: <stem>.channels.txt, FACEGOOD's names .npy
    "channel_list",  # FACEGOOD's bsname.txt (checked against the .npy names)
    "settings",  # curves.json: corpus-level frame rate / channel names
    "words",  # a word alignment: <stem>.align (GRID); last, so older checksums stand
)
#: Motion groups a channel may belong to (:class:`ingest.clip.ChannelSchema`).
GROUPS = ("head", "upper_face", "lips", "pose", "other")

#: Audio and motion durations may differ by max(DURATION_TOLERANCE_S, DURATION_TOLERANCE_REL
#: x audio duration) seconds.
DURATION_TOLERANCE_S = 0.2
DURATION_TOLERANCE_REL = 0.02

#: Largest JSON side file (metadata, settings) read, bytes.
MAX_JSON_BYTES = 1 << 20
#: Deepest nesting of a JSON side file (a clip's metadata is two or three levels deep).
MAX_JSON_DEPTH = 32

#: Metadata keys copied onto a :class:`ingest.clip.RawClip`.
META_KEYS = ("text", "emotion", "speaker", "sentence_id")


@dataclass(frozen=True, order=True)
class ClipSource:
    """One clip found on disk, before anything heavy is read.

    Attributes
    ----------
    corpus : str
        Corpus name (the corpus folder's name).
    clip_id : str
        Unique within the corpus (file stem or clip folder name).
    kind : str
        ``"markers"``, ``"curves"`` or ``"landmarks"``.
    layout : str
        Which reader loads it: ``"synthetic"`` (the project's corpus), ``"markers"``
        (generic marker folder), ``"facegood"``, ``"curves"`` (generic curve clips) or
        ``"talkingface"`` or ``"livelink"`` (an iPhone capture).
    source : Path
        The motion file (or, for landmark clips, the clip folder).
    files : tuple of (str, Path)
        The clip's files as ``(role, path)`` in :data:`ROLES` order (roles absent from
        the clip are left out; ``"audio"`` is absent when no audio file was found).
    """

    corpus: str
    clip_id: str
    kind: str
    layout: str
    source: Path
    files: tuple[tuple[str, Path], ...]

    @classmethod
    def make(cls, corpus: str, clip_id: str, kind: str, layout: str, source: Path,
             files: dict[str, Path | None]) -> ClipSource:
        """Build a source from a ``role -> path`` dict (None entries dropped)."""
        unknown = set(files) - set(ROLES)
        if unknown:
            raise ValueError(f"unknown file roles {sorted(unknown)}")
        ordered = tuple((role, Path(files[role])) for role in ROLES if files.get(role))
        return cls(corpus, clip_id, kind, layout, Path(source), ordered)

    @property
    def path(self) -> Path:
        """The clip's main path (same as ``source``)."""
        return self.source

    def file(self, role: str) -> Path | None:
        """The file playing ``role``, or None."""
        for name, path in self.files:
            if name == role:
                return path
        return None

    @property
    def paths(self) -> tuple[Path, ...]:
        """All files, in checksum order."""
        return tuple(path for _, path in self.files)


def duration_tolerance(audio_seconds: float) -> float:
    """Largest allowed difference (s) between motion and audio durations."""
    return max(DURATION_TOLERANCE_S, DURATION_TOLERANCE_REL * audio_seconds)


def check_durations(n_frames: int, fps: float, audio_seconds: float, where: Path) -> None:
    """Raise DataError if the motion and audio durations disagree beyond the tolerance."""
    motion_seconds = n_frames / fps
    tolerance = duration_tolerance(audio_seconds)
    if abs(motion_seconds - audio_seconds) > tolerance:
        raise DataError(
            f"{where}: motion lasts {motion_seconds:.3f} s ({n_frames} frames at {fps:g} fps) "
            f"but audio {audio_seconds:.3f} s (tolerance {tolerance:.2f} s)"
        )


def check_motion(motion: np.ndarray, channel_names, where: Path, what: str = "channel",
                 stride: int = 1) -> np.ndarray:
    """Check a motion array; return it as C-contiguous float64.

    Parameters
    ----------
    motion : np.ndarray, shape (n_frames, n_channels)
        Motion as read.
    channel_names : sequence of str
        Names of the items checked for being missing throughout: one per channel, or
        one per ``stride`` consecutive channels (a marker's x/y/z).
    where : Path
        Named in errors.
    what : str
        What an item is called in the message ("marker", "curve", "landmark").
    stride : int
        Channels per named item.

    Raises
    ------
    DataError
        If the array is not 2-D real numbers with a frame at least, holds infinities, or
        an item is NaN in every frame (the first few are named).
    """
    motion = np.asarray(motion)
    if motion.dtype.kind not in REAL_KINDS:  # complex, booleans, text: not cast silently
        raise DataError(f"{where}: motion holds {holds(motion.dtype)}, not real numbers")
    motion = np.ascontiguousarray(motion, dtype=np.float64)
    if motion.ndim != 2 or motion.shape[0] < 1 or motion.shape[1] < 1:
        raise DataError(
            f"{where}: motion must be (n_frames, n_channels) with at least one of each, "
            f"got shape {motion.shape}"
        )
    if np.isinf(motion).any():
        raise DataError(f"{where}: motion has infinite values")
    missing = np.isnan(motion).all(axis=0)
    if stride > 1:
        missing = missing.reshape(-1, stride).any(axis=1)
    if missing.any():
        names = [str(n) for n, gone in zip(channel_names, missing, strict=True) if gone]
        shown = ", ".join(names[:5]) + (f" and {len(names) - 5} more" if len(names) > 5 else "")
        raise DataError(f"{where}: {what} {shown} missing (NaN) in every frame")
    return motion


def read_json_object(path: Path) -> dict:
    """Read a JSON file holding an object; DataError naming the file otherwise.

    A side file larger than :data:`MAX_JSON_BYTES` or nested deeper than
    :data:`MAX_JSON_DEPTH` is refused (one clip rejected, not a ``RecursionError``), and
    so is anything but a file (a FIFO named ``clip.json`` would block the read forever).
    """
    # read_bytes: a file only, and no more than the bound read (a size checked first
    # could grow before the read)
    data = read_bytes(path, "metadata file", MAX_JSON_BYTES)
    try:
        value = json.loads(data.decode("utf-8-sig"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise DataError(f"corrupt JSON in {path}: {exc}") from None
    except RecursionError:
        raise DataError(f"{path}: JSON nested too deeply") from None
    if _depth(value) > MAX_JSON_DEPTH:
        raise DataError(f"{path}: JSON nested deeper than {MAX_JSON_DEPTH} levels")
    if not isinstance(value, dict):
        raise DataError(f"{path}: expected a JSON object, got {type(value).__name__}")
    return value


def _depth(value, limit: int = MAX_JSON_DEPTH + 1) -> int:
    """Nesting depth of a parsed JSON value (counted up to ``limit``, iteratively)."""
    deepest, stack = 0, [(value, 1)]
    while stack:
        item, depth = stack.pop()
        if isinstance(item, dict | list):
            deepest = max(deepest, depth)
            if depth < limit:
                children = item.values() if isinstance(item, dict) else item
                stack.extend((child, depth + 1) for child in children)
    return deepest


def metadata_fields(meta: dict, path: Path) -> dict[str, str | None]:
    """The :data:`META_KEYS` of a metadata object as str (numbers converted) or None."""
    out: dict[str, str | None] = {}
    for key in META_KEYS:
        value = meta.get(key)
        if value is None or (isinstance(value, str) and not value.strip()):
            out[key] = None
        elif isinstance(value, str | int) and not isinstance(value, bool):
            out[key] = str(value).strip()
        else:
            raise DataError(f"{path}: {key!r} must be a string, got {value!r}")
    return out


def read_fps(meta: dict, path: Path) -> float | None:
    """The ``fps`` of a metadata object (None if absent); DataError if not a rate."""
    if "fps" not in meta:
        return None
    value = meta["fps"]
    if isinstance(value, bool) or not isinstance(value, int | float) or not (
        math.isfinite(value) and value > 0
    ):
        raise DataError(f"{path}: 'fps' must be a number > 0, got {value!r}")
    return float(value)


def read_transcript(path: Path) -> str:
    """Read a transcript file (UTF-8); DataError if it is empty or not text."""
    text = read_utf8(path, "transcript", limit=MAX_SIDE_FILE_BYTES)
    text = " ".join(text.split())
    if not text:
        raise DataError(f"empty transcript file: {path}")
    return text


def read_labels(path: Path) -> list[Segment]:
    """Read phone labels by file type: ``.phones.csv``, ``.TextGrid`` or ``.lab``."""
    name = path.name.lower()
    if name.endswith(".phones.csv"):
        return read_phones_csv(path)
    if name.endswith(".textgrid"):
        return read_textgrid(path)
    if name.endswith(".lab"):
        return read_htk_lab(path)
    raise DataError(f"unknown phone label file type: {path}")


def read_labels_for(path: Path, audio: np.ndarray, sample_rate: int) -> list[Segment]:
    """Phones of speech ``audio`` from a label file, as ingest reads a clip's: phone
    labels (:func:`read_labels`), or a GRID word alignment (``.align``, which ingest reads
    beside a clip) whose words' times are kept and each word's phones aligned inside it
    (:func:`ingest.speech.words.align_words`, what ingest does with it)."""
    path = Path(path)
    if not path.name.lower().endswith(".align"):
        return read_labels(path)
    from ingest.speech.words import align_words

    words = tuple(read_grid_align(path))
    seconds = len(audio) / sample_rate
    if not words or words[-1].end > seconds + duration_tolerance(seconds):
        end = f"end at {words[-1].end:.3f} s" if words else "are none"
        raise DataError(f"{path}: its words {end}, the speech lasts {seconds:.3f} s")
    phones, _ = align_words(np.asarray(audio, dtype=np.float32), sample_rate, words)
    return list(phones)


def check_labels(phones: list[Segment], audio_seconds: float, where: Path) -> None:
    """Raise DataError if phone labels run past the end of the audio."""
    if phones and phones[-1].end > audio_seconds + duration_tolerance(audio_seconds):
        raise DataError(
            f"{where}: phone labels end at {phones[-1].end:.3f} s, after the audio "
            f"({audio_seconds:.3f} s)"
        )


def transcript_and_labels(source, audio_seconds: float) -> tuple[str | None,
                                                                  tuple[Segment, ...] | None]:
    """The clip's transcript file, phone labels and word alignment, if it has them (checked).

    A TextGrid with a word tier but no phone tier (``phones``/``phone``/``segments``) is
    a word alignment; with both, its phones are read. Without a transcript file, the
    transcript is the word alignment's words.
    """
    text = None
    transcript_path = source.file("transcript")
    if transcript_path is not None:
        text = read_transcript(transcript_path)
    phones = words = None
    labels_path = source.file("labels")
    if labels_path is not None and _word_textgrid(labels_path):
        words = read_textgrid_words(labels_path)
    elif labels_path is not None:
        segments = read_labels(labels_path)
        check_labels(segments, audio_seconds, labels_path)
        phones = tuple(segments)
    words_path = source.file("words")
    if words_path is not None and words is None:
        words = read_grid_align(words_path)
    if words is not None:
        words = tuple(words)
        if words[-1].end > audio_seconds + duration_tolerance(audio_seconds):
            raise DataError(f"{words_path or labels_path}: words end at {words[-1].end:.3f} s, "
                            f"after the audio ({audio_seconds:.3f} s)")
        spoken = " ".join(w.word for w in words if w.word)
        if text is None:
            text = spoken
        elif _normalised(text) != _normalised(spoken):
            raise DataError(f"{words_path or labels_path}: its words {spoken[:60]!r} are not "
                            f"the transcript's {text[:60]!r} (another utterance?)")
    return text, phones, words


def _normalised(text: str) -> list[str]:
    words = (w.strip(".,;:!?'\"") for w in text.lower().replace("-", " ").split())
    return [w for w in words if w]


def _word_textgrid(path: Path) -> bool:
    """A TextGrid whose only label tier is a word tier."""
    if not path.name.lower().endswith(".textgrid"):
        return False
    tiers = [t.name.strip().lower() for t in read_tiers(path) if t.kind == "IntervalTier"]
    return (any(t in WORD_TIER_NAMES for t in tiers)
            and not any(t in PHONE_TIER_NAMES for t in tiers))


def speech_and_side_files(source, n_frames: int, fps: float, where: Path, meta: dict,
                          meta_path: Path | None):
    """A clip's audio (a WAV, or a video's sound track: :func:`ingest.formats.media.
    read_audio`; its duration checked against the motion's), metadata fields,
    transcript, phone labels and word alignment.

    Returns
    -------
    audio : np.ndarray, shape (n_samples,)
    sample_rate : int
    fields : dict
        :data:`META_KEYS` from ``meta`` (None if absent), ``"text"`` from a transcript
        file if there is one.
    phones : tuple of Segment or None
    words : tuple of Word or None
        A word alignment beside the clip (:func:`transcript_and_labels`).
    """
    from ingest.formats.media import read_audio

    audio, sample_rate = read_audio(source.file("audio"))
    audio_seconds = len(audio) / sample_rate
    check_durations(n_frames, fps, audio_seconds, where)
    fields = metadata_fields(meta, meta_path) if meta_path else dict.fromkeys(META_KEYS)
    text, phones, words = transcript_and_labels(source, audio_seconds)
    if text is not None:
        fields["text"] = text
    return audio, sample_rate, fields, phones, words


def load_npy(path: Path) -> np.ndarray:
    """Load a ``.npy`` array; never unpickles.

    Unpickling runs code from the file, so an array of Python objects is refused, also
    in the FACEGOOD layout (its shipped files are plain arrays that load without it).

    Parameters
    ----------
    path : Path
        The file.

    Raises
    ------
    DataError
        If the file is missing, truncated (also: a header declaring more data than the
        file holds, :func:`db.npyfile.check_npy`), not a ``.npy`` array, or needs
        unpickling.
    """
    if not path.is_file():
        raise DataError(f"array file not found: {path}")
    with warnings.catch_warnings():
        # numpy warns when it has to parse a Python-2 header ("(3295L, 116L)").
        warnings.simplefilter("ignore", UserWarning)
        check_npy(path)  # a header's shape is not allocated before the file can hold it
        try:
            array = np.load(path, allow_pickle=False)
        except ValueError as exc:
            if "allow_pickle" in str(exc):
                raise DataError(f"{path} holds Python objects (a pickle); refused: only "
                                f"plain numeric arrays are read") from None
            raise DataError(f"unreadable or truncated array file {path}: {exc}") from None
        except (OSError, EOFError) as exc:
            raise DataError(f"unreadable or truncated array file {path}: {exc}") from None
    if not isinstance(array, np.ndarray):
        raise DataError(f"{path}: expected a .npy array, got {type(array).__name__}")
    return array
