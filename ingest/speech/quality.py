"""What may be wrong with input speech: warnings before it is animated (issue 13, "Bad input").

Each check gives one line saying what is wrong and what it costs, or nothing:

* **clipping** -- flat tops: samples at the clip's peak in runs of at least
  :data:`CLIP_RUN` (a waveform cut off by the recorder's range; a loud but clean one
  touches its peak for single samples). Warned above :data:`CLIPPED_FRACTION` of the
  samples.
* **narrow band** -- telephone audio: a sampling rate below 16 kHz, or almost no energy
  above 4 kHz (:data:`NARROW_BAND_ENERGY`; speech keeps 0.3-3 % there, an 8 kHz
  recording resampled keeps none). The phone engines and RASTA-PLP are built for 16 kHz.
* **no speech the phone engine knows** -- music, noise, or a language the engine does
  not model: the hama CTC model's confident phones per second of sound
  (:data:`MIN_PHONE_RATE`; its blank fills the rest). Conversational speech has
  10-15 phones per second; the recogniser finds 9-13 on English and German here.

Silence is an error elsewhere (:func:`animegraph.synthesis.query_phones`); a transcript
that does not fit the audio is warned by :func:`ingest.speech.segment.segment`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ingest.speech.phones import PHONES, SILENCE

__all__ = ["AudioQuality", "assess", "warnings_for"]

#: Shortest run of samples at the peak counted as a flat (clipped) top.
CLIP_RUN = 3
#: Share of samples in flat tops above which the audio is called clipped.
CLIPPED_FRACTION = 0.001
#: Share of the energy above 4 kHz below which audio is called narrow-band.
NARROW_BAND_ENERGY = 0.0005
#: Fewest confident phones per second of sound for speech the engine models.
MIN_PHONE_RATE = 4.0
#: A frame is a confident phone when its blank probability is below this.
PHONE_FRAME = 0.5
#: Frames within this many dB of the loudest count as sound (not pause).
SOUND_DB = 30.0


@dataclass(frozen=True)
class AudioQuality:
    """Measures of one recording (see the module docstring); None where not measured."""

    sample_rate: int
    clipped_fraction: float
    high_band_energy: float | None
    phone_rate: float | None  # confident phones per second of sound (hama)


def assess(audio: np.ndarray, sample_rate: int,
           posteriors: np.ndarray | None = None) -> AudioQuality:
    """Measure ``audio`` (shape (n_samples,), float); ``posteriors`` (n_frames,
    len(PHONES)) from :func:`ingest.speech.ctc.posteriors` for the phone rate."""
    x = np.asarray(audio, dtype=np.float64)
    peak = float(np.max(np.abs(x))) if x.size else 0.0
    clipped = 0.0
    if peak > 0:
        top = np.abs(x) >= 0.999 * peak
        edges = np.diff(np.concatenate(([0], top.astype(np.int8), [0])))
        starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
        runs = stops - starts
        clipped = float(runs[runs >= CLIP_RUN].sum() / x.size)
    high = None
    if sample_rate > 8000 and x.size >= 256:
        power = np.abs(np.fft.rfft(x[: 30 * sample_rate])) ** 2
        freqs = np.fft.rfftfreq(min(x.size, 30 * sample_rate), 1.0 / sample_rate)
        total = float(power.sum())
        high = float(power[freqs > 4000].sum() / total) if total > 0 else 0.0
    rate = None
    if posteriors is not None and len(posteriors):
        rate = _phone_rate(x, sample_rate, np.asarray(posteriors))
    return AudioQuality(int(sample_rate), clipped, high, rate)


def _phone_rate(x: np.ndarray, sample_rate: int, posteriors: np.ndarray) -> float:
    """Confident phone onsets per second of sound (frames within SOUND_DB of the loudest)."""
    n = len(posteriors)
    hop = len(x) / n
    edges = np.round(np.arange(n + 1) * hop).astype(np.int64)
    energy = np.add.reduceat(x * x, edges[:-1]) / np.maximum(np.diff(edges), 1)
    db = 10 * np.log10(np.maximum(energy, 1e-12))
    sound = db > db.max() - SOUND_DB
    phone = posteriors[:, PHONES.index(SILENCE)] < PHONE_FRAME
    onsets = phone & ~np.concatenate(([False], phone[:-1]))
    seconds = sound.sum() * hop / sample_rate
    return float(onsets.sum() / seconds) if seconds > 0 else 0.0


def warnings_for(quality: AudioQuality) -> list[str]:
    """One line per problem found in ``quality`` (none: an empty list)."""
    out = []
    if quality.clipped_fraction > CLIPPED_FRACTION:
        out.append(f"the audio is clipped ({100 * quality.clipped_fraction:.1f} % of samples "
                   "in flat tops at full scale): phones and loudness may be wrong")
    if quality.sample_rate < 16000:
        out.append(f"the audio is sampled at {quality.sample_rate} Hz (telephone band); the "
                   "phone engines and prosody features expect 16 kHz speech")
    elif quality.high_band_energy is not None and quality.high_band_energy < NARROW_BAND_ENERGY:
        out.append("the audio has almost nothing above 4 kHz (telephone band, or resampled "
                   "from 8 kHz): phones will be less reliable")
    if quality.phone_rate is not None and quality.phone_rate < MIN_PHONE_RATE:
        out.append(f"the phone engine finds little speech it knows ({quality.phone_rate:.1f} "
                   f"phones per second of sound; speech has about 10): music, noise, or a "
                   f"language it does not model? The lip-sync will be poor")
    return out
