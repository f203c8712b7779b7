"""Checks of the speech and transcript every phone engine is given, and the limits below
which there is nothing to segment (shared by :mod:`ingest.speech.sphinx`,
:mod:`ingest.speech.ctc` and :mod:`ingest.speech.words`)."""

from __future__ import annotations

import numpy as np

from db.errors import ParameterError

__all__ = ["MIN_DURATION", "SILENCE_PEAK", "check_audio", "check_text", "mono_samples"]

#: Clips shorter than this (seconds) hold no phone to find: they give one SIL segment.
MIN_DURATION = 0.1
#: Peak below which audio counts as silent (about -80 dBFS).
SILENCE_PEAK = 1e-4


def check_audio(audio: object, sample_rate: object) -> tuple[np.ndarray, int]:
    """Mono float64 samples and an int rate from what a caller gave, or ParameterError
    (a 2-D array of one channel is flattened, integer PCM scaled to [-1, 1))."""
    if isinstance(sample_rate, bool) or not isinstance(sample_rate, int | np.integer):
        raise ParameterError(f"sample_rate: expected an int in Hz, got {sample_rate!r}")
    if not 1000 <= int(sample_rate) <= 384000:
        raise ParameterError(f"sample_rate: expected 1000..384000 Hz, got {sample_rate}")
    if not isinstance(audio, np.ndarray):
        raise ParameterError(f"audio: expected a numpy array, got {type(audio).__name__}")
    return mono_samples(audio, np.float64), int(sample_rate)


def mono_samples(audio: np.ndarray, dtype, what: str = "audio") -> np.ndarray:
    """``audio`` as ``dtype`` samples of shape (n,) in [-1, 1): a 2-D array of one channel
    flattened, integer PCM scaled by its full scale; ParameterError (its text starting with
    ``what``) for more than one channel, another kind of number, NaN or infinite samples."""
    if audio.ndim == 2 and 1 in audio.shape:
        audio = audio.reshape(-1)
    if audio.ndim != 1:
        raise ParameterError(f"{what}: expected mono samples (1-D), got shape {audio.shape}")
    if np.issubdtype(audio.dtype, np.integer):
        scale = float(np.iinfo(audio.dtype).max) + 1.0
        audio = audio.astype(dtype) / dtype(scale)
    elif np.issubdtype(audio.dtype, np.floating):
        audio = audio.astype(dtype, copy=False)
    else:
        raise ParameterError(f"{what}: expected float or integer samples, got {audio.dtype}")
    if audio.size and not np.all(np.isfinite(audio)):
        raise ParameterError(f"{what}: contains NaN or infinite samples")
    return audio


def check_text(text: object) -> str:
    """``text`` if it is a transcript with something in it, else ParameterError."""
    if not isinstance(text, str):
        raise ParameterError(f"text: expected a transcript string, got {type(text).__name__}")
    if not text.strip():
        raise ParameterError(f"text: the transcript is empty ({text!r})")
    return text
