"""Frame-level audio features: RASTA-PLP cepstra (the prosody curves C of Cao et al.) and MFCC.

Cao et al. 2005, §4.1 and §4.2: every phoneme of a training utterance (an *anime*) and of an
input utterance (a *search node*) carries a prosody feature curve C, "the trajectories of the
first nine parameters returned by RASTA-PLP". :func:`rasta_plp` computes those trajectories
for a whole utterance and :func:`slice_frames` cuts out one phone's curve.

RASTA-PLP
---------
Perceptual linear prediction (Hermansky 1990, "Perceptual linear predictive (PLP) analysis
of speech", JASA 87(4)) with RASTA filtering of the critical-band trajectories (Hermansky &
Morgan 1994, "RASTA processing of speech", IEEE TSAP 2(4)), implemented after Dan Ellis'
reference Matlab code ``rastaplp.m`` (*PLP and RASTA (and MFCC, and inversion) in Matlab*,
Columbia University, 2005), step by step:

1. ``powspec`` -- short-time power spectrum: symmetric Hann window (Matlab ``hanning``),
   FFT length the next power of two, samples scaled to the 16-bit range (x 32768) and a
   constant ``win_len`` added to every bin (Ellis' stand-in for a white dither of about one
   LSB: the floor that keeps every log finite, see :func:`rasta_plp`).
2. ``audspec`` / ``fft2barkmx`` -- integration into ``ceil(bark(sr / 2)) + 1`` critical
   bands one Bark apart (for the default band edges), trapezoidal in Bark: flat over 1 Bark,
   a skirt rising 10 dB/Bark below and one falling 25 dB/Bark above (Hermansky 1990's
   critical-band curve); ``bark(f) = 6 asinh(f / 600)``.
3. ``log`` -> ``rastafilt`` -> ``exp`` (only when ``rasta``) -- each band's log trajectory is
   band-pass filtered along time by ``H(z) = (0.2 + 0.1 z^-1 - 0.1 z^-3 - 0.2 z^-4) /
   (1 - 0.94 z^-1)`` (:data:`RASTA_NUMERATOR`, :data:`RASTA_DENOMINATOR`); the first four
   frames only prime the filter's state and are output as zeros (Ellis' initial conditions,
   which avoid a start-up transient from each band's level).
4. ``postaud`` -- equal-loudness pre-emphasis (the ICSI ``rasta`` form of Hermansky 1990's
   approximation to the 40 dB equal-loudness curve) and the
   intensity-loudness power law ``** 0.33``; the first and last bands are replaced by their
   neighbours.
5. ``dolpc`` -- autocorrelation as the inverse DFT of the (symmetrically extended)
   auditory spectrum, all-pole model of order ``model_order`` by Levinson-Durbin.
6. ``lpc2cep`` -- cepstrum of the all-pole model (coefficient 0 is the log of the model's
   gain, i.e. of the prediction error), ``n_coeffs`` coefficients.
7. ``lifter`` -- coefficient ``i >= 1`` multiplied by ``i ** lifter_exp``.

Frame timing
------------
Every feature here is a ``(n_frames, n_channels)`` array whose frame ``k`` is centred at
``k * hop_s`` seconds (:func:`frame_times`), frame 0 at the first sample: frame ``k`` covers
the ``win_len = round(win_s * sr)`` samples starting at ``round(k * hop_s * sr) - win_len // 2``,
i.e. about ``[k * hop_s - win_s / 2, k * hop_s + win_s / 2)``; the signal is padded with
zeros (digital silence) where the windows reach past either end. A file of ``n_samples``
samples has ``floor(n_samples / (sr * hop_s)) + 1`` frames, so even a single sample gives one
frame. Frame centres are rounded to whole samples one by one, so a hop that is not a whole
number of samples (10 ms at 22.05 kHz) does not drift: the error stays under half a sample.

Differences from Ellis' ``rastaplp.m``
--------------------------------------
* Frames are centred on their nominal times (above); ``specgram`` starts frame 0 at the
  first sample and rounds the hop once, which drifts for hops of fractional samples.
* ``postaud`` puts the equal-loudness curve at the filterbank's own centre frequencies;
  Ellis assumes ``min_freq = 0`` (``linspace(0, bark(fmax))``). Identical for the defaults.
* Levinson-Durbin is guarded (reflection coefficients clipped inside the unit circle,
  prediction error floored at 1e-12 of the frame's power) so that no frame can give a
  non-finite cepstrum; it never triggers on speech or silence.
* ``n_coeffs`` may exceed ``model_order + 1`` (the LPC-to-cepstrum recursion continues with
  zero coefficients); Ellis' ``lpc2cep`` indexes past the end of its array there.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from db.errors import DataError, ParameterError
from ingest.filters import lfilter
from ingest.formats.wav import SPEECH_RATE_RANGE

logger = logging.getLogger(__name__)

__all__ = [
    "RASTA_DENOMINATOR",
    "RASTA_NUMERATOR",
    "SAMPLE_RATE_RANGE",
    "RastaPlpConfig",
    "frame_times",
    "mfcc",
    "rasta_plp",
    "slice_frames",
]

#: Numerator of the RASTA filter, ``-[-2, -1, 0, 1, 2] / 10`` (Ellis ``rastafilt.m``; the
#: regression-slope FIR part of Hermansky & Morgan 1994's filter, made causal: no ``z^4``).
RASTA_NUMERATOR: np.ndarray = np.array([0.2, 0.1, 0.0, -0.1, -0.2])
RASTA_NUMERATOR.setflags(write=False)
#: Denominator of the RASTA filter: one pole at 0.94 (Ellis ``rastafilt.m``, after ICSI's
#: ``rasta``; the 1994 paper's filter has its pole at 0.98).
RASTA_DENOMINATOR: np.ndarray = np.array([1.0, -0.94])
RASTA_DENOMINATOR.setflags(write=False)

#: Hz, the rates the features are tested at; speech is read at these (ingest.formats.wav).
SAMPLE_RATE_RANGE: tuple[int, int] = SPEECH_RATE_RANGE
_INT16_SCALE = 32768.0  # powspec.m: "values coming out of rasta treat samples as integers"
_LOUDNESS_EXPONENT = 0.33  # postaud.m: cube-root intensity-loudness compression (not 1/3)
_N_MELS = 40  # mel bands of mfcc(): filled at 8 kHz with a 256-point FFT, standard for ASR
_MEL_FLOOR = 1e-10  # mfcc(): absolute power floor before the log (librosa's amin), -100 dB
_CHUNK_FRAMES = 2048  # frames per FFT batch: bounds memory on long files (~35 MB at 48 kHz)
_TIME_EPS = 1e-9  # tolerance, in frames, when comparing times with frame centres


@dataclass(frozen=True)
class RastaPlpConfig:
    """Options of :func:`rasta_plp` (Cao et al. 2005 §4.1; Ellis ``rastaplp.m``).

    The critical bands are spread evenly in Bark over ``[min_freq, max_freq]``; their number
    is always ``ceil(bark(sr / 2)) + 1``, as in ``audspec.m``, so narrowing the range makes
    the bands overlap more rather than fewer.

    Raises :class:`~db.errors.ParameterError` on construction if a value is out of range;
    ``max_freq`` and ``model_order`` are also checked against the sample rate by
    :func:`rasta_plp`.
    """

    win_s: float = 0.025  # analysis window, seconds (powspec.m default, 25 ms)
    hop_s: float = 0.010  # frame hop, seconds (powspec.m default; RASTA is designed at 100 Hz)
    model_order: int = 8  # all-pole model order (rastaplp.m default) -> 9 cepstra
    n_coeffs: int = 9  # cepstra kept, model_order + 1 (lpc2cep.m); Cao et al.'s "first nine"
    rasta: bool = True  # RASTA-filter the log critical bands (rastaplp.m dorasta = 1)
    lifter_exp: float = 0.6  # cepstral lifter exponent, c_i * i ** 0.6 (rastaplp.m, lifter.m)
    min_freq: float = 0.0  # lower band edge, Hz (audspec.m / fft2barkmx.m default)
    max_freq: float | None = None  # upper band edge, Hz; None = sr / 2 (audspec.m default)

    def __post_init__(self) -> None:
        for name in ("win_s", "hop_s"):
            value = getattr(self, name)
            if not _is_real(value) or not (math.isfinite(value) and value > 0):
                raise ParameterError(f"{name} must be a positive number of seconds, got {value!r}")
        for name in ("model_order", "n_coeffs"):
            value = getattr(self, name)
            if not _is_int(value) or value < 1:
                raise ParameterError(f"{name} must be a positive integer, got {value!r}")
        if not isinstance(self.rasta, bool | np.bool_):
            raise ParameterError(f"rasta must be a bool, got {self.rasta!r}")
        if not _is_real(self.lifter_exp) or not (
            math.isfinite(self.lifter_exp) and self.lifter_exp >= 0
        ):
            raise ParameterError(f"lifter_exp must be a number >= 0, got {self.lifter_exp!r}")
        if not _is_real(self.min_freq) or not (
            math.isfinite(self.min_freq) and self.min_freq >= 0
        ):
            raise ParameterError(f"min_freq must be a number of Hz >= 0, got {self.min_freq!r}")
        if self.max_freq is not None and (
            not _is_real(self.max_freq)
            or not math.isfinite(self.max_freq)
            or self.max_freq <= self.min_freq
        ):
            raise ParameterError(
                f"max_freq must be None or a number of Hz > min_freq ({self.min_freq}), "
                f"got {self.max_freq!r}"
            )


# ---------------------------------------------------------------------------------------------
# Argument checks
# ---------------------------------------------------------------------------------------------


def _is_int(value: object) -> bool:
    return isinstance(value, int | np.integer) and not isinstance(value, bool | np.bool_)


def _is_real(value: object) -> bool:
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(
        value, bool | np.bool_
    )


def _check_audio(audio: object) -> np.ndarray:
    """Return ``audio`` as a floating-point ``(n_samples,)`` array (not copied), or raise."""
    array = np.asarray(audio)
    if array.ndim != 1:
        raise ParameterError(
            f"audio must be mono, shape (n_samples,); got shape {array.shape} "
            "(mix or select a channel first)"
        )
    if array.size == 0:
        raise ParameterError("audio must have at least one sample, got an empty array")
    if not np.issubdtype(array.dtype, np.floating):
        raise ParameterError(
            f"audio must be floating point samples in [-1, 1], got dtype {array.dtype}"
        )
    if not np.isfinite(array).all():
        raise DataError(f"audio has {int((~np.isfinite(array)).sum())} non-finite samples")
    return array


def _check_sample_rate(sample_rate: object) -> int:
    lo, hi = SAMPLE_RATE_RANGE
    if not _is_int(sample_rate) or not lo <= sample_rate <= hi:
        raise ParameterError(
            f"sample_rate must be an integer in [{lo}, {hi}] Hz, got {sample_rate!r}"
        )
    return int(sample_rate)


def _window_length(win_s: float, hop_s: float, sample_rate: int) -> int:
    win_len = int(round(win_s * sample_rate))
    if win_len < 8:
        raise ParameterError(
            f"win_s must span at least 8 samples at {sample_rate} Hz, got {win_s!r}"
        )
    if hop_s * sample_rate < 1:
        raise ParameterError(
            f"hop_s must span at least 1 sample at {sample_rate} Hz, got {hop_s!r}"
        )
    return win_len


# ---------------------------------------------------------------------------------------------
# Framing and the short-time power spectrum
# ---------------------------------------------------------------------------------------------


def _n_frames(n_samples: int, sample_rate: int, hop_s: float) -> int:
    """``floor(duration / hop_s) + 1``, robust to the rounding of ``hop_s``."""
    return int(math.floor(n_samples / (sample_rate * hop_s) + _TIME_EPS)) + 1


def _band_spectrogram(
    audio: np.ndarray,
    sample_rate: int,
    *,
    hop_s: float,
    window: np.ndarray,
    n_fft: int,
    reduce: Callable[[np.ndarray], np.ndarray],
) -> np.ndarray:
    """Short-time power spectra of centred frames, reduced to bands batch by batch.

    Parameters
    ----------
    audio : np.ndarray, shape (n_samples,)
    sample_rate : int
    hop_s : float
        Frame hop; frame ``k`` is centred on sample ``round(k * hop_s * sample_rate)``.
    window : np.ndarray, shape (win_len,)
        Analysis window, including any scaling of the samples.
    n_fft : int
        FFT length, ``>= win_len`` (the frame is zero-padded).
    reduce : callable
        Maps a batch of power spectra ``(n, n_fft // 2 + 1)`` to ``(n, n_bands)``.

    Returns
    -------
    np.ndarray, shape (n_frames, n_bands), float64
    """
    win_len = len(window)
    n_frames = _n_frames(len(audio), sample_rate, hop_s)
    centres = np.floor(np.arange(n_frames) * (hop_s * sample_rate) + 0.5).astype(np.int64)
    starts = centres - win_len // 2
    offsets = np.arange(win_len)
    out = []
    for first in range(0, n_frames, _CHUNK_FRAMES):
        chunk = starts[first : first + _CHUNK_FRAMES]
        # The samples this batch needs, zero where the windows reach past the signal: no
        # padded copy of the whole (possibly hour-long) signal.
        lo, hi = int(chunk[0]), int(chunk[-1]) + win_len
        segment = np.zeros(hi - lo)
        a, b = max(lo, 0), min(hi, len(audio))
        if b > a:
            segment[a - lo : b - lo] = audio[a:b]
        frames = segment[(chunk - lo)[:, None] + offsets] * window
        spectrum = np.fft.rfft(frames, n=n_fft, axis=1)
        out.append(reduce(spectrum.real**2 + spectrum.imag**2))
    return np.concatenate(out, axis=0)


# ---------------------------------------------------------------------------------------------
# RASTA-PLP stages (Ellis' rastamat, transposed to (n_frames, n_bands))
# ---------------------------------------------------------------------------------------------


def _hz_to_bark(freq: np.ndarray | float) -> np.ndarray:
    """Hermansky's Bark scale, ``6 asinh(f / 600)`` (Ellis ``hz2bark.m``)."""
    return 6.0 * np.arcsinh(np.asarray(freq, dtype=np.float64) / 600.0)


def _bark_to_hz(bark: np.ndarray | float) -> np.ndarray:
    """Inverse of :func:`_hz_to_bark`, ``600 sinh(z / 6)`` (Ellis ``bark2hz.m``)."""
    return 600.0 * np.sinh(np.asarray(bark, dtype=np.float64) / 6.0)


@lru_cache(maxsize=16, typed=True)  # a live stream takes every window's RASTA-PLP
def _bark_filterbank(
    sample_rate: int, n_fft: int, min_freq: float, max_freq: float
) -> tuple[np.ndarray, np.ndarray]:
    """Trapezoidal critical-band weights (Ellis ``fft2barkmx.m``, width 1 Bark; PLP §2.1),
    built once per rate, FFT size and band (read-only).

    Returns
    -------
    weights : np.ndarray, shape (n_bands, n_fft // 2 + 1)
    centres_hz : np.ndarray, shape (n_bands,)
        Band centres; ``n_bands = ceil(bark(sample_rate / 2)) + 1`` as in ``audspec.m``.
    """
    n_bands = int(math.ceil(float(_hz_to_bark(sample_rate / 2)))) + 1
    min_bark = float(_hz_to_bark(min_freq))
    step = (float(_hz_to_bark(max_freq)) - min_bark) / (n_bands - 1)
    centres = min_bark + step * np.arange(n_bands)
    bin_barks = _hz_to_bark(np.arange(n_fft // 2 + 1) * sample_rate / n_fft)
    distance = bin_barks[None, :] - centres[:, None]
    # Power weights: 1 over a 1-Bark flat top, +10 dB/Bark below it, -25 dB/Bark above.
    weights = 10.0 ** np.minimum(0.0, np.minimum(distance + 0.5, -2.5 * (distance - 0.5)))
    centres_hz = _bark_to_hz(centres)
    for a in (weights, centres_hz):
        a.flags.writeable = False
    return weights, centres_hz


def _rasta_filter(log_bands: np.ndarray) -> np.ndarray:
    """RASTA band-pass along time, axis 0 (Hermansky & Morgan 1994; Ellis ``rastafilt.m``).

    Parameters
    ----------
    log_bands : np.ndarray, shape (n_frames, n_bands)
        Log critical-band energies.

    Returns
    -------
    np.ndarray, shape (n_frames, n_bands)
        Zero for the first four frames, which only set the FIR part of the filter state
        (so that each band's level does not cause a transient); the full IIR filter runs
        from frame 4 on. Matlab's ``filter``, :func:`scipy.signal.lfilter` and
        :func:`ingest.filters.lfilter` (used here: the same, without importing
        :mod:`scipy.signal`) share the transposed direct form II, so the state carries over
        unchanged.
    """
    n_prime = len(RASTA_NUMERATOR) - 1
    zi = np.zeros((n_prime, log_bands.shape[1]))
    _, state = lfilter(RASTA_NUMERATOR, [1.0], log_bands[:n_prime], zi)
    out = np.zeros_like(log_bands)
    if len(log_bands) > n_prime:
        out[n_prime:], _ = lfilter(RASTA_NUMERATOR, RASTA_DENOMINATOR, log_bands[n_prime:],
                                   state)
    return out


def _postaud(bands: np.ndarray, centres_hz: np.ndarray) -> np.ndarray:
    """Equal-loudness weighting and cube-root compression (PLP §2.2-2.3; ``postaud.m``).

    Parameters
    ----------
    bands : np.ndarray, shape (n_frames, n_bands)
        Critical-band power.
    centres_hz : np.ndarray, shape (n_bands,)

    Returns
    -------
    np.ndarray, shape (n_frames, n_bands)
        Loudness, first and last bands copied from their neighbours (unreliable edges).
    """
    fsq = centres_hz**2
    equal_loudness = (fsq / (fsq + 1.6e5)) ** 2 * ((fsq + 1.44e6) / (fsq + 9.61e6))
    loudness = (bands * equal_loudness) ** _LOUDNESS_EXPONENT
    loudness[:, 0] = loudness[:, 1]
    loudness[:, -1] = loudness[:, -2]
    return loudness


def _levinson(autocorr: np.ndarray, order: int) -> tuple[np.ndarray, np.ndarray]:
    """Levinson-Durbin recursion on every frame at once (Ellis ``dolpc.m``).

    Parameters
    ----------
    autocorr : np.ndarray, shape (n_frames, >= order + 1)
        Autocorrelation lags 0.. of each frame; lag 0 must be positive.
    order : int

    Returns
    -------
    a : np.ndarray, shape (n_frames, order + 1)
        Prediction polynomial ``1 + a_1 z^-1 + ... + a_p z^-p``.
    error : np.ndarray, shape (n_frames,)
        Prediction error power (the model's gain squared).
    """
    n_frames = len(autocorr)
    a = np.zeros((n_frames, order + 1))
    a[:, 0] = 1.0
    error = autocorr[:, 0].copy()
    floor = autocorr[:, 0] * 1e-12
    for i in range(1, order + 1):
        acc = autocorr[:, i] + np.einsum("fj,fj->f", a[:, 1:i], autocorr[:, i - 1 : 0 : -1])
        k = np.clip(-acc / error, -1.0 + 1e-9, 1.0 - 1e-9)
        a[:, 1:i] += k[:, None] * a[:, i - 1 : 0 : -1]
        a[:, i] = k
        error = np.maximum(error * (1.0 - k * k), floor)
    return a, error


def _lpc_to_cepstrum(a: np.ndarray, error: np.ndarray, n_coeffs: int) -> np.ndarray:
    """Cepstrum of the all-pole model ``sqrt(error) / A(z)`` (Ellis ``lpc2cep.m``, HTK).

    Parameters
    ----------
    a : np.ndarray, shape (n_frames, order + 1)
    error : np.ndarray, shape (n_frames,)
    n_coeffs : int

    Returns
    -------
    np.ndarray, shape (n_frames, n_coeffs)
        ``c_0 = log(error)``, ``c_n = -a_n - sum_{m=1}^{n-1} (n - m) / n a_m c_{n-m}``
        with ``a_n = 0`` past the model order.
    """
    n_frames, n_a = a.shape
    a = np.concatenate([a, np.zeros((n_frames, max(0, n_coeffs - n_a)))], axis=1)
    c = np.zeros((n_frames, n_coeffs))
    c[:, 0] = np.log(error)
    for n in range(1, n_coeffs):
        m = np.arange(1, n)
        acc = (a[:, m] * c[:, n - m]) @ ((n - m) / n)
        c[:, n] = -(a[:, n] + acc)
    return c


# ---------------------------------------------------------------------------------------------
# Public API
# ---------------------------------------------------------------------------------------------


def rasta_plp(
    audio: np.ndarray, sample_rate: int, *, config: RastaPlpConfig | None = None
) -> np.ndarray:
    """RASTA-PLP cepstra of a mono signal: the prosody curves C of Cao et al. 2005 §4.1.

    Hermansky's PLP (1990) with RASTA filtering (Hermansky & Morgan 1994), following Ellis'
    ``rastaplp.m`` (see the module docstring for the stages and the deviations).

    Parameters
    ----------
    audio : np.ndarray, shape (n_samples,)
        Mono floating-point samples, nominally in [-1, 1] (louder is allowed).
    sample_rate : int
        Hz, in [8000, 48000]. The critical-band filterbank adapts to it:
        ``ceil(bark(sample_rate / 2)) + 1`` bands (17 at 8 kHz, 21 at 16 kHz, 28 at 48 kHz).
    config : RastaPlpConfig, optional
        Defaults to ``RastaPlpConfig()`` (25 ms windows, 10 ms hop, order 8, 9 cepstra).

    Returns
    -------
    np.ndarray, shape (n_frames, config.n_coeffs), float32
        Liftered cepstra; frame ``k`` is centred at ``k * hop_s`` seconds and
        ``n_frames = floor(n_samples / (sample_rate * hop_s)) + 1`` (module docstring,
        *Frame timing*; :func:`frame_times`). Always finite.

    Raises
    ------
    ParameterError
        ``audio`` not 1-D, empty or not floating point; ``sample_rate`` out of range; a
        window under 8 samples or a hop under one; ``max_freq`` above ``sample_rate / 2``;
        ``model_order`` not below the number of bands.
    DataError
        ``audio`` holds NaN or infinite samples.

    Notes
    -----
    *Floor.* Before the log, every power-spectrum bin gets ``+ win_len`` on the 16-bit scale
    (Ellis' dither term: about the spectrum of white noise of 1.6 LSB RMS, -83 dB re a
    full-scale sine, whatever the sample rate). Digital silence therefore has the spectrum of
    faint white noise and finite cepstra, and quiet passages meet a fixed, level-independent
    floor rather than one relative to the file's loudest frame.

    *RASTA timing.* The RASTA filter is causal and designed for 100 frames/s. With
    ``rasta=True`` the first four frames (up to 30 ms) carry no information: they are the
    cepstrum of a unit critical-band spectrum, whatever the signal. Output frames lag the
    modulations they respond to by the filter's group delay: about 2 frames at 4-10 Hz,
    4.7 at 2 Hz, 9.5 at 1 Hz. This is the reference behaviour and is the same for the
    database and the query; advancing the output by two frames made phone discrimination on
    eSpeak speech worse, not better, so it is not compensated. Another ``hop_s`` rescales the
    filter's modulation pass-band (-3 dB at 0.9-13.4 Hz for 10 ms).

    With ``rasta=True``, ``c_0`` is the RASTA-filtered log gain, a measure of loudness
    *change*; with ``rasta=False`` it tracks the log energy of the frame.
    """
    config = RastaPlpConfig() if config is None else config
    if not isinstance(config, RastaPlpConfig):
        raise ParameterError(f"config must be a RastaPlpConfig, got {type(config).__name__}")
    audio = _check_audio(audio)
    sample_rate = _check_sample_rate(sample_rate)
    win_len = _window_length(config.win_s, config.hop_s, sample_rate)
    max_freq = sample_rate / 2 if config.max_freq is None else float(config.max_freq)
    if max_freq > sample_rate / 2:
        raise ParameterError(
            f"max_freq must be at most the Nyquist frequency {sample_rate / 2} Hz, "
            f"got {config.max_freq!r}"
        )
    if config.min_freq >= max_freq:
        raise ParameterError(
            f"min_freq must be below max_freq ({max_freq} Hz), got {config.min_freq!r}"
        )

    n_fft = 1 << (win_len - 1).bit_length()  # powspec.m: 2 ^ ceil(log2(win_len))
    weights, centres_hz = _bark_filterbank(sample_rate, n_fft, config.min_freq, max_freq)
    n_bands = len(centres_hz)
    if config.model_order >= n_bands:
        raise ParameterError(
            f"model_order must be below the {n_bands} critical bands at {sample_rate} Hz, "
            f"got {config.model_order!r}"
        )
    # Matlab hanning(N) (symmetric, no zero ends), with powspec.m's scaling of the samples.
    window = np.hanning(win_len + 2)[1:-1] * _INT16_SCALE
    dither = float(win_len)
    weights_t = np.ascontiguousarray(weights.T)

    bands = _band_spectrogram(
        audio,
        sample_rate,
        hop_s=config.hop_s,
        window=window,
        n_fft=n_fft,
        reduce=lambda power: (power + dither) @ weights_t,
    )  # (n_frames, n_bands), > 0
    if config.rasta:
        bands = np.exp(_rasta_filter(np.log(bands)))
    loudness = _postaud(bands, centres_hz)
    # dolpc.m: the auditory spectrum is a power spectrum on [0, pi]; its inverse DFT, with
    # the mirror image implied by irfft, is the autocorrelation.
    autocorr = np.fft.irfft(loudness, n=2 * (n_bands - 1), axis=1)[:, : config.model_order + 1]
    a, error = _levinson(autocorr, config.model_order)
    cepstra = _lpc_to_cepstrum(a, error, config.n_coeffs)
    if config.lifter_exp > 0:
        cepstra[:, 1:] *= np.arange(1, config.n_coeffs) ** config.lifter_exp
    logger.debug(
        "rasta_plp: %d samples at %d Hz -> %s (%d bands, rasta=%s)",
        len(audio), sample_rate, cepstra.shape, n_bands, config.rasta,
    )
    return cepstra.astype(np.float32)


def frame_times(n_frames: int, config: RastaPlpConfig | None = None) -> np.ndarray:
    """Nominal centre times of feature frames.

    Parameters
    ----------
    n_frames : int
        Number of frames, >= 0.
    config : RastaPlpConfig, optional
        Only ``hop_s`` is used (default 10 ms); pass ``RastaPlpConfig(hop_s=...)`` for an
        :func:`mfcc` with another hop.

    Returns
    -------
    np.ndarray, shape (n_frames,), float64
        ``k * hop_s`` seconds. The analysed window is centred on the nearest sample, within
        half a sample of this time.
    """
    config = RastaPlpConfig() if config is None else config
    if not isinstance(config, RastaPlpConfig):
        raise ParameterError(f"config must be a RastaPlpConfig, got {type(config).__name__}")
    if not _is_int(n_frames) or n_frames < 0:
        raise ParameterError(f"n_frames must be an integer >= 0, got {n_frames!r}")
    return np.arange(int(n_frames)) * config.hop_s


def mfcc(
    audio: np.ndarray,
    sample_rate: int,
    *,
    n_mfcc: int = 13,
    hop_s: float = 0.010,
    win_s: float = 0.025,
) -> np.ndarray:
    """Mel-frequency cepstral coefficients on the same frames as :func:`rasta_plp`.

    The power spectrum (periodic Hann window of ``round(win_s * sample_rate)`` samples, FFT
    of the next power of two, frames centred at ``k * hop_s``) is integrated by 40 Slaney
    mel filters (:func:`slaney_mel_filters`, 0 Hz to Nyquist, as ``librosa.filters.mel``),
    converted to dB with an absolute floor of -100 dB (no ``top_db`` clamp, so a frame does
    not depend on the rest of the file) and transformed by the orthonormal DCT-II (as
    :func:`librosa.feature.mfcc`). NumPy only: a one-shot ``synth`` guided by mu-mlp does
    not import librosa (about a second; tests/test_features.py checks the values against
    librosa's).

    Parameters
    ----------
    audio : np.ndarray, shape (n_samples,)
        Mono floating-point samples in [-1, 1].
    sample_rate : int
        Hz, in [8000, 48000].
    n_mfcc : int, optional
        Coefficients kept, 1..40 (default 13, ``c_0`` included).
    hop_s, win_s : float, optional
        Frame hop and window in seconds (10 ms, 25 ms).

    Returns
    -------
    np.ndarray, shape (n_frames, n_mfcc), float32
        ``n_frames = floor(n_samples / (sample_rate * hop_s)) + 1``; frame ``k`` centred at
        ``k * hop_s`` seconds, as for :func:`rasta_plp`.

    Raises
    ------
    ParameterError
        Bad ``audio`` shape or dtype, ``sample_rate``, ``n_mfcc``, ``hop_s`` or ``win_s``.
    DataError
        ``audio`` holds NaN or infinite samples.
    """
    if not _is_int(n_mfcc) or not 1 <= n_mfcc <= _N_MELS:
        raise ParameterError(f"n_mfcc must be an integer in [1, {_N_MELS}], got {n_mfcc!r}")
    for name, value in (("hop_s", hop_s), ("win_s", win_s)):
        if not _is_real(value) or not (math.isfinite(value) and value > 0):
            raise ParameterError(f"{name} must be a positive number of seconds, got {value!r}")
    audio = _check_audio(audio)
    sample_rate = _check_sample_rate(sample_rate)
    win_len = _window_length(win_s, hop_s, sample_rate)
    n_fft = 1 << (win_len - 1).bit_length()
    mel_t, dct_t = _mel_bases(sample_rate, n_fft, n_mfcc)
    window = np.hanning(win_len + 1)[:-1]  # periodic Hann, librosa's "hann"
    mel_power = _band_spectrogram(
        audio, sample_rate, hop_s=float(hop_s), window=window, n_fft=n_fft,
        reduce=lambda power: power @ mel_t,
    )
    log_mel = 10.0 * np.log10(np.maximum(mel_power, _MEL_FLOOR))  # (n_frames, n_mels), dB
    coeffs = log_mel @ dct_t
    return np.ascontiguousarray(coeffs, dtype=np.float32)


@lru_cache(maxsize=16)
def _mel_bases(sample_rate: int, n_fft: int, n_mfcc: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`mfcc`'s mel filters, transposed (n_fft // 2 + 1, n_mels), and DCT rows,
    transposed (n_mels, n_mfcc), read-only: built once per rate and size (a live stream's
    guide takes the MFCCs of every window; building them was 1 % of its update)."""
    mel_t = np.ascontiguousarray(slaney_mel_filters(sample_rate, n_fft, _N_MELS).T)
    dct = dct_ii(_N_MELS)
    for a in (mel_t, dct):
        a.flags.writeable = False
    return mel_t, dct[:n_mfcc].T


def slaney_mel_filters(sample_rate: int, n_fft: int, n_mels: int) -> np.ndarray:
    """Slaney's mel filterbank from 0 Hz to Nyquist (the Auditory Toolbox's; librosa's
    ``filters.mel`` default: mel scale linear below 1 kHz and logarithmic above, each
    triangle scaled to unit area).

    Returns
    -------
    np.ndarray, shape (n_mels, n_fft // 2 + 1), float64
    """
    def hz_to_mel(f):
        f = np.asarray(f, dtype=np.float64)
        mel = f / (200.0 / 3)
        high = f >= 1000.0
        return np.where(high, 15.0 + np.log(np.maximum(f, 1000.0) / 1000.0)
                        / (np.log(6.4) / 27.0), mel)

    def mel_to_hz(m):
        m = np.asarray(m, dtype=np.float64)
        return np.where(m >= 15.0, 1000.0 * np.exp(np.log(6.4) / 27.0 * (m - 15.0)),
                        m * (200.0 / 3))

    fft_hz = np.linspace(0.0, sample_rate / 2.0, n_fft // 2 + 1)
    edges = mel_to_hz(np.linspace(hz_to_mel(0.0), hz_to_mel(sample_rate / 2.0), n_mels + 2))
    width = np.diff(edges)
    ramps = edges[:, None] - fft_hz[None, :]
    lower = -ramps[:-2] / width[:-1, None]
    upper = ramps[2:] / width[1:, None]
    weights = np.maximum(0.0, np.minimum(lower, upper))
    return weights * (2.0 / (edges[2:] - edges[:-2]))[:, None]


def dct_ii(n: int) -> np.ndarray:
    """The orthonormal DCT-II matrix, shape (n, n): ``y = dct_ii(n) @ x``."""
    k = np.arange(n)[:, None]
    basis = np.cos(np.pi / n * (np.arange(n)[None, :] + 0.5) * k) * np.sqrt(2.0 / n)
    basis[0] /= np.sqrt(2.0)
    return basis


def slice_frames(
    features: np.ndarray, start: float, end: float, *, hop_s: float = 0.010
) -> np.ndarray:
    """The frames of one segment (a phone's prosody curve C, Cao et al. 2005 §4.1).

    Parameters
    ----------
    features : np.ndarray, shape (n_frames, n_channels)
        Frame ``k`` centred at ``k * hop_s`` seconds (:func:`rasta_plp`, :func:`mfcc`).
    start, end : float
        Segment bounds in seconds, ``start <= end``.
    hop_s : float, optional
        The features' hop (10 ms).

    Returns
    -------
    np.ndarray, shape (n_rows, n_channels), n_rows >= 1
        A view of the rows whose centre time lies in ``[start, end)``. If there is none
        (a segment shorter than a hop, or one past the last frame centre) the single row
        nearest the segment's midpoint, so every phone gets a curve.

    Raises
    ------
    ParameterError
        ``features`` not a non-empty 2-D array, bad bounds or ``hop_s``.
    DataError
        The segment lies entirely more than one hop outside the features' time span
        (features and segmentation from different signals).
    """
    if not isinstance(features, np.ndarray) or features.ndim != 2 or len(features) == 0:
        shape = getattr(features, "shape", type(features).__name__)
        raise ParameterError(
            f"features must be a (n_frames, n_channels) array with n_frames >= 1, got {shape}"
        )
    if not _is_real(hop_s) or not (math.isfinite(hop_s) and hop_s > 0):
        raise ParameterError(f"hop_s must be a positive number of seconds, got {hop_s!r}")
    for name, value in (("start", start), ("end", end)):
        if not _is_real(value) or not math.isfinite(value):
            raise ParameterError(f"{name} must be a finite number of seconds, got {value!r}")
    if end < start:
        raise ParameterError(f"end must be >= start ({start}), got {end!r}")
    n = len(features)
    if start > n * hop_s or end < -hop_s:
        raise DataError(
            f"segment [{start}, {end}) s lies outside the features' span "
            f"[0, {(n - 1) * hop_s:.3f}] s ({n} frames of {hop_s} s)"
        )
    first = min(n, max(0, math.ceil(start / hop_s - _TIME_EPS)))
    stop = min(n, max(0, math.ceil(end / hop_s - _TIME_EPS)))
    if stop <= first:
        nearest = min(n - 1, max(0, math.floor((start + end) / (2 * hop_s) + 0.5)))
        return features[nearest : nearest + 1]
    return features[first:stop]
