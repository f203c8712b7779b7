"""Phoneme segmentation of speech (Cao et al. 2005, §4.1): the front door, :func:`segment`.

Given labels are checked and snapped to the audio (:func:`ingest.speech.tiling.snap_labels`);
else a transcript is force-aligned, else the phones are recognised, by a phone engine of
:mod:`ingest.speech.engines`: PocketSphinx (:mod:`ingest.speech.sphinx`), the CTC model
of :mod:`ingest.speech.ctc`, or each task by the engine that measured better at it.

Every engine returns :class:`~ingest.formats.phones_csv.Segment` lists that tile
``[0, len(audio) / sample_rate]`` exactly, in seconds of the input audio, with ARPAbet
phones of :data:`ingest.speech.phones.PHONE_SET` (pauses, edges and PocketSphinx's noise fillers
are ``SIL``; adjacent ``SIL`` are merged; no segment is empty).
:mod:`ingest.speech.scoring` scores a segmentation against a reference.

Failures
--------
An empty transcript raises :class:`~db.errors.ParameterError`. Audio shorter than
:data:`ingest.speech.inputs.MIN_DURATION`, or silent audio given to recognition, gives one
``SIL`` segment. When the aligner finds no path through the transcript, it raises
:class:`~db.errors.DataError`; :func:`segment` then logs a warning and falls back to
recognition (its method says ``"recognized"``).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence

import numpy as np

from db.errors import DataError
from ingest.formats.phones_csv import Segment
from ingest.speech.engines import aligner, check_engine, recognizer
from ingest.speech.inputs import check_audio, check_text
from ingest.speech.tiling import snap_labels

logger = logging.getLogger(__name__)

__all__ = ["segment"]


def segment(
    audio: np.ndarray,
    sample_rate: int,
    *,
    text: str | None = None,
    labels: Sequence[Segment] | None = None,
    engine: str | None = None,
    on_fallback: Callable[[str], object] | None = None,
) -> tuple[list[Segment], str]:
    """Phone segments of speech by the best means at hand.

    In order of preference: ``labels`` (checked and snapped to the audio by
    :func:`ingest.speech.tiling.snap_labels`), forced alignment of ``text``, phone
    recognition, by the phone engine ``engine`` (:mod:`ingest.speech.engines`:
    PocketSphinx's (:mod:`ingest.speech.sphinx`), the CTC model of
    :mod:`ingest.speech.ctc`, or each task by the engine that measured better at it). If
    the alignment
    fails (:class:`~db.errors.DataError`) recognition is used instead, and a line saying
    so ("transcript alignment failed: ...; fell back to phone recognition") is logged as
    a warning, or given to ``on_fallback``.

    Parameters
    ----------
    audio : numpy.ndarray, shape (n_samples,)
        Mono audio.
    sample_rate : int
        Its sampling rate in Hz.
    text : str, optional
        The transcript.
    labels : sequence of Segment, optional
        Known phone labels (seconds).
    engine : str, optional
        One of :data:`ingest.speech.engines.ENGINES`; default ``"auto"``.
    on_fallback : callable, optional
        Receives the line on a failed alignment instead of the log.

    Returns
    -------
    segments : list of Segment
        Tiling ``[0, len(audio) / sample_rate]``.
    method : str
        ``"labels"``, ``"aligned"`` or ``"recognized"``: how they were obtained.

    Raises
    ------
    ParameterError
        Bad audio, sample rate or labels; an empty transcript.
    DataError
        If PocketSphinx is unusable.
    """
    samples, sample_rate = check_audio(audio, sample_rate)
    engine = check_engine(engine)
    if labels is not None:
        return snap_labels(labels, len(samples) / sample_rate), "labels"
    do_align, do_recognize = aligner(engine), recognizer(engine)
    if text is not None:
        check_text(text)
        try:
            return do_align(samples, sample_rate, text), "aligned"
        except DataError as exc:
            line = f"transcript alignment failed: {exc}; fell back to phone recognition"
            if on_fallback is None:
                logger.warning("%s", line)
            else:
                on_fallback(line)
    return do_recognize(samples, sample_rate), "recognized"
