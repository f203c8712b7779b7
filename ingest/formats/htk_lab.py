"""HTK label files (``.lab``): ``start end label [score] [more ...]`` per line.

Times are integers in HTK's unit of 100 ns. Files with decimal times (WaveSurfer and
Audacity write seconds in the same three columns) are read as seconds; a file is one
or the other, never mixed. Columns after the label (scores, words) are ignored; of
several alternative transcriptions (separated by ``///``) the first is read; lines
starting with ``#`` are comments. An HTS full-context label
(``x^y-PHONE+z=...``) contributes its centre phone. Labels are mapped to ARPAbet by
:func:`ingest.formats.labels.to_arpabet`.
"""

from __future__ import annotations

import logging
import math
import os
import re
from collections.abc import Iterable
from pathlib import Path

from db.atomic import atomic_write
from db.errors import DataError
from ingest.formats.labels import decode_text
from ingest.formats.phones_csv import Segment, append_read, as_segments
from ingest.formats.text import MAX_SIDE_FILE_BYTES, read_bytes

logger = logging.getLogger(__name__)

#: Seconds per HTK time unit (100 ns).
HTK_UNIT = 1e-7
_INTEGER = re.compile(r"[-+]?\d+")
_FULL_CONTEXT = re.compile(r"^[^-]*\^[^-]*-([^+]+)\+")


def read_htk_lab(path: str | os.PathLike[str]) -> list[Segment]:
    """Read phone segments from an HTK label file.

    Parameters
    ----------
    path : str or os.PathLike
        The ``.lab`` file (UTF-8 or UTF-16).

    Returns
    -------
    list of Segment
        In file order, times in seconds, phones mapped to ARPAbet.

    Raises
    ------
    DataError
        If the file is missing, empty or not text, or a line (named by its number) has
        fewer than three columns, bad or mixed times, ``start >= end``, an unknown label,
        or is out of order or overlaps the line before.
    """
    path = Path(path)
    text = decode_text(read_bytes(path, "HTK label file", MAX_SIDE_FILE_BYTES), path,
                       "HTK label file")
    rows: list[tuple[int, str, str, str]] = []
    for number, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        if line == "///":
            logger.info("%s:%d: reading the first of several transcriptions", path, number)
            break
        fields = line.split()
        if len(fields) < 3:
            raise DataError(
                f"{path}:{number}: expected 'start end label', got {line!r}"
            )
        rows.append((number, fields[0], fields[1], fields[2]))
    if not rows:
        raise DataError(f"HTK label file has no labels: {path}")

    integer = [bool(_INTEGER.fullmatch(s)) and bool(_INTEGER.fullmatch(e)) for _, s, e, _ in rows]
    in_seconds = not all(integer)
    if in_seconds and any(integer):
        number = rows[integer.index(not integer[0])][0]
        raise DataError(f"{path}:{number}: mixes integer (100 ns) and decimal (s) times")
    if in_seconds:
        logger.info("%s: decimal times, read as seconds", path)

    segments: list[Segment] = []
    for number, start_text, end_text, label in rows:
        try:
            if in_seconds:
                start, end = float(start_text), float(end_text)
            else:
                start, end = int(start_text) * HTK_UNIT, int(end_text) * HTK_UNIT
        except ValueError:
            raise DataError(f"{path}:{number}: bad time in {start_text!r} {end_text!r}") from None
        if not (math.isfinite(start) and math.isfinite(end)) or start < 0:
            raise DataError(f"{path}:{number}: times must be finite and >= 0")
        context = _FULL_CONTEXT.match(label)
        if context is not None:
            label = context.group(1)
        append_read(segments, label, round(start, 7), round(end, 7), f"{path}:{number}")
    return segments


def write_htk_lab(path: str | os.PathLike[str], segments: Iterable[object]) -> None:
    """Write phone segments as an HTK label file (times in 100 ns units), atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Target file.
    segments : iterable
        Sorted, non-overlapping segments (``.phone .start .end`` or
        ``(phone, start, end)``), ARPAbet phones, seconds.

    Raises
    ------
    ParameterError
        On bad segments.
    DataError
        If the file cannot be written.
    """
    rows = as_segments(segments)
    lines = [f"{round(s.start / HTK_UNIT)} {round(s.end / HTK_UNIT)} {s.phone}\n" for s in rows]
    with atomic_write(path) as handle:
        handle.write("".join(lines).encode("utf-8"))
    logger.debug("wrote %s: %d segments", path, len(rows))
