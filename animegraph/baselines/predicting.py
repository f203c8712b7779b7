"""What every fitted baseline does at prediction time, NumPy only (no scikit-learn).

:class:`Predicting` holds :meth:`~Predicting.predict` (input checks, frame times, the
method's ``_predict``) and :meth:`~Predicting.check_channels`. The estimators
(:class:`animegraph.baselines.base.BaselineModel`) inherit it, and so do the stored
models restored without scikit-learn for a one-shot ``synth``
(:class:`animegraph.baselines.mu_mlp_forward.StoredMuMlp`).
"""

from __future__ import annotations

import numpy as np

from animegraph.baselines.data import frame_times
from db.errors import DataError, ParameterError

#: BLAS threads while fitting and predicting. The baselines' matrices are small (tens to
#: hundreds of columns); extra BLAS threads only contend: on a loaded two-core machine a
#: small mu-mlp fit spent over a minute in BLAS calls with the default thread pool and took
#: 14 s in all with one thread.
BLAS_THREADS = 1


class NotFitted(DataError):
    """A model asked to predict before it was fitted."""


class Predicting:
    """Prediction of a fitted audio-to-visual mapping (a mixin).

    Needs ``channels_``, ``fps_``, ``emotions_``, ``method`` and ``_predict(audio,
    sample_rate, times, emotion)`` returning motion at ``times`` (s), shape
    (len(times), n_channels).
    """

    method = ""

    def predict(self, audio: np.ndarray, sample_rate: int, *, emotion: str | None = None,
                n_frames: int | None = None) -> np.ndarray:
        """Motion for speech ``audio``.

        Parameters
        ----------
        audio : np.ndarray, shape (n_samples,)
            Mono speech: float in [-1, 1] or int16.
        sample_rate : int
            Hz.
        emotion : str, optional
            An emotion the model was trained on (methods without an expression model
            ignore it).
        n_frames : int, optional
            Frames to produce (default: the audio's duration at ``fps_``, rounded).

        Returns
        -------
        np.ndarray, shape (n_frames, n_channels), float64
            Motion in the training database's channels at ``fps_``.
        """
        from threadpoolctl import threadpool_limits

        if not hasattr(self, "channels_"):
            raise NotFitted(f"this {self.method or type(self).__name__} model is not fitted "
                            "yet: call fit first")
        audio = np.asarray(audio)
        if audio.ndim != 1:
            raise ParameterError(f"audio must be mono (n_samples,), got shape {audio.shape}")
        audio = (audio.astype(np.float32) / 32767.0 if audio.dtype == np.int16
                 else audio.astype(np.float32))
        if emotion is not None and emotion not in self.emotions_:
            raise ParameterError(f"emotion {emotion!r} was not in the training data "
                                 f"(it had {', '.join(self.emotions_)})")
        if n_frames is None:
            n_frames = int(round(len(audio) / sample_rate * self.fps_))
        if n_frames < 1:
            raise DataError("the audio is too short for one motion frame")
        with threadpool_limits(limits=BLAS_THREADS):
            out = self._predict(audio, int(sample_rate), frame_times(n_frames, self.fps_),
                                emotion)
        return np.asarray(out, dtype=np.float64)

    def _predict(self, audio: np.ndarray, sample_rate: int, times: np.ndarray,
                 emotion: str | None) -> np.ndarray:
        """Motion at ``times`` (s): shape (len(times), n_channels)."""
        raise NotImplementedError

    def _set_described(self, description: dict) -> None:
        """The fitted attributes common to all methods from a stored description
        (``channels``, ``groups``, ``kind``, ``fps``, ``emotions``)."""
        self.channels_ = tuple(description["channels"])
        self.groups_ = tuple(description["groups"])
        self.kind_ = description["kind"]
        self.fps_ = float(description["fps"])
        self.emotions_ = tuple(description["emotions"])

    def check_channels(self, names, where: str = "the database") -> None:
        """Raise DataError unless ``names`` are the channels the model was trained on."""
        names = tuple(names)
        if names != tuple(self.channels_):
            extra = sorted(set(names) - set(self.channels_))[:3]
            lacking = sorted(set(self.channels_) - set(names))[:3]
            raise DataError(
                f"the {self.method} model has {len(self.channels_)} channels and {where} "
                f"{len(names)}: they do not match (e.g. new {extra or 'none'}, missing "
                f"{lacking or 'none'}); refit the model on it")
