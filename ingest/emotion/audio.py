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
    "SILENCE_BELOW_PEAK_DB",
    "SILENCE_DBFS",
    "as_float_pcm",
    "check_speech",
    "is_pair",
    "prepare_audio",
    "speech_measures",
    "speech_problem",
    "speed_perturb",
    "utterances",
]

#: Every signal is resampled to this rate (Hz) before features are computed.
FEATURE_SAMPLE_RATE = 16000
#: Shortest utterance accepted, in seconds.
MIN_DURATION = 0.25
#: Frames (25 ms, hop 10 ms) more than this many dB below the recording's loudest frame
#: count as silence: judged against the recording's own level, which is normalised later
#: (real speech whose peak is at -70 dBFS was refused as silence by a fixed -60 dBFS).
SILENCE_BELOW_PEAK_DB = 50.0
#: A recording whose loudest frame is quieter than this (dBFS, RMS) is silence whatever
#: its dynamics: digital silence, or the dither of a 24-bit converter's idle input.
SILENCE_DBFS = -110.0
#: What speech is (:func:`speech_problem`), measured by ``scripts/measure_speech_check.py``
#: on real speech (EmoDB, RAVDESS, GRID) against generated noise, tones and music
#: (docs/results/robustness.md, "Nothing escapes"): least share of sounding frames that are voiced
#: (periodic: a normalised autocorrelation peak above VOICED_CORRELATION at a pitch lag
#: of 2.5 to 16 ms, 62-400 Hz) -- noise has none --, most share of them -- a held tone,
#: a chord, music's notes are voiced throughout, speech's consonants are not --, and the
#: least spread (standard deviation, dB) of the sounding frames' levels -- speech's
#: syllables rise and fall, a steady noise or tone does not.
MIN_VOICED_SHARE = 0.10
MAX_VOICED_SHARE = 0.94
MIN_LEVEL_SPREAD_DB = 3.0
VOICED_CORRELATION = 0.6
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
    levels = _frame_levels(x)
    if levels.max() < SILENCE_DBFS:
        raise DataError(f"audio is silence: its loudest 25 ms is at {levels.max():.0f} "
                        f"dBFS, below {SILENCE_DBFS:g}")
    active = _active(levels)
    seconds = np.count_nonzero(active) * _HOP / FEATURE_SAMPLE_RATE
    if seconds < MIN_ACTIVE:
        raise DataError(f"audio is silence: {seconds:.2f} s within {SILENCE_BELOW_PEAK_DB:g} "
                        f"dB of its loudest sound, {MIN_ACTIVE} s needed")
    return x / np.percentile(np.abs(x), LEVEL_PERCENTILE)


def check_speech(audio, sample_rate) -> np.ndarray:
    """:func:`prepare_audio`, and a DataError unless it sounds like speech
    (:func:`speech_problem`): noise and music are refused with the reason, rather than
    given an emotion (white noise was "angry 0.81")."""
    x = prepare_audio(audio, sample_rate)
    problem = speech_problem(x)
    if problem:
        raise DataError(f"audio is not speech: {problem}")
    return x


def speech_measures(x: np.ndarray) -> dict[str, float]:
    """What :func:`speech_problem` judges, of a signal ``x`` at 16 kHz: ``voiced`` (share
    of sounding frames that are periodic at a pitch lag), ``spread`` (standard deviation
    of their levels, dB) and ``seconds`` (sounding time)."""
    levels = _frame_levels(x)
    active = _active(levels)
    frames = _frames(x)[active]
    voiced = _voiced(frames)
    return {"voiced": float(voiced.mean()) if len(voiced) else 0.0,
            "spread": float(np.std(levels[active])) if active.any() else 0.0,
            "seconds": float(np.count_nonzero(active) * _HOP / FEATURE_SAMPLE_RATE)}


def speech_problem(x: np.ndarray) -> str:
    """Why the signal ``x`` (16 kHz) is not speech, in words; empty if it may be.

    Speech alternates voiced sounds (periodic, at a pitch of 62-400 Hz) with unvoiced ones
    and pauses, and its level rises and falls with its syllables. Noise is never periodic;
    a tone, a chord or music are periodic throughout, or steady. Thresholds:
    :data:`MIN_VOICED_SHARE`, :data:`MAX_VOICED_SHARE`, :data:`MIN_LEVEL_SPREAD_DB`.
    """
    m = speech_measures(x)
    if m["voiced"] < MIN_VOICED_SHARE:
        return (f"{100 * m['voiced']:.0f} % of its sound is voiced (periodic at a voice's "
                f"pitch), speech has at least {100 * MIN_VOICED_SHARE:.0f} %: noise?")
    if m["voiced"] > MAX_VOICED_SHARE:
        return (f"{100 * m['voiced']:.0f} % of its sound is voiced, without the unvoiced "
                f"sounds and pauses of speech (at most {100 * MAX_VOICED_SHARE:.0f} %): "
                "a tone or music?")
    if m["spread"] < MIN_LEVEL_SPREAD_DB:
        return (f"its level hardly changes ({m['spread']:.1f} dB standard deviation, "
                f"speech's syllables at least {MIN_LEVEL_SPREAD_DB:g} dB): a steady sound?")
    return ""


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


def _frames(x: np.ndarray) -> np.ndarray:
    """25 ms frames every 10 ms of ``x`` (16 kHz), a view: shape (n_frames, 400)."""
    if x.size < _FRAME:
        x = np.pad(x, (0, _FRAME - x.size))
    return np.lib.stride_tricks.sliding_window_view(x, _FRAME)[::_HOP]


def _frame_levels(x: np.ndarray) -> np.ndarray:
    """RMS level of each 25 ms frame, dBFS (-inf for digital silence)."""
    frames = _frames(x)
    with np.errstate(divide="ignore"):
        return 10.0 * np.log10(np.einsum("ij,ij->i", frames, frames) / _FRAME)


def _active(levels: np.ndarray) -> np.ndarray:
    """The frames that sound: within :data:`SILENCE_BELOW_PEAK_DB` of the loudest."""
    return levels > max(levels.max() - SILENCE_BELOW_PEAK_DB, SILENCE_DBFS)


def _voiced(frames: np.ndarray) -> np.ndarray:
    """Which frames (n, 400) are periodic at a voice's pitch: their normalised
    autocorrelation (mean removed, Hann-windowed, by FFT) peaks above
    :data:`VOICED_CORRELATION` at a lag of 2.5-16 ms (62-400 Hz)."""
    if len(frames) == 0:
        return np.zeros(0, dtype=bool)
    lo, hi = FEATURE_SAMPLE_RATE // 400, FEATURE_SAMPLE_RATE // 62
    out = np.empty(len(frames), dtype=bool)
    window = np.hanning(_FRAME)
    for start in range(0, len(frames), 4096):  # bounded memory on a long recording
        f = frames[start:start + 4096]
        f = (f - f.mean(axis=1, keepdims=True)) * window
        spectrum = np.fft.rfft(f, n=2 * _FRAME, axis=1)
        r = np.fft.irfft(np.abs(spectrum) ** 2, axis=1)[:, :hi + 1]
        # Divided by the window's own autocorrelation: a periodic frame's peak is then
        # near 1 whatever its lag (the unbiased estimate, Boersma 1993).
        own = np.correlate(window, window, "full")[_FRAME - 1:_FRAME + hi]
        r = r / np.maximum(r[:, :1], 1e-300) / (own / own[0])
        out[start:start + len(f)] = r[:, lo:hi + 1].max(axis=1) > VOICED_CORRELATION
    return out


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
