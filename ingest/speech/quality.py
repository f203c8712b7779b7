"""What may be wrong with input speech: warnings before it is animated (issue 13, "Bad input").

Each check gives one line saying what is wrong and what it costs, or nothing:

* **clipping** -- flat tops: samples at the clip's peak in runs of at least
  :data:`CLIP_RUN` (a waveform cut off by the recorder's range; a loud but clean one
  touches its peak for single samples). Warned above :data:`CLIPPED_FRACTION` of the
  samples.
* **narrow band** -- telephone audio: a sampling rate below 16 kHz, or almost nothing
  above 4 kHz: the power density over :data:`HIGH_BAND` more than :data:`NARROW_BAND_DB`
  below that over :data:`SPEECH_BAND` (an 8 kHz recording brought to 16 kHz keeps only
  its resampler's leakage up there, and that mostly just above 4 kHz, where the high band
  does not start). The phone engines and RASTA-PLP are built for 16 kHz. The band is
  judged only over :data:`MIN_BAND_SOUND` s of sound or more: a single vowel has little
  up there either.
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
#: Bands (Hz) whose power densities are compared: above an 8 kHz recording's 4 kHz limit
#: and a resampler's transition band, and speech's own upper band below it.
HIGH_BAND = (4300.0, 6000.0)
SPEECH_BAND = (2000.0, 3700.0)
#: dB of the high band's density below the speech band's, under which audio is called
#: narrow-band. Measured (``scripts/eval_narrow_band.py``, 16 kHz): real speech -18.5 dB
#: at least on 267 GRID clips, -21.2 on 535 EmoDB clips (one under -20), -11.2 on
#: talkingface; the same brought to 8 kHz and back -21.5 dB at most. The share of all
#: energy above 4 kHz, tested before, called 11 % of GRID's clips narrow-band and missed
#: telephone versions that keep a resampler's transition band.
NARROW_BAND_DB = -20.0
#: Fewest confident phones per second of sound for speech the engine models.
MIN_PHONE_RATE = 4.0
#: A frame is a confident phone when its blank probability is below this.
PHONE_FRAME = 0.5
#: Frames within this many dB of the loudest count as sound (not pause).
SOUND_DB = 30.0
#: Frames (s) the sound is measured in without the phone engine's: its 20 ms.
SOUND_FRAME = 0.02
#: Least sound (s) over which the high band says whether the audio is narrow-band.
#: Speech has it in fricatives and stop bursts, which a second of speech (4-5 syllables)
#: is likely to hold and a vowel does not. Of random cuts of GRID, EmoDB and talkingface,
#: 1-3 % with less than 1 s of sound fell below NARROW_BAND_DB, 1 of 930 with 1 s or
#: more (``scripts/eval_narrow_band.py``).
MIN_BAND_SOUND = 1.0


@dataclass(frozen=True)
class AudioQuality:
    """Measures of one recording (see the module docstring); None where not measured."""

    sample_rate: int
    clipped_fraction: float
    high_band_db: float | None  # HIGH_BAND's power density over SPEECH_BAND's, dB
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
        ``high_band_db`` is None below 16 kHz, or with less than
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
    if (sample_rate >= 16000 and head.size >= 256
            and _sound_seconds(head, sample_rate, n_frames) >= MIN_BAND_SOUND):
        power = np.abs(np.fft.rfft(head)) ** 2
        freqs = np.fft.rfftfreq(head.size, 1.0 / sample_rate)

        def density(band):
            return float(power[(freqs > band[0]) & (freqs <= band[1])].mean())

        speech = density(SPEECH_BAND)
        high = 10 * np.log10(max(density(HIGH_BAND), 1e-30) / speech) if speech > 0 else None
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
    elif quality.high_band_db is not None and quality.high_band_db < NARROW_BAND_DB:
        out.append("the audio has almost nothing above 4 kHz (telephone band, or resampled "
                   "from 8 kHz): phones will be less reliable")
    if quality.phone_rate is not None and quality.phone_rate < MIN_PHONE_RATE:
        out.append(f"the phone engine finds little speech it knows ({quality.phone_rate:.1f} "
                   f"phones per second of sound; speech has about 10): music, noise, or a "
                   f"language it does not model? The lip-sync will be poor")
    return out
