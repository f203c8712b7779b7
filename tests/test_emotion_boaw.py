"""Speed perturbation and bag-of-audio-words for emotion from speech (issue #16, third
session)."""

from __future__ import annotations

import numpy as np
import pytest

from db.errors import ParameterError
from ingest.emotion.audio import speed_perturb
from ingest.emotion.boaw import N_DESCRIPTORS, BagOfAudioWords, frame_descriptors

SR = 16000


def _voice(rng, f0=150.0, seconds=1.0):
    t = np.arange(int(seconds * SR)) / SR
    x = sum(np.sin(2 * np.pi * k * f0 * t) / k for k in range(1, 6))
    return 0.3 * x / np.abs(x).max() + 0.01 * rng.standard_normal(t.size)


def _peak_hz(x):
    return np.abs(np.fft.rfft(x)).argmax() * SR / x.size


def test_speed_perturbation_moves_tempo_and_pitch_together(rng):
    x = _voice(rng)
    slow, fast = speed_perturb(x, SR, 0.9), speed_perturb(x, SR, 1.1)
    assert slow.size == np.ceil(x.size / 0.9) and fast.size == np.ceil(x.size / 1.1)
    assert _peak_hz(slow) == pytest.approx(0.9 * 150, abs=2)
    assert _peak_hz(fast) == pytest.approx(1.1 * 150, abs=2)
    stereo = np.stack([x, x], axis=1)
    np.testing.assert_allclose(speed_perturb(stereo, float(SR), 1.0), x)
    i16 = np.round(x * 32767).astype(np.int16)
    np.testing.assert_allclose(speed_perturb(i16, SR, 0.9), slow, atol=1e-3)
    for bad in (0.2, 3, True, "fast"):
        with pytest.raises(ParameterError, match="factor"):
            speed_perturb(x, SR, bad)


def test_frame_descriptors_hold_mfccs_energy_and_f0(rng):
    d = frame_descriptors(_voice(rng, f0=200.0), SR)
    assert d.shape == (101, 2 * N_DESCRIPTORS) and np.all(np.isfinite(d))
    semitones = d[10:-10, N_DESCRIPTORS - 1]  # F0 of the voiced middle frames
    assert np.median(semitones) == pytest.approx(12 * np.log2(200 / 27.5), abs=0.5)
    assert np.allclose(d[10:-10, -1], 0, atol=0.2)  # a steady tone: F0 delta near 0


def test_bag_of_audio_words_counts_nearest_words(rng):
    low = [frame_descriptors(_voice(rng, f0=110.0), SR) for _ in range(3)]
    high = [frame_descriptors(_voice(rng, f0=260.0), SR) for _ in range(3)]
    bag = BagOfAudioWords(size=20, assignments=3).fit(low + high)
    H = bag.transform(low + high)
    assert H.shape == (6, 40) and np.all(H >= 0)
    # every frame counts 3 words per codebook: sum of 10**H - 1 is 3 x frames per second
    rate = (10 ** H[0, :20] - 1).sum()
    assert rate == pytest.approx(3 / 0.01)
    # two voices use different words: same-voice histograms are closer
    dist = np.linalg.norm(H[:, None] - H[None], axis=2)
    assert dist[0, 1] < dist[0, 4] and dist[3, 4] < dist[3, 1]
    arrays = bag.to_arrays()
    assert arrays["boaw_codebook0"].shape == (20, N_DESCRIPTORS)
    with pytest.raises(ParameterError, match="assignments"):
        BagOfAudioWords(size=5, assignments=6).fit(low)
    with pytest.raises(ParameterError, match="training frames"):
        BagOfAudioWords(size=1000).fit(low[:1])
