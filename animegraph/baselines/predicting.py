"""What every fitted baseline does at prediction time, NumPy only (no scikit-learn).

:class:`Predicting` holds :meth:`~Predicting.predict` (input checks, frame times, the
method's ``_predict``) and :meth:`~Predicting.check_channels`. The estimators
(:class:`animegraph.baselines.base.BaselineModel`) inherit it, and so do the stored
models restored without scikit-learn for a one-shot ``synth``
(:class:`animegraph.baselines.mu_mlp_forward.StoredMuMlp`).
"""

from __future__ import annotations

import functools

import numpy as np

from animegraph.baselines.data import frame_times
from db.errors import DataError, ParameterError

#: BLAS threads while fitting and predicting. The baselines' matrices are small (tens to
#: hundreds of columns); extra BLAS threads only contend: on a loaded two-core machine a
#: small mu-mlp fit spent over a minute in BLAS calls with the default thread pool and took
#: 14 s in all with one thread.
BLAS_THREADS = 1


#: The largest frame rate (Hz) and count (frames averaged, iterations) a *stored* model's
#: settings may ask for. A stored description is someone else's data: a feature rate of
#: 10**9 Hz or an inversion of 10**12 iterations is a hang, not a model (motion is
#: captured at 24-240 fps; the papers iterate tens of times).
MAX_STORED_RATE = 1000.0
MAX_STORED_COUNT = 10_000


def check_stored_setting(name: str, value: object, high: float) -> None:
    """ValueError unless a stored setting is a finite number in (0, ``high``]."""
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating) \
            or not (np.isfinite(value) and 0 < value <= high):
        raise ValueError(f"its {name} {value!r} is not in (0, {high:g}]")


def implausible(method: str, where: str, exc: Exception) -> DataError:
    """The one-line error of a stored ``method`` model whose arrays do not work."""
    return DataError(f"stored {method} model {where} is implausible ({exc}); "
                     f"'animegraph fit --method {method}' fits it again")


@functools.lru_cache(maxsize=1)
def threadpools():
    """The process' thread pools (BLAS, OpenMP), found once: finding them walks the loaded
    libraries (about 20 ms a time, which a live stream predicting ten times a second
    would pay on every update)."""
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


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
        with threadpools().limit(limits=BLAS_THREADS):
            try:
                out = self._predict(audio, int(sample_rate),
                                    frame_times(n_frames, self.fps_), emotion)
            except (ValueError, IndexError, KeyError, TypeError) as exc:
                if not getattr(self, "restored_from_", None):
                    raise
                # Arrays from someone else's database that the dry run of
                # check_restored did not reach (e.g. a cluster no noise frame falls in).
                raise implausible(self.method, self.restored_from_, exc) from exc
        return np.asarray(out, dtype=np.float64)

    def check_restored(self, where: str) -> None:
        """A dry run of a model restored from stored arrays (someone else's database):
        half a second of fixed noise in every emotion must give finite motion of the
        model's channels. DataError naming ``where`` if not, so that arrays that do not
        fit together are one line when read; and a later :meth:`predict` that fails on
        them is one line too."""
        self.restored_from_ = where  # predict's errors are then the arrays' (one line)
        noise = np.random.default_rng(0).normal(0.0, 0.1, 8000).astype(np.float32)
        try:
            with np.errstate(all="ignore"):  # e.g. a zero spread: said once, below
                for emotion in (None, *self.emotions_):
                    out = self.predict(noise, 16000, emotion=emotion)
                    if out.shape[1:] != (len(self.channels_),) or not np.isfinite(out).all():
                        raise ValueError("its motion is not finite motion of its channels")
        except (ValueError, IndexError, KeyError, TypeError, FloatingPointError) as exc:
            raise implausible(self.method, where, exc) from exc

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


class Stored(Predicting):
    """A stored model restored for prediction alone, without scikit-learn (a mixin beside
    the method's prediction half): :meth:`from_arrays` checks the method, sets the
    hyper-parameters prediction needs (``_set_params``), the described attributes and the
    learned arrays."""

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray], description: dict):
        """The model of ``arrays`` and its ``description`` (method, params, channels,
        groups, kind, fps, emotions), as :func:`animegraph.baselines.base.save_model`
        wrote them.

        Raises
        ------
        KeyError, ValueError, TypeError
            On a description or arrays that do not hold a model of this method.
        """
        if description.get("method") != cls.method:
            raise ValueError(f"stored model is {description.get('method')!r}, not {cls.method}")
        self = cls()
        self._set_params(description["params"])
        self._set_described(description)
        self._restore(dict(arrays))
        return self

    def _set_params(self, params: dict) -> None:
        """The stored hyper-parameters that prediction needs."""
        raise NotImplementedError
