"""Reference rows of an evaluation, below which no speech-driven method should fall.

- :class:`MeanPose`: the training motion's mean frame, whatever is said (the error of
  not moving at all; its mouth-opening correlation is undefined).
- :class:`LoudnessLine`: each channel a straight line of the audio's loudness (RMS in
  dB at each motion frame, floored 50 dB below the clip's peak:
  :func:`ingest.readers.sync.audio_envelope`), fitted by least squares on the training
  clips: a mouth that opens with the volume.

They follow the baselines' estimator contract (:class:`.base.BaselineModel`) so that an
evaluation scores them like any baseline; they are not synthesis methods and are not in
:data:`animegraph.baselines.ESTIMATORS`.
"""

from __future__ import annotations

import numpy as np

from animegraph.baselines.base import BaselineModel
from animegraph.baselines.data import TrainingSet
from db.errors import DataError
from ingest.readers.sync import FLOOR_DB, audio_envelope


def loudness_db(audio: np.ndarray, sample_rate: int, times: np.ndarray) -> np.ndarray:
    """Loudness (dB, floored :data:`FLOOR_DB` below the peak) at ``times`` (s), shape
    (len(times),); ``times`` evenly spaced from 0."""
    fps = 1.0 / (times[1] - times[0]) if len(times) > 1 else 100.0
    rms = audio_envelope(audio, sample_rate, fps, len(times))
    db = 20.0 * np.log10(rms + 1e-10)
    return np.maximum(db, db.max() - FLOOR_DB)


class MeanPose(BaselineModel):
    """The mean training frame for every frame."""

    method = "mean-pose"

    def _fit(self, data: TrainingSet) -> None:
        self.mean_ = np.nanmean(np.concatenate([c.motion for c in data.clips]), axis=0)

    def _predict(self, audio, sample_rate, times, emotion):
        return np.tile(self.mean_, (len(times), 1))

    def _arrays(self):
        return {"mean": self.mean_}

    def _restore(self, arrays):
        self.mean_ = arrays["mean"]


class LoudnessLine(BaselineModel):
    """Every channel a least-squares line of the audio loudness (dB)."""

    method = "loudness"

    def _fit(self, data: TrainingSet) -> None:
        x, y = [], []
        for clip in data.clips:
            times = np.arange(clip.n_frames) / clip.fps
            x.append(loudness_db(clip.audio, clip.sample_rate, times))
            y.append(clip.motion)
        db, motion = np.concatenate(x), np.concatenate(y)
        keep = np.isfinite(motion).all(axis=1)
        if keep.sum() < 2 or np.ptp(db[keep]) == 0:
            raise DataError("too little data for a loudness line: the audio never changes")
        design = np.stack([np.ones(keep.sum()), db[keep]], axis=1)
        self.coef_, *_ = np.linalg.lstsq(design, motion[keep], rcond=None)  # (2, n_channels)

    def _predict(self, audio, sample_rate, times, emotion):
        db = loudness_db(audio, sample_rate, times)
        return np.stack([np.ones(len(db)), db], axis=1) @ self.coef_

    def _arrays(self):
        return {"coef": self.coef_}

    def _restore(self, arrays):
        self.coef_ = arrays["coef"]
