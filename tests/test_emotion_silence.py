"""The emotion features under digital silence: pauses of exact zeros (clean or noise-gated
speech) must describe the speech as a quiet noise floor does (the silence floor,
:mod:`ingest.emotion.features`)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import soundfile as sf

from db.errors import DataError
from ingest.emotion.classifier import EmotionClassifier
from ingest.emotion.classifier_arrays import CLASSIFIER_FORMAT
from ingest.emotion.features import block_features
from ingest.emotion.frames import SILENCE_FLOOR, frame_analysis

#: Samples below this are set to zero: a noise gate, well above the synthetic corpus'
#: noise floor (3e-4) and far below its speech.
GATE = 2e-3


def _clips(corpus, n=None):
    wavs = sorted((corpus / "clips").glob("*.wav"))[:n]
    return [(sf.read(w, dtype="float32")[0], json.loads(w.with_suffix(".json").read_text())
             ["emotion"]) for w in wavs]


def _gated(x: np.ndarray) -> np.ndarray:
    out = x.copy()
    out[np.abs(out) < GATE] = 0.0
    return out


@pytest.fixture(scope="module")
def clips(tiny_corpus):
    return _clips(tiny_corpus)


def test_gated_pauses_have_the_noise_floor_features(clips, tiny_config):
    """The functionals of a clip with its pauses gated to exact zeros stay close to the
    clip's own, in standard deviations over the corpus (measured: median 0.03, 95th
    percentile 0.25, log energy 0.03; before the floor 0.25, 8 and 38: the 10th percentile
    of the log energy is the pause level)."""
    sr = tiny_config.sample_rate

    def functionals(x):
        f = block_features(x, sr, "rich+cepstrum")
        return np.concatenate([f["rich"], f["cepstrum"]])

    noisy = np.vstack([functionals(x) for x, _ in clips])
    spread = noisy.std(axis=0)
    spread[spread == 0] = 1.0
    for (x, _), f in list(zip(clips, noisy, strict=True))[:6]:
        assert np.count_nonzero(_gated(x) == 0) > 0.1 * x.size  # the pauses are zeros
        moved = np.abs(functionals(_gated(x)) - f) / spread
        assert np.median(moved) < 0.05
        assert np.percentile(moved, 95) < 0.5, np.argsort(-moved)[:5]
        assert moved[80:86].max() < 0.1  # the log energy's statistics


def test_silent_frames_are_the_floor(tiny_config, clips):
    from ingest.emotion.audio import prepare_audio

    x = prepare_audio(_gated(clips[0][0]), tiny_config.sample_rate)
    fr = frame_analysis(x)
    spec, silent = fr["spec"], fr["silent"]
    assert 0 < silent.mean() < 0.6
    floor = np.mean(spec[:, ~silent] ** 2, axis=0).max() * 10 ** (-SILENCE_FLOOR / 10)
    np.testing.assert_allclose(spec[:, silent] ** 2, floor, rtol=1e-4)
    assert spec.min() >= np.sqrt(floor) * (1 - 1e-6)  # speech's valleys floored too
    legacy = frame_analysis(x, None)
    assert not legacy["silent"].any()
    assert np.all(np.mean(legacy["spec"][:, silent] ** 2, axis=0) < floor)


def test_classifier_gated_speech_as_its_own_emotion(clips, tiny_config):
    """A classifier fitted on the corpus (pauses with a noise floor) gives a clip with gated
    pauses the class and probabilities it gives the clip."""
    sr = tiny_config.sample_rate
    audio = [(x, sr) for x, _ in clips]
    labels = np.array([e for _, e in clips])
    model = EmotionClassifier(features="rich+cepstrum", probability=True,
                              calibration_cv=2).fit(audio, labels)
    test = audio[::5]
    gated = [(_gated(x), sr) for x, _ in test]
    np.testing.assert_array_equal(model.predict(gated), model.predict(test))
    np.testing.assert_allclose(model.predict_proba(gated), model.predict_proba(test),
                               atol=0.05)


def test_silence_floor_stored_and_older_formats_read_without_it(clips, tiny_config, caplog):
    sr = tiny_config.sample_rate
    audio = [(x, sr) for x, _ in clips]
    labels = np.array([e for _, e in clips])
    model = EmotionClassifier(features="rich").fit(audio, labels)
    arrays = model.to_arrays()
    assert int(arrays["format"]) == CLASSIFIER_FORMAT == 7
    assert float(arrays["silence_floor"]) == SILENCE_FLOOR
    assert EmotionClassifier.from_arrays(arrays).silence_floor == SILENCE_FLOOR
    # fitted with silence_floor=None: stored without it, read back as None
    none = EmotionClassifier(features="rich", silence_floor=None).fit(audio, labels)
    assert "silence_floor" not in none.to_arrays()
    assert EmotionClassifier.from_arrays(none.to_arrays()).silence_floor is None
    # a format-5 classifier was fitted without the floor: it keeps its features, warned
    old = {**none.to_arrays(), "format": np.array(5)}
    with caplog.at_level("WARNING"):
        back = EmotionClassifier.from_arrays(old)
    assert back.silence_floor is None and "silence floor" in caplog.text
    np.testing.assert_array_equal(back.featurize(audio[:2]), none.featurize(audio[:2]))
    with pytest.raises(DataError, match="silence_floor"):
        EmotionClassifier.from_arrays({**arrays, "silence_floor": np.array(np.nan)})


def test_a_classifier_from_before_the_floor_is_learnt_again_by_the_next_ingest():
    """``stored_model_current`` decides it, for ingest (learn the model again from the
    stored clips) and for the default database (brought up to date on first use)."""
    from ingest.emotion.classifier_arrays import SILENCE_FLOOR_FORMAT
    from ingest.emotion.model import stored_model_current

    def manifest(classifier):
        return {"emotion": {"emotions": ["happy", "sad"], "classifier": classifier}}

    assert not stored_model_current({})  # before emotion models
    assert stored_model_current(manifest(None))  # one emotion: no classifier to refit
    assert not stored_model_current(manifest({"kernel": "linear"}))  # before the format
    assert not stored_model_current(manifest({"format": SILENCE_FLOOR_FORMAT - 1}))
    assert stored_model_current(manifest({"format": SILENCE_FLOOR_FORMAT}))


def test_ingest_writes_its_classifiers_format_in_the_manifest(tiny_db):
    from db.store import Database
    from ingest.emotion.model import stored_model_current

    manifest = Database.open(tiny_db[0]).manifest
    if manifest["emotion"].get("classifier"):
        assert manifest["emotion"]["classifier"]["format"] == CLASSIFIER_FORMAT
    assert stored_model_current(manifest)
