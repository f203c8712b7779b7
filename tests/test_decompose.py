"""PCA + FastICA decomposition and the learned low-pass cutoffs, on known answers."""

from __future__ import annotations

import numpy as np
import pytest

from db.errors import DataError, ParameterError
from ingest.decompose import MotionDecomposer, cutoff_frequencies
from ingest.motion import fill_gaps, interpolate, resample_motion


@pytest.fixture
def mixed(rng):
    t = np.linspace(0, 40, 4000)
    sources = np.c_[np.sign(np.sin(3 * t)), rng.laplace(size=t.size), np.sin(7 * t) ** 3]
    mixing = rng.normal(size=(3, 20))
    return sources, sources @ mixing + 1e-3 * rng.normal(size=(t.size, 20))


def test_recovers_known_independent_sources(mixed):
    sources, x = mixed
    model = MotionDecomposer(variance=0.999).fit(x)
    assert model.n_pcs_ == 3 and model.ica_converged_
    corr = np.abs(np.corrcoef(model.transform(x).T, sources.T)[:3, 3:])
    assert (corr.max(axis=1) > 0.99).all()  # each component is one source, up to sign/scale


def test_variance_kept_and_round_trips(mixed):
    _, x = mixed
    model = MotionDecomposer(variance=0.95).fit(x)
    assert model.explained_variance_ratio_.sum() >= 0.95
    u = model.fit_transform(x)
    np.testing.assert_allclose(u, model.transform(x), atol=1e-8)
    # All 20 components: 17 of them noise, on which FastICA never converges; the round trip
    # holds for any unmixing it stops at, and 20 iterations take 0.5 s, not 1,000's 15 s.
    full = MotionDecomposer(variance=1.0, max_iter=20).fit(x)
    np.testing.assert_allclose(full.inverse_transform(full.transform(x)), x, atol=1e-6)
    again = MotionDecomposer.from_arrays(model.to_arrays())
    np.testing.assert_array_equal(again.transform(x), model.transform(x))


def test_refuses_bad_input():
    with pytest.raises(DataError, match="NaN"):
        MotionDecomposer().fit(np.array([[0.0, np.nan]] * 5))
    with pytest.raises(ParameterError):
        MotionDecomposer(variance=1.5).fit(np.ones((10, 2)))


def test_cutoff_keeps_99_percent_of_energy():
    fps = 120.0
    t = np.arange(2400) / fps
    slow = np.sin(2 * np.pi * 2.0 * t)  # all of its energy at 2 Hz
    fast = np.sin(2 * np.pi * 20.0 * t)
    cut = cutoff_frequencies([np.c_[slow, fast][:1200], np.c_[slow, fast][1200:]], fps)
    assert 1.5 < cut[0] < 3.5 and 19.0 < cut[1] < 22.0


def test_fill_gaps_interpolates_and_marks():
    x = np.linspace(0, 1, 20)[:, None] * np.array([[1.0, 2.0]])
    holed = x.copy()
    holed[5:9, 0] = np.nan
    holed[0:2, 1] = np.nan
    filled, missing = fill_gaps(holed)
    np.testing.assert_allclose(filled[:, 0], x[:, 0], atol=1e-12)  # a line stays a line
    assert missing[5:9, 0].all() and missing.sum() == 6
    assert filled[0, 1] == filled[2, 1]  # held at the clip's edge
    with pytest.raises(DataError, match="lip.x is missing in every frame"):
        fill_gaps(np.full((4, 1), np.nan), ["lip.x"])


def test_resample_motion_keeps_duration():
    x = np.arange(30, dtype=float)[:, None]
    y = resample_motion(x, 30.0, 120.0)
    assert len(y) == 120 and y[4, 0] == pytest.approx(1.0)


@pytest.mark.parametrize("n_in, fps_in, fps", [(75, 25, 30), (40, 120, 50), (2, 30, 100),
                                               (1, 30, 25)])
def test_interpolate_is_np_interp_of_every_channel(n_in, fps_in, fps):
    """All channels at once, as np.interp one at a time: held at both ends, exact on the
    input's own times."""
    rng = np.random.default_rng(n_in)
    times_in, values = np.arange(n_in) / fps_in, rng.standard_normal((n_in, 9))
    times = np.arange(-3, int(n_in * fps / fps_in) + 4) / fps
    expected = np.stack([np.interp(times, times_in, col) for col in values.T], axis=1)
    np.testing.assert_allclose(interpolate(times_in, values, times), expected, rtol=0,
                               atol=1e-12)
    np.testing.assert_array_equal(interpolate(times_in, values, times_in), values)
