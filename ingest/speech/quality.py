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
  10-15 phones per second; the recogniser finds 9-13 on English and German here. Heavy
  reverberation blurs phones too: 20 of 100 GRID clips with an RT60 of 1 s fell under
  the rate (``scripts/eval_music.py``), so the line names it among the causes.
* **music** -- two measures of the sound alone, after Scheirer & Slaney ("Construction
  and evaluation of a robust multifeature speech/music discriminator", ICASSP 1997: the
  "percentage of low-energy frames" and the "pulse metric"):

  - *low energy*: the share of 20 ms frames whose energy is under half the mean of their
    1 s window (Lu, Zhang & Jiang's "low short-time energy ratio", LSTER, IEEE Trans.
    Speech Audio Process. 10(7), 2002), averaged over the windows that hold sound. Speech
    falls between syllables and words several times a second; played music keeps its
    level. Warned under :data:`MUSIC_LOW_ENERGY`.
  - *pulse*: the largest correlation of the onset envelope (the rise of the log energy
    in 20 bands from 100 Hz to 7 kHz, summed) with itself :data:`PULSE_LAGS` later. A
    drum beat repeats; speech's syllables do not keep time. Warned above
    :data:`MUSIC_PULSE`, judged on :data:`MIN_PULSE_AUDIO` s of audio or more.

  Measured (``scripts/eval_music.py``) on real speech and on real music from Debian's
  game-music and sample packages: no real speech called music (2,387 clips and cuts,
  noisy and reverberant ones too); 68 % of 955 music excerpts (3-10 s) named by these
  two, 96 % by the phone rate, 97.6 % by either. The phone rate alone misses music with
  drums and voices: 5 confident phones per second in a song with both, GRID's speech 7.8
  (``docs/results/robustness.md``, "Speech input checks").

Silence is an error elsewhere (:func:`animegraph.synthesis.query_phones`); a transcript
that does not fit the audio is warned by :func:`ingest.speech.segment.segment`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ingest.speech.phones import PHONES, SILENCE

__all__ = ["AudioQuality", "assess", "is_silent", "warnings_for"]

#: Peak under which audio is silence (-80 dBFS: below any recording's noise floor).
SILENT_PEAK = 1e-4
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
#: Frames (s) and windows (s) of the low-energy share, and the windows' hop (s).
MUSIC_FRAME = 0.02
MUSIC_WINDOW = 1.0
MUSIC_HOP = 0.5
#: Share of low-energy frames under which the audio is called music. Measured
#: (``scripts/eval_music.py``, 2,387 real speech clips and cuts, none under it): speech 0.27
#: at least (EmoDB's 2 s), 0.42 GRID, 0.34 talkingface (3 s cuts), 0.61 FACEGOOD, 0.48
#: the Live Link take, 0.52 eSpeak NG; 0.28 GRID in white noise at 10 dB SNR, 0.30 in
#: pink at 5 dB, 0.30 talkingface with 1 s of reverberation (RT60). Music's median: 0.11
#: orchestral, 0.04 rock, 0.25-0.35 electronic; drums alone 0.57-0.78 (the pulse's case).
MUSIC_LOW_ENERGY = 0.2
#: Least audio (s) the low-energy share is judged on (EmoDB's 2 s are the shortest measured).
MIN_MUSIC_AUDIO = 2.0
#: Onset envelope: frame hop (s), analysis frame (s), bands (Hz, log-spaced edges).
PULSE_HOP = 0.01
PULSE_FRAME = 0.032
PULSE_BANDS = np.geomspace(100.0, 7000.0, 21)
#: Lags (s) of the pulse: 240 to 60 beats per minute; at most a third of the audio.
PULSE_LAGS = (0.25, 1.0)
#: Onset correlation above which the audio is called music (a steady beat). Measured
#: (``scripts/eval_music.py``): real speech 0.54 at most (GRID; 0.53 FACEGOOD's cuts and
#: GRID with reverberation), 0.37 in noise, 0.40 eSpeak NG; music's median 0.86 for
#: drum loops assembled from recorded kits, 0.51 played loops, 0.59 electronic, 0.17
#: orchestral.
MUSIC_PULSE = 0.65
#: Least audio (s) the pulse is judged on (GRID's clips, 2.98 s, are judged): on
#: shorter speech it runs higher, 0.61 on EmoDB's 2 s and on a 1.9 s eSpeak sentence.
MIN_PULSE_AUDIO = 2.5


@dataclass(frozen=True)
class AudioQuality:
    """Measures of one recording (see the module docstring); None where not measured."""

    sample_rate: int
    clipped_fraction: float
    high_band_db: float | None  # HIGH_BAND's power density over SPEECH_BAND's, dB
    phone_rate: float | None  # confident phones per second of sound (hama)
    low_energy: float | None = None  # share of low-energy frames (LSTER)
    pulse: float | None = None  # onset envelope's largest correlation at PULSE_LAGS


def is_silent(audio: np.ndarray) -> bool:
    """True if no sample of ``audio`` (float, full scale 1, any shape) rises above
    :data:`SILENT_PEAK`: nothing to segment or animate (ingest and ``synth`` refuse it)."""
    return not np.any(np.abs(audio) > SILENT_PEAK)


def assess(audio: np.ndarray, sample_rate: int,
           posteriors: np.ndarray | None = None, *, band: bool = True) -> AudioQuality:
    """Measure ``audio`` for :func:`warnings_for`.

    Parameters
    ----------
    audio : np.ndarray, shape (n_samples,)
        Float speech.
    sample_rate : int
    posteriors : np.ndarray, shape (n_frames, len(PHONES)), optional
        From :func:`ingest.speech.ctc.posteriors`, for the phone rate.
    band : bool, optional
        Judge the band (default). Off when the phones come from labels: the band matters
        to finding phones in the audio.

    Returns
    -------
    AudioQuality
        ``high_band_db`` is None without ``band``, below 16 kHz, or with less than
        :data:`MIN_BAND_SOUND` s of sound in the first 30 s (too little to judge);
        ``phone_rate`` None without ``posteriors``; ``low_energy`` None under
        :data:`MIN_MUSIC_AUDIO` s of audio or without sound, ``pulse`` None under
        :data:`MIN_PULSE_AUDIO` s.
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
    if (band and sample_rate >= 16000 and head.size >= 256
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
    duration = x.size / sample_rate
    low = _low_energy(x, sample_rate) if duration >= MIN_MUSIC_AUDIO else None
    pulse = _pulse(x, sample_rate) if duration >= MIN_PULSE_AUDIO else None
    return AudioQuality(int(sample_rate), clipped, high, rate, low, pulse)


def _low_energy(x: np.ndarray, sample_rate: int) -> float | None:
    """Share of :data:`MUSIC_FRAME` frames under half their :data:`MUSIC_WINDOW`'s mean
    energy, over the windows within :data:`SOUND_DB` of the loudest (a window of digital
    silence, whose every frame is at its mean, says nothing)."""
    frame = max(1, round(MUSIC_FRAME * sample_rate))
    n = x.size // frame
    framed = x[: n * frame].reshape(n, frame)
    energy = np.einsum("ij,ij->i", framed, framed) / frame  # no squared copy of the audio
    size, hop = round(MUSIC_WINDOW / MUSIC_FRAME), round(MUSIC_HOP / MUSIC_FRAME)
    starts = np.arange(0, max(n - size, 0) + 1, hop)
    windows = energy[starts[:, None] + np.arange(min(size, n))[None, :]]
    mean = windows.mean(axis=1)
    if not mean.size or mean.max() <= 0:
        return None
    sound = mean > mean.max() * 10 ** (-SOUND_DB / 10)
    return float((windows[sound] < 0.5 * mean[sound, None]).mean())


def _pulse(x: np.ndarray, sample_rate: int) -> float | None:
    """Largest Pearson correlation of the onset envelope with itself at :data:`PULSE_LAGS`."""
    hop = max(1, round(PULSE_HOP * sample_rate))
    size = round(PULSE_FRAME * sample_rate)
    n = 1 + (x.size - size) // hop
    if n < 3:
        return None
    nfft = 1 << (size - 1).bit_length()
    cuts = np.searchsorted(np.fft.rfftfreq(nfft, 1.0 / sample_rate), PULSE_BANDS)
    window = np.hanning(size)
    bands = np.empty((n, len(PULSE_BANDS) - 1))  # (frames, bands)
    for first in range(0, n, 1000):  # a thousand frames at a time: bounded memory
        idx = hop * np.arange(first, min(n, first + 1000))[:, None] + np.arange(size)[None, :]
        power = np.abs(np.fft.rfft(x[idx] * window, nfft, axis=1)) ** 2
        cum = np.concatenate([np.zeros((len(idx), 1)), np.cumsum(power, axis=1)], axis=1)
        bands[first:first + len(idx)] = cum[:, cuts[1:]] - cum[:, cuts[:-1]]
    floor = max(float(bands.mean()), 1e-30) * 1e-6  # 60 dB under the mean: no rise in silence
    onsets = np.maximum(np.diff(np.log(bands + floor), axis=0), 0.0).sum(axis=1)
    lo = round(PULSE_LAGS[0] / PULSE_HOP)
    hi = min(round(PULSE_LAGS[1] / PULSE_HOP), onsets.size // 3)
    best = None
    for lag in range(lo, hi + 1):
        a, b = onsets[:-lag], onsets[lag:]
        a, b = a - a.mean(), b - b.mean()
        den = np.sqrt((a * a).sum() * (b * b).sum())
        if den > 0:
            r = float((a * b).sum() / den)
            best = r if best is None else max(best, r)
    return best


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
                   f"phones per second of sound; speech has about 10): music, noise, a "
                   f"reverberant room, or a language it does not model? The lip-sync will "
                   f"be poor")
    if quality.low_energy is not None and quality.low_energy < MUSIC_LOW_ENERGY:
        out.append(f"the audio sounds like music or steady noise, not speech (its loudness "
                   f"hardly dips: {100 * quality.low_energy:.0f} % of frames are quiet, speech "
                   f"has 25 % or more): the lip-sync will be poor")
    elif quality.pulse is not None and quality.pulse > MUSIC_PULSE:
        out.append(f"the audio sounds like music, not speech (a steady beat: its onsets "
                   f"repeat with correlation {quality.pulse:.2f}, speech stays under 0.6): "
                   f"the lip-sync will be poor")
    return out
