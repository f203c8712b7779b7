"""Boundary refinement (ingest.speech.refine): the spectral change computed near the
boundaries only is the whole recording's there."""

import numpy as np

from ingest.speech.refine import REFINE_WINDOW, _spectral_change, refine_onsets


def _speechlike(seconds: float = 2.0, rate: int = 16000) -> np.ndarray:
    """Int16 audio whose spectrum changes every 137 ms (tones and noise bursts)."""
    rng = np.random.default_rng(3)
    t = np.arange(int(seconds * rate)) / rate
    part = (t // 0.137).astype(int)
    tone = np.sin(2 * np.pi * (200 + 170 * (part % 7)) * t)
    noise = rng.normal(0, 0.3, t.size) * (part % 3 == 0)
    return np.round(8000 * (tone + noise)).astype(np.int16)


def test_change_near_boundaries_equals_the_whole():
    samples = _speechlike()
    whole = _spectral_change(samples)
    near = np.array([-5, 0, 1, 2, 40, 41, 300, len(whole) - 2, len(whole) + 9])
    local = _spectral_change(samples, near)
    assert local.shape == whole.shape
    inside = np.unique(np.clip(near, 2, len(whole) - 3))
    np.testing.assert_allclose(local[inside], whole[inside], rtol=1e-12, atol=0)
    others = np.setdiff1d(np.arange(len(whole)), inside)
    assert not local[others].any()


def test_refined_onsets_move_to_the_largest_change_near_them():
    samples = _speechlike()
    onsets = [("SIL", 0.0), ("AA", 0.14), ("B", 0.41), ("SIL", 1.1)]
    refined = refine_onsets(onsets, samples, REFINE_WINDOW)
    whole = _spectral_change(samples)
    hop = 40 / 16000
    for (_, before), (_, after) in zip(onsets[1:], refined[1:], strict=True):
        centre, reach = round(before / hop), round(REFINE_WINDOW / hop)
        window = whole[centre - reach: centre + reach + 1]
        assert abs(after - before) <= REFINE_WINDOW + 1e-9
        assert np.isclose(whole[round(after / hop)], window.max())
