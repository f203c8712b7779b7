"""ppg-ridge's prediction (:mod:`animegraph.baselines.ppg_ridge`) from its arrays, NumPy only.

:func:`ppg_features` is the regression's input (the hama posteriorgram, the CTC blank and
the relative loudness, each in context); :class:`PpgForward` applies the stored affine
map; :class:`StoredPpgRidge` restores a stored model without scikit-learn, so that a
one-shot ``synth`` guided by ppg-ridge does not import it (as
:mod:`animegraph.baselines.mu_mlp_forward` does for mu-mlp).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar

import numpy as np

from animegraph.baselines.data import rms_envelope
from animegraph.baselines.predicting import Stored
from db.errors import ParameterError
from ingest.speech import ctc
from ingest.speech.phones import PHONES
from ingest.speech.posteriorgram import HOP_S, PHONE_COLUMNS, fold
from ingest.speech.posteriorgram import blank as blank_of

#: Context each side of a frame (s) and the step between context frames (s).
CONTEXT_S = 0.2
CONTEXT_STEP_S = 0.04
#: The clip's loud level, against which each frame's log loudness is taken (percentile of
#: the frames' RMS); and the floor of that ratio (-60 dB).
LOUD_PERCENTILE = 95.0
LOUDNESS_FLOOR = 1e-3
#: RMS window of the loudness feature (s): one 25 ms analysis frame.
RMS_WINDOW_S = 0.025
#: Columns per context offset: the posteriorgram's phones, the blank, the loudness.
N_PER_OFFSET = len(PHONES) + 1
#: The loud level set by :func:`loud_level` for the features built in its block (None:
#: each audio's own).
_LOUD: ContextVar[float | None] = ContextVar("ppg_loud_level", default=None)


@contextmanager
def loud_level(loud: float | None) -> Iterator[None]:
    """Within the block, :func:`ppg_features` takes each frame's loudness relative to
    ``loud`` (an RMS, > 0) instead of the audio's own loud level. A live stream predicts
    from a short window: its own loud level is the room's noise before the first word
    (heard as loud as speech: a half-open mouth), so the stream gives the level of all
    it has heard (:class:`animegraph.live.frontend.LoudLevel`), as offline the clip's.

    A context, not a parameter: the level would go through ``window_motion``,
    ``guide_trajectory`` and the shared ``predict(audio, sample_rate)`` and
    ``_predict`` of every guide (mu-mlp, av-hmm, ..., which have no use for it), or
    ``guide_trajectory`` would single ppg-ridge out of a list of guides."""
    token = _LOUD.set(None if loud is None or not loud > 0 else float(loud))
    try:
        yield
    finally:
        _LOUD.reset(token)


def n_offsets(context_s: float, step_s: float) -> int:
    """How many context frames ``context_s`` and ``step_s`` give (2 k + 1), computed
    without building them: a stored model's settings are someone else's data.

    Raises
    ------
    ParameterError
        Unless ``context_s >= 0`` and ``step_s > 0``, both finite.
    """
    if not (np.isfinite(context_s) and np.isfinite(step_s) and context_s >= 0 and step_s > 0):
        raise ParameterError(f"context_s must be >= 0 and step_s > 0, got {context_s}, "
                             f"{step_s}")
    return 2 * int(round(context_s / step_s)) + 1


def context_offsets(context_s: float, step_s: float) -> np.ndarray:
    """Offsets (s) of the context frames, earliest first: shape (:func:`n_offsets`,)."""
    k = n_offsets(context_s, step_s) // 2
    return np.arange(-k, k + 1) * step_s


def _at(values: np.ndarray, hop_s: float, times: np.ndarray) -> np.ndarray:
    """Rows of ``values`` (frame ``t`` centred at ``(t + 0.5) * hop_s``) linearly
    interpolated at ``times`` (edge rows held): shape (len(times), n_columns)."""
    pos = np.clip(np.asarray(times) / hop_s - 0.5, 0.0, len(values) - 1.0)
    lo = np.floor(pos).astype(np.int64)
    hi = np.minimum(lo + 1, len(values) - 1)
    frac = (pos - lo)[:, None]
    return values[lo] * (1.0 - frac) + values[hi] * frac


def stored_posteriors(clip) -> tuple[np.ndarray, np.ndarray] | None:
    """A training clip's stored posteriorgram and CTC blank (:class:`~animegraph.baselines
    .data.TrainingClip`), if they fit its audio; else None (hama hears it again).

    They come with a database, someone else's data: they are used only when there is one
    blank a frame, 39 posteriorgram columns, as many frames as the audio gives (within 2)
    and every value a finite probability.
    """
    post, blank = getattr(clip, "posteriors", None), getattr(clip, "posterior_blank", None)
    if post is None or blank is None:
        return None
    post = np.asarray(post, dtype=np.float32)
    blank = np.asarray(blank, dtype=np.float32)
    expected = len(clip.audio) / clip.sample_rate / HOP_S
    if (post.ndim != 2 or post.shape[1] != len(PHONE_COLUMNS) or blank.shape != (len(post),)
            or abs(len(post) - expected) > 2 or not len(post)):
        return None
    if not (np.isfinite(post).all() and np.isfinite(blank).all()
            and 0 <= min(post.min(), blank.min()) and max(post.max(), blank.max()) <= 1):
        return None
    return post, blank


def ppg_features(audio: np.ndarray, sample_rate: int, times: np.ndarray, *,
                 context_s: float = CONTEXT_S, step_s: float = CONTEXT_STEP_S,
                 stored: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """The regression's input at ``times`` (s).

    Parameters
    ----------
    audio : np.ndarray, shape (n_samples,), float in [-1, 1]
    sample_rate : int
    times : np.ndarray, shape (n,)
    context_s, step_s : float
        Context each side and step (s).
    stored : (np.ndarray, np.ndarray), optional
        The audio's posteriorgram, shape (q, 39), and CTC blank, shape (q,), as ingest
        stored them (:func:`stored_posteriors`): used instead of running hama again.

    Returns
    -------
    np.ndarray, shape (n, N_PER_OFFSET * n_offsets), float64
        Per context offset (earliest first): the 39 posteriorgram columns, the blank's
        probability and the log loudness relative to the clip's loud frames (the
        :data:`LOUD_PERCENTILE` of its frames' RMS, or the level :func:`loud_level` set).
    """
    if stored is None:
        probs = ctc.posteriors(audio, sample_rate)
        stored = fold(probs), blank_of(probs)
    frames = np.column_stack(stored)
    n_frames = len(frames)
    level = frame_loudness(audio, sample_rate, n_frames)
    loud = _LOUD.get()  # a stream's level of all it has heard (loud_level), else the clip's
    if loud is None:
        loud = float(np.percentile(level, LOUD_PERCENTILE)) if n_frames else 0.0
    rel = (np.log(np.maximum(level / loud, LOUDNESS_FLOOR)) if loud > 0
           else np.full(n_frames, np.log(LOUDNESS_FLOOR)))
    frames = np.column_stack([frames.astype(np.float64), rel])
    times = np.asarray(times, dtype=np.float64)
    return np.concatenate([_at(frames, HOP_S, times + o)
                           for o in context_offsets(context_s, step_s)], axis=1)


def frame_loudness(audio: np.ndarray, sample_rate: int, n_frames: int) -> np.ndarray:
    """RMS of ``audio`` (shape (n_samples,)) over :data:`RMS_WINDOW_S` at the centre of
    each of ``n_frames`` posteriorgram frames: shape (n_frames,)."""
    return rms_envelope(audio, sample_rate, (np.arange(n_frames) + 0.5) * HOP_S,
                        window=RMS_WINDOW_S, smooth=0.0)


class PpgForward:
    """The prediction half of ppg-ridge: motion = [1, features] @ ``coef_``."""

    context_s = CONTEXT_S
    step_s = CONTEXT_STEP_S

    def features(self, audio: np.ndarray, sample_rate: int, times: np.ndarray, *,
                 stored: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        """:func:`ppg_features` with this model's context."""
        return ppg_features(audio, sample_rate, times, context_s=self.context_s,
                            step_s=self.step_s, stored=stored)

    def _predict(self, audio, sample_rate, times, emotion):
        x = self.features(audio, sample_rate, times)
        return self.coef_[0] + x @ self.coef_[1:]  # (n_frames, n_channels)

    def _arrays(self) -> dict[str, np.ndarray]:
        return {"coef": self.coef_, "alpha": np.array([self.alpha_])}

    def _restore(self, arrays: dict[str, np.ndarray]) -> None:
        coef = np.asarray(arrays["coef"], dtype=np.float64)
        # Checked before any prediction: a context out of step with the coefficients
        # (e.g. a stored step of 1e-9 s) would build features no coefficient reads.
        if coef.ndim != 2 or len(coef) != 1 + N_PER_OFFSET * n_offsets(self.context_s,
                                                                        self.step_s):
            raise ValueError(f"coefficients of shape {coef.shape} do not fit a context of "
                             f"{self.context_s} s every {self.step_s} s")
        self.coef_ = coef
        self.alpha_ = float(np.asarray(arrays["alpha"]).reshape(-1)[0])


class StoredPpgRidge(PpgForward, Stored):
    """A stored ppg-ridge model that predicts without scikit-learn
    (:meth:`~animegraph.baselines.predicting.Stored.from_arrays`)."""

    method = "ppg-ridge"

    def _set_params(self, params: dict) -> None:
        self.context_s, self.step_s = float(params["context_s"]), float(params["step_s"])
