"""A known transcript aligned to a live stream's phone posteriors as the audio arrives.

A text-to-speech voice knows what it says. Offline, the transcript's phones are placed on
the whole recording by forced alignment (:func:`ingest.speech.ctc.align`: CTC Viterbi of
the transcript's phone sequence through hama's posteriors). Live, the recording is never
whole: :class:`TranscriptTrack` runs the same CTC Viterbi on the frames heard so far with
a *free end* (the path may stop in any state: the speech has said a prefix of the
transcript), and, to stay bounded, fixes the path of frames older than
:data:`COMMIT_S` before the newest one (the fixed-lag decoding of online Viterbi): the
next update's search starts from the state the path was in there. Each update costs a
Viterbi over ``COMMIT_S + hop`` of frames and the states those frames can reach (at most
two a frame), whatever the length of the transcript.

The window's phones are then the phones of this path in the window, timed as
:func:`ingest.speech.ctc.recognize` times its own (:func:`ingest.speech.ctc_timing.last_frames`
and :func:`~ingest.speech.ctc_timing.timed`): only which phone, and where it starts, come
from the transcript instead of the likeliest class of each frame.

A transcript that does not fit (another utterance, words left out, or speech going on
after its end) is found by offline's two tests (:func:`ingest.speech.ctc.check_transcript`),
here over the last :data:`CHECK_S` of fixed frames: the path's log posterior falls
below free recognition's by more than :data:`MAX_LIVE_ALIGN_LOSS` nats per frame
(offline's :data:`ingest.speech.ctc.MAX_ALIGN_LOSS`, calibrated for live posteriors), or
it says fewer than :data:`MIN_LIVE_PHONE_SHARE` phones per phone recognition hears
(offline's :data:`ingest.speech.ctc.MIN_PHONE_SHARE`, calibrated likewise; with a free
end a path of a wrong transcript can stay on the blank and say nothing). The stream
then recognises the phones of the rest of the speech, as the offline path falls back to
recognition.

What the loss measures live is whether the *path* kept its place, which a wrong
transcript cannot, and a right one does not always: where hama hears no phone of a word
(GRID's "with" after the colour, its W IH DH unheard), the path, free at its end, waits
on the blank, falls behind the speech and is closed at the end over phones it never
matched. That is why the live threshold is higher than offline's, which aligns the whole
recording at once, and why a one-word change is seldom caught.

Those tests need :data:`MIN_CHECK_S` of fixed frames, and the last :data:`COMMIT_S` of a
stream are never fixed while it runs: a wrong transcript of a short utterance (a GRID
sentence is 3 s) would go unnoticed. When the speech ends (:meth:`TranscriptTrack.finish`)
the path is closed as offline closes it (it must end on the transcript's last phone or
the blank after it: the speech said all of it), every frame is fixed, and the same tests
run over all of it from offline's shortest clip (:data:`ingest.speech.inputs.MIN_DURATION`)
on. The frames already sent followed the transcript: a failure there is reported (the
stream counts a warning), not mended.
"""

from __future__ import annotations

import math

import numpy as np

from db.errors import DataError

#: The path of frames older than this before the newest frame is fixed (s): the Viterbi
#: of an update starts there. A phone's place moves little once a second of audio after
#: it is heard; the free end's path is the best one only up to its last frames.
COMMIT_S = 1.0
#: The transcript's fit is checked against free recognition over the last this many
#: seconds of fixed frames, once there are :data:`MIN_CHECK_S` of them. As offline, the
#: mean is over pauses too: over 2 s of speech alone a right transcript's path fell
#: 0.5-0.7 nats/frame below recognition (eSpeak NG), a wrong one's 0.8-1.1.
CHECK_S, MIN_CHECK_S = 10.0, 2.0
#: The live test's alignment threshold (nats/frame below free recognition), in place of
#: offline's :data:`ingest.speech.ctc.MAX_ALIGN_LOSS` (0.6), which live posteriors and a
#: path fixed as it goes exceed with right transcripts. Rule: the right transcripts' 99th
#: percentile at the default setting plus 0.05, over GRID's database clips (every 8th of
#: the 640 of ``grid_split``, none held out; ``scripts/eval_live_transcript_check.py``):
#: 0.85 + 0.05, above all 80 of them (at most 0.89). Wrong transcripts there: another
#: clip's sentence reported 33 of 80 times, a one-word change 0-17 of 80 by its slot
#: (docs/results/live.md, "The transcript's test at the stream's end").
MAX_LIVE_ALIGN_LOSS = 0.9
#: The live test's share: fewer phones said than this many per phone recognition hears
#: gives the transcript up, in place of offline's :data:`ingest.speech.ctc.MIN_PHONE_SHARE`
#: (0.5), which right transcripts of eSpeak NG speech fell just below at ``--low-latency``
#: with their path in place (0.48-0.49, the alignment under its threshold): free
#: recognition on posteriors settled 40 ms after their frame (that setting's value when
#: this was measured; it settles 80 ms after since) hears more phone onsets.
#: Rule: the 1st percentile of the worst share of the right transcripts the alignment test
#: keeps (0.465), less 0.05, rounded down to a tenth, on clips that are not the reported
#: ones (GRID's database clips every 32nd from the 4th, 20, and the synthetic corpus'
#: second take, 23; both settings; ``scripts/eval_live_transcript_check.py --offset 4
#: --every 32 --synthetic --take 2``). Wrong transcripts are mostly caught by the
#: alignment; the one there the share alone caught said nothing (docs/results/live.md,
#: "The transcript's test at the stream's end").
MIN_LIVE_PHONE_SHARE = 0.4
#: Log posterior floor (a probability of 0 from the model would make a path impossible).
LOG_FLOOR = -30.0


class TranscriptTrack:
    """The best CTC path of a transcript through the posteriors heard so far.

    Parameters
    ----------
    text : str
        What the voice says (English; numbers and symbols are spelled out, as offline).
    frame_rate : int
        Posterior frames per second.
    test : bool, default=True
        Give the transcript up when it stops fitting the speech. False: the fit is still
        measured (:attr:`fit`) but the path follows the transcript whatever the tests
        say (to measure them, as ``scripts/eval_live_transcript_check.py`` does); a path
        that cannot be closed at the end is still reported.
    fed : list, optional
        Every posterior block the track is given is appended to it, as ``(log_probs,
        first, at_end)`` (a copy; ``at_end``: given to :meth:`finish`), so that a stream's
        feeding can be replayed to other tracks (``scripts/eval_live_transcript_check.py``).

    Attributes
    ----------
    phones : list of str
        The transcript's ARPAbet phones.
    failed : str or None
        Why the transcript was given up (it does not fit the speech), once it was.
    fit : tuple of (float, int, int) or None
        The last test's alignment loss (nats/frame below free recognition), phones
        said and phones heard (None before the first test).

    Raises
    ------
    ParameterError
        An empty transcript.
    DataError
        A transcript with no pronounceable word.
    """

    def __init__(self, text: str, frame_rate: int, *, test: bool = True,
                 fed: list | None = None) -> None:
        from ingest.speech import ctc
        from ingest.speech.inputs import check_text
        from ingest.speech.phones import PHONES, SILENCE

        text = check_text(text)
        self.phones = ctc.transcript_phones(text)
        if not self.phones:
            raise DataError(f"the transcript {text[:60]!r} has no pronounceable word")
        self.text = text
        self.frame_rate = int(frame_rate)
        self.test = bool(test)
        self.fed = fed
        self._blank = PHONES.index(SILENCE)
        labels = np.asarray([PHONES.index(p) for p in self.phones], dtype=np.int64)
        self._states = np.full(2 * len(labels) + 1, self._blank, dtype=np.int64)
        self._states[1::2] = labels
        self._can_skip = np.zeros(len(self._states), dtype=bool)
        self._can_skip[3::2] = labels[1:] != labels[:-1]
        self._max_loss, self._min_share = MAX_LIVE_ALIGN_LOSS, MIN_LIVE_PHONE_SHARE
        self.failed: str | None = None
        self.fit: tuple[float, int, int] | None = None
        self._fixed = 0  # frames whose state is fixed
        self._fixed_state = -1  # the state of frame _fixed - 1 (-1: none yet)
        self._first = 0  # frame index of _path[0]
        self._path = np.zeros(0, dtype=np.int64)  # state per frame, fixed then tentative
        self._loss = np.zeros(0)  # per fixed frame kept: free best minus the path's
        self._heard = np.zeros(0, dtype=bool)  # ... a phone begins on the free best path
        self._said = np.zeros(0, dtype=bool)  # ... a transcript phone begins on the path
        self._last_best = -1  # the free best class of the last fixed frame

    @property
    def frames(self) -> int:
        """Frames with a state on the path."""
        return self._first + len(self._path)

    @property
    def fixed(self) -> int:
        """Frames whose state is fixed (the next update's posteriors start here)."""
        return self._fixed

    def update(self, log_probs: np.ndarray, first: int) -> None:
        """Extend the path over the frames from ``first`` on.

        Parameters
        ----------
        log_probs : np.ndarray, shape (n_frames, n_classes)
            Log posteriors of frames ``first`` to ``first + n_frames``; ``first`` must
            not be after the first frame not fixed yet (earlier rows are skipped).
        first : int
        """
        if self.fed is not None:
            self.fed.append((np.array(log_probs), int(first), False))
        if self.failed is not None or not len(log_probs):
            return
        if first > self._fixed:
            raise ValueError(f"posteriors from frame {first}, the path is fixed to "
                             f"{self._fixed}")
        lp = np.maximum(log_probs[self._fixed - first:], LOG_FLOOR)
        if not len(lp):
            return
        visited = self._viterbi(lp)
        kept = self._path[: self._fixed - self._first]
        self._path = np.concatenate([kept, visited])
        # Fix the frames older than COMMIT_S before the newest one.
        newest = self._fixed + len(lp)
        fix_to = max(self._fixed, newest - int(round(COMMIT_S * self.frame_rate)))
        if fix_to > self._fixed:
            self._fix(lp, visited, fix_to - self._fixed)
            self._check()

    def finish(self, log_probs: np.ndarray, first: int) -> None:
        """The speech has ended: close the path over the frames from ``first`` on (the
        stream's last posteriors, as :meth:`update` takes them), fix every frame and test
        the fit over all of them (see the module's docstring); :attr:`failed` says why
        it does not fit."""
        from ingest.speech.inputs import MIN_DURATION

        if self.fed is not None:
            self.fed.append((np.array(log_probs), int(first), True))
        if self.failed is not None:
            return
        if first > self._fixed:
            raise ValueError(f"posteriors from frame {first}, the path is fixed to "
                             f"{self._fixed}")
        lp = np.maximum(log_probs[self._fixed - first:], LOG_FLOOR)
        if len(lp):
            visited = self._viterbi(lp, closed=True)
            if visited is None:  # the frames left cannot say the phones left
                said = (max(self._fixed_state, 0) + 1) // 2
                self.failed = (f"the transcript does not fit the speech at its end "
                               f"({said} of its {len(self.phones)} phones said)")
                return
            self._path = np.concatenate([self._path[: self._fixed - self._first], visited])
            self._fix(lp, visited, len(lp))
        self._check(min_s=MIN_DURATION, at="at its end")

    def _fix(self, lp: np.ndarray, visited: np.ndarray, n_fix: int) -> None:
        """Fix the first ``n_fix`` frames of ``visited`` (their posteriors ``lp``): keep
        what the fit's tests need of them."""
        rows = lp[:n_fix]
        on_path = rows[np.arange(n_fix), self._states[visited[:n_fix]]]
        self._loss = np.concatenate([self._loss, rows.max(axis=1) - on_path])
        best = np.argmax(rows, axis=1)
        before = np.concatenate([[self._last_best], best[:-1]])
        self._heard = np.concatenate([self._heard, (best != before) & (best != self._blank)])
        states = visited[:n_fix]
        entered = np.concatenate([[self._fixed_state], states[:-1]]) != states
        self._said = np.concatenate([self._said, entered & (states % 2 == 1)])
        self._last_best = int(best[-1])
        self._fixed_state = int(visited[n_fix - 1])
        self._fixed += n_fix

    def _viterbi(self, lp: np.ndarray, *, closed: bool = False) -> np.ndarray | None:
        """States of the best path through ``lp`` from the fixed state, free at its end
        (``closed``: ending on the last phone or the blank after it; None if it cannot)."""
        n = len(lp)
        lo = max(self._fixed_state, 0)
        hi = min(len(self._states), lo + 2 * n + 2)
        states = self._states[lo:hi]
        skip = self._can_skip[lo:hi]
        score = np.full(hi - lo, -np.inf)
        if self._fixed_state < 0:  # the start: the first blank or the first phone
            score[:2] = lp[0, states[:2]]
        else:  # from the fixed state: stay, one on, or a blank skipped
            prev = np.full(hi - lo, -np.inf)
            prev[0] = 0.0
            score = self._step(prev, skip) + lp[0, states]
        back = np.zeros((n, hi - lo), dtype=np.int8)
        if self._fixed_state >= 0:
            back[0] = self._moves(np.where(np.arange(hi - lo) == 0, 0.0, -np.inf), skip)
        for t in range(1, n):
            back[t] = self._moves(score, skip)
            score = self._step(score, skip) + lp[t, states]
        if closed:  # the last phone or the final blank, if this many frames reach them
            ends = np.arange(hi - lo) + lo >= len(self._states) - 2
            if not np.isfinite(score[ends]).any():
                return None
            score = np.where(ends, score, -np.inf)
        s = int(np.argmax(score))  # free end: any state
        visited = np.empty(n, dtype=np.int64)
        for t in range(n - 1, -1, -1):
            visited[t] = s
            s -= int(back[t, s])
        return visited + lo

    @staticmethod
    def _candidates(score: np.ndarray, skip: np.ndarray) -> tuple[np.ndarray, ...]:
        step = np.full(len(score), -np.inf)
        step[1:] = score[:-1]
        hop = np.full(len(score), -np.inf)
        hop[2:] = score[:-2]
        return score, step, np.where(skip, hop, -np.inf)

    def _step(self, score: np.ndarray, skip: np.ndarray) -> np.ndarray:
        stay, step, hop = self._candidates(score, skip)
        return np.maximum(stay, np.maximum(step, hop))

    def _moves(self, score: np.ndarray, skip: np.ndarray) -> np.ndarray:
        stay, step, hop = self._candidates(score, skip)
        best = np.maximum(stay, np.maximum(step, hop))
        return np.where(best == stay, 0, np.where(best == step, 1, 2)).astype(np.int8)

    def _check(self, min_s: float = MIN_CHECK_S, at: str | None = None) -> None:
        """Give the transcript up when its fixed path fits the last :data:`CHECK_S` of
        speech (once there are ``min_s`` of it) much worse than free recognition does."""
        n = int(round(CHECK_S * self.frame_rate))
        self._loss, self._heard, self._said = self._loss[-n:], self._heard[-n:], self._said[-n:]
        if len(self._loss) < min_s * self.frame_rate:
            return
        loss = float(np.mean(self._loss))
        heard, said = int(self._heard.sum()), int(self._said.sum())
        self.fit = (loss, said, heard)
        then = "phones recognised from there on" if at is None else "the frames followed it"
        at = at or f"after {self._fixed / self.frame_rate:.1f} s"
        if loss > self._max_loss:
            why = f"alignment {loss:.2f} nats/frame below recognition"
        elif said < self._min_share * heard:  # a free end can stop saying phones
            why = f"it says {said} phones where about {heard} were heard"
        else:
            return
        if self.test:
            self.failed = f"the transcript does not fit the speech {at} ({why}): {then}"

    def phone_starts(self, first: int, count: int) -> tuple[list[str], np.ndarray]:
        """The transcript's phones on the path in frames ``first`` to ``first + count``
        and their first frames (relative to ``first``; a phone begun before the window
        starts at 0). Blank frames are no phone (pauses, or between two phones)."""
        a = max(first, self._first)
        visited = self._path[a - self._first: first + count - self._first]
        phones: list[str] = []
        starts: list[int] = []
        prev = -1
        for t, s in enumerate(visited):
            if s % 2 == 1 and s != prev:
                phones.append(self.phones[s // 2])
                starts.append(t + a - first)
            prev = s
        return phones, np.asarray(starts, dtype=np.int64)

    def forget(self, before: int) -> None:
        """Drop the fixed path of frames before ``before``."""
        cut = min(before, self._fixed) - self._first
        if cut > 0:
            self._path = self._path[cut:]
            self._first += cut


def window_segments(track: TranscriptTrack, probs: np.ndarray, first: int, audio: np.ndarray,
                    sample_rate: int):
    """The window's phones from the transcript's path, timed as :func:`ingest.speech.ctc.
    recognize` times recognised ones: segments tiling the window's audio.

    Parameters
    ----------
    probs : np.ndarray, shape (n_frames, n_classes)
        The window's posteriors (its frames from ``first``).
    audio : np.ndarray, shape (n_samples,)
        The window's audio at ``sample_rate``.
    """
    from animegraph.live.frontend import to_model_rate
    from ingest.speech.ctc_timing import last_frames, timed
    from ingest.speech.phones import PHONES
    from ingest.speech.tiling import silence

    duration = len(audio) / sample_rate
    phones, starts = track.phone_starts(first, len(probs))
    if not phones:
        return silence(duration)
    labels = np.asarray([PHONES.index(p) for p in phones], dtype=np.int64)
    log_probs = np.log(np.maximum(probs, math.exp(LOG_FLOOR)))
    last = last_frames(starts, log_probs, labels)
    samples16 = to_model_rate(audio, sample_rate).astype(np.float32)
    return timed(phones, starts, last, samples16, len(probs), duration, True)
