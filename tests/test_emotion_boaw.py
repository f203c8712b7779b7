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
    with pytest.raises(ParameterError, match="needs at least 10.0 s of training speech"):
        BagOfAudioWords(size=1000).fit(low[:1])


def test_block_widths_weight_blocks_after_scaling_and_round_trip(rng):
    from ingest.emotion.classifier import EmotionClassifier, block_weights
    from ingest.emotion.classifier_arrays import CLASSIFIER_FORMAT

    w = block_weights((1, 4))
    np.testing.assert_allclose(w, [np.sqrt(2.5)] + [np.sqrt(5 / 8)] * 4)
    assert (w**2).sum() == pytest.approx(5)  # the total variance is kept
    y = np.repeat(["a", "b", "c"], 20)
    F = rng.normal(size=(60, 5)) + (y == "a")[:, None] * np.array([2.0, 0, 0, 0, 0]) \
        + (y == "b")[:, None] * np.array([0, 0.5, 0.5, 0.5, 0.5])
    spk = np.tile(["s1", "s2"], 30)
    plain = EmotionClassifier(C=1.0).fit(F, y, speakers=spk)
    weighted = EmotionClassifier(C=1.0, block_widths=(1, 4)).fit(F, y, speakers=spk)
    assert not np.allclose(plain.decision_function(F), weighted.decision_function(F))
    scaled = weighted.pipeline_["scale"].transform(weighted.normalizer_.transform(F, spk))
    np.testing.assert_allclose(weighted.pipeline_[:-1].transform(
        weighted.normalizer_.transform(F, spk)), scaled * w)
    arrays = weighted.to_arrays()
    assert int(arrays["format"]) == CLASSIFIER_FORMAT and arrays["block_widths"].tolist() == [1, 4]
    assert arrays["block_widths_fitted"].tolist() == [1, 4] and "boaw_mean" not in arrays
    back = EmotionClassifier.from_arrays(arrays)
    assert back.block_widths == back.block_widths_ == (1, 4)
    np.testing.assert_allclose(back.decision_function(F), weighted.decision_function(F))
    # formats 3 (block widths, no fitted widths) and 2 (no block widths) stay readable
    three = {**{k: v for k, v in arrays.items() if k != "block_widths_fitted"},
             "format": np.array(3)}
    np.testing.assert_allclose(EmotionClassifier.from_arrays(three).decision_function(F),
                               weighted.decision_function(F))
    two = {**{k: v for k, v in plain.to_arrays().items() if not k.startswith("block")},
           "format": np.array(2)}
    np.testing.assert_array_equal(EmotionClassifier.from_arrays(two).predict(F),
                                  plain.predict(F))
    from db.errors import DataError

    with pytest.raises(DataError, match="block_widths"):
        EmotionClassifier.from_arrays({k: v for k, v in three.items()
                                       if k != "block_widths"})
    with pytest.raises(ParameterError, match="sum to 6"):
        EmotionClassifier(block_widths=(2, 4)).fit(F, y)
    for bad in ((0, 5), (1.5, 3.5), "15", ()):
        with pytest.raises(ParameterError, match="block_widths"):
            EmotionClassifier(block_widths=bad).fit(F, y)


def test_stored_codebooks_are_checked(rng):
    from db.errors import DataError

    frames = [frame_descriptors(_voice(rng, f0=f), SR) for f in (110.0, 180.0, 260.0)]
    bag = BagOfAudioWords(size=20, assignments=3).fit(frames)
    arrays = bag.to_arrays()
    back = BagOfAudioWords.from_arrays(arrays)
    np.testing.assert_array_equal(back.transform(frames), bag.transform(frames))
    book = arrays["boaw_codebook1"]
    nan = book.copy()
    nan[0, 0] = np.nan
    for key, bad, needle in [("boaw_codebook1", book[:-1], "boaw_codebook1"),
                             ("boaw_codebook0", book[:, :5], "boaw_codebook0"),
                             ("boaw_codebook1", nan, "not finite"),
                             ("boaw_mean", arrays["boaw_mean"][:-1], "boaw_mean"),
                             ("boaw_scale", -arrays["boaw_scale"], "positive"),
                             ("boaw_assignments", np.array(21), "boaw_assignments"),
                             ("boaw_assignments", np.array(2.5), "boaw_assignments"),
                             ("boaw_mean", np.array(["a"] * 44), "not finite")]:
        with pytest.raises(DataError, match=needle):
            BagOfAudioWords.from_arrays({**arrays, key: bad})
    with pytest.raises(DataError, match="lacks array 'boaw_scale'"):
        BagOfAudioWords.from_arrays({k: v for k, v in arrays.items() if k != "boaw_scale"})


def test_classifier_learns_its_codebooks_at_fit_and_stores_them(rng):
    from db.errors import DataError
    from ingest.emotion.classifier import EmotionClassifier, SpeechFeatures
    from ingest.emotion.classifier_arrays import CLASSIFIER_FORMAT

    f0s = {"low": (100.0, 120.0, 110.0, 105.0), "high": (240.0, 260.0, 250.0, 270.0)}
    audio = [(_voice(rng, f0=f, seconds=0.8), SR) for lab in f0s for f in f0s[lab]]
    y = np.repeat(list(f0s), 4)
    spk = np.tile(["a", "b"], 4)
    model = EmotionClassifier(C=1.0, probability=True, calibration_cv=2)
    described = model.describe(audio)
    assert described.functionals.shape == (8, 171) and len(described.frames) == 8
    model.fit(audio, y, speakers=spk)
    # the default: an ensemble of 5 codebook pairs, 5,000 words as one block
    assert model.bag_ is not None and model.block_widths_ == (171, 5000)
    assert model.n_features_in_ == 5171 and model.featurize(audio).shape == (8, 5171)
    assert model.bag_.n_codebooks == model.n_codebooks == 5 and model.kernel_width_ == 1171
    # the same fit from what ingest's workers compute per clip
    again = EmotionClassifier(C=1.0, probability=True, calibration_cv=2).fit(
        SpeechFeatures(described.functionals, described.frames), y, speakers=spk)
    np.testing.assert_array_equal(again.bag_.codebooks_[1], model.bag_.codebooks_[1])
    arrays = model.to_arrays()
    assert int(arrays["format"]) == CLASSIFIER_FORMAT
    assert arrays["boaw_codebook0"].shape == (500, 22)
    back = EmotionClassifier.from_arrays(arrays)
    np.testing.assert_allclose(back.decision_function(audio), model.decision_function(audio))
    np.testing.assert_allclose(back.predict_proba(audio[:2]), model.predict_proba(audio[:2]))
    # a feature matrix is used as given: no words learned, the old format-2-like model
    plain = EmotionClassifier(C=1.0).fit(described.functionals, y)
    assert plain.bag_ is None and plain.block_widths_ is None
    assert "boaw_mean" not in plain.to_arrays()
    # the stored arrays are checked when read, each failure one line
    for key, bad, needle in [
            ("support_vectors", arrays["support_vectors"][:, :-1], "support_vectors"),
            ("dual_coef", np.full_like(arrays["dual_coef"], np.inf), "not finite"),
            ("n_support", arrays["n_support"] + 1, "n_support"),
            ("calib_coef", np.ones((2, 2)), "calib_coef"),
            ("block_widths_fitted", np.array([171, 999]), "block widths"),
            ("boaw_codebook0", arrays["boaw_codebook0"][:, :3], "boaw_codebook0"),
            ("format", np.array("4"), "older animegraph")]:
        with pytest.raises(DataError, match=needle) as info:
            EmotionClassifier.from_arrays({**arrays, key: bad})
        assert "\n" not in str(info.value)


def test_too_little_labelled_speech_for_the_words_is_a_note(rng):
    # 4 clips of 0.5 s: two per emotion, but 2 s of speech for 500 audio words. Ingest's
    # classifier step says so in a note and goes on without a classifier.
    from ingest.emotion.model import _fit_classifier

    audio = [(_voice(rng, f0=f, seconds=0.5), SR) for f in (110.0, 120.0, 250.0, 260.0)]
    notes: list[str] = []
    assert _fit_classifier(audio, ["sad", "sad", "happy", "happy"], None, notes) is None
    assert notes == ["the emotion classifier could not be trained: a codebook of 500 audio "
                     "words needs at least 5.0 s of training speech (500 frames), got 2.04 s"]


def test_an_ensemble_of_codebooks_starts_with_the_single_pair_and_round_trips(rng):
    from db.errors import DataError
    from ingest.emotion.boaw import codebook_seeds

    frames = [frame_descriptors(_voice(rng, f0=f, seconds=0.6), SR)
              for f in (100.0, 130.0, 170.0, 220.0, 260.0)]
    one = BagOfAudioWords(size=20, assignments=3).fit(frames)
    ens = BagOfAudioWords(size=20, assignments=3, n_codebooks=3).fit(frames)
    H1, H3 = one.transform(frames), ens.transform(frames)
    assert H1.shape == (5, 40) and H3.shape == (5, 120) and ens.n_words == 120
    np.testing.assert_array_equal(H3[:, :40], H1)  # the first pair is the one pair
    assert not np.array_equal(ens.codebooks_[2], ens.codebooks_[0])
    # ensembles of different seeds share no codebook
    assert not set(codebook_seeds(0, 5)) & set(codebook_seeds(1, 5))
    arrays = ens.to_arrays()
    assert int(arrays["boaw_n_codebooks"]) == 3 and "boaw_codebook5" in arrays \
        and "boaw_codebook6" not in arrays
    np.testing.assert_array_equal(BagOfAudioWords.from_arrays(arrays).transform(frames), H3)
    for key, bad, needle in [("boaw_n_codebooks", np.array(4), "lacks array 'boaw_codebook6'"),
                             ("boaw_n_codebooks", np.array(0), "boaw_n_codebooks"),
                             ("boaw_n_codebooks", np.array(2.5), "boaw_n_codebooks"),
                             ("boaw_codebook5", arrays["boaw_codebook5"][:-1], "boaw_codebook5"),
                             ("boaw_codebook4", arrays["boaw_codebook4"].T, "boaw_codebook4")]:
        with pytest.raises(DataError, match=needle):
            BagOfAudioWords.from_arrays({**arrays, key: bad})
    for bad in (0, True, 1.5):
        with pytest.raises(ParameterError, match="n_codebooks"):
            BagOfAudioWords(size=20, n_codebooks=bad).fit(frames)


def test_the_ensemble_kernel_varies_less_with_the_seed(rng):
    # The reason for the ensemble (ingest.emotion.boaw): the linear kernel between two
    # utterances' histograms is a random draw through the codebook; the mean of K draws
    # varies less from seed to seed than one draw.
    frames = [frame_descriptors(_voice(rng, f0=f, seconds=0.5), SR)
              for f in np.linspace(90.0, 300.0, 8)]

    def spread(k):
        kernels = []
        for seed in range(6):
            H = BagOfAudioWords(size=30, assignments=3, n_codebooks=k,
                                random_state=10 * seed).fit(frames).transform(frames)
            H = H - H.mean(0)
            kernels.append(H @ H.T / k)
        return np.std(kernels, axis=0).mean() / np.abs(np.mean(kernels, axis=0)).mean()

    assert spread(4) < 0.7 * spread(1)


def test_classifier_with_an_ensemble_stores_it_and_reads_format_4(rng):
    from db.errors import DataError
    from ingest.emotion.classifier import EmotionClassifier
    from ingest.emotion.classifier_arrays import CLASSIFIER_FORMAT

    f0s = {"low": (100.0, 120.0, 110.0, 105.0), "high": (240.0, 260.0, 250.0, 270.0)}
    audio = [(_voice(rng, f0=f, seconds=0.8), SR) for lab in f0s for f in f0s[lab]]
    y = np.repeat(list(f0s), 4)
    spk = np.tile(["a", "b"], 4)
    described = EmotionClassifier().describe(audio)
    model = EmotionClassifier(C=1.0, n_codebooks=2, probability=True, calibration_cv=2)
    model.fit(described, y, speakers=spk)
    # the two pairs' 2,000 words are one block against the functionals, and the kernel's
    # scale is one pair's (C means the same whatever the number of pairs)
    assert model.block_widths_ == (171, 2000) and model.n_features_in_ == 2171
    w = model.pipeline_["weigh"].kw_args["w"]
    assert model.kernel_width_ == 1171 and (w**2).sum() == pytest.approx(1171)
    assert (w[:171] ** 2).sum() == pytest.approx((w[171:] ** 2).sum())
    arrays = model.to_arrays()
    assert int(arrays["format"]) == CLASSIFIER_FORMAT and int(arrays["n_codebooks"]) == 2
    assert int(arrays["boaw_n_codebooks"]) == 2 and arrays["boaw_codebook3"].shape == (500, 22)
    back = EmotionClassifier.from_arrays(arrays)
    assert back.n_codebooks == 2 and back.bag_.n_codebooks == 2
    np.testing.assert_allclose(back.decision_function(audio), model.decision_function(audio))
    np.testing.assert_allclose(back.predict_proba(audio[:2]), model.predict_proba(audio[:2]))
    for key, bad, needle in [
            ("n_codebooks", np.array(3), "2 codebook pairs stored, n_codebooks says 3"),
            ("n_codebooks", np.array(0.5), "n_codebooks must be"),
            ("boaw_n_codebooks", np.array(1), "codebook pairs stored"),
            ("boaw_codebook3", arrays["boaw_codebook3"][:, :-2], "boaw_codebook3"),
            ("block_widths_fitted", np.array([1171, 1000]), "not its last block")]:
        with pytest.raises(DataError, match=needle) as info:
            EmotionClassifier.from_arrays({**arrays, key: bad})
        assert "\n" not in str(info.value)
    for key in ("n_codebooks", "boaw_n_codebooks"):
        with pytest.raises(DataError, match=f"lacks array '{key}'"):
            EmotionClassifier.from_arrays({k: v for k, v in arrays.items() if k != key})
    # on the precomputed matrix, kernel_width gives the estimator's kernel (what the
    # evaluation tunes on: scripts/eval_emotion_boaw.py, system "ensemble")
    X = model.featurize(described)
    on_matrix = EmotionClassifier(C=1.0, block_widths=(171, 2000), kernel_width=1171).fit(
        X, y, speakers=spk)
    np.testing.assert_allclose(on_matrix.decision_function(X), model.decision_function(X))
    plain = EmotionClassifier(C=1.0, block_widths=(171, 2000)).fit(X, y, speakers=spk)
    assert plain.kernel_width_ == 2171
    stored = on_matrix.to_arrays()
    assert int(stored["kernel_width"]) == 1171
    assert EmotionClassifier.from_arrays(stored).kernel_width == 1171
    with pytest.raises(DataError, match="kernel_width"):
        EmotionClassifier.from_arrays({**stored, "kernel_width": np.array(-3.0)})
    for bad in (0, 1.5, True):
        with pytest.raises(ParameterError, match="kernel_width"):
            EmotionClassifier(kernel_width=bad).fit(X, y)
    # format 4 (one pair, no n_codebooks arrays), as the fourth session stored it (its
    # features without the silence floor)
    single = EmotionClassifier(C=1.0, n_codebooks=1, probability=True, calibration_cv=2,
                               silence_floor=None).fit(audio, y, speakers=spk)
    four = {**{k: v for k, v in single.to_arrays().items()
               if k not in ("n_codebooks", "boaw_n_codebooks")}, "format": np.array(4)}
    old = EmotionClassifier.from_arrays(four)
    assert old.n_codebooks == 1 and old.bag_.n_codebooks == 1
    np.testing.assert_allclose(old.decision_function(audio), single.decision_function(audio))
    np.testing.assert_allclose(old.predict_proba(audio), single.predict_proba(audio))
    # the first pair of the ensemble is the single model's (the same seed)
    one = EmotionClassifier(C=1.0, n_codebooks=1).fit(described, y, speakers=spk)
    np.testing.assert_array_equal(model.bag_.codebooks_[1], one.bag_.codebooks_[1])


def test_clips_without_emotion_labels_are_told_so(rng):
    # FACEGOOD's and talkingface's ingest said "(it has no usable clip)" of clips that
    # were all usable, only unlabelled.
    from ingest.emotion.model import _fit_classifier

    audio = [(_voice(rng, f0=110.0, seconds=0.5), SR)] * 3
    notes: list[str] = []
    assert _fit_classifier(audio, ["unknown"] * 3, None, notes) is None
    assert notes[0].endswith("(its clips carry no emotion labels)"), notes
    notes = []
    assert _fit_classifier([(np.zeros(10), SR)], ["sad"], None, notes) is None
    assert notes[-1].endswith("(it has no usable clip)"), notes
