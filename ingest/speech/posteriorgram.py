"""Phonetic posteriorgrams: per-frame phone posteriors as a speech feature (beyond the paper).

A posteriorgram is the sequence of posterior distributions over phone classes, one per
frame; two stretches of speech are compared by dynamic time warping with the local
distance ``-log(p . q)`` (Hazen, Shen & White 2009, "Query-by-example spoken term
detection using phonetic posteriorgram templates", ASRU, §2-3; Zhang & Glass 2009,
"Unsupervised spoken keyword spotting via segmental DTW on Gaussian posteriorgrams",
ASRU). Unlike spectral features it abstracts from the speaker and channel, and unlike a
recognised phone label it keeps the recogniser's doubt: a frame the model finds half /m/,
half /b/ matches both.

The posteriors come from the hama CTC model (:func:`ingest.speech.ctc.posteriors`, 20 ms
frames, over :data:`ingest.speech.phones.PHONES`). Two steps make them a posteriorgram:

* **The CTC blank is removed** and each frame renormalised over the phones. The blank
  ("no new phone here") fills most frames of a CTC model and carries no phonetic
  identity; Hazen et al.'s posteriors come from a frame classifier in which every frame
  has a phone class. Between a phone's peaks the remaining mass rests on that phone and
  its neighbours. (The ``SIL`` column is the blank and the symbols without a phone.)
* **Smoothing**: each frame is interpolated with the uniform distribution,
  ``(1 - SMOOTHING) p + SMOOTHING / n`` (Hazen et al. 2009 §3.1 smooth the same way so
  that ``-log`` of an inner product stays finite).

Stored in the database per anime (``animes.posteriors``, float16; ingest computes them
when hama is installed) and matched by :func:`animegraph.search.dtw.audio_costs_many`
with ``metric="neglog-dot"``.
"""

from __future__ import annotations

import numpy as np

from ingest.speech.ctc import FRAME_RATE
from ingest.speech.phones import PHONES, SILENCE

__all__ = ["HOP_S", "PHONE_COLUMNS", "SMOOTHING", "blank", "compute", "fold"]

#: Frame period of a posteriorgram (s): the hama model's 20 ms.
HOP_S = 1.0 / FRAME_RATE
#: Weight of the uniform distribution mixed into every frame (Hazen et al. 2009 §3.1).
SMOOTHING = 0.01
#: The phones a posteriorgram's columns stand for: :data:`PHONES` without ``SIL``.
PHONE_COLUMNS: tuple[str, ...] = tuple(p for p in PHONES if p != SILENCE)
_KEEP = np.array([p != SILENCE for p in PHONES])


def fold(probs: np.ndarray) -> np.ndarray:
    """A posteriorgram from phone posteriors: blank removed, renormalised, smoothed.

    Parameters
    ----------
    probs : np.ndarray, shape (n_frames, len(PHONES))
        Posteriors over :data:`ingest.speech.phones.PHONES` (rows sum to 1; ``SIL`` holds
        the CTC blank), as :func:`ingest.speech.ctc.posteriors` returns.

    Returns
    -------
    np.ndarray, shape (n_frames, len(PHONE_COLUMNS)), float32
        Rows sum to 1; every entry at least ``SMOOTHING / len(PHONE_COLUMNS)``.
    """
    probs = np.asarray(probs, dtype=np.float64)
    if probs.ndim != 2 or probs.shape[1] != len(PHONES):
        raise ValueError(f"posteriors must be (n_frames, {len(PHONES)}), got {probs.shape}")
    phones = np.clip(probs[:, _KEEP], 0.0, None)
    total = phones.sum(axis=1, keepdims=True)
    width = phones.shape[1]
    phones = np.where(total > 0, phones / np.where(total > 0, total, 1.0), 1.0 / width)
    return ((1.0 - SMOOTHING) * phones + SMOOTHING / width).astype(np.float32)


def blank(probs: np.ndarray) -> np.ndarray:
    """The CTC blank's probability in each frame of ``probs`` (the ``SIL`` column of
    :func:`ingest.speech.ctc.posteriors`, which :func:`fold` leaves out): shape
    (n_frames,), float32."""
    probs = np.asarray(probs)
    if probs.ndim != 2 or probs.shape[1] != len(PHONES):
        raise ValueError(f"posteriors must be (n_frames, {len(PHONES)}), got {probs.shape}")
    return probs[:, PHONES.index(SILENCE)].astype(np.float32)


def compute(audio: np.ndarray, sample_rate: int) -> np.ndarray:
    """The posteriorgram of ``audio`` (shape (n_samples,)): :func:`fold` of hama's posteriors.

    Returns
    -------
    np.ndarray, shape (n_frames, len(PHONE_COLUMNS)), float32
        Frame ``t`` covers audio from ``t * HOP_S`` seconds.

    Raises
    ------
    DataError
        If hama is not installed or fails (one line).
    """
    from ingest.speech import ctc

    return fold(ctc.posteriors(audio, sample_rate))
