"""What may be wrong with input speech: warnings before it is animated (issue 13, "Bad input").

Each check gives one line saying what is wrong and what it costs, or nothing:

* **clipping** -- flat tops: samples at the clip's peak in runs of at least
  :data:`CLIP_RUN` (a waveform cut off by the recorder's range; a loud but clean one
  touches its peak for single samples). Warned above :data:`CLIPPED_FRACTION` of the
  samples.
* **narrow band** -- telephone audio: a sampling rate below 16 kHz, or almost no energy
  above 4 kHz (:data:`NARROW_BAND_ENERGY`; speech keeps 0.3-3 % there, an 8 kHz
  recording resampled keeps none). The phone engines and RASTA-PLP are built for 16 kHz.
  The energy is judged only over :data:`MIN_BAND_SOUND` s of sound or more: a single
  vowel has none up there either.
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
#: Frames (s) the sound is measured in without the phone engine's: its 20 ms.
SOUND_FRAME = 0.02
#: Least sound (s) whose energy above 4 kHz says whether the audio is narrow-band. Speech
#: has it in fricatives and stop bursts, which a second of speech (4-5 syllables) is likely
#: to hold and a vowel does not. On cuts of real speech (GRID s1, talkingface, EmoDB)
#: with less than 1 s of sound a third fell below NARROW_BAND_ENERGY; with 1 s or more
#: 12 %, as many as of the whole clips.
MIN_BAND_SOUND = 1.0


@dataclass(frozen=True)
class AudioQuality:
    """Measures of one recording (see the module docstring); None where not measured."""

    sample_rate: int
    clipped_fraction: float
    high_band_energy: float | None
    phone_rate: float | None  # confident phones per second of sound (hama)


def assess(audio: np.ndarray, sample_rate: int,
           posteriors: np.ndarray | None = None) -> AudioQuality:
    """Measure ``audio`` for :func:`warnings_for`.

    Parameters
    ----------
    audio : np.ndarray, shape (n_samples,)
        Float speech.
    sample_rate : int
    posteriors : np.ndarray, shape (n_frames, len(PHONES)), optional
        From :func:`ingest.speech.ctc.posteriors`, for the phone rate.

    Returns
    -------
    AudioQuality
        ``high_band_energy`` is None at 8 kHz or below, or with less than
        :data:`MIN_BAND_SOUND` s of sound in the first 30 s (too little to judge);
        ``phone_rate`` None without ``posteriors``.
    """
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
    head = x[: 30 * sample_rate]
    n_frames = max(1, round(head.size / (SOUND_FRAME * sample_rate)))
    if (sample_rate > 8000 and head.size >= 256
            and _sound_seconds(head, sample_rate, n_frames) >= MIN_BAND_SOUND):
        power = np.abs(np.fft.rfft(head)) ** 2
        freqs = np.fft.rfftfreq(head.size, 1.0 / sample_rate)
        total = float(power.sum())
        high = float(power[freqs > 4000].sum() / total) if total > 0 else 0.0
    rate = None
    if posteriors is not None and len(posteriors):
        rate = _phone_rate(x, sample_rate, np.asarray(posteriors))
    return AudioQuality(int(sample_rate), clipped, high, rate)


def _phone_rate(x: np.ndarray, sample_rate: int, posteriors: np.ndarray) -> float:
    """Confident phone onsets per second of sound (:func:`_sound_seconds`)."""
    phone = posteriors[:, PHONES.index(SILENCE)] < PHONE_FRAME
    onsets = phone & ~np.concatenate(([False], phone[:-1]))
    seconds = _sound_seconds(x, sample_rate, len(posteriors))
    return float(onsets.sum() / seconds) if seconds > 0 else 0.0


def _sound_seconds(x: np.ndarray, sample_rate: int, n_frames: int) -> float:
    """Seconds of ``x`` (shape (n_samples,)), cut into ``n_frames`` equal frames, in
    frames within :data:`SOUND_DB` of the loudest: sound, not pause."""
    hop = len(x) / n_frames
    edges = np.round(np.arange(n_frames + 1) * hop).astype(np.int64)
    energy = np.add.reduceat(x * x, edges[:-1]) / np.maximum(np.diff(edges), 1)
    db = 10 * np.log10(np.maximum(energy, 1e-12))
    return float((db > db.max() - SOUND_DB).sum() * hop / sample_rate)


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
