"""Phones aligned inside known word boundaries (a word alignment such as GRID's ``.align``).

When a clip comes with a word alignment, its word boundaries are better than any a
forced aligner finds on its own: :func:`align_words` keeps them and aligns each word's
phones inside its own interval with the PocketSphinx aligner
(:func:`ingest.speech.sphinx.align` on the word's stretch of audio). Pauses inside a
word's interval are given to the phones around them (a word boundary is a phone
boundary, nothing else moves across it). Where PocketSphinx finds no path through a
word (a word too short for its phones' minimum durations: 3 frames = 30 ms a phone in
its model), the word's pronunciation (CMUdict, else G2P) shares the interval evenly.
Intervals marked silent, and stretches no word covers, are ``SIL``.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np

from db.errors import DataError, ParameterError
from ingest.formats.phones_csv import Segment
from ingest.formats.words import WordSegment
from ingest.speech.g2p import pronounce, transcript_words
from ingest.speech.inputs import MIN_DURATION, check_audio
from ingest.speech.phones import SILENCE
from ingest.speech.sphinx import align
from ingest.speech.tiling import tile

logger = logging.getLogger(__name__)


def _even(phones: Sequence[str], start: float, end: float) -> list[tuple[str, float]]:
    step = (end - start) / max(len(phones), 1)
    return [(phone, start + k * step) for k, phone in enumerate(phones)]


def _word_phones(word: str) -> list[str]:
    return [p for w in transcript_words(word) for p in pronounce(w)]


def align_words(
    audio: np.ndarray, sample_rate: int, words: Sequence[WordSegment], *, refine: bool = True
) -> tuple[list[Segment], int]:
    """Phone segments with each word's phones aligned inside the word's interval.

    Parameters
    ----------
    audio : numpy.ndarray, shape (n_samples,)
        Mono speech.
    sample_rate : int
        Its rate (Hz).
    words : sequence of WordSegment
        ``(word or None for silence, start, end)`` in seconds, in time order.
    refine : bool
        Passed to :func:`ingest.speech.sphinx.align`.

    Returns
    -------
    segments : list of Segment
        ARPAbet phones and ``SIL`` tiling ``[0, len(audio) / sample_rate]``; every word
        boundary inside the audio is a segment boundary.
    n_even : int
        Words whose phones were spread evenly (PocketSphinx found no path).

    Raises
    ------
    ParameterError
        Bad audio or sample rate, or no words.
    """
    samples, sample_rate = check_audio(audio, sample_rate)
    duration = len(samples) / sample_rate
    if not any(w.word for w in words):
        raise ParameterError("words: expected at least one word, got only silence")
    # Each word ends with a SIL onset at its end, replaced by the next word's first phone
    # when that starts there (_merge_gaps): stretches no word covers stay SIL.
    onsets: list[tuple[str, float]] = [(SILENCE, 0.0)]
    n_even = 0
    for item in words:
        start, end = max(0.0, float(item.start)), min(duration, float(item.end))
        if end <= start:
            continue
        if not item.word:
            onsets.append((SILENCE, start))
            continue
        phones = _word_phones(item.word)
        if not phones:
            logger.warning("word %r has no pronunciation: left silent", item.word)
            onsets.append((SILENCE, start))
            continue
        inside: list[tuple[str, float]] = []
        piece = samples[int(round(start * sample_rate)):int(round(end * sample_rate))]
        if end - start >= MIN_DURATION:
            try:
                found = align(piece, sample_rate, item.word, refine=refine)
                inside = [(s.phone, start + s.start) for s in found if s.phone != SILENCE]
            except (DataError, ParameterError) as exc:
                logger.debug("word %r in [%.3f, %.3f]: %s", item.word, start, end, exc)
        if not inside:
            inside = _even(phones, start, end)
            n_even += 1
        inside[0] = (inside[0][0], start)  # the word's start is its first phone's
        onsets += inside
        onsets.append((SILENCE, end))  # closed by the next word if it starts here
    return tile(_merge_gaps(onsets), duration), n_even


def _merge_gaps(onsets: list[tuple[str, float]]) -> list[tuple[str, float]]:
    """Drop zero-length SIL placeholders (a SIL onset followed by one at the same time)."""
    out: list[tuple[str, float]] = []
    for phone, onset in onsets:
        if out and abs(out[-1][1] - onset) < 1e-9:
            out[-1] = (phone, onset)  # the later onset at the same time wins
        else:
            out.append((phone, onset))
    return out
