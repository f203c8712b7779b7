"""Reference rows of the lip-sync tables (animegraph.baselines.reference): the training
mean pose and the audio's loudness mapped onto the face (issue 13)."""

from __future__ import annotations

import numpy as np
import pytest

from animegraph.baselines.reference import Loudness, MeanPose, rms_envelope
from animegraph.motion import measures
from db.errors import ParameterError
from db.store import Database
from ingest.tables import prepared_from_database


@pytest.fixture(scope="module")
def split(tiny_db):
    clips = prepared_from_database(Database.open(tiny_db[0]))
    held = sorted({c.sentence_id for c in clips})[0]
    return ([c for c in clips if c.sentence_id != held],
            [c for c in clips if c.sentence_id == held])


def test_rms_envelope_measures_loudness():
    rate = 16000
    t = np.arange(rate) / rate
    audio = np.where(t < 0.5, 0.0, 0.4 * np.sin(2 * np.pi * 200 * t))
    times = np.arange(0, 1.0, 0.01)
    env = rms_envelope(audio, rate, times)
    assert env.shape == times.shape
    np.testing.assert_allclose(env[times < 0.4], 0.0, atol=1e-12)
    np.testing.assert_allclose(env[times > 0.6], 0.4 / np.sqrt(2), rtol=0.02)
    assert np.all(np.diff(env[(times > 0.4) & (times < 0.6)]) >= -1e-12)  # a smooth rise


def test_mean_pose_and_loudness(split):
    train, test = split
    mean = MeanPose().fit(train)
    loud = Loudness().fit(train)
    truth_mean = np.concatenate([c.motion for c in train]).mean(axis=0)
    names, kind = test[0].schema.names, test[0].schema.kind
    rs = []
    for clip in test:
        n = len(clip.motion)
        flat = mean.predict(clip.audio, clip.sample_rate, n_frames=n)
        np.testing.assert_allclose(flat, np.broadcast_to(truth_mean, flat.shape), atol=1e-3)
        pred = loud.predict(clip.audio, clip.sample_rate, n_frames=n)
        assert pred.shape == clip.motion.shape and np.isfinite(pred).all()
        rs.append(measures.pearson(measures.mouth_opening(pred, names, kind),
                                   measures.mouth_opening(clip.motion, names, kind)))
    # loud speech opens the mouth: the envelope follows the recorded mouth opening
    assert np.mean(rs) > 0.3
    # silence gives the training face at rest (the intercept), no NaN
    quiet = loud.predict(np.zeros(16000, dtype=np.float32), 16000)
    np.testing.assert_allclose(quiet, np.broadcast_to(loud.coef_[0], quiet.shape))
    with pytest.raises(ParameterError):
        Loudness(window=0).fit(train)
