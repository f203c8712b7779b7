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

from db.errors import DataError
from ingest.emotion.audio import as_float_pcm, check_speech

#: Seconds of a window, and between the starts of two (``classify --timeline``).
WINDOW_S = 4.0
HOP_S = 4.0
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


def spans(seconds: float) -> list[tuple[float, float]]:
    """The windows' (start, end) over a recording of ``seconds``: every :data:`HOP_S`,
    :data:`WINDOW_S` long; the last ends at the end (a short tail joins the one before)."""
    if seconds > MAX_RECORDING_S:
        raise DataError(f"the recording lasts {seconds / 3600:.1f} h; at most "
                        f"{MAX_RECORDING_S / 3600:g} h is classified (cut it)")
    if seconds <= WINDOW_S:
        return [(0.0, seconds)]
    starts = np.arange(0.0, seconds - WINDOW_S + 1e-9, HOP_S)
    out = [(float(s), float(s) + WINDOW_S) for s in starts]
    if seconds - out[-1][1] > 0.5 * WINDOW_S:
        out.append((seconds - WINDOW_S, seconds))
    else:
        out[-1] = (out[-1][0], seconds)
    return out


def classify_windows(classifier, audio, sample_rate) -> list[Window]:
    """Each window of ``audio`` (shape (n,) or (n, channels)) classified, or why not.

    Parameters
    ----------
    classifier : EmotionClassifier
        Fitted with probabilities (``predict_proba``).
    audio : array-like
    sample_rate : int or float

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
    spanned = spans(len(x) / rate)

    def flush():
        proba = classifier.predict_proba([(piece, rate) for _, piece in pending])
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
        if len(pending) == BATCH:
            flush()
    if pending:
        flush()
    return out


def mean_probabilities(windows: list[Window]) -> dict[str, float]:
    """The speech windows' mean probabilities, most likely first; DataError if none is
    speech (with the first window's reason)."""
    speech = [w.probabilities for w in windows if w.probabilities is not None]
    if not speech:
        raise DataError(f"no {WINDOW_S:g} s window of the recording is speech (the first: "
                        f"{windows[0].reason})")
    names = list(speech[0])
    mean = {n: float(np.mean([p[n] for p in speech])) for n in names}
    return dict(sorted(mean.items(), key=lambda kv: -kv[1]))
