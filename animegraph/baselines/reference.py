"""Reference rows for lip-sync tables: the training mean pose and the audio's loudness.

Not published methods but the floor every lip-sync method must clear (issue 13): a system
that does not beat the *loudness* of the audio, mapped linearly onto the face, is not
doing lip-sync, and one that does not beat showing the *mean pose* adds nothing.

* :class:`MeanPose` -- every frame is the mean of the training motion.
* :class:`Loudness` -- the RMS envelope of the speech (:data:`RMS_WINDOW` windows at the
  motion's frame times, smoothed by a centred moving average of :data:`SMOOTH_SECONDS`),
  mapped to every channel by least squares on the training clips: motion ≈ a + b · env,
  per channel. Mouth opening then follows the loudness with the scale and offset the
  training mouth has.

Both follow the contract of :mod:`animegraph.baselines` (``fit`` on prepared clips,
``predict(audio, sample_rate, n_frames=...)``), but are not selectable by ``synth
--method``: they are yardsticks for ``scripts/eval_lipsync.py``.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from animegraph.baselines.base import BaselineModel, check_enough
from animegraph.baselines.data import RMS_WINDOW, SMOOTH_SECONDS, TrainingSet, rms_envelope
from db.errors import ParameterError

__all__ = ["RMS_WINDOW", "SMOOTH_SECONDS", "FeatureLine", "Loudness", "MeanPose",
           "rms_envelope"]

class MeanPose(BaselineModel):
    """Every frame the training motion's mean (a reference row, not a method)."""

    method: ClassVar[str] = "mean-pose"

    def _fit(self, data: TrainingSet) -> None:
        check_enough(data.n_frames, 1, "the mean pose")
        self.mean_ = np.mean(np.concatenate([c.motion for c in data.clips]), axis=0)

    def _predict(self, audio, sample_rate, times, emotion):
        return np.repeat(self.mean_[None], len(times), axis=0)

    def _arrays(self):
        return {"mean": self.mean_}

    def _restore(self, arrays):
        self.mean_ = arrays["mean"]


class FeatureLine(BaselineModel):
    """Motion as a per-channel affine function of per-frame features: motion ≈ a + B · w,
    fitted by least squares on the training clips (how the loudness and the peer tools'
    shape weights, :mod:`animegraph.baselines.peers`, are mapped onto the face)."""

    def _features(self, audio: np.ndarray, sample_rate: int, times: np.ndarray,
                  phones=None) -> np.ndarray:
        """Features of ``audio`` at ``times``: shape (len(times), n_features). ``phones``:
        a training clip's phone segments (None when predicting from audio alone)."""
        raise NotImplementedError

    def _fit(self, data: TrainingSet) -> None:
        w, motion = [], []
        for clip in data.clips:
            times = np.arange(clip.n_frames) / clip.fps
            w.append(self._features(clip.audio, clip.sample_rate, times, clip.phones))
            motion.append(clip.motion)
        x = np.concatenate(w)
        check_enough(len(x), x.shape[1] + 1, f"the {self.method} mapping")
        design = np.column_stack([np.ones(len(x)), x])
        self.coef_, *_ = np.linalg.lstsq(design, np.concatenate(motion), rcond=None)

    def _predict(self, audio, sample_rate, times, emotion):
        w = self._features(audio, sample_rate, times)
        return np.column_stack([np.ones(len(w)), w]) @ self.coef_  # (n_frames, n_channels)

    def _arrays(self):
        return {"coef": self.coef_}

    def _restore(self, arrays):
        self.coef_ = arrays["coef"]


class Loudness(FeatureLine):
    """Motion as a per-channel affine function of the speech's smoothed RMS envelope.

    Parameters
    ----------
    window : float
        RMS window (s), default :data:`RMS_WINDOW`.
    smooth : float
        Moving-average length (s), default :data:`SMOOTH_SECONDS`.
    """

    method: ClassVar[str] = "loudness"

    def __init__(self, window: float = RMS_WINDOW, smooth: float = SMOOTH_SECONDS):
        self.window = window
        self.smooth = smooth

    def _fit(self, data: TrainingSet) -> None:
        if not (self.window > 0 and self.smooth >= 0):
            raise ParameterError(f"window must be > 0 and smooth >= 0, got {self.window}, "
                                 f"{self.smooth}")
        super()._fit(data)

    def _features(self, audio, sample_rate, times, phones=None):
        return rms_envelope(audio, sample_rate, times, window=self.window,
                            smooth=self.smooth)[:, None]
