"""Non-verbal facial motion driven by the audio: brow raises, head nods, blinks, drift.

Speakers raise their brows on pitch accents and nod on loud, stressed syllables; they
blink at irregular intervals and their head is never quite still. These gestures make
the synthetic motion carry prosody the way real motion capture does, so that the
audio features of the Anime Graph have something in the face to match.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.signal import find_peaks

#: Analysis hop for pitch and energy: 10 ms.
_HOP_S = 0.01


@dataclass(frozen=True)
class Prosody:
    """Pitch and energy of an utterance, sampled at frame times.

    Attributes
    ----------
    f0_semitones : np.ndarray, shape (n_frames,)
        Pitch in semitones above the utterance's median pitch; NaN where unvoiced.
    energy_db : np.ndarray, shape (n_frames,)
        RMS energy in dB relative to the loudest frame.
    """

    f0_semitones: np.ndarray
    energy_db: np.ndarray


def analyze_prosody(audio: np.ndarray, sample_rate: int, times: np.ndarray) -> Prosody:
    """Measure pitch (YIN) and energy of ``audio`` (shape (n_samples,)) at ``times`` (s)."""
    import librosa  # deferred: it is slow to import and only the generator needs it here

    hop = int(round(_HOP_S * sample_rate))
    frame = 2048 if sample_rate > 24000 else 1024
    y = np.asarray(audio, dtype=np.float32)
    f0 = librosa.yin(y, fmin=60.0, fmax=500.0, sr=sample_rate, frame_length=frame,
                     hop_length=hop)
    rms = librosa.feature.rms(y=y, frame_length=frame, hop_length=hop)[0]
    n = min(len(f0), len(rms))
    f0, rms = f0[:n], rms[:n]
    energy = 20 * np.log10(np.maximum(rms, 1e-6) / max(rms.max(), 1e-6))
    # YIN has no voicing decision: trust it only where the frame is loud enough.
    voiced = energy > -30.0
    st = np.full(n, np.nan)
    if voiced.any():
        semis = 12 * np.log2(f0[voiced])
        st[voiced] = semis - np.median(semis)
    idx = np.clip(np.round(times / _HOP_S).astype(np.int64), 0, n - 1)
    return Prosody(f0_semitones=st[idx], energy_db=energy[idx])


def warm_up() -> None:
    """Compile (and cache) the numba kernels :func:`analyze_prosody` uses, in this process.

    librosa's YIN runs cached numba gufuncs. When two fresh worker processes compile and
    cache the same gufunc at once, numba can leave mismatched cache files that crash with
    a null function pointer (numba issues #10128, #4807; seen here as a segfaulting corpus
    worker in a new environment). Calling this once before starting workers means they
    only ever read a complete cache.
    """
    rng = np.random.default_rng(0)
    noise = (0.01 * rng.standard_normal(8000)).astype(np.float32)
    analyze_prosody(noise, 16000, np.arange(10) / 100.0)


def _pulse(times: np.ndarray, centre: float, width: float) -> np.ndarray:
    """A raised-cosine bump of total ``width`` seconds, peak 1 at ``centre``."""
    u = (times - centre) / (width / 2)
    return np.where(np.abs(u) < 1, 0.5 * (1 + np.cos(np.pi * u)), 0.0)


def brow_raises(prosody: Prosody, times: np.ndarray, fps: float) -> np.ndarray:
    """Brow-raise control (0..~1, shape (n_frames,)): a bump on each pitch accent."""
    st = np.nan_to_num(prosody.f0_semitones, nan=0.0)
    smooth = gaussian_filter1d(st, sigma=max(1.0, 0.04 * fps))
    peaks, props = find_peaks(smooth, prominence=1.5, distance=max(1, int(0.35 * fps)))
    out = np.zeros_like(times)
    for p, prom in zip(peaks, props["prominences"], strict=True):
        out = np.maximum(out, min(prom / 5.0, 1.0) * _pulse(times, times[p], 0.45))
    return out


def head_nods(prosody: Prosody, times: np.ndarray, fps: float) -> np.ndarray:
    """Head pitch in degrees (shape (n_frames,)): a dip on each energy peak (stress)."""
    smooth = gaussian_filter1d(prosody.energy_db, sigma=max(1.0, 0.03 * fps))
    peaks, props = find_peaks(smooth, prominence=6.0, height=-12.0,
                              distance=max(1, int(0.4 * fps)))
    out = np.zeros_like(times)
    for p, prom in zip(peaks, props["prominences"], strict=True):
        # Slightly after the syllable's loudness peak, as the head follows the voice.
        out += 2.0 * min(prom / 20.0, 1.0) * _pulse(times, times[p] + 0.05, 0.4)
    return out


def blinks(times: np.ndarray, rate: float, rng: np.random.Generator) -> np.ndarray:
    """Blink control (0..1, shape (n_frames,)): Poisson blinks, fast to close, slow to open."""
    out = np.zeros_like(times)
    if rate <= 0 or len(times) == 0:
        return out
    t, end = float(rng.exponential(1 / rate)), float(times[-1])
    while t < end:
        close, opening = rng.uniform(0.05, 0.08), rng.uniform(0.10, 0.18)
        rising = (times >= t) & (times < t + close)
        out[rising] = np.maximum(out[rising], (times[rising] - t) / close)
        falling = (times >= t + close) & (times < t + close + opening)
        out[falling] = np.maximum(out[falling], 1 - (times[falling] - t - close) / opening)
        t += close + opening + float(rng.exponential(1 / rate))
    return out


def slow_drift(times: np.ndarray, rng: np.random.Generator, n_terms: int = 3) -> np.ndarray:
    """A smooth random curve in [-1, 1] (shape (n_frames,)) from 0.1-0.5 Hz sinusoids."""
    freqs = rng.uniform(0.1, 0.5, n_terms)
    phases = rng.uniform(0, 2 * np.pi, n_terms)
    amps = rng.uniform(0.5, 1.0, n_terms)
    curve = (amps[:, None] * np.sin(2 * np.pi * freqs[:, None] * times + phases[:, None])).sum(0)
    return curve / amps.sum()
