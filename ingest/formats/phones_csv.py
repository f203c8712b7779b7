"""Phone-label files (``<clip>.phones.csv``).

One header line ``start,end,phone``, then one line per phone segment: start and end
times in seconds with six decimals, and an ARPAbet phone of
:data:`ingest.speech.phones.PHONE_SET` (written upper case, no stress digit; read as the
other label readers read theirs, :func:`ingest.formats.labels.to_arpabet`: ``ah0``,
``sp`` or ``sil`` as well)::

    start,end,phone
    0.000000,0.120000,SIL
    0.120000,0.185000,HH

Segments are sorted and do not overlap (gaps are allowed).
"""

from __future__ import annotations

import csv
import io
import logging
import math
import os
from collections.abc import Iterable
from pathlib import Path
from typing import NamedTuple

from db.atomic import atomic_write
from db.errors import DataError, ParameterError
from ingest.formats.labels import to_arpabet
from ingest.formats.text import MAX_SIDE_FILE_BYTES, read_utf8
from ingest.speech.phones import PHONE_SET

logger = logging.getLogger(__name__)

HEADER: tuple[str, str, str] = ("start", "end", "phone")
#: Decimals written for times (a microsecond; the format asks for at least four).
TIME_DECIMALS = 6


class Segment(NamedTuple):
    """One labelled phone: ``phone`` from ``start`` to ``end`` seconds."""

    phone: str
    start: float
    end: float

    @property
    def duration(self) -> float:
        """Length in seconds."""
        return self.end - self.start


def _as_segment(item: object, index: int) -> Segment:
    """Turn an object with ``.phone .start .end`` or a 3-tuple into a rounded Segment."""
    if all(hasattr(item, name) for name in ("phone", "start", "end")):
        phone, start, end = item.phone, item.start, item.end  # type: ignore[attr-defined]
    elif isinstance(item, tuple | list) and len(item) == 3:
        phone, start, end = item
    else:
        raise ParameterError(
            f"segments[{index}]: expected (phone, start, end) or an object with "
            f".phone .start .end, got {item!r}"
        )
    if not isinstance(phone, str) or phone not in PHONE_SET:
        raise ParameterError(f"segments[{index}].phone: unknown phone {phone!r}")
    times = []
    for name, value in (("start", start), ("end", end)):
        if isinstance(value, bool):
            raise ParameterError(f"segments[{index}].{name}: expected seconds, got {value!r}")
        try:
            seconds = float(value)
        except (TypeError, ValueError) as exc:
            raise ParameterError(
                f"segments[{index}].{name}: expected seconds, got {value!r}"
            ) from exc
        if not math.isfinite(seconds) or seconds < 0:
            raise ParameterError(
                f"segments[{index}].{name}: expected finite seconds >= 0, got {value!r}"
            )
        times.append(round(seconds, TIME_DECIMALS))
    return Segment(phone, times[0], times[1])


#: Overlap forgiven between neighbours read from other tools' files (rounding of times
#: written as decimals or as 100 ns units).
ORDER_TOLERANCE = 1e-9


def order_error(segment, previous, *, tolerance: float = 0.0) -> str | None:
    """Why ``segment`` cannot follow ``previous`` (None if it can).

    Parameters
    ----------
    segment, previous : objects with ``.start`` and ``.end`` in seconds
        A phone or word segment and the one before it (``previous`` None for the first).
    tolerance : float, optional
        Overlap in seconds forgiven (:data:`ORDER_TOLERANCE` for other tools' files).

    Returns
    -------
    str or None
        The problem in a few words, for the caller to prefix with where it is.
    """
    if not segment.start < segment.end:
        return f"start {segment.start} is not before end {segment.end}"
    if previous is not None:
        if segment.start < previous.start - tolerance:
            return f"start {segment.start} is before the previous start {previous.start}"
        if segment.start < previous.end - tolerance:
            return f"start {segment.start} overlaps the previous segment ending {previous.end}"
    return None


def append_read(segments: list[Segment], label: str, start: float, end: float, where: str,
                *, noun: str = "", note: str = "") -> None:
    """Append a phone segment read from another tool's file to ``segments``: its label
    mapped to ARPAbet (:func:`ingest.formats.labels.to_arpabet`), its times checked
    against the segment before (:func:`order_error`, forgiving :data:`ORDER_TOLERANCE`).
    The phones CSV, TextGrid and HTK label readers check their segments this one way.

    Parameters
    ----------
    segments : list of Segment
        The segments read so far (appended to).
    label : str
        The file's label of the phone.
    start, end : float
        Its times in seconds (finite: the caller has parsed them).
    where : str
        ``path:line``, which a message starts with.
    noun, note : str, optional
        What an order problem is of (``"interval "``), and what follows a message
        (``" in tier 'phones'"``).

    Raises
    ------
    DataError
        An unknown label, ``start >= end``, or a segment out of order or overlapping the
        one before.
    """
    try:
        phone = to_arpabet(label)
    except DataError as exc:
        raise DataError(f"{where}: {exc}{note}") from None
    segment = Segment(phone, start, end)
    problem = order_error(segment, segments[-1] if segments else None,
                         tolerance=ORDER_TOLERANCE)
    if problem is not None:
        raise DataError(f"{where}: {noun}{problem}{note}")
    segments.append(segment)


def as_segments(segments: Iterable[object]) -> list[Segment]:
    """Check phone segments before they are written; return them as :class:`Segment`.

    Parameters
    ----------
    segments : iterable
        Objects with ``.phone .start .end`` (seconds) or ``(phone, start, end)`` tuples;
        phones of :data:`ingest.speech.phones.PHONE_SET`, sorted, not overlapping. Times are
        rounded to a microsecond.

    Returns
    -------
    list of Segment

    Raises
    ------
    ParameterError
        On an unknown phone, bad times, ``start >= end``, or a segment out of order or
        overlapping the one before.
    """
    if isinstance(segments, str | bytes) or not isinstance(segments, Iterable):
        raise ParameterError(f"segments: expected an iterable of segments, got {segments!r}")
    rows: list[Segment] = []
    for index, item in enumerate(segments):
        segment = _as_segment(item, index)
        problem = order_error(segment, rows[-1] if rows else None)
        if problem is not None:
            raise ParameterError(f"segments[{index}]: {problem}")
        rows.append(segment)
    return rows


def write_phones_csv(path: str | os.PathLike[str], segments: Iterable[object]) -> None:
    """Write phone segments to a ``.phones.csv`` file, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Target file; written to a temporary file beside it, then renamed.
    segments : iterable
        Sorted, non-overlapping segments, each an object with ``.phone``, ``.start``
        and ``.end`` attributes (seconds) or a ``(phone, start, end)`` tuple. Times are
        rounded to :data:`TIME_DECIMALS` decimals before they are checked.

    Raises
    ------
    ParameterError
        If a segment has an unknown phone, bad times, ``start >= end``, or is out of
        order or overlaps the one before.
    DataError
        If the file cannot be written.
    """
    rows = as_segments(segments)
    text = io.StringIO()
    out = csv.writer(text, lineterminator="\n")
    out.writerow(HEADER)
    for segment in rows:
        out.writerow(
            (f"{segment.start:.{TIME_DECIMALS}f}", f"{segment.end:.{TIME_DECIMALS}f}",
             segment.phone)
        )
    with atomic_write(path) as handle:
        handle.write(text.getvalue().encode("utf-8"))
    logger.debug("wrote %s: %d segments", path, len(rows))


def read_phones_csv(path: str | os.PathLike[str]) -> list[Segment]:
    """Read phone segments from a ``.phones.csv`` file.

    Parameters
    ----------
    path : str or os.PathLike
        The file; the header must be ``start,end,phone`` (any case, spaces around the
        names, a leading BOM); phone labels as :func:`ingest.formats.labels.to_arpabet`
        reads them.

    Returns
    -------
    list of Segment
        The segments in file order (possibly empty if the file has only a header).

    Raises
    ------
    DataError
        If the file is missing, empty, not UTF-8, has a wrong header, or a line (named
        by its number) has the wrong field count, an unknown phone, bad times,
        ``start >= end``, or is out of order or overlaps the line before.
    """
    path = Path(path)
    text = read_utf8(path, "phones file", limit=MAX_SIDE_FILE_BYTES)
    lines = csv.reader(io.StringIO(text))
    try:
        header = next(lines, None)
        if header is None:
            raise DataError(f"phones file is empty: {path}")
        if tuple(field.strip().lower() for field in header) != HEADER:
            raise DataError(
                f"{path}:1: expected header 'start,end,phone', got {','.join(header)!r}"
            )
        segments: list[Segment] = []
        for row in lines:
            line = lines.line_num
            if not row or (len(row) == 1 and not row[0].strip()):
                continue  # blank line
            if len(row) != 3:
                raise DataError(f"{path}:{line}: expected 3 fields, got {len(row)}: {row!r}")
            start_text, end_text, label = (field.strip() for field in row)
            try:
                start, end = float(start_text), float(end_text)
            except ValueError as exc:
                raise DataError(f"{path}:{line}: bad time in {row!r}") from exc
            if not (math.isfinite(start) and math.isfinite(end)) or start < 0:
                raise DataError(f"{path}:{line}: times must be finite and >= 0, got {row!r}")
            append_read(segments, label, start, end, f"{path}:{line}")
    except csv.Error as exc:
        raise DataError(f"{path}:{lines.line_num}: malformed CSV: {exc}") from exc
    return segments
