"""The phone posteriors of a live stream, computed once for each 20 ms of audio.

hama's model (:mod:`ingest.speech.ctc`) hears its whole input: a frame's posteriors move a
little with every sample before or after it. Re-running it on a sliding window, as a
stream did, paid for the same frames again at every update. :class:`PosteriorTrack`
runs it only on the audio whose posteriors are not *settled* yet, with the context the
model needs:

* each update, the model hears from :attr:`~PosteriorTrack.context_s` before the first
  unsettled 20 ms frame up to the newest sample (one call);
* the frames at least :attr:`~PosteriorTrack.settle_s` before the newest sample are then
  settled: kept, and never computed again; the later ones are kept as tentative, and
  computed again by the next update with more audio after them;
* every call hears the audio at one level, that of the loudest sample heard so far
  (offline, the model hears each clip scaled to its own peak: a stream cannot know its
  peak ahead, and a window's own peak would change the level from update to update).

So the model hears ``context + settle + hop`` of audio per update rather than the whole
window. Before the stream's first sample it hears silence (the context's worth): the
model hears the start of its input as the start of speech, and heard the room's noise
there as phones. A frame's posteriors are those of one call that heard ``context_s`` before it
and at least ``settle_s`` after it: what a window of that reach gives
(``tests/test_live.py`` compares them with such windows, and with the whole utterance).
"""

from __future__ import annotations

import math

import numpy as np

#: Audio (s) before the first unsettled frame that the model hears again (its left
#: context), and audio after a frame heard before its posteriors are settled. The model
#: hears its whole input, so less context costs agreement with the offline posteriors
#: (three eSpeak NG sentences, hop 40 ms, against the whole utterance's: mean total
#: variation per frame 0.14 with 600 / 120 ms, 0.22 with 300 / 40 ms) and, more, with the
#: offline motion: 300 / 40 ms cut the synthetic split's live mouth R by 0.1 at every
#: look-ahead while saving a third of the CPU (docs/results/live.md). The default keeps
#: the windowed stream's quality. The model's cost is a straight line in the audio a
#: call hears (1 ms a call and 43 ms per second heard, on the calling thread only;
#: ``scripts/bench_hama.py``), and no part of it carries over from one call to the next.
CONTEXT_S = 0.6
SETTLE_S = 0.12
#: hama's frame rate (Hz) and rate (Hz) of the audio it hears.
FRAME_RATE, MODEL_RATE = 50, 16000
#: The model hears audio scaled so that the loudest sample heard so far is at this level
#: (as :func:`ingest.speech.ctc.posteriors` scales a clip to its peak).
LEVEL = 0.9


class PosteriorTrack:
    """hama's phone posteriors of a stream, 50 frames per second, settled frame by frame.

    Parameters
    ----------
    sample_rate : int
        Of the audio given to :meth:`update`.
    context_s : float
        Left context the model hears before the first unsettled frame.
    settle_s : float
        Audio heard after a frame before its posteriors are kept for good.

    Attributes
    ----------
    settled : int
        Frames whose posteriors are final.
    model_s : float
        Seconds of audio the model heard in all (its cost).
    """

    def __init__(self, sample_rate: int, *, context_s: float = CONTEXT_S,
                 settle_s: float = SETTLE_S) -> None:
        self.sample_rate = int(sample_rate)
        self.context_s = float(context_s)
        self.settle_s = float(settle_s)
        self.settled = 0
        self.model_s = 0.0
        self._first = 0  # frame index of self._rows[0]
        self._rows = np.zeros((0, 0))  # settled rows kept, then tentative ones
        self._heard = 0  # samples covered by the last update

    @property
    def frames(self) -> int:
        """Frames with posteriors (settled or tentative)."""
        return self._first + len(self._rows)

    def update(self, buffer: np.ndarray, buffer_start: int, heard: int, peak: float) -> None:
        """Compute the posteriors of the frames not settled, from the audio heard.

        Parameters
        ----------
        buffer : np.ndarray, shape (n,), float32
            The stream's audio from sample ``buffer_start`` to sample ``heard``; it must
            reach back :attr:`context_s` before the first unsettled frame.
        buffer_start, heard : int
            Sample indices (input rate).
        peak : float
            The loudest sample heard so far (sets the level the model hears).
        """
        from ingest.speech import ctc

        if heard <= self._heard:
            return
        per_frame = self.sample_rate / FRAME_RATE
        ctx = int(math.ceil(self.context_s * FRAME_RATE))
        start_frame = max(0, self.settled - ctx)
        a = int(round(start_frame * per_frame))
        if a < buffer_start:  # the buffer was cut: hear what is left
            start_frame = int(math.ceil(buffer_start / per_frame))
            a = int(round(start_frame * per_frame))
        audio = buffer[a - buffer_start: heard - buffer_start]
        x = to_model_rate(audio, self.sample_rate)
        if peak > 0:
            x = x * (LEVEL / peak)
        # Near the stream's start the frames to settle have less than the context before
        # them: the model hears silence before the first sample, as if it had listened
        # to nothing before. The start of its input is heard as the start of speech: GRID's
        # leading noise, at the very start of the input, was heard as phones (1-7 frames
        # of its first 10), with 600 ms of silence before it as silence, as offline.
        pad = max(0, ctx - (self.settled - start_frame)) if start_frame == 0 else 0
        x = np.concatenate([np.zeros(pad * (MODEL_RATE // FRAME_RATE)), x])
        probs = ctc.phone_probs(x.astype(np.float32))[pad:]
        self.model_s += len(x) / MODEL_RATE
        n_total = int(math.ceil(heard / per_frame))  # frames the audio so far begins
        probs = _fit(probs, n_total - start_frame)
        keep_from = self.settled - start_frame
        new = probs[keep_from:]
        settled_rows = self.settled - self._first
        rows = self._rows[:settled_rows] if len(self._rows) else np.zeros((0, new.shape[1]))
        self._rows = np.concatenate([rows, new])
        # Settled: frames that end at least settle_s before the newest sample.
        done = int(math.floor((heard / self.sample_rate - self.settle_s) * FRAME_RATE))
        self.settled = max(self.settled, min(done, n_total))
        self._heard = heard

    def posteriors(self, first: int, count: int) -> np.ndarray:
        """Rows ``first`` to ``first + count`` (shape (count, len(PHONES))); rows past the
        last computed one repeat it, rows before the first kept one repeat that."""
        idx = np.clip(np.arange(first, first + count) - self._first, 0, len(self._rows) - 1)
        return self._rows[idx]

    def forget(self, before: int) -> None:
        """Drop the rows of frames before ``before`` (settled ones only)."""
        cut = min(before, self.settled) - self._first
        if cut > 0:
            self._rows = self._rows[cut:]
            self._first += cut


class LoudLevel:
    """The loud level (RMS) of a stream's speech, which ppg-ridge's loudness feature is
    relative to (:func:`animegraph.baselines.ppg_forward.loud_level`).

    Offline it is the clip's: the :data:`~animegraph.baselines.ppg_forward.LOUD_PERCENTILE`
    of its 20 ms frames' RMS (over 25 ms). Live it is that percentile of every 20 ms of
    the stream heard so far (each span's RMS, whatever the chunks pushed; a
    histogram in :data:`BIN_DB` steps, so that a long stream costs no more), but at least
    ``over_noise_db`` over the quietest frame's RMS: before the first word every frame
    is the room's noise, and a window's own loud level made the noise as loud as speech
    (ppg-ridge then opened the mouth in the leading silence; docs/results/live.md).

    Parameters
    ----------
    over_noise_db : float
        The least ratio of the loud level to the quietest frame's RMS (dB).
    """

    BIN_DB = 0.1
    FLOOR_DB = -160.0  # digital silence counts as this

    def __init__(self, over_noise_db: float) -> None:
        self.over_noise_db = float(over_noise_db)
        self._counts = np.zeros(int(-self.FLOOR_DB / self.BIN_DB) + 1, dtype=np.int64)
        self._quietest = np.inf

    def add(self, rms: np.ndarray) -> None:
        """Count frames of RMS ``rms`` (shape (n,))."""
        rms = np.asarray(rms, dtype=np.float64)
        if not rms.size:
            return
        db = 20 * np.log10(np.maximum(rms, 10 ** (self.FLOOR_DB / 20)))
        bins = np.clip(np.round((db - self.FLOOR_DB) / self.BIN_DB).astype(np.int64), 0,
                       len(self._counts) - 1)
        np.add.at(self._counts, bins, 1)
        self._quietest = min(self._quietest, float(rms.min()))

    def level(self) -> float:
        """The loud level (RMS; 0 before any frame)."""
        from animegraph.baselines.ppg_forward import LOUD_PERCENTILE

        total = int(self._counts.sum())
        if not total:
            return 0.0
        # As np.percentile: between the frames of rank floor(r) and floor(r) + 1.
        r = LOUD_PERCENTILE / 100 * (total - 1)
        ranks = np.minimum([int(r), int(r) + 1], total - 1)
        bins = np.searchsorted(np.cumsum(self._counts), ranks, side="right")
        at = 10 ** ((self.FLOOR_DB + bins * self.BIN_DB) / 20)
        loud = at[0] + (r - int(r)) * (at[1] - at[0])
        return max(float(loud), min(1.0, self._quietest * 10 ** (self.over_noise_db / 20)))


def to_model_rate(audio: np.ndarray, sample_rate: int) -> np.ndarray:
    """``audio`` (shape (n,)) resampled to hama's :data:`MODEL_RATE`, float64."""
    if sample_rate == MODEL_RATE:
        return np.asarray(audio, dtype=np.float64)
    from scipy.signal import resample_poly

    g = math.gcd(MODEL_RATE, sample_rate)
    return resample_poly(np.asarray(audio, dtype=np.float64), MODEL_RATE // g, sample_rate // g)


def _fit(probs: np.ndarray, n: int) -> np.ndarray:
    """``probs`` cut or padded (last row repeated) to ``n`` rows."""
    if len(probs) >= n:
        return probs[:n]
    pad = probs[-1:] if len(probs) else np.full((1, probs.shape[1]), 1.0 / probs.shape[1])
    return np.concatenate([probs, np.repeat(pad, n - len(probs), axis=0)])
