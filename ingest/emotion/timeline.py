"""A recording classified window by window: bounded memory and time for any length.

The classifier takes one utterance (a few seconds: EmoDB's last 1-9 s); a 10-minute
recording given whole took 157 s and 1.9 GB for one label of all of it. Here a recording
is cut into windows of :data:`WINDOW_S` every :data:`HOP_S` seconds; each is checked
(:func:`ingest.emotion.audio.check_speech`: silence and non-speech are said, not
classified) and the speech windows are classified :data:`BATCH` at a time, so memory
stays that of a few windows and time grows linearly with the length.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from db.errors import DataError, ParameterError
from ingest.emotion.audio import as_float_pcm, check_speech

#: Seconds of a window, and between the starts of two (``classify --timeline``, and
#: ``synth --emotion auto`` over a long line): measured by ``scripts/eval_emotion_timeline.py``
#: (docs/results/emotion.md, "Emotion over a long recording").
WINDOW_S = 4.0
HOP_S = 2.0
#: Window lengths accepted, seconds (the classifier is trained on utterances of a few s).
MIN_WINDOW_S, MAX_WINDOW_S = 1.0, 10.0
#: A recording longer than this is classified in windows, its probabilities their mean
#: over the windows that are speech (a single utterance of the training data is shorter).
MAX_UTTERANCE_S = 15.0
#: Longest recording classified at all, seconds (a day of audio is refused in one line).
MAX_RECORDING_S = 4 * 3600.0
#: Windows classified at once.
BATCH = 8


@dataclass(frozen=True)
class Window:
    """One window of a recording.

    Attributes
    ----------
    start, end : float
        Seconds.
    probabilities : dict of str to float or None
        The classes' probabilities, most likely first; None if it is no speech.
    reason : str
        Why it was not classified (silence, not speech), else empty.
    """

    start: float
    end: float
    probabilities: dict | None
    reason: str = ""


def spans(seconds: float, window: float = WINDOW_S, hop: float = HOP_S
          ) -> list[tuple[float, float]]:
    """The windows' (start, end) over a recording of ``seconds``: every ``hop`` seconds,
    ``window`` long; the last ends at the end (a short tail joins the one before)."""
    if not MIN_WINDOW_S <= window <= MAX_WINDOW_S:
        raise ParameterError(f"the window must last {MIN_WINDOW_S:g} to {MAX_WINDOW_S:g} s, "
                             f"got {window:g}")
    if not 0.1 <= hop <= window:
        raise ParameterError(f"the hop must be 0.1 s to the window ({window:g} s), got {hop:g}")
    if seconds > MAX_RECORDING_S:
        raise DataError(f"the recording lasts {seconds / 3600:.1f} h; at most "
                        f"{MAX_RECORDING_S / 3600:g} h is classified (cut it)")
    if seconds <= window:
        return [(0.0, seconds)]
    starts = np.arange(0.0, seconds - window + 1e-9, hop)
    out = [(float(s), float(s) + window) for s in starts]
    if seconds - out[-1][1] > 0.5 * window:
        out.append((seconds - window, seconds))
    else:
        out[-1] = (out[-1][0], seconds)
    return out


#: With ``one_speaker``: most windows normalised together (about 4 minutes at a 1 s hop;
#: bounded memory for any length, each group by its own statistics).
GROUP = 256
#: The speaker name of a recording's windows (no training speaker's name: a control
#: character starts it).
_THIS_RECORDING = "\x01this recording"


def classify_windows(classifier, audio, sample_rate, *, window: float = WINDOW_S,
                     hop: float = HOP_S, one_speaker: bool = False) -> list[Window]:
    """Each window of ``audio`` (shape (n,) or (n, channels)) classified, or why not.

    With ``one_speaker`` the windows are one speaker's takes: normalised together by their
    own statistics (the estimator's per-speaker normalisation, from
    :data:`ingest.emotion.speakers.MIN_SPEAKER_UTTERANCES` windows up), up to
    :data:`GROUP` at a time, rather than each alone by the training population's.

    Parameters
    ----------
    classifier : EmotionClassifier
        Fitted with probabilities (``predict_proba``).
    audio : array-like
    sample_rate : int or float
    window, hop : float, optional
        Seconds (:func:`spans`).
    one_speaker : bool, optional
        Normalise the windows together (above).

    Returns
    -------
    list of Window
        In time order.
    """
    x = as_float_pcm(audio)
    if x.ndim == 2:
        x = x.mean(axis=1)
    rate = float(sample_rate)
    out: list[Window | None] = []
    pending: list[tuple[int, np.ndarray]] = []
    spanned = spans(len(x) / rate, window, hop)

    batch = GROUP if one_speaker else BATCH

    def flush():
        X = [(piece, rate) for _, piece in pending]
        proba = (classifier.predict_proba(X, speakers=np.full(len(X), _THIS_RECORDING))
                 if one_speaker else classifier.predict_proba(X))
        for (k, _), p in zip(pending, proba, strict=True):
            order = np.argsort(-p)
            start, end = spanned[k]
            out[k] = Window(start, end, {str(classifier.classes_[j]): float(p[j])
                                         for j in order})
        pending.clear()

    for k, (start, end) in enumerate(spanned):
        piece = x[int(round(start * rate)):int(round(end * rate))]
        out.append(None)
        try:
            check_speech(piece, rate)
        except DataError as exc:
            out[k] = Window(start, end, None, str(exc))
            continue
        pending.append((k, piece))
        if len(pending) == batch:
            flush()
    if pending:
        flush()
    return out


def mean_probabilities(windows: list[Window]) -> dict[str, float]:
    """The speech windows' mean probabilities, most likely first; DataError if none is
    speech (with the first window's reason)."""
    speech = [w.probabilities for w in windows if w.probabilities is not None]
    if not speech:
        raise DataError(f"no window of the recording is speech (the first: "
                        f"{windows[0].reason})")
    names = list(speech[0])
    mean = {n: float(np.mean([p[n] for p in speech])) for n in names}
    return dict(sorted(mean.items(), key=lambda kv: -kv[1]))


def weights_over_time(windows: list[Window], times) -> tuple[list[str], np.ndarray]:
    """Each class's probability at ``times`` (seconds, shape (n,)): linear between the
    centres of the speech windows, held before the first and after the last.

    Returns
    -------
    (names, weights)
        The classes (the most probable over the windows first) and an array of shape
        (n, n_classes) whose rows sum to 1.

    Raises
    ------
    DataError
        No window is speech.
    """
    speech = [w for w in windows if w.probabilities is not None]
    names = list(mean_probabilities(windows))  # raises if none is speech
    centres = np.array([(w.start + w.end) / 2 for w in speech])
    p = np.array([[w.probabilities[n] for n in names] for w in speech])
    t = np.asarray(times, dtype=np.float64)
    out = np.column_stack([np.interp(t, centres, p[:, k]) for k in range(len(names))])
    return names, out / out.sum(axis=1, keepdims=True)


def utterance_probabilities(classifier, audio, sample_rate) -> dict[str, float]:
    """The classes' probabilities for a recording, most likely first: one utterance
    classified whole (speech only, :func:`ingest.emotion.audio.check_speech`), a recording
    over :data:`MAX_UTTERANCE_S` as the mean of its speech windows (side by side: the mean
    needs no overlap, and it is a third of the work of the timeline's hop)."""
    if np.shape(audio)[0] / float(sample_rate) > MAX_UTTERANCE_S:
        return mean_probabilities(classify_windows(classifier, audio, sample_rate,
                                                   hop=WINDOW_S))
    check_speech(audio, sample_rate)
    p = classifier.predict_proba([(audio, sample_rate)])[0]
    return {str(classifier.classes_[k]): float(p[k]) for k in np.argsort(-p)}
