"""Word alignments: GRID ``.align`` files and the word tier of a Praat TextGrid.

A word alignment gives each word of an utterance its start and end; the phone
alignment is then made inside each word (:func:`ingest.speech.words.align_words`), so
the known word boundaries are also phone boundaries.

- GRID ``.align`` (Cooke et al. 2006): one word a line, ``start end word``, times in
  units of 1/25000 s (:data:`GRID_UNIT`; the corpus' video runs at 25 fps, so a frame
  is 1000 units), ``sil`` (and ``sp``) for silence, CRLF line ends as shipped.
- TextGrid: the interval tier named ``words`` or ``word`` (any case; or a named tier);
  empty and silence intervals (:data:`ingest.formats.labels.SILENCE_LABELS`) are
  silence.

Silence is kept as a :class:`WordSegment` with ``word=None``, so a reader can tell a
pause the aligner marked from a gap it left.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import NamedTuple

from db.errors import DataError
from ingest.formats.labels import SILENCE_LABELS, decode_text
from ingest.formats.phones_csv import ORDER_TOLERANCE, order_error
from ingest.formats.text import MAX_SIDE_FILE_BYTES, read_bytes
from ingest.formats.textgrid import read_tiers

#: Seconds per time unit of a GRID ``.align`` file.
GRID_UNIT = 1.0 / 25000.0
#: Tier names taken as the word tier of a TextGrid, compared case-insensitively.
WORD_TIER_NAMES = ("words", "word")


class WordSegment(NamedTuple):
    """One word (or a silence, ``word=None``) and its interval in seconds."""

    word: str | None
    start: float
    end: float


def _checked(segments: list[WordSegment], where: str, lines: list[int]) -> list[WordSegment]:
    for k, seg in enumerate(segments):
        if not (math.isfinite(seg.start) and math.isfinite(seg.end)) or seg.start < 0:
            raise DataError(f"{where}:{lines[k]}: bad times {seg.start}, {seg.end}")
        problem = order_error(seg, segments[k - 1] if k else None, tolerance=ORDER_TOLERANCE)
        if problem is not None:
            raise DataError(f"{where}:{lines[k]}: word {problem}")
    if not any(seg.word for seg in segments):
        raise DataError(f"{where}: no words (only silence)")
    return segments


def _word(label: str) -> str | None:
    text = label.strip()
    return None if text.lower() in SILENCE_LABELS else text


def read_grid_align(path: str | os.PathLike[str]) -> list[WordSegment]:
    """Read a GRID word alignment.

    Parameters
    ----------
    path : str or os.PathLike
        The ``.align`` file (``start end word`` a line, 1/25000 s units).

    Returns
    -------
    list of WordSegment
        In file order, seconds; silences with ``word=None``.

    Raises
    ------
    DataError
        If the file is missing, empty or not text, or a line (named by its number) does
        not have three columns, has times that are not integers, ``start >= end``, or
        overlaps the line before.
    """
    path = Path(path)
    text = decode_text(read_bytes(path, "word alignment", MAX_SIDE_FILE_BYTES), path,
                       "word alignment")
    segments: list[WordSegment] = []
    lines: list[int] = []
    for number, raw in enumerate(text.splitlines(), 1):
        fields = raw.split()
        if not fields:
            continue
        if len(fields) != 3:
            raise DataError(f"{path}:{number}: expected 'start end word', got {raw.strip()!r}")
        try:
            start, end = int(fields[0]), int(fields[1])
        except ValueError:
            raise DataError(f"{path}:{number}: times must be integers (1/25000 s), "
                            f"got {fields[0]!r} {fields[1]!r}") from None
        segments.append(WordSegment(_word(fields[2]), start * GRID_UNIT, end * GRID_UNIT))
        lines.append(number)
    if not segments:
        raise DataError(f"word alignment is empty: {path}")
    return _checked(segments, str(path), lines)


def word_tier(path: str | os.PathLike[str]) -> str | None:
    """Name of the word tier of a TextGrid (:data:`WORD_TIER_NAMES`), or None."""
    for tier in read_tiers(path):
        if tier.kind == "IntervalTier" and tier.name.strip().lower() in WORD_TIER_NAMES:
            return tier.name
    return None


def read_textgrid_words(path: str | os.PathLike[str], *,
                        tier: str | None = None) -> list[WordSegment]:
    """Read the word tier of a Praat TextGrid.

    Parameters
    ----------
    path : str or os.PathLike
        A TextGrid (long or short text format).
    tier : str, optional
        Name of the tier (exact); by default the interval tier named ``words`` or
        ``word`` (any case).

    Returns
    -------
    list of WordSegment
        One per interval, in time order; silence and empty intervals ``word=None``.

    Raises
    ------
    DataError
        If the file cannot be read as a TextGrid, has no such tier, or an interval is
        empty in time or overlaps the one before.
    """
    path = Path(path)
    tiers = read_tiers(path)
    wanted = [t for t in tiers if t.kind == "IntervalTier" and (
        t.name == tier if tier is not None else t.name.strip().lower() in WORD_TIER_NAMES)]
    if not wanted:
        names = [t.name for t in tiers]
        what = repr(tier) if tier is not None else "/".join(WORD_TIER_NAMES)
        raise DataError(f"{path}: no word interval tier {what} (tiers: {names})")
    chosen = wanted[0]
    segments = [WordSegment(_word(text), start, end) for start, end, text, _ in chosen.items]
    return _checked(segments, str(path), [line for *_, line in chosen.items])
