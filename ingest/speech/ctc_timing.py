"""From the CTC phone recogniser's frame posteriors (:mod:`ingest.speech.ctc`) to timed
phones: the best CTC path of a phone sequence (:func:`ctc_viterbi`), and phones with their
first and last frames made segments tiling the clip (:func:`timed`).

CTC posteriors are *peaky*: a phone shows as one or two frames of high probability
near its start, then blanks. A segment therefore runs from its phone's first frame (less
:data:`ONSET_SHIFT`, the median lead measured on the synthetic corpus, see
``scripts/eval_segmentation.py``) to the next phone's start. Pauses come from the audio:
a run of at least :data:`MIN_PAUSE` seconds of quiet 20 ms frames (:func:`_quiet_frames`:
:data:`PAUSE_DB` below the clip's loud frames, or nearer its noise floor) lying between
two phones is ``SIL``; so is the edge before the first phone, and the end of the clip from
the first such quiet run after the last phone's frames (or the quiet frames that reach the
end, if shorter): no phone is heard after it, so a louder frame there is not speech.
"""

from __future__ import annotations

import math

import numpy as np

from db.errors import DataError
from ingest.formats.phones_csv import Segment
from ingest.speech.phones import SILENCE
from ingest.speech.refine import refine_onsets
from ingest.speech.tiling import tile

__all__ = ["FRAME_RATE", "MIN_PAUSE", "ONSET_SHIFT", "PAUSE_DB", "REFINE_WINDOW", "SAMPLE_RATE",
           "ctc_viterbi", "frame_energy", "last_frames", "timed"]

#: Sampling rate of the model's input (Hz).
SAMPLE_RATE = 16000
#: Output frames per second: 160-sample hop, subsampled by 2 (20 ms frames).
FRAME_RATE = 50
#: Seconds a phone's segment starts before its first frame: the median lead of the true
#: onset on the synthetic corpus (``scripts/eval_segmentation.py --engine hama``).
ONSET_SHIFT = 0.06
#: Boundaries move to the largest spectral change this near (seconds; the 20 ms frames'
#: quantisation), as PocketSphinx's do within 10 ms (:func:`ingest.speech.refine.refine_onsets`).
REFINE_WINDOW = 0.02
#: Shortest quiet run (seconds) between two phones taken as a pause (``SIL``).
MIN_PAUSE = 0.1
#: A 20 ms frame is quiet when this many dB below the clip's loud (95th percentile) frames.
PAUSE_DB = 30.0
#: ... or this fraction of the way from the clip's noise floor to its loud frames, if higher.
PAUSE_FRACTION = 0.35
#: Frames (20 ms) over which frame levels are median-smoothed before the quiet test.
PAUSE_SMOOTH = 5


def ctc_viterbi(log_probs: np.ndarray, labels: np.ndarray, blank: int, *,
                path: bool = True) -> tuple[np.ndarray | None, float]:
    """The best CTC path of a label sequence through frame log posteriors.

    States are ``blank, l1, blank, l2, ..., lL, blank`` (``2L + 1``); a path starts in the
    first blank or ``l1``, ends in ``lL`` or the last blank, and at each frame stays, moves
    one state on, or skips a blank between two different labels (Graves et al. 2006, §4.1).

    Parameters
    ----------
    log_probs : numpy.ndarray, shape (n_frames, n_classes)
        Per-frame log posteriors.
    labels : numpy.ndarray, shape (n_labels,), int
        Class indices of the sequence (none equal to ``blank``), at least one.
    blank : int
        Class index of the blank.
    path : bool, optional
        Trace the path back (False: only its score, without the (n_frames, 2 n_labels
        + 1) table of back-pointers: a byte per cell, 3 GB for 30 min of speech).

    Returns
    -------
    starts : numpy.ndarray, shape (n_labels,), int, or None
        First frame of each label on the best path (None without ``path``).
    score : float
        Log probability of that path.

    Raises
    ------
    DataError
        If there are fewer frames than the sequence needs.
    """
    n_frames, n_labels = len(log_probs), len(labels)
    states = np.full(2 * n_labels + 1, blank, dtype=np.int64)
    states[1::2] = labels
    n_states = len(states)
    needed = n_labels + int(np.sum(labels[1:] == labels[:-1]))
    if n_frames < needed:
        raise DataError(f"{n_labels} phones need at least {needed} frames of "
                        f"{1000 // FRAME_RATE} ms, the audio has {n_frames}")
    can_skip = np.zeros(n_states, dtype=bool)
    can_skip[3::2] = labels[1:] != labels[:-1]
    score = np.full(n_states, -np.inf)
    score[:2] = log_probs[0, states[:2]]
    back = np.zeros((n_frames if path else 0, n_states), dtype=np.int8)
    for t in range(1, n_frames):
        stay = score
        step = np.concatenate(([-np.inf], score[:-1]))
        skip = np.where(can_skip, np.concatenate(([-np.inf, -np.inf], score[:-2])), -np.inf)
        best = np.maximum(stay, np.maximum(step, skip))
        if path:
            back[t] = np.where(best == stay, 0, np.where(best == step, 1, 2))
        score = best + log_probs[t, states]
    end = n_states - 1 if n_states == 1 or score[-1] >= score[-2] else n_states - 2
    total = float(score[end])
    if not math.isfinite(total):
        raise DataError("no CTC path through the transcript")
    if not path:
        return None, total
    visited = np.empty(n_frames, dtype=np.int64)  # the state at each frame
    s = end
    for t in range(n_frames - 1, -1, -1):
        visited[t] = s
        s -= int(back[t, s])
    starts = np.empty(n_labels, dtype=np.int64)
    label_frames = visited % 2 == 1
    first = np.full(n_states, -1, dtype=np.int64)
    frames = np.flatnonzero(label_frames)
    for t in frames[::-1]:
        first[visited[t]] = t
    starts[:] = first[1::2]
    return starts, total



def frame_energy(samples16: np.ndarray, n_frames: int) -> np.ndarray:
    """Mean square of each 20 ms frame of 16 kHz audio (zero-padded to ``n_frames``),
    float64, shape (n_frames,)."""
    hop = SAMPLE_RATE // FRAME_RATE
    padded = np.zeros(n_frames * hop, dtype=np.float64)
    m = min(len(samples16), len(padded))
    padded[:m] = samples16[:m]
    return np.mean(padded.reshape(n_frames, hop) ** 2, axis=1)


def _quiet_frames(samples16: np.ndarray, n_frames: int) -> np.ndarray:
    """True for quiet 20 ms frames.

    Frame levels (dB, median-smoothed over :data:`PAUSE_SMOOTH` frames) are quiet below
    the higher of: :data:`PAUSE_DB` under the clip's loud frames (95th percentile), or
    :data:`PAUSE_FRACTION` of the way from its noise floor (5th percentile) to them (a
    recording's noise floor may lie only 30 dB under its speech).
    """
    from scipy.ndimage import median_filter

    energy = frame_energy(samples16, n_frames)
    level = median_filter(10 * np.log10(energy + 1e-12), size=PAUSE_SMOOTH, mode="nearest")
    if not n_frames:
        return np.zeros(0, dtype=bool)
    loud, floor = np.percentile(level, 95), np.percentile(level, 5)
    threshold = max(loud - PAUSE_DB, floor + PAUSE_FRACTION * (loud - floor))
    return level < threshold


def timed(phones: list[str], starts: np.ndarray, last: np.ndarray, samples16: np.ndarray,
           n_frames: int, duration: float, refine: bool) -> list[Segment]:
    """Phones with their first and last frames -> segments tiling ``[0, duration]``."""
    quiet = _quiet_frames(samples16, n_frames)

    frame = 1.0 / FRAME_RATE
    min_run = max(1, int(round(MIN_PAUSE * FRAME_RATE)))
    onsets: list[tuple[str, float]] = [(SILENCE, 0.0)]
    n = len(quiet)
    for k, phone in enumerate(phones):
        onsets.append((phone, max(0.0, starts[k] * frame - ONSET_SHIFT)))
        lo = int(last[k]) + 1
        if k + 1 == len(phones):
            # Trailing silence from the first pause after the last phone: no phone was
            # heard later, so a louder frame there (a breath, noise) is not speech either
            # (GRID: the last phone ran on into the silence after the sentence).
            tail = quiet[lo:n]
            first = _first_run(tail, min_run)
            if first is None and len(tail) and tail[-1]:  # else the quiet frames at the end
                first = int(np.flatnonzero(~tail)[-1]) + 1 if (~tail).any() else 0
            if first is not None:
                onsets.append((SILENCE, (lo + first) * frame))
            break
        run = _longest_run(quiet[lo: int(starts[k + 1])])
        if run is not None and run[1] - run[0] >= min_run:
            onsets.append((SILENCE, (lo + run[0]) * frame))
    if refine:
        onsets = refine_onsets(onsets, samples16 * 32767.0, REFINE_WINDOW)
    return tile(onsets, duration)


def _first_run(mask: np.ndarray, min_run: int) -> int | None:
    """Start of the first run of at least ``min_run`` True in ``mask``, or None."""
    padded = np.concatenate(([False], mask, [False])).astype(np.int8)
    runs = np.flatnonzero(np.diff(padded)).reshape(-1, 2)
    long = runs[runs[:, 1] - runs[:, 0] >= min_run]
    return int(long[0, 0]) if len(long) else None


def _longest_run(mask: np.ndarray) -> tuple[int, int] | None:
    """(start, end) of the longest run of True in ``mask``, or None."""
    if not mask.any():
        return None
    padded = np.concatenate(([False], mask, [False])).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    runs = edges.reshape(-1, 2)
    k = int(np.argmax(runs[:, 1] - runs[:, 0]))
    return int(runs[k, 0]), int(runs[k, 1])


def last_frames(path_starts: np.ndarray, log_probs: np.ndarray, labels: np.ndarray
                 ) -> np.ndarray:
    """Last frame of each phone: its start, extended while the phone stays most likely."""
    last = path_starts.copy()
    n = len(log_probs)
    best = np.argmax(log_probs, axis=1)
    for k, start in enumerate(path_starts):
        stop = path_starts[k + 1] if k + 1 < len(path_starts) else n
        t = int(start)
        while t + 1 < stop and best[t + 1] == labels[k]:
            t += 1
        last[k] = t
    return last
