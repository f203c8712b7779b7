"""Labelled recordings for training or checking the emotion classifier: emotion and speaker
of each file from a corpus' naming scheme (``--preset``) or a CSV (``--labels``).

The presets speak one vocabulary of emotions, so that a classifier fitted on one corpus
names what it hears as another corpus' labels do: ``neutral``, ``calm``, ``happy``,
``sad``, ``angry``, ``fearful``, ``disgust``, ``surprised``, ``boredom`` (RAVDESS's own
words; EmoDB's, TESS's and CREMA-D's codes are mapped onto them, :data:`PRESET_EMOTIONS`).

A CSV has a header naming ``path`` and ``emotion`` (and optionally ``speaker``), one row a
recording. Its paths are relative to the folder of recordings (``DIR``) and may not leave
it: a row whose path is absolute, climbs out with ``..`` or through a link, names no file,
repeats a file, or holds an empty or malformed label is rejected with its reason, and the
good rows are used.
"""

from __future__ import annotations

import csv
import re
from dataclasses import dataclass, field
from pathlib import Path

from db.errors import DataError, ParameterError

__all__ = ["AUDIO_SUFFIXES", "PRESETS", "PRESET_EMOTIONS", "Labelled", "audio_files",
           "from_csv", "from_preset", "preset_label"]

#: Files taken from a folder: what libsndfile reads.
AUDIO_SUFFIXES = (".wav", ".flac", ".ogg", ".mp3")
#: Most recordings read from a folder or a CSV (a mistaken ``/`` is said, not walked).
MAX_FILES = 200_000
#: Largest labels CSV, bytes.
MAX_CSV_BYTES = 64 << 20

#: Each preset's emotion codes in its file names, to the common vocabulary.
PRESET_EMOTIONS = {
    # 03-01-05-02-01-01-07: modality, channel, EMOTION, intensity, statement, repetition, actor
    "ravdess": {"01": "neutral", "02": "calm", "03": "happy", "04": "sad", "05": "angry",
                "06": "fearful", "07": "disgust", "08": "surprised"},
    # 03a01Fa: speaker, text, EMOTION letter (German initials), version
    "emodb": {"W": "angry", "L": "boredom", "E": "disgust", "A": "fearful", "F": "happy",
              "T": "sad", "N": "neutral"},
    # OAF_back_angry: speaker (OAF, YAF), word, EMOTION ("ps": pleasant surprise)
    "tess": {"angry": "angry", "disgust": "disgust", "fear": "fearful", "happy": "happy",
             "neutral": "neutral", "ps": "surprised", "sad": "sad"},
    # 1001_DFA_ANG_XX: actor, sentence, EMOTION, level
    "crema-d": {"ANG": "angry", "DIS": "disgust", "FEA": "fearful", "HAP": "happy",
                "NEU": "neutral", "SAD": "sad"},
}
PRESETS = tuple(PRESET_EMOTIONS)

_RAVDESS = re.compile(r"^(0[1-3])-(0[12])-(0[1-8])-(0[12])-(0[12])-(0[12])-(\d\d)$")
_EMODB = re.compile(r"^(\d\d)[a-z]\d\d([WLEAFTN])[a-z]$")
_TESS = re.compile(r"^([A-Za-z]+)_[A-Za-z]+_([A-Za-z]+)$")
_CREMA = re.compile(r"^(\d{4})_[A-Z]{3}_([A-Z]{3})_[A-Z]{2}$")
#: An emotion label: what ``synth --emotion`` accepts as a name.
_LABEL = re.compile(r"^[A-Za-z][A-Za-z0-9_-]{0,63}$")
#: A speaker name.
_SPEAKER = re.compile(r"^[^\x00-\x1f\x7f]{1,128}$")


@dataclass
class Labelled:
    """Recordings with their emotion (or None) and speaker, and the rows left out.

    Attributes
    ----------
    paths : list of Path
    emotions : list of str or None
    speakers : list of str or None
        None: not known.
    rejected : list of str
        One line per file or row left out, with its reason.
    """

    paths: list = field(default_factory=list)
    emotions: list = field(default_factory=list)
    speakers: list = field(default_factory=list)
    rejected: list = field(default_factory=list)

    def add(self, path: Path, emotion: str | None, speaker: str | None) -> None:
        self.paths.append(path)
        self.emotions.append(emotion)
        self.speakers.append(speaker)


def audio_files(inputs) -> list[Path]:
    """The recordings among ``inputs`` (files, and folders searched for
    :data:`AUDIO_SUFFIXES` in sorted order), each once.

    Raises
    ------
    DataError
        A path that does not exist, more than :data:`MAX_FILES`.
    """
    out: dict[Path, None] = {}
    for item in inputs:
        item = Path(item)
        if item.is_dir():
            for path in sorted(item.rglob("*")):
                if path.suffix.lower() in AUDIO_SUFFIXES and path.is_file():
                    out[path] = None
                    if len(out) > MAX_FILES:
                        raise DataError(f"more than {MAX_FILES} recordings under {item}")
        elif item.is_file():
            out[item] = None
        else:
            raise DataError(f"no such file or folder: {item}")
    return list(out)


def preset_label(preset: str, path: Path) -> tuple[str, str]:
    """(emotion, speaker) of a file named by ``preset``'s scheme.

    Raises
    ------
    DataError
        The name is not the preset's (the reason, one line).
    """
    stem = Path(path).stem
    codes = PRESET_EMOTIONS[preset]
    if preset == "ravdess":
        m = _RAVDESS.match(stem)
        if m is not None and m.group(2) == "02":
            raise DataError("a RAVDESS song (channel 02), not speech")
        if m is not None:
            return codes[m.group(3)], m.group(7)
    elif preset == "emodb":
        m = _EMODB.match(stem)
        if m is not None:
            return codes[m.group(2)], m.group(1)
    elif preset == "tess":
        m = _TESS.match(stem)
        if m is not None and m.group(2).lower() in codes:
            return codes[m.group(2).lower()], m.group(1).upper()
    elif preset == "crema-d":
        m = _CREMA.match(stem)
        if m is not None and m.group(2) in codes:
            return codes[m.group(2)], m.group(1)
    else:
        raise ParameterError(f"unknown preset {preset!r}: one of {', '.join(PRESETS)}")
    raise DataError(f"not a {preset} file name")


def from_preset(inputs, preset: str) -> Labelled:
    """The recordings among ``inputs`` labelled by ``preset``'s naming; a file named
    otherwise is rejected with the reason."""
    if preset not in PRESET_EMOTIONS:
        raise ParameterError(f"unknown preset {preset!r}: one of {', '.join(PRESETS)}")
    out = Labelled()
    for path in audio_files(inputs):
        try:
            emotion, speaker = preset_label(preset, path)
        except DataError as exc:
            out.rejected.append(f"{path.name}: {exc}")
            continue
        out.add(path, emotion, speaker)
    return out


def _inside(root: Path, text: str) -> Path:
    """``root / text`` if it stays inside ``root`` (links resolved), else DataError."""
    if not text:
        raise DataError("empty path")
    candidate = Path(text)
    if candidate.is_absolute() or candidate.drive:
        raise DataError("an absolute path (paths are relative to the folder)")
    full = (root / candidate).resolve()
    if not full.is_relative_to(root):
        raise DataError("the path leaves the folder")
    if not full.is_file():
        raise DataError("no such file")
    return full


def from_csv(csv_path: Path, root: Path, *, need_emotion: bool = True) -> Labelled:
    """Rows of a labels CSV (``path,emotion[,speaker]`` with a header), paths inside ``root``.

    Parameters
    ----------
    csv_path : Path
    root : Path
        The folder the paths are relative to.
    need_emotion : bool, optional
        A row without an emotion is rejected (training); else its emotion is None.

    Raises
    ------
    DataError
        The CSV cannot be read, is too large, or its header lacks ``path`` or ``emotion``.
    """
    csv_path, root = Path(csv_path), Path(root).resolve()
    try:
        if csv_path.stat().st_size > MAX_CSV_BYTES:
            raise DataError(f"{csv_path}: larger than {MAX_CSV_BYTES >> 20} MB")
        text = csv_path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise DataError(f"labels file not found: {csv_path}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"cannot read the labels file {csv_path}: "
                        f"{getattr(exc, 'strerror', None) or exc}") from None
    reader = csv.reader(text.splitlines())
    header = [h.strip().lower() for h in next(reader, [])]
    if "path" not in header or "emotion" not in header:
        raise DataError(f"{csv_path}: the first line must name the columns path,emotion"
                        f"[,speaker], got {','.join(header) or 'nothing'}")
    col = {name: header.index(name) for name in ("path", "emotion", "speaker")
           if name in header}
    out, seen = Labelled(), set()
    for line, row in enumerate(reader, start=2):
        if not any(cell.strip() for cell in row):
            continue
        where = f"{csv_path.name} line {line}"
        if len(row) != len(header):
            out.rejected.append(f"{where}: {len(row)} fields, the header has {len(header)}")
            continue
        if line - 1 > MAX_FILES:
            raise DataError(f"{csv_path}: more than {MAX_FILES} rows")
        cells = {name: row[k].strip() for name, k in col.items()}
        try:
            path = _inside(root, cells["path"])
        except DataError as exc:
            out.rejected.append(f"{where}: {cells['path'][:80]!r}: {exc}")
            continue
        emotion = cells["emotion"] or None
        if emotion is None and need_emotion:
            out.rejected.append(f"{where}: no emotion")
            continue
        if emotion is not None and not _LABEL.match(emotion):
            out.rejected.append(f"{where}: emotion {emotion[:40]!r} is not a name (a letter, "
                                "then letters, digits, _ or -)")
            continue
        speaker = cells.get("speaker") or None
        if speaker is not None and not _SPEAKER.match(speaker):
            out.rejected.append(f"{where}: speaker {speaker[:40]!r} is not a name")
            continue
        if path in seen:
            out.rejected.append(f"{where}: {cells['path']} is listed twice")
            continue
        seen.add(path)
        out.add(path, None if emotion is None else emotion.lower(), speaker)
    return out
