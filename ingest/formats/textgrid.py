"""Praat TextGrid files: phone segments from (and to) an interval tier.

Both of Praat's text formats are read, the long one (``xmin = 0``, ``intervals [1]:``)
and the short one (bare values, one per line), in UTF-8 or UTF-16 (Praat writes
UTF-16 when a label is not ASCII). Both are read by one tokenizer that keeps the
quoted strings, the numbers and the ``<exists>`` flag and skips the rest (keys, ``=``,
``[1]`` indices, ``!`` comments), as Praat itself does. Binary TextGrids are refused.

Labels are mapped to ARPAbet by :func:`ingest.formats.labels.to_arpabet`; an empty
interval is silence.
"""

from __future__ import annotations

import bisect
import logging
import os
import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from db.atomic import atomic_write
from db.errors import DataError, ParameterError
from ingest.formats.labels import decode_text, format_seconds
from ingest.formats.phones_csv import Segment, append_read, as_segments
from ingest.formats.text import MAX_SIDE_FILE_BYTES, read_bytes

logger = logging.getLogger(__name__)

#: Tier names taken as the phone tier, compared case-insensitively.
PHONE_TIER_NAMES = ("phones", "phone", "segments")
#: Slack for interval boundaries written with rounding (seconds).

_TOKEN = re.compile(
    r"""
    (?P<str>"(?:[^"]|"")*")
    | (?P<flag><exists>|<absent>)
    | (?P<skip>\[[^\]\n]*\]|![^\n]*|[A-Za-z_][A-Za-z0-9_?]*|\s+|[=:])
    | (?P<num>[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)
    | (?P<bad>.)
    """,
    re.VERBOSE | re.DOTALL,
)


@dataclass(frozen=True)
class Tier:
    """One tier of a TextGrid.

    Attributes
    ----------
    kind : str
        ``"IntervalTier"`` or ``"TextTier"`` (a point tier).
    name : str
        Tier name.
    items : tuple of (float, float, str, int)
        ``(start, end, text, line)`` per interval (``start == end`` for points); ``line``
        is where the text appears in the file.
    """

    kind: str
    name: str
    items: tuple[tuple[float, float, str, int], ...]


class _Tokens:
    """Cursor over the (kind, value, line) tokens of a TextGrid."""

    def __init__(self, text: str, path: Path) -> None:
        self.path = path
        starts = [0] + [m.end() for m in re.finditer("\n", text)]
        self.items: list[tuple[str, str, int]] = []
        for match in _TOKEN.finditer(text):
            kind = match.lastgroup
            if kind == "skip":
                continue
            line = bisect.bisect_right(starts, match.start())
            if kind == "bad":
                char = match.group()
                problem = "unterminated string" if char == '"' else f"unexpected {char!r}"
                raise DataError(f"{path}:{line}: {problem}")
            self.items.append((kind, match.group(), line))
        self.pos = 0

    def _next(self, what: str) -> tuple[str, str, int]:
        if self.pos >= len(self.items):
            raise DataError(f"truncated TextGrid {self.path}: ends where {what} was expected")
        item = self.items[self.pos]
        self.pos += 1
        return item

    def string(self, what: str) -> tuple[str, int]:
        kind, value, line = self._next(what)
        if kind != "str":
            raise DataError(f"{self.path}:{line}: expected {what} (a quoted string), got {value}")
        return value[1:-1].replace('""', '"'), line

    def number(self, what: str) -> float:
        kind, value, line = self._next(what)
        if kind != "num":
            raise DataError(f"{self.path}:{line}: expected {what} (a number), got {value}")
        return float(value)

    def count(self, what: str) -> int:
        line = self.items[self.pos][2] if self.pos < len(self.items) else 0
        value = self.number(what)
        if value < 0 or value != int(value):
            raise DataError(f"{self.path}:{line}: {what} must be a whole number >= 0, got {value}")
        return int(value)

    def flag(self, what: str) -> bool:
        kind, value, line = self._next(what)
        if kind != "flag":
            raise DataError(f"{self.path}:{line}: expected {what} (<exists>), got {value}")
        return value == "<exists>"


def read_tiers(path: str | os.PathLike[str]) -> list[Tier]:
    """Read every tier of a TextGrid (long or short text format).

    Parameters
    ----------
    path : str or os.PathLike
        The ``.TextGrid`` file.

    Returns
    -------
    list of Tier
        In file order.

    Raises
    ------
    DataError
        If the file is missing, binary, not a TextGrid, truncated or malformed (the
        message names the line).
    """
    path = Path(path)
    data = read_bytes(path, "TextGrid file", MAX_SIDE_FILE_BYTES)
    if not data.strip():
        raise DataError(f"TextGrid file is empty: {path}")
    if data.startswith(b"ooBinaryFile"):
        raise DataError(f"binary TextGrid not supported (save it as a text file): {path}")
    tokens = _Tokens(decode_text(data, path, "TextGrid"), path)
    if not tokens.items:
        raise DataError(f"not a Praat TextGrid (no values found): {path}")
    file_type, line = tokens.string("the file type")
    if not file_type.startswith("ooTextFile"):
        raise DataError(f"{path}:{line}: not a Praat text file (file type {file_type!r})")
    object_class, line = tokens.string("the object class")
    if object_class != "TextGrid":
        raise DataError(f"{path}:{line}: object class is {object_class!r}, not 'TextGrid'")
    tokens.number("xmin")
    tokens.number("xmax")
    tiers: list[Tier] = []
    if not tokens.flag("tiers? <exists>"):
        return tiers
    for index in range(tokens.count("the number of tiers")):
        kind, line = tokens.string(f"the class of tier {index + 1}")
        if kind not in ("IntervalTier", "TextTier"):
            raise DataError(f"{path}:{line}: unknown tier class {kind!r}")
        name, _ = tokens.string(f"the name of tier {index + 1}")
        tokens.number("tier xmin")
        tokens.number("tier xmax")
        items = []
        for _ in range(tokens.count(f"the size of tier {name!r}")):
            if kind == "IntervalTier":
                start, end = tokens.number("interval xmin"), tokens.number("interval xmax")
            else:
                start = end = tokens.number("point time")
            text, line = tokens.string("a label")
            items.append((start, end, text, line))
        tiers.append(Tier(kind=kind, name=name, items=tuple(items)))
    if tokens.pos < len(tokens.items):
        logger.debug("%s: ignoring %d tokens after the last tier", path,
                     len(tokens.items) - tokens.pos)
    return tiers


def _pick_tier(tiers: list[Tier], tier: str | None, path: Path) -> Tier:
    names = [t.name for t in tiers]
    if tier is not None:
        for candidate in tiers:
            if candidate.name == tier:
                if candidate.kind != "IntervalTier":
                    raise DataError(f"{path}: tier {tier!r} is a point tier, not an interval tier")
                return candidate
        raise DataError(f"{path}: no tier named {tier!r} (tiers: {names})")
    intervals = [t for t in tiers if t.kind == "IntervalTier"]
    for candidate in intervals:
        if candidate.name.strip().lower() in PHONE_TIER_NAMES:
            return candidate
    if not intervals:
        raise DataError(f"{path}: no interval tier (tiers: {names})")
    logger.info("%s: no tier named %s; using the last interval tier %r", path,
                "/".join(PHONE_TIER_NAMES), intervals[-1].name)
    return intervals[-1]


def read_textgrid(path: str | os.PathLike[str], *, tier: str | None = None) -> list[Segment]:
    """Read the phone segments of a Praat TextGrid.

    Parameters
    ----------
    path : str or os.PathLike
        A TextGrid in Praat's long or short text format, UTF-8 or UTF-16.
    tier : str, optional
        Name of the tier to read (exact). By default the interval tier named
        ``phones``, ``phone`` or ``segments`` (any case), else the last interval tier.

    Returns
    -------
    list of Segment
        One segment per interval in time order, phones mapped to ARPAbet by
        :func:`ingest.formats.labels.to_arpabet` (empty intervals are ``"SIL"``).

    Raises
    ------
    DataError
        If the file cannot be read as a TextGrid, has no suitable tier, or an interval
        has an unknown label, ``xmin >= xmax`` or overlaps the one before (naming the
        line).
    """
    path = Path(path)
    chosen = _pick_tier(read_tiers(path), tier, path)
    segments: list[Segment] = []
    for start, end, text, line in chosen.items:
        append_read(segments, text, start, end, f"{path}:{line}", noun="interval ",
                    note=f" in tier {chosen.name!r}")
    return segments


def _quote(text: str) -> str:
    return '"' + text.replace('"', '""') + '"'


def write_textgrid(
    path: str | os.PathLike[str],
    segments: Iterable[object],
    *,
    tier: str = "phones",
    xmax: float | None = None,
    short: bool = False,
    encoding: str = "utf-8",
) -> None:
    """Write phone segments as a one-tier TextGrid, atomically.

    Gaps between segments (and before the first) become empty intervals, as Praat's
    interval tiers cover their whole time range; they read back as ``"SIL"``.

    Parameters
    ----------
    path : str or os.PathLike
        Target file.
    segments : iterable
        Sorted, non-overlapping segments (``.phone .start .end`` or
        ``(phone, start, end)``), ARPAbet phones, seconds.
    tier : str
        Name of the interval tier.
    xmax : float, optional
        End of the TextGrid (at least the last segment's end; default that end).
    short : bool
        Write Praat's short text format instead of the long one.
    encoding : {"utf-8", "utf-16"}
        Text encoding (UTF-16 with a byte-order mark, as Praat writes it).

    Raises
    ------
    ParameterError
        On bad segments, an ``xmax`` before the last segment's end, or another encoding.
    DataError
        If the file cannot be written.
    """
    rows = as_segments(segments)
    if encoding not in ("utf-8", "utf-16"):
        raise ParameterError(f"encoding: expected 'utf-8' or 'utf-16', got {encoding!r}")
    if not isinstance(tier, str) or not tier:
        raise ParameterError(f"tier: expected a non-empty str, got {tier!r}")
    end = rows[-1].end if rows else 0.0
    if xmax is None:
        xmax = end
    if not xmax >= end:
        raise ParameterError(f"xmax: {xmax!r} is before the last segment's end {end}")
    if xmax <= 0:
        raise ParameterError("segments: a TextGrid needs a time range; got no segments and no xmax")

    intervals: list[tuple[float, float, str]] = []
    cursor = 0.0
    for seg in rows:
        if seg.start > cursor:
            intervals.append((cursor, seg.start, ""))
        intervals.append((seg.start, seg.end, seg.phone))
        cursor = seg.end
    if xmax > cursor:
        intervals.append((cursor, xmax, ""))

    t0, t1 = format_seconds(0.0), format_seconds(xmax)
    if short:
        lines = ['File type = "ooTextFile"', 'Object class = "TextGrid"', "", t0, t1,
                 "<exists>", "1", '"IntervalTier"', _quote(tier), t0, t1, str(len(intervals))]
        for start, stop, text in intervals:
            lines += [format_seconds(start), format_seconds(stop), _quote(text)]
    else:
        lines = ['File type = "ooTextFile"', 'Object class = "TextGrid"', "",
                 f"xmin = {t0} ", f"xmax = {t1} ", "tiers? <exists> ", "size = 1 ", "item []: ",
                 "    item [1]:", '        class = "IntervalTier" ',
                 f"        name = {_quote(tier)} ",
                 f"        xmin = {t0} ", f"        xmax = {t1} ",
                 f"        intervals: size = {len(intervals)} "]
        for number, (start, stop, text) in enumerate(intervals, 1):
            lines += [f"        intervals [{number}]:",
                      f"            xmin = {format_seconds(start)} ",
                      f"            xmax = {format_seconds(stop)} ",
                      f"            text = {_quote(text)} "]
    with atomic_write(path) as handle:
        handle.write(("\n".join(lines) + "\n").encode(encoding))
    logger.debug("wrote %s: %d intervals", path, len(intervals))
