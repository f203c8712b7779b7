"""Speech in, checked and made comparable, for the emotion classifier (issue #16).

Whatever a caller hands the classifier -- a WAV read as int16, a float stereo array at
48000.0 Hz, a generator of ``(audio, rate)`` pairs, an object array of them -- becomes
one list of float64 mono signals at :data:`FEATURE_SAMPLE_RATE` with the same level, or
one clear error:

* :func:`as_float_pcm` -- integer PCM scaled to ``[-1, 1)`` by its type's full scale
  (int16 / 32768, int32 / 2**31, uint8 centred on 128), floats kept;
* :func:`prepare_audio` -- one utterance: shape ``(n_samples,)`` or ``(n_samples,
  n_channels)`` (channels averaged), an integer or float rate (48000.0, 22050.5), resampled
  to 16 kHz, refused when shorter than :data:`MIN_DURATION` or when it holds less than
  :data:`MIN_ACTIVE` of frames above :data:`SILENCE_DBFS` (silence or near-silence), then
  scaled so that its :data:`LEVEL_PERCENTILE` percentile of ``|x|`` is 1 -- the features
  no longer depend on the recording level (what is left of loudness is its dynamics);
* :func:`utterances` -- a sequence, generator or object array of pairs as a list.
"""

from __future__ import annotations

from fractions import Fraction
from numbers import Real

import numpy as np
from scipy.signal import resample_poly

from db.errors import DataError, ParameterError

__all__ = [
    "FEATURE_SAMPLE_RATE",
    "LEVEL_PERCENTILE",
    "MIN_ACTIVE",
    "MIN_DURATION",
    "SILENCE_DBFS",
    "as_float_pcm",
    "is_pair",
    "prepare_audio",
    "speed_perturb",
    "utterances",
]

#: Every signal is resampled to this rate (Hz) before features are computed.
FEATURE_SAMPLE_RATE = 16000
#: Shortest utterance accepted, in seconds.
MIN_DURATION = 0.25
#: Frames (25 ms, hop 10 ms) quieter than this (dB re full scale, RMS) count as silence.
SILENCE_DBFS = -60.0
#: Least time (s) of non-silent frames an utterance must hold.
MIN_ACTIVE = 0.2
#: Percentile of ``|x|`` scaled to 1 (the peak, but robust to a single click).
LEVEL_PERCENTILE = 99.9
#: Most channels accepted in ``(n_samples, n_channels)`` audio (a transposed signal is
#: refused rather than averaged over thousands of "channels").
MAX_CHANNELS = 8
#: Lowest and highest sampling rates accepted (Hz).
MIN_RATE, MAX_RATE = 1000.0, 768000.0

_FRAME, _HOP = 400, 160  # 25 ms frames, 10 ms hop at 16 kHz


def as_float_pcm(audio) -> np.ndarray:
    """Samples as float64, integer PCM scaled by its full scale.

    Parameters
    ----------
    audio : array-like
        Samples of any shape; integer types are read as PCM (``int16`` / 32768,
        ``int32`` / 2**31, ``uint8`` as ``(x - 128) / 128``), floats and booleans are not
        rescaled.

    Returns
    -------
    np.ndarray
        float64, same shape.

    Raises
    ------
    ParameterError
        Non-numeric samples (strings, objects, complex).
    """
    x = np.asarray(audio)
    if x.dtype.kind in "iu":
        info = np.iinfo(x.dtype)
        mid = (int(info.max) + int(info.min) + 1) / 2.0  # 128 for uint8, 0 for signed
        return (x.astype(np.float64) - mid) / (int(info.max) + 1 - mid)
    if x.dtype.kind in "fb":
        return x.astype(np.float64)
    raise ParameterError(f"audio must hold numeric samples, got dtype {x.dtype}")


def _rate(sample_rate) -> Fraction:
    if isinstance(sample_rate, bool) or not isinstance(sample_rate, Real | np.number) \
            or not np.isfinite(float(sample_rate)) \
            or not MIN_RATE <= float(sample_rate) <= MAX_RATE:
        raise ParameterError(f"sample_rate must be a number of Hz in [{MIN_RATE:g}, "
                             f"{MAX_RATE:g}], got {sample_rate!r}")
    return Fraction(float(sample_rate)).limit_denominator(100)


def prepare_audio(audio, sample_rate) -> np.ndarray:
    """One utterance, checked, down-mixed, resampled to 16 kHz and level-normalised.

    Parameters
    ----------
    audio : array-like, shape (n_samples,) or (n_samples, n_channels)
        Speech, integer PCM or float; channels are averaged.
    sample_rate : int or float
        Its rate in Hz (an integer or a float such as 48000.0 or 22050.5).

    Returns
    -------
    np.ndarray, shape (n_16k,)
        float64 at :data:`FEATURE_SAMPLE_RATE`, its :data:`LEVEL_PERCENTILE` percentile of
        ``|x|`` equal to 1.

    Raises
    ------
    ParameterError
        Bad rate, dtype or shape.
    DataError
        Non-finite samples, shorter than :data:`MIN_DURATION`, or silence (less than
        :data:`MIN_ACTIVE` s of frames above :data:`SILENCE_DBFS` dBFS).
    """
    rate = _rate(sample_rate)
    x = as_float_pcm(audio)
    if x.ndim == 2 and 1 <= x.shape[1] <= MAX_CHANNELS:
        x = x.mean(axis=1)
    elif x.ndim != 1:
        raise ParameterError(f"audio must have shape (n_samples,) or (n_samples, n_channels) "
                             f"with at most {MAX_CHANNELS} channels, got {x.shape}")
    if not np.all(np.isfinite(x)):
        raise DataError("audio contains NaN or infinite samples")
    seconds = x.size / float(rate)
    if seconds < MIN_DURATION:
        raise DataError(f"audio too short: {seconds:.3f} s < {MIN_DURATION} s needed")
    if rate != FEATURE_SAMPLE_RATE:
        ratio = Fraction(FEATURE_SAMPLE_RATE) / rate
        x = resample_poly(x, ratio.numerator, ratio.denominator)
    active = _active_seconds(x)
    if active < MIN_ACTIVE:
        raise DataError(f"audio is silence: {active:.2f} s above {SILENCE_DBFS:g} dBFS, "
                        f"{MIN_ACTIVE} s of sound needed")
    return x / np.percentile(np.abs(x), LEVEL_PERCENTILE)


def speed_perturb(audio, sample_rate, factor: float) -> np.ndarray:
    """The utterance played ``factor`` times faster: tempo and pitch together.

    Speed perturbation (Ko, Peddinti, Povey & Khudanpur 2015, "Audio augmentation for
    speech recognition", INTERSPEECH): the signal resampled by ``1 / factor`` and read at
    the original rate, as ``sox speed``; 0.9 lowers the pitch and the formants by 10 %
    and lasts 11 % longer. The perturbed copy of a speaker sounds like another speaker.

    Parameters
    ----------
    audio : array-like, shape (n_samples,) or (n_samples, n_channels)
        Speech, integer or float PCM (channels averaged).
    sample_rate : int or float
        Its rate in Hz (only checked; the output has the same rate).
    factor : float
        Speed factor in [0.5, 2] (Ko et al.: 0.9, 1.0, 1.1).

    Returns
    -------
    np.ndarray, shape (ceil(n_samples / factor),)
        float64 mono at ``sample_rate``.
    """
    _rate(sample_rate)
    if isinstance(factor, bool) or not isinstance(factor, Real) \
            or not 0.5 <= float(factor) <= 2.0:
        raise ParameterError(f"factor must be a number in [0.5, 2], got {factor!r}")
    x = as_float_pcm(audio)
    if x.ndim == 2:
        x = x.mean(axis=1)
    ratio = Fraction(float(factor)).limit_denominator(100)
    if ratio == 1:
        return x
    return resample_poly(x, ratio.denominator, ratio.numerator)


def _active_seconds(x: np.ndarray) -> float:
    """Seconds of 25 ms frames whose RMS is above :data:`SILENCE_DBFS` (x at 16 kHz)."""
    if x.size < _FRAME:
        x = np.pad(x, (0, _FRAME - x.size))
    frames = np.lib.stride_tricks.sliding_window_view(x, _FRAME)[::_HOP]
    rms = np.sqrt(np.mean(frames * frames, axis=1))
    return float(np.count_nonzero(rms > 10 ** (SILENCE_DBFS / 20))) * _HOP \
        / FEATURE_SAMPLE_RATE


def is_pair(item) -> bool:
    """Whether ``item`` looks like an ``(audio, sample_rate)`` pair."""
    if isinstance(item, str | bytes):
        return False
    try:
        audio, sr = item
    except (TypeError, ValueError):
        return False
    return np.ndim(audio) >= 1 and np.ndim(sr) == 0


def utterances(X) -> list | None:
    """``X`` as a list of ``(audio, sample_rate)`` pairs, or None if it is not made of them.

    Accepts lists, tuples, generators and other iterators, and object arrays of shape
    ``(n,)`` (holding pairs) or ``(n, 2)`` (audio, rate columns).

    Raises
    ------
    ParameterError
        An iterator or object array whose items are not all pairs (naming the first bad
        one).
    """
    if isinstance(X, np.ndarray):
        if X.dtype != object or X.size == 0 or (X.ndim == 2 and np.ndim(X.flat[0]) == 0):
            return None  # numbers (a feature matrix): the caller's checks apply
        if X.ndim == 2 and X.shape[1] == 2:
            items = [tuple(row) for row in X]
        elif X.ndim == 1:
            items = list(X)
        else:
            raise ParameterError(f"an object array X must have shape (n,) of (audio, "
                                 f"sample_rate) pairs or (n, 2), got {X.shape}")
    elif isinstance(X, list | tuple):
        items = list(X)
        if not items or not is_pair(items[0]):
            return None
    elif hasattr(X, "__next__") or (hasattr(X, "__iter__") and not hasattr(X, "__len__")):
        items = list(X)
    else:
        return None
    for i, item in enumerate(items):
        if not is_pair(item):
            raise ParameterError(f"X[{i}] must be an (audio, sample_rate) pair, got "
                                 f"{type(item).__name__}")
    return items
