"""Curve clips: named animation curves (e.g. blendshape weights) with their speech.

Two layouts:

- FACEGOOD (``code/train`` of FACEGOOD-Audio2Face): ``wav/<clip>.wav``,
  ``bs_value/bs_value_<clip>.npy`` (frames x 116, 0..1), channel names in
  ``shirley_1119_bs_name.npy`` and/or ``bsname.txt`` (a count, then one name per line);
  :data:`FACEGOOD_FPS` frames per second (the corpus README: frames / 30 = audio
  duration) unless a ``curves.json`` in the corpus folder says otherwise;
- generic: ``<stem>.npy`` or ``<stem>.curves.csv`` (frames x channels) with ``<stem>.wav``;
  channel names from ``<stem>.channels.txt`` (one per line), else the CSV's header, else
  ``"channels"`` of a ``curves.json`` in the folder or the one above; the frame rate
  from ``"fps"`` in ``<stem>.json``, else in ``curves.json``, else the CSV's ``time``
  column. A CSV's leading ``frame``/``time`` columns are not channels.

Motion groups are guessed from the curve names (:func:`curve_group`).
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np

from db.errors import DataError
from ingest.clip import ChannelSchema, RawClip, checksum_files
from ingest.formats.marker_csv import infer_rate
from ingest.formats.text import MAX_SIDE_FILE_BYTES, read_csv_rows, read_utf8
from ingest.readers.common import (
    ClipSource,
    check_motion,
    load_npy,
    read_fps,
    read_json_object,
    speech_and_side_files,
)

logger = logging.getLogger(__name__)

#: FACEGOOD's bs_value frame rate (its README: frames / 30 = audio duration).
FACEGOOD_FPS = 30.0
#: Name prefixes (lower case, after any ``namespace.``/``namespace:``) -> motion group.
GROUP_PREFIXES: tuple[tuple[tuple[str, ...], str], ...] = (
    (("jaw", "mouth", "lip", "cheek", "tongue", "tooth", "teeth", "chin"), "lips"),
    (("brow", "eye", "forehead"), "upper_face"),
    (("head",), "head"),
)


def curve_group(name: str) -> str:
    """Motion group of a curve, guessed from its name.

    ``jaw*``, ``mouth*``, ``lip*``, ``cheek*``, ``tongue*``, ``tooth*``/``teeth*``, ``chin*``
    -> ``"lips"``; ``brow*``, ``eye*``, ``forehead*`` -> ``"upper_face"``; ``head*`` ->
    ``"head"``; anything else ``"other"``. Case is ignored, as is a namespace before the
    last ``.`` or ``:`` (``blendShape1.jawOpen``).
    """
    base = name.rsplit(".", 1)[-1].rsplit(":", 1)[-1].strip().lower()
    for prefixes, group in GROUP_PREFIXES:
        if base.startswith(prefixes):
            return group
    return "other"


def _read_lines(path: Path) -> list[str]:
    text = read_utf8(path, "channel list", limit=MAX_SIDE_FILE_BYTES)
    return [line.strip() for line in text.splitlines() if line.strip()]


def read_channel_names(path: Path) -> list[str]:
    """Curve names from a text file (one per line; FACEGOOD's ``bsname.txt`` starts with
    their count) or a ``.npy`` array of strings."""
    if path.suffix.lower() == ".npy":
        names = load_npy(path)
        if names.ndim != 1 or names.dtype.kind not in "US":
            raise DataError(f"{path}: expected a 1-D array of names, got {names.dtype} "
                            f"{names.shape}")
        return [str(n.decode("latin1") if isinstance(n, bytes) else n).strip() for n in names]
    lines = _read_lines(path)
    if lines and lines[0].isdigit():
        count = int(lines[0])
        if count != len(lines) - 1:
            raise DataError(f"{path}: says {count} names but lists {len(lines) - 1}")
        lines = lines[1:]
    if not lines:
        raise DataError(f"channel list is empty: {path}")
    return lines


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


#: Name given to FACEGOOD's first column, which carries no curve (constant 0).
FACEGOOD_UNNAMED = "unnamed_0"


def facegood_column_names(names: list[str]) -> list[str]:
    """The names of FACEGOOD's ``bs_value`` columns, given its 116-name list.

    Column ``i`` carries the ``i``-th token of ``bsname.txt`` *counting the leading count
    line* ("116") as token 0: the arrays are one column off the name list as shipped.
    The evidence, over all five clips: column 0 is constant; with names shifted by one,
    left/right pairs move together (lip-corner pull l/r and pucker l/r correlate 1.0,
    where the unshifted names pair unrelated columns, r = -0.01), and the curve that
    follows the speech's loudness (r = 0.75) is ``mouth_stretch_c`` (FACS mouth stretch,
    the jaw opening) rather than ``mouth_suck_dl``. The list's last name (``cheek_r``)
    has no column.
    """
    return [FACEGOOD_UNNAMED, *names[:-1]]


def read_curves_csv(path: Path) -> tuple[np.ndarray, list[str] | None, float | None]:
    """Read a ``.curves.csv``: motion (n_frames, n_channels), header names, rate from time.

    Returns
    -------
    motion : np.ndarray, shape (n_frames, n_channels)
    names : list of str or None
        From the header, if the first line is one.
    rate : float or None
        From a ``time`` column, if there is one.
    """
    rows = read_csv_rows(path, "curves CSV")
    if not rows:
        raise DataError(f"curves CSV is empty: {path}")
    header = None
    if not all(_is_number(c) for c in rows[0][1] if c.strip()):
        header = [c.strip() for c in rows[0][1]]
        rows = rows[1:]
    if not rows:
        raise DataError(f"curves CSV has no frames: {path}")
    width = len(header) if header else len(rows[0][1])
    values = np.empty((len(rows), width))
    for i, (line, row) in enumerate(rows):
        if len(row) != width:
            raise DataError(f"{path}:{line}: expected {width} fields, got {len(row)}")
        try:
            values[i] = [float(c) if c.strip() else math.nan for c in row]
        except ValueError:
            raise DataError(f"{path}:{line}: a value is not a number") from None
    rate = None
    lead = 0
    if header:
        lower = [h.lower() for h in header]
        if lower[:1] == ["frame"]:
            lead = 1
        if lower[lead:lead + 1] == ["time"]:
            frames = values[:, 0] if lead else np.arange(len(values))
            decimals = max((len(r[lead].partition(".")[2]) for _, r in rows), default=6)
            rate = infer_rate(frames, values[:, lead], decimals or 6, path)
            lead += 1
    return values[:, lead:], (header[lead:] if header else None), rate


def load_curves(source: ClipSource) -> RawClip:
    """Read one curve clip (FACEGOOD or generic layout).

    Raises
    ------
    DataError
        On a missing, unreadable or truncated file, a motion array that is not 2-D,
        channel names that do not match the columns (unknown channel layout), no frame
        rate, a curve NaN in every frame, an empty transcript, bad labels, or audio and
        motion durations that disagree.
    """
    motion_path = source.source
    audio_path = source.file("audio")
    if audio_path is None:
        raise DataError(f"{motion_path}: no audio file beside it")
    facegood = source.layout == "facegood"

    csv_names, csv_rate = None, None
    if motion_path.name.lower().endswith(".csv"):
        motion, csv_names, csv_rate = read_curves_csv(motion_path)
    else:
        # FACEGOOD's bs_value files were saved by Python 2 but hold plain float64
        # arrays, which load without unpickling; nothing is ever unpickled (a crafted
        # .npy would run code), so a file of Python objects is refused.
        motion = load_npy(motion_path)
        if motion.ndim != 2 or not np.issubdtype(motion.dtype, np.number):
            raise DataError(f"{motion_path}: expected a 2-D (n_frames, n_channels) numeric "
                            f"array, got {motion.dtype} {motion.shape}")

    settings_path = source.file("settings")
    settings = read_json_object(settings_path) if settings_path else {}
    names = None
    names_path = source.file("channel_names")
    if names_path is not None:
        names = read_channel_names(names_path)
    list_path = source.file("channel_list")
    if list_path is not None:
        listed = read_channel_names(list_path)
        if names is not None and listed != names:
            raise DataError(f"{list_path}: channel names differ from {names_path.name}")
        names = listed if names is None else names
    if names is None:
        names = csv_names
    if names is None and "channels" in settings:
        names = settings["channels"]
        if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
            raise DataError(f"{settings_path}: 'channels' must be a list of names")
    if names is None:
        raise DataError(f"{motion_path}: unknown channel layout (no {motion_path.stem}"
                        f".channels.txt, CSV header or 'channels' in curves.json)")
    if source.layout == "facegood":
        names = facegood_column_names(names)
    if len(names) != motion.shape[1]:
        raise DataError(f"{motion_path}: unknown channel layout: {motion.shape[1]} columns "
                        f"but {len(names)} channel names")
    motion = check_motion(motion, names, motion_path, "curve")

    meta_path = source.file("metadata")
    meta = read_json_object(meta_path) if meta_path else {}
    fps = (read_fps(meta, meta_path) if meta_path else None) or (
        read_fps(settings, settings_path) if settings_path else None)
    if fps is None:
        fps = FACEGOOD_FPS if facegood else csv_rate
    if fps is None:
        raise DataError(f"{motion_path}: no frame rate ('fps' in {motion_path.stem}.json or "
                        f"curves.json)")
    try:
        schema = ChannelSchema(kind="curves", names=tuple(names),
                               groups=tuple(curve_group(n) for n in names), units="unit")
    except DataError as exc:
        raise DataError(f"{motion_path}: {exc}") from None

    audio, sample_rate, fields, phones, words = speech_and_side_files(
        source, len(motion), fps, motion_path, meta, meta_path)
    audio_seconds = len(audio) / sample_rate
    return RawClip(
        clip_id=source.clip_id, corpus=source.corpus, source=motion_path, motion=motion,
        fps=fps, schema=schema, audio=audio, sample_rate=sample_rate,
        checksum=checksum_files(source.paths), text=fields["text"], phones=phones,
        words=words,
        emotion=fields["emotion"], speaker=fields["speaker"],
        sentence_id=fields["sentence_id"],
        extra={"layout": source.layout,
               "motion_audio_offset_s": round(len(motion) / fps - audio_seconds, 4)},
    )
