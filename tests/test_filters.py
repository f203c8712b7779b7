"""The NumPy filters that replace scipy.signal in synthesis give SciPy's output."""

import numpy as np
import pytest
import scipy.fft
import scipy.signal as ss

from db.errors import ParameterError
from ingest import lowpass
from ingest.filters import butter_lowpass, lfilter, sosfiltfilt
from ingest.speech import features


@pytest.mark.parametrize("order", [2, 4, 6])
@pytest.mark.parametrize("cutoff", [0.01, 0.05, 0.3, 0.77, 0.98])
def test_butter_sections_equal_scipys(order, cutoff):
    np.testing.assert_allclose(butter_lowpass(order, cutoff),
                               ss.butter(order, cutoff, output="sos"), rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("order", [1, 2, 3, 4, 5])
def test_zero_phase_filter_equals_scipys(order, rng):
    x = rng.normal(size=(400, 6)).cumsum(axis=0)
    cutoffs = rng.uniform(0.02, 0.9, size=6)
    sos = np.stack([butter_lowpass(order, c) for c in cutoffs], axis=2)
    ours = sosfiltfilt(sos, x)
    theirs = np.stack([ss.sosfiltfilt(ss.butter(order, c, output="sos"), x[:, k])
                       for k, c in enumerate(cutoffs)], axis=1)
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-10 * np.abs(x).max())
    shared = sosfiltfilt(butter_lowpass(order, 0.2), x)  # one filter for every column
    np.testing.assert_allclose(shared, ss.sosfiltfilt(ss.butter(order, 0.2, output="sos"), x,
                                                      axis=0),
                               rtol=0, atol=1e-10 * np.abs(x).max())


def test_smooth_equals_the_scipy_smoothing_it_replaces(rng):
    fps = 120.0
    motion = rng.normal(size=(300, 5)).cumsum(axis=0)
    cutoffs = np.array([1.0, 7.5, 59.9, 0.0, 20.0])  # 59.9: within 1 % of Nyquist, passes
    expected = motion.copy()
    for k, cut in enumerate(cutoffs):
        if 0 < cut < 0.99 * fps / 2:
            sos = ss.butter(lowpass.SMOOTHING_ORDER, cut / (fps / 2), output="sos")
            expected[:, k] = ss.sosfiltfilt(sos, motion[:, k])
    np.testing.assert_allclose(lowpass.smooth(motion, cutoffs, fps), expected, rtol=0,
                               atol=1e-10 * np.abs(motion).max())
    short = motion[:10]
    np.testing.assert_array_equal(lowpass.smooth(short, cutoffs, fps), short)


def test_smooth_designs_each_set_of_cutoffs_once_and_filters_as_designed_anew(rng):
    # The sections are kept per set of cutoffs (a live stream smooths every window with
    # the same ones): the output is that of the filters designed on the call, bit for
    # bit, for float64 and float32 cutoffs alike, and a new set is designed anew.
    fps = 60.0
    motion = rng.normal(size=(50, 3)).cumsum(axis=0)
    for cutoffs in (np.array([2.0, 5.5, 11.0]), np.array([2.0, 5.5, 11.0], np.float32),
                    np.array([3.0, 5.5, 11.0])):
        sos = np.stack([butter_lowpass(lowpass.SMOOTHING_ORDER, c / (fps / 2))
                        for c in cutoffs], axis=2)
        for _ in range(2):  # designed, then taken from the cache
            np.testing.assert_array_equal(lowpass.smooth(motion, cutoffs, fps),
                                          sosfiltfilt(sos, motion))
    assert lowpass._sections.cache_info().hits >= 3


def test_lfilter_equals_scipys(rng):
    b = -np.array([-2.0, -1.0, 0.0, 1.0, 2.0]) / 10
    a = np.array([1.0, -0.94])
    x = rng.normal(size=(200, 7))
    zi = rng.normal(size=(4, 7))
    ours, our_state = lfilter(b, a, x, zi)
    theirs, their_state = ss.lfilter(b, a, x, axis=0, zi=zi)
    np.testing.assert_allclose(ours, theirs, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(our_state, their_state, rtol=1e-13, atol=1e-13)
    ours, _ = lfilter([0.5, 0.25], [2.0, -0.5, 0.1], x, np.zeros((2, 7)))
    theirs, _ = ss.lfilter([0.5, 0.25], [2.0, -0.5, 0.1], x, axis=0, zi=np.zeros((2, 7)))
    np.testing.assert_allclose(ours, theirs, rtol=1e-13, atol=1e-13)


def test_rasta_plp_equals_its_scipy_form(rng, monkeypatch):
    """The features as computed with scipy.signal.lfilter and scipy.fft before."""
    audio = (0.1 * rng.normal(size=16000)).astype(np.float32)
    ours = features.rasta_plp(audio, 16000)

    def scipy_lfilter(b, a, x, zi):
        return ss.lfilter(b, a, x, axis=0, zi=zi)

    monkeypatch.setattr(features, "lfilter", scipy_lfilter)
    monkeypatch.setattr(features.np.fft, "rfft", scipy.fft.rfft)
    monkeypatch.setattr(features.np.fft, "irfft", scipy.fft.irfft)
    theirs = features.rasta_plp(audio, 16000)
    np.testing.assert_allclose(ours, theirs, rtol=1e-9, atol=1e-9)


def test_bad_filter_arguments_are_parameter_errors():
    with pytest.raises(ParameterError, match="order"):
        butter_lowpass(0, 0.5)
    with pytest.raises(ParameterError, match="cutoff"):
        butter_lowpass(2, 1.0)
    with pytest.raises(ParameterError, match="more than 9"):
        sosfiltfilt(butter_lowpass(2, 0.5), np.zeros((9, 1)))
    with pytest.raises(ParameterError, match="zi"):
        lfilter([1.0, 1.0], [1.0], np.zeros((5, 2)), np.zeros((2, 2)))
