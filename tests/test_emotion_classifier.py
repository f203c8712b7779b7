"""Emotion classification (Cao et al. 2005, §6): cepstrum, features, classifier, EmoDB."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import require_shared
from sklearn.base import clone
from sklearn.exceptions import NotFittedError

from db.errors import DataError, ParameterError
from ingest.emotion.audio import LEVEL_PERCENTILE
from ingest.emotion.classifier import (
    EMODB_EMOTIONS,
    EmotionClassifier,
    emotion_features,
    load_emodb,
    real_cepstrum,
    rich_features,
)

SR = 16000


# ----------------------------------------------------------------- real cepstrum
def test_cepstrum_of_impulse_is_log_gain_only():
    x = np.zeros(4096)
    x[0] = 3.0  # flat magnitude spectrum |X| = 3
    c = real_cepstrum(x)
    assert c.shape == (4096,)
    assert c[0] == pytest.approx(np.log(3.0))
    np.testing.assert_allclose(c[1:], 0.0, atol=1e-12)


def test_cepstrum_of_two_impulses_has_known_series():
    # log(1 + a e^{-jwd}) = a e^{-jwd} - a^2/2 e^{-2jwd} + ... is the complex cepstrum;
    # the real cepstrum is its even part: c[d] = a/2, c[2d] = -a^2/4, c[3d] = a^3/6.
    a, d = 0.5, 100
    x = np.zeros(8192)
    x[0], x[d] = 1.0, a
    c = real_cepstrum(x)
    assert c[d] == pytest.approx(a / 2, abs=1e-9)
    assert c[2 * d] == pytest.approx(-a * a / 4, abs=1e-9)
    assert c[3 * d] == pytest.approx(a**3 / 6, abs=1e-9)
    off = np.ones(c.size // 2, bool)
    off[::d] = False
    assert np.abs(c[: c.size // 2][off]).max() < 1e-9


def test_echo_gives_cepstral_peak_at_delay(rng):
    delay = 137  # samples at 16 kHz
    s = rng.standard_normal(SR)
    x = s.copy()
    x[delay:] += 0.6 * s[:-delay]
    f = emotion_features(x, SR, n_cepstrum=500)
    ceps = f[3:]
    assert 20 + np.argmax(ceps[20:]) == delay


# ----------------------------------------------------------------- features
def test_feature_shape_stats_and_resampling(rng):
    x = 0.1 + 0.3 * rng.standard_normal(SR)
    f = emotion_features(x, SR)
    assert f.shape == (503,) and np.all(np.isfinite(f))
    level = np.percentile(np.abs(x), LEVEL_PERCENTILE)  # the level is normalised first
    assert f[0] == pytest.approx(x.mean() / level)
    assert f[1] == pytest.approx(x.var() / level**2)
    assert f[2] == pytest.approx(np.sqrt(np.mean(x**2)) / level)
    assert emotion_features(x, SR, n_cepstrum=50).shape == (53,)
    fr = emotion_features(x, SR, n_cepstrum=1000, cepstrum="frames")
    assert fr.shape == (1003,) and np.all(np.isfinite(fr))
    # Resampling: a 440 Hz tone at 44.1 kHz and at 16 kHz give nearly the same cepstrum.
    t16, t44 = np.arange(SR) / SR, np.arange(44100) / 44100
    a = emotion_features(np.sin(2 * np.pi * 440 * t16), SR, n_cepstrum=100, cepstrum="frames")
    b = emotion_features(np.sin(2 * np.pi * 440 * t44), 44100, n_cepstrum=100,
                         cepstrum="frames")
    assert np.corrcoef(a[3:], b[3:])[0, 1] > 0.99


def test_rich_features_shape(rng):
    t = np.arange(SR) / SR
    x = np.sin(2 * np.pi * 150 * t) * (1 + 0.5 * np.sin(2 * np.pi * 3 * t))
    f = rich_features(x + 0.01 * rng.standard_normal(SR), SR)
    assert f.shape == (121,) and np.all(np.isfinite(f))


@pytest.mark.parametrize("func", [emotion_features, rich_features])
def test_feature_errors(func, rng):
    with pytest.raises(DataError, match="too short"):
        func(rng.standard_normal(int(0.2 * SR)), SR)
    with pytest.raises(DataError, match="silence"):
        func(np.zeros(SR), SR)
    with pytest.raises(DataError, match="NaN"):
        func(np.full(SR, np.nan), SR)
    with pytest.raises(ParameterError, match="n_channels"):
        func(rng.standard_normal((2, SR)), SR)
    with pytest.raises(ParameterError, match="sample_rate"):
        func(rng.standard_normal(SR), 0)


def test_feature_parameter_errors(rng):
    x = rng.standard_normal(SR)
    with pytest.raises(ParameterError, match="n_cepstrum"):
        emotion_features(x, SR, n_cepstrum=0)
    with pytest.raises(ParameterError, match="n_cepstrum"):
        emotion_features(x, SR, n_cepstrum=2000, cepstrum="frames")
    with pytest.raises(ParameterError, match="cepstrum"):
        emotion_features(x, SR, cepstrum="mel")


def test_features_do_not_depend_on_the_callers_blas_threads(rng):
    # Ingest's workers run with the cores shared out, classify and a refit with all of them:
    # OpenBLAS rounds a float32 product differently with another thread count (the mel
    # filterbank's), so the features (and the stored classifier) would follow the machine
    # (ingest.emotion.frames.BLAS_THREADS).
    from threadpoolctl import threadpool_limits

    t = np.arange(4 * SR) / SR
    x = sum(np.sin(2 * np.pi * k * 120 * t) / k for k in range(1, 8)) * (1 + 0.5 * np.sin(
        2 * np.pi * 3 * t)) + 0.05 * rng.standard_normal(t.size)
    pcm = np.round(0.3 * x / np.abs(x).max() * 32767).astype(np.int16)
    model = EmotionClassifier()  # the database's features: functionals and frame descriptors
    described = []
    for threads in (1, 2, 4):
        with threadpool_limits(limits=threads, user_api="blas"):
            described.append(model.describe([(pcm, SR)]))
    for other in described[1:]:
        np.testing.assert_array_equal(described[0].functionals, other.functionals)
        np.testing.assert_array_equal(described[0].frames[0], other.frames[0])


# ----------------------------------------------------------------- classifier
def _toy_corpus(rng, per_class=12):
    """Three separable 'emotions': low voice-like buzz, high buzz, breathy noise."""
    clips, labels = [], []
    for label in ("low", "high", "noise"):
        for _ in range(per_class):
            n = int(SR * rng.uniform(0.5, 0.8))
            t = np.arange(n) / SR
            if label == "noise":
                x = rng.standard_normal(n)
            else:
                f0 = rng.uniform(90, 130) if label == "low" else rng.uniform(260, 340)
                x = sum(np.sin(2 * np.pi * k * f0 * t) / k for k in range(1, 8))
                x = x + 0.05 * rng.standard_normal(n)
            clips.append((rng.uniform(0.05, 0.5) * x / np.abs(x).max(), SR))
            labels.append(label)
    return clips, np.array(labels)


@pytest.fixture(scope="module")
def toy():
    rng = np.random.default_rng(7)
    train = _toy_corpus(rng)
    test = _toy_corpus(rng, per_class=6)
    return train, test


def test_classifier_learns_toy_problem(toy):
    (Xtr, ytr), (Xte, yte) = toy
    model = EmotionClassifier.paper(n_cepstrum=100, probability=True)
    assert model.fit(Xtr, ytr) is model
    assert list(model.classes_) == ["high", "low", "noise"]
    assert model.n_features_in_ == 103
    assert model.score(Xte, yte) >= 0.9
    proba = model.predict_proba(Xte)
    assert proba.shape == (len(Xte), 3)
    np.testing.assert_allclose(proba.sum(axis=1), 1.0)
    assert (model.classes_[proba.argmax(1)] == yte).mean() >= 0.9


def test_classifier_feature_matrix_and_round_trip(toy, tmp_path):
    (Xtr, ytr), (Xte, yte) = toy
    Ftr = np.vstack([emotion_features(a, sr, n_cepstrum=50) for a, sr in Xtr])
    Fte = np.vstack([emotion_features(a, sr, n_cepstrum=50) for a, sr in Xte])
    for kernel, weight in (("linear", None), ("rbf", None), ("linear", "balanced")):
        model = EmotionClassifier.paper(n_cepstrum=50, kernel=kernel, class_weight=weight,
                                        probability=True).fit(Ftr, ytr)
        np.testing.assert_array_equal(model.predict(Fte), model.predict(Xte))
        np.savez(tmp_path / "m.npz", **model.to_arrays())
        with np.load(tmp_path / "m.npz", allow_pickle=False) as z:
            back = EmotionClassifier.from_arrays(z)
        assert back.get_params() == model.get_params()
        np.testing.assert_array_equal(back.predict(Fte), model.predict(Fte))
        np.testing.assert_array_equal(back.decision_function(Fte), model.decision_function(Fte))
        np.testing.assert_allclose(back.predict_proba(Fte), model.predict_proba(Fte),
                                   rtol=0, atol=1e-12)


def test_class_weight(toy):
    # "balanced" scales C per class by its rarity: on a set with one rare class the SVM
    # changes; an old stored model without the array is unweighted.
    (Xtr, ytr), _ = toy
    F = np.vstack([emotion_features(a, sr, n_cepstrum=50) for a, sr in Xtr])
    keep = (ytr != "noise") | (np.cumsum(ytr == "noise") <= 3)  # 3 noise, 12 + 12 others
    plain = EmotionClassifier.paper(n_cepstrum=50, C=0.01).fit(F[keep], ytr[keep])
    weighted = EmotionClassifier.paper(n_cepstrum=50, C=0.01,
                                       class_weight="balanced").fit(F[keep], ytr[keep])
    assert not np.allclose(plain.decision_function(F), weighted.decision_function(F))
    arrays = plain.to_arrays()
    assert str(arrays.pop("class_weight")) == "none"
    assert EmotionClassifier.from_arrays(arrays).class_weight is None
    with pytest.raises(ParameterError, match="class_weight"):
        EmotionClassifier(class_weight="equal").fit(F, ytr)


def test_binary_round_trip(toy):
    (Xtr, ytr), _ = toy
    keep = ytr != "noise"
    F = np.vstack([emotion_features(a, sr, n_cepstrum=50) for a, sr in Xtr])[keep]
    model = EmotionClassifier.paper(n_cepstrum=50, probability=True).fit(F, ytr[keep])
    back = EmotionClassifier.from_arrays(model.to_arrays())
    np.testing.assert_array_equal(back.predict(F), model.predict(F))
    np.testing.assert_allclose(back.predict_proba(F), model.predict_proba(F), atol=1e-12)
    assert model.predict_proba(F).shape == (F.shape[0], 2)


def test_rich_classifier(toy):
    (Xtr, ytr), (Xte, yte) = toy
    model = EmotionClassifier(features="rich", normalize="none", kernel="rbf",
                              C=1.0).fit(Xtr, ytr)
    assert model.n_features_in_ == 121
    assert model.score(Xte, yte) >= 0.9


def test_estimator_contract_and_errors(toy):
    (Xtr, ytr), _ = toy
    model = EmotionClassifier.paper(n_cepstrum=50, probability=True)
    assert clone(model).get_params() == model.get_params()
    with pytest.raises(NotFittedError):
        model.predict(Xtr)
    with pytest.raises(NotFittedError):
        model.predict_proba(Xtr)
    with pytest.raises(NotFittedError):
        model.to_arrays()
    with pytest.raises(ParameterError, match="kernel"):
        EmotionClassifier(kernel="cubic").fit(Xtr, ytr)
    with pytest.raises(ParameterError, match="features"):
        EmotionClassifier(features="mfcc").fit(Xtr, ytr)
    with pytest.raises(ParameterError, match="C must"):
        EmotionClassifier(C=0).fit(Xtr, ytr)
    with pytest.raises(ParameterError, match="two emotion classes"):
        model.fit(Xtr[:5], ytr[:5])
    with pytest.raises(ParameterError, match="y must have shape"):
        model.fit(Xtr, ytr[:-1])
    with pytest.raises(ValueError, match="Reshape your data"):
        model.fit([1.0, 2.0], ["a", "b"])
    with pytest.raises(ParameterError, match="Reshape your data"):
        model.fit(np.ones(SR), ["a"])
    with pytest.raises(DataError, match="too short"):
        model.fit([(np.ones(100), SR), (np.ones(100), SR)], ["a", "b"])
    model.fit(Xtr, ytr)
    with pytest.raises(ParameterError, match="expecting 53 features"):
        model.predict(np.zeros((2, 10)))
    with pytest.raises(DataError, match="re-ingest"):
        EmotionClassifier.from_arrays({"kernel": np.array("linear")})
    with pytest.raises(DataError, match="lacks array"):
        EmotionClassifier.from_arrays({"format": np.array(2), "kernel": np.array("linear")})


@pytest.mark.filterwarnings("ignore")
def test_sklearn_common_checks():
    from sklearn.utils.estimator_checks import check_estimator

    for model in (EmotionClassifier(), EmotionClassifier(probability=True, calibration_cv=2)):
        results = check_estimator(model, on_fail=None)
        failed = [r["check_name"] for r in results if r["status"] == "failed"]
        assert failed == []


# ----------------------------------------------------------------- EmoDB
@pytest.mark.shared
def test_emodb_smoke():
    root = require_shared("emodb")
    utterances, labels, speakers = load_emodb(root)
    assert len(utterances) == labels.size == speakers.size
    assert set(labels) <= set(EMODB_EMOTIONS.values())
    assert np.unique(speakers).size == 10
    # A small, deterministic subset: every 9th file (60 files).
    sub = np.arange(0, len(utterances), 9)
    X = [utterances[i] for i in sub]
    y = labels[sub]
    model = EmotionClassifier.paper(probability=True).fit(X, y)
    assert model.score(X, y) >= 0.9  # Table I: linear kernel, 500 coefficients
    proba = model.predict_proba(X[:5])
    np.testing.assert_allclose(proba.sum(axis=1), 1.0)


def test_speaker_normalize(rng):
    from ingest.emotion.classifier import speaker_normalize

    F = rng.standard_normal((20, 4)) * 3 + 7
    F[:, 3] = 1.0
    spk = np.repeat(["a", "b"], 10)
    Z = speaker_normalize(F, spk)
    for s in ("a", "b"):
        np.testing.assert_allclose(Z[spk == s, :3].mean(0), 0, atol=1e-12)
        np.testing.assert_allclose(Z[spk == s, :3].std(0), 1)
    np.testing.assert_array_equal(Z[:, 3], 0)
    with pytest.raises(ParameterError, match="speakers"):
        speaker_normalize(F, spk[:-1])


def test_speaker_and_population_normalisation(rng, tmp_path):
    # The default SVM learns every training utterance twice: normalised by its speaker's
    # statistics and by the population's (how a lone utterance is normalised).
    from ingest.emotion.classifier import DEFAULT_NORMALIZE
    from ingest.emotion.classifier_arrays import CLASSIFIER_FORMAT
    from ingest.emotion.speakers import SpeakerNormalizer

    spk = np.repeat(["a", "b", "c", "d"], 12)
    y = np.tile(np.repeat(["calm", "loud", "sad"], 4), 4)
    offsets = rng.normal(0, 3, (4, 6))  # speakers move features more than emotions
    F = (offsets[np.repeat(np.arange(4), 12)] + (y == "loud")[:, None] * 1.5
         - (y == "sad")[:, None] + rng.standard_normal((48, 6)))
    test = rng.standard_normal((10, 6)) + 2
    assert DEFAULT_NORMALIZE == "speaker+population"
    model = EmotionClassifier(probability=True).fit(F, y, speakers=spk)
    assert model.normalize == DEFAULT_NORMALIZE
    norm = SpeakerNormalizer().fit(F, spk)
    by_hand = EmotionClassifier(normalize="none").fit(
        np.vstack([norm.transform(F, spk), norm.transform(F)]), np.tile(y, 2))
    for who in (None, np.repeat(["e", "f"], 5), np.repeat(["a", "b"], 5)):
        np.testing.assert_allclose(model.decision_function(test, who),
                                   by_hand.decision_function(norm.transform(test, who)),
                                   atol=1e-9)
    # the former default differs, and without speakers both are one normalisation
    speaker = EmotionClassifier(normalize="speaker").fit(F, y, speakers=spk)
    assert not np.allclose(speaker.decision_function(test), model.decision_function(test))
    np.testing.assert_allclose(EmotionClassifier().fit(F, y).decision_function(test),
                               EmotionClassifier(normalize="speaker").fit(F, y)
                               .decision_function(test), atol=1e-9)
    proba = model.predict_proba(test)
    np.testing.assert_allclose(proba.sum(axis=1), 1.0)
    # stored as format 7; a format-6 model (normalize="speaker") still reads
    np.savez(tmp_path / "m.npz", **model.to_arrays())
    with np.load(tmp_path / "m.npz", allow_pickle=False) as z:
        assert int(z["format"]) == CLASSIFIER_FORMAT == 7
        back = EmotionClassifier.from_arrays(z)
    assert back.normalize == "speaker+population"
    np.testing.assert_allclose(back.predict_proba(test, np.repeat(["e", "f"], 5)),
                               model.predict_proba(test, np.repeat(["e", "f"], 5)), atol=1e-12)
    old = {**speaker.to_arrays(), "format": np.array(6)}
    np.testing.assert_array_equal(EmotionClassifier.from_arrays(old).predict(test),
                                  speaker.predict(test))
