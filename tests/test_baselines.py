"""The baselines of issue #8 (mu-mlp, hier-pca): contract, learning, storage, bad input, CLI."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from conftest import AS_INGESTED, require_shared

from animegraph.apps.cli import main
from animegraph.baselines import BASELINES, METHODS, estimator_class, make_estimator
from animegraph.baselines.base import (
    fitted_model,
    load_model,
    model_path,
    read_model,
    save_model,
)
from animegraph.baselines.data import audio_features, training_set
from animegraph.baselines.hier_pca import HierPca, _pca, _speech_to_d
from animegraph.baselines.mu_mlp import MuMlp, principal_axes
from animegraph.baselines.ppg_forward import N_PER_OFFSET
from animegraph.baselines.ppg_ridge import ALPHAS, PpgRidge, ridge_loo
from animegraph.baselines.stored import FORWARD, load_forward
from animegraph.motion import measures
from db.errors import DataError, ParameterError
from db.store import Database
from ingest.tables import prepared_from_database

# Small models: the tiny corpus has ~2 minutes of speech, far less than the papers'.
SMALL = {
    "mu-mlp": {"n_mfcc": 6, "context": 1, "subset_hidden": (3, 4), "expression_hidden": 4,
               "frame_rate": 60.0},
    "hier-pca": {"n_clusters": 8},
    "ppg-ridge": {},
}


@pytest.fixture(scope="module")
def clips(tiny_db):
    return prepared_from_database(Database.open(tiny_db[0]))


@pytest.fixture(scope="module")
def split(clips):
    """Training clips and the held-out clips of one sentence spoken in all five emotions."""
    held = sorted({c.sentence_id for c in clips})[0]
    return ([c for c in clips if c.sentence_id != held],
            [c for c in clips if c.sentence_id == held])


@pytest.fixture(scope="module")
def fitted(split):
    train, _ = split
    return {m: make_estimator(m, **SMALL[m]).fit(train) for m in SMALL}


def test_registry():
    assert METHODS[0] == "anime-graph" and set(BASELINES) == set(METHODS[1:])
    assert estimator_class("mu-mlp") is MuMlp and estimator_class("hier-pca") is HierPca
    with pytest.raises(ParameterError, match="unknown baseline"):
        estimator_class("anime-graph")
    # scikit-learn conventions: parameters round-trip through get_params/set_params.
    est = MuMlp(n_mfcc=8)
    assert est.get_params()["n_mfcc"] == 8 and est.set_params(context=2).context == 2


def test_audio_features_stack_edge_padded_context():
    rng = np.random.default_rng(0)
    audio = rng.normal(0, 0.1, 16000).astype(np.float32)
    f = audio_features(audio, 16000, 50, 25.0, n_mfcc=10, context=3)
    assert f.shape == (50, 70)
    # Block k holds the frame k - 3 away: frame t's "+1" block is frame t+1's centre block.
    np.testing.assert_allclose(f[10, 40:50], f[11, 30:40], atol=1e-9)
    # Edge padding: the "-3" block of frame 0 repeats the first frame.
    np.testing.assert_allclose(f[0, 0:10], f[0, 30:40], atol=1e-9)


def test_training_set_from_database_and_prepared_clips(tiny_db, clips):
    from_db = training_set(tiny_db[0])
    from_clips = training_set(clips)
    assert from_db.n_frames == from_clips.n_frames > 0
    assert from_db.emotions == ("angry", "frustrated", "happy", "neutral", "sad")
    clip = from_clips.clips[0]
    assert clip.audio.dtype == np.float32 and np.abs(clip.audio).max() <= 1.0
    assert clip.motion.shape[1] == from_clips.n_channels == 216


@pytest.mark.parametrize("method", sorted(SMALL))
def test_fit_predict_shapes(fitted, split, method):
    est = fitted[method]
    clip = split[1][0]
    out = est.predict(clip.audio, clip.sample_rate, emotion=clip.emotion,
                      n_frames=len(clip.motion))
    assert out.shape == clip.motion.shape and np.isfinite(out).all()
    default = est.predict(clip.audio.astype(np.float32) / 32767, clip.sample_rate)
    assert abs(len(default) - len(clip.motion)) <= 1


@pytest.mark.parametrize("method", ["hier-pca", "mu-mlp"])
def test_learns_more_than_the_mean(fitted, split, method):
    """On held-out speech the mouth moves with the recording; mu-mlp also beats the mean
    face in lip RMSE (hier-pca does not on this little data, see docs/results/lipsync.md, "Baseline
    settings").
    ppg-ridge's 451 inputs overfit the 4 training sentences of this corpus (its
    posteriorgram part alone predicts the fifth sentence's mouth with R < 0): its check
    is on real speech, :func:`test_ppg_ridge_on_real_speech`."""
    train, test = split
    names, groups, kind = test[0].schema.names, test[0].schema.groups, test[0].schema.kind
    lips = measures.lip_channels(names, groups)
    mean = np.concatenate([c.motion for c in train]).mean(axis=0)
    rs, err, base = [], [], []
    for clip in test:
        pred = fitted[method].predict(clip.audio, clip.sample_rate, emotion=clip.emotion,
                                      n_frames=len(clip.motion))
        rs.append(measures.pearson(measures.mouth_opening(pred, names, kind),
                                   measures.mouth_opening(clip.motion, names, kind)))
        err.append(measures.rmse(pred, clip.motion, lips))
        base.append(measures.rmse(np.broadcast_to(mean, clip.motion.shape), clip.motion, lips))
    assert np.mean(rs) > 0.1
    if method == "mu-mlp":
        assert np.mean(err) < np.mean(base)


def test_mu_mlp_motion_units_and_expressions(fitted, split):
    est = fitted["mu-mlp"]
    assert est.m0_.shape == (216, 7)  # A0 = 7 utterance MUs (Hong §IV-A)
    np.testing.assert_allclose(est.m0_.T @ est.m0_, np.eye(7), atol=1e-9)
    assert set(est.expressions_) == {"angry", "frustrated", "happy", "sad"}
    assert all(e["mk"].shape == (216, 2) for e in est.expressions_.values())
    clip = split[1][0]
    neutral = est.predict(clip.audio, clip.sample_rate, emotion="neutral")
    happy = est.predict(clip.audio, clip.sample_rate, emotion="happy")
    assert np.abs(neutral - happy).max() > 0.1  # the expression MLP changes the face


def test_principal_axes_are_the_svds_with_a_fixed_sign():
    rng = np.random.default_rng(5)
    x = rng.standard_normal((500, 12)) @ rng.standard_normal((12, 12))
    x -= x.mean(axis=0)
    axes, share = principal_axes(x, 4)
    _, s, vt = np.linalg.svd(x, full_matrices=False)
    np.testing.assert_allclose(np.abs(axes.T @ vt[:4].T), np.eye(4), atol=1e-9)
    assert share == pytest.approx((s[:4] ** 2).sum() / (s**2).sum(), rel=1e-12)
    assert (axes[np.abs(axes).argmax(axis=0), np.arange(4)] > 0).all()
    assert principal_axes(x[:3], 7)[0].shape == (12, 3)


def test_mu_mlp_fits_its_perceptrons_on_threads_as_one_after_another(fitted, split,
                                                                    monkeypatch):
    """The perceptrons fitted on a thread a core are those fitted one after another:
    each gets the seed it had in that order."""
    import animegraph.baselines.mu_mlp as mu_mlp

    monkeypatch.setattr(mu_mlp, "usable_cpus", lambda: 1)
    serial = MuMlp(**SMALL["mu-mlp"]).fit(split[0])
    arrays, threaded = serial.to_arrays(), fitted["mu-mlp"].to_arrays()
    assert any(k.startswith("subset/") for k in arrays) and arrays.keys() == threaded.keys()
    for key, values in arrays.items():
        np.testing.assert_array_equal(values, threaded[key], err_msg=key)


def test_mu_mlp_trained_in_float32_predicts_as_in_float64(fitted, split):
    """The default float32 training (half the cost) against the float64 one on the same
    data and seed: the motion each predicts for held-out speech differs by under a fifth
    of how much the motion moves, and follows the same mouth (r > 0.9)."""
    train, test = split
    wide = MuMlp(**SMALL["mu-mlp"], mlp_dtype="float64").fit(train)
    assert fitted["mu-mlp"].mlp_dtype == "float32"
    names, kind = wide.channels_, wide.kind_
    for clip in test:
        a = fitted["mu-mlp"].predict(clip.audio, clip.sample_rate, n_frames=len(clip.motion))
        b = wide.predict(clip.audio, clip.sample_rate, n_frames=len(clip.motion))
        assert np.sqrt(np.mean((a - b) ** 2)) < 0.2 * np.sqrt(np.mean((b - b.mean(0)) ** 2))
        assert measures.pearson(measures.mouth_opening(a, names, kind),
                                measures.mouth_opening(b, names, kind)) > 0.9
    with pytest.raises(ParameterError, match="mlp_dtype"):
        MuMlp(**SMALL["mu-mlp"], mlp_dtype="float16").fit(train)


@pytest.mark.parametrize("method", sorted(SMALL))
def test_array_round_trip_and_database_storage(fitted, split, tiny_db, tmp_path, method):
    est = fitted[method]
    clip = split[1][0]
    want = est.predict(clip.audio, clip.sample_rate, emotion=clip.emotion)
    arrays = est.to_arrays()
    assert all(isinstance(v, np.ndarray) and v.dtype == np.float64 for v in arrays.values())
    again = type(est).from_arrays(arrays, est.describe())
    np.testing.assert_array_equal(again.predict(clip.audio, clip.sample_rate,
                                                emotion=clip.emotion), want)
    db = tmp_path / "db"
    shutil.copytree(tiny_db[0], db, ignore=AS_INGESTED)
    assert load_model(db, method) is None
    path = save_model(est, db)
    assert path == model_path(db, method) and path.suffix == ".parquet"
    assert b"pickle" not in path.read_bytes()
    stored = fitted_model(db, method)  # the stored model is used as is
    assert stored.get_params() == est.get_params()
    np.testing.assert_array_equal(stored.predict(clip.audio, clip.sample_rate,
                                                 emotion=clip.emotion), want)
    if method in FORWARD:  # restored without scikit-learn for a one-shot synth
        np.testing.assert_allclose(load_forward(db, method).predict(
            clip.audio, clip.sample_rate, emotion=clip.emotion), want, atol=1e-9)
    key = {"mu-mlp": "x_mean", "hier-pca": "a_mean", "ppg-ridge": "coef"}[method]
    np.testing.assert_array_equal(read_model(path).to_arrays()[key], arrays[key])


def test_ppg_ridge_features_are_gain_free_and_in_context(split):
    """The posteriorgram hears every clip at one level and the loudness is relative to the
    clip's loud frames: a quieter recording of the same speech gives the same features;
    each context block is the centre block shifted by its offset."""
    clip = split[1][0]
    audio = clip.audio.astype(np.float32) / 32767
    times = np.arange(len(clip.motion)) / clip.fps
    est = PpgRidge()
    f = est.features(audio, clip.sample_rate, times)
    assert f.shape == (len(times), N_PER_OFFSET * 11) and np.isfinite(f).all()
    np.testing.assert_allclose(est.features(audio * 0.1, clip.sample_rate, times), f,
                               atol=1e-3)  # float32 rounding in the model
    shifted = est.features(audio, clip.sample_rate, times + 0.04)  # one step later
    k = N_PER_OFFSET  # offset 0 is block 5 of 11, +40 ms block 6
    np.testing.assert_allclose(shifted[:, 5 * k:6 * k], f[:, 6 * k:7 * k], atol=1e-9)
    with pytest.raises(ParameterError, match="step_s"):
        PpgRidge(step_s=0).fit(split[0])


def test_ppg_ridge_loudness_is_relative_to_a_level_given(split):
    """Within ``loud_level(L)`` each frame's loudness is taken relative to ``L`` (what a
    live stream has heard) instead of the audio's own loud frames: the loudness columns
    shift by log(own / L), the posteriorgram's do not; the audio's own level changes
    nothing."""
    from animegraph.baselines.ppg_forward import LOUD_PERCENTILE, frame_loudness, loud_level
    from ingest.speech import ctc

    clip = split[1][0]
    audio = clip.audio.astype(np.float32) / 32767
    q = len(ctc.posteriors(audio, clip.sample_rate))
    times = (np.arange(q) + 0.5) * 0.02  # the frames' centres: each feature one frame's
    est = PpgRidge()
    f = est.features(audio, clip.sample_rate, times)
    own = float(np.percentile(frame_loudness(audio, clip.sample_rate, q), LOUD_PERCENTILE))
    with loud_level(own):
        np.testing.assert_allclose(est.features(audio, clip.sample_rate, times), f, atol=1e-12)
    with loud_level(10 * own):
        g = est.features(audio, clip.sample_rate, times)
    loudness = np.arange(N_PER_OFFSET - 1, f.shape[1], N_PER_OFFSET)
    others = np.setdiff1d(np.arange(f.shape[1]), loudness)
    np.testing.assert_allclose(g[:, others], f[:, others], atol=1e-12)
    loud = f[:, loudness] > np.log(1e-3) + np.log(10) + 1e-6  # not at the floor either way
    assert loud.mean() > 0.5
    np.testing.assert_allclose(g[:, loudness][loud], f[:, loudness][loud] - np.log(10),
                               atol=1e-9)
    with loud_level(None):  # no level: the audio's own
        np.testing.assert_allclose(est.features(audio, clip.sample_rate, times), f, atol=1e-12)


@pytest.mark.shared
@pytest.mark.parametrize("n, p, t, noise", [(400, 30, 5, 1.0), (1500, 80, 12, 0.1),
                                             (1500, 80, 12, 30.0), (1200, 40, 90, 3.0)])
@pytest.mark.parametrize("search", ["local", "all"])
def test_ridge_loo_chooses_and_solves_as_ridge_cv(n, p, t, noise, search):
    """Either search, and with more targets than features (residual norms from the
    targets' products, not the residuals), the penalty and coefficients of RidgeCV."""
    from sklearn.linear_model import RidgeCV

    rng = np.random.default_rng(n + p)
    x = rng.standard_normal((n, p))
    x[:, -1] = x[:, 0] - x[:, 1]  # collinear, and a constant (after centring) column
    x[:, 3] = 1.0
    y = x @ (rng.standard_normal((p, t)) * (rng.random((p, 1)) < 0.3))
    y += noise * rng.standard_normal((n, t))
    x, y = x - x.mean(axis=0), y - y.mean(axis=0)
    alpha, weights = ridge_loo(x, y, ALPHAS, search=search)
    ridge = RidgeCV(alphas=ALPHAS, gcv_mode="svd").fit(x, y)
    assert alpha == ridge.alpha_ and ALPHAS[0] < alpha < ALPHAS[-1]
    np.testing.assert_allclose(weights, ridge.coef_.T, rtol=0, atol=1e-9 * np.abs(weights).max())


def test_ridge_loo_local_search_is_the_full_search_and_refuses_an_unknown_one(split):
    rng = np.random.default_rng(3)
    x = rng.standard_normal((600, 20))
    y = x @ rng.standard_normal((20, 30)) + 2.0 * rng.standard_normal((600, 30))
    x, y = x - x.mean(axis=0), y - y.mean(axis=0)
    local, everything = ridge_loo(x, y, ALPHAS), ridge_loo(x, y, ALPHAS, search="all")
    assert local[0] == everything[0] and np.array_equal(local[1], everything[1])
    with pytest.raises(ParameterError, match="search"):
        ridge_loo(x, y, ALPHAS, search="some")
    with pytest.raises(ParameterError, match="alpha_search"):
        PpgRidge(alpha_search="some").fit(split[0])


def test_ppg_ridge_on_real_speech():
    """Fitted on a minute of each of two FACEGOOD clips (Mandarin, ARKit-style curves, read
    as recorded), it follows 30 s of a third clip's jaw opening (the full evaluation:
    docs/results/lipsync.md)."""
    from animegraph.baselines.data import TrainingClip, TrainingSet
    from ingest.readers import discover, load

    def minutes(raw, seconds):
        n = int(seconds * raw.fps)
        return TrainingClip(clip_id=raw.clip_id, audio=raw.audio[:int(seconds * raw.sample_rate)],
                            sample_rate=raw.sample_rate, motion=raw.motion[:n], fps=raw.fps,
                            emotion="neutral", phones=())

    root = require_shared("facegood")
    raws = [load(s) for s in sorted(discover([root]), key=lambda s: s.clip_id)[:3]]
    schema = raws[0].schema
    train = TrainingSet(clips=tuple(minutes(r, 60) for r in raws[:2]), names=schema.names,
                        groups=schema.groups, kind=schema.kind, fps=raws[0].fps)
    test = minutes(raws[2], 30)
    est = make_estimator("ppg-ridge").fit(train)
    pred = est.predict(test.audio, test.sample_rate, n_frames=test.n_frames)
    r = measures.pearson(measures.mouth_opening(pred, schema.names, schema.kind),
                         measures.mouth_opening(test.motion, schema.names, schema.kind))
    assert r > 0.7 and est.alpha_ in ALPHAS[1:-1], (r, est.alpha_)  # alpha inside the range


def test_hier_pca_eq9_is_the_regression_of_the_cluster_data():
    """Eq. 9 from a cluster's truncated joint PCA predicts its own appearance about as well
    as least squares; conditioning the truncated model without its noise term had made
    it far worse than the cluster mean (R² -6.4 here)."""
    rng = np.random.default_rng(0)
    s = rng.normal(size=(300, 6)) * np.sqrt([100, 30, 10, 3, 1, 0.5])
    c = 0.1 * s[:, :3] @ rng.normal(size=(3, 3)) + rng.normal(size=(300, 3))
    y = c - c.mean(axis=0)
    ols = s - s.mean(axis=0)
    ols = ols @ np.linalg.lstsq(ols, y, rcond=None)[0]
    for variance in (0.98, 1.0):
        mean, r, sd, noise = _pca(np.hstack([c, s]), variance)
        assert (len(sd) <= 6 and noise > 0) if variance < 1 else noise == 0
        pred = _speech_to_d(r[3:], sd**2, noise, s - mean[3:]) @ r[:3].T
        r2 = 1 - ((y - pred) ** 2).sum() / (y**2).sum()
        assert r2 > 0.95 * (1 - ((y - ols) ** 2).sum() / (y**2).sum())
    np.testing.assert_allclose(pred, ols, atol=1e-8)  # nothing discarded: exactly OLS


def test_hier_pca_refuses_a_model_stored_before_the_noise_term(fitted):
    est = fitted["hier-pca"]
    arrays = {k: v for k, v in est.to_arrays().items() if not k.endswith("/noise_var")}
    with pytest.raises(DataError, match="refit"):
        HierPca.from_arrays(arrays, est.describe())


@pytest.mark.parametrize("params", [{"n_clusters": 0}, {"clamp_sd": -1.0},
                                    {"speech_variance": 0.0}, {"speech_variance": 1.5}])
def test_hier_pca_bad_parameters(split, params):
    with pytest.raises(ParameterError, match="must be"):
        HierPca(**params).fit(split[0])


def test_too_little_data_and_missing_neutral(clips):
    with pytest.raises(DataError, match="too little data"):
        MuMlp().fit(clips[:2])
    # In plain words, with the paper's term, and the seconds of speech it needs.
    with pytest.raises(DataError, match=r"too little data for mu-mlp's speech-to-face network "
                                        r"\(the paper's pooled audio-to-UMUP MLP\) on the "
                                        r"'neutral' clips: \d+ frames for \d+ parameters, "
                                        r"[\d.]+ s where it needs [\d.]+ s$"):
        MuMlp().fit(clips)
    with pytest.raises(DataError, match="too little data"):
        HierPca().fit([_shortened(clips[0], 5)])
    with pytest.raises(DataError, match="too little data for the ppg-ridge"):
        make_estimator("ppg-ridge").fit([_shortened(clips[0], 100)])
    no_neutral = [c for c in clips if c.emotion != "neutral"]
    with pytest.raises(DataError, match="'neutral' clips"):
        MuMlp(**SMALL["mu-mlp"]).fit(no_neutral)
    with pytest.raises(DataError, match="no clips"):
        HierPca().fit([])


def test_channel_mismatch_and_bad_predict_input(fitted, clips):
    est = fitted["hier-pca"]
    with pytest.raises(DataError, match="do not match"):
        est.check_channels(est.channels_[:-3] + ("a.x", "a.y", "a.z"), "database X")
    # Names that passed pass again (a live stream checks every window); other names, or
    # the same after the model's channels changed, do not.
    names = tuple(est.channels_)
    est.check_channels(names)
    est.check_channels(names)
    with pytest.raises(DataError, match="do not match"):
        est.check_channels(names[:-1])
    kept = est.channels_
    try:
        est.channels_ = kept[:-1] + ("a.x",)
        with pytest.raises(DataError, match="do not match"):
            est.check_channels(names)
    finally:
        est.channels_ = kept
    with pytest.raises(ParameterError, match="emotion 'bored'"):
        est.predict(clips[0].audio, 16000, emotion="bored")
    with pytest.raises(ParameterError, match="mono"):
        est.predict(np.zeros((100, 2), np.float32), 16000)
    with pytest.raises(DataError, match="different|other channels"):
        from dataclasses import replace

        from ingest.clip import ChannelSchema

        s = clips[0].schema
        other = ChannelSchema(kind=s.kind, names=s.names[:-3] + ("q.x", "q.y", "q.z"),
                              groups=s.groups, units=s.units)
        HierPca().fit([clips[0], replace(clips[1], schema=other)])


def _shortened(clip, n_frames):
    from dataclasses import replace

    samples = int(n_frames / clip.fps * clip.sample_rate)
    return replace(clip, motion=clip.motion[:n_frames], audio=clip.audio[:samples],
                   emotion_features=None)


def test_cli_synth_method_says_what_it_fits_on_first_use(tiny_db, split, tmp_path, capsys):
    """av-hmm fitted for 5 minutes, hier-pca likewise, in silence on first use: it is said
    once what is fitted (and that it takes a while), and not again once stored."""
    from ingest.formats.wav import write_wav

    db = tmp_path / "db"
    shutil.copytree(tiny_db[0], db, ignore=AS_INGESTED)
    clip = split[1][0]
    wav = tmp_path / "speech.wav"
    write_wav(wav, clip.audio.astype(np.float32) / 32767, clip.sample_rate)
    command = ["synth", str(wav), "--db", str(db), "--method", "hier-pca", "-o",
               str(tmp_path / "out.npz")]
    assert main(command) == 0
    err = capsys.readouterr().err
    assert err.count("fitting hier-pca") == 1 and "Gaussian-mixture" in err \
        and "first use" in err and "can take minutes" in err
    assert main(command) == 0
    assert "fitting" not in capsys.readouterr().err


def test_cli_synth_method_uses_the_stored_model(fitted, tiny_db, split, tmp_path, capsys):
    from ingest.formats.wav import write_wav

    db = tmp_path / "db"
    shutil.copytree(tiny_db[0], db, ignore=AS_INGESTED)
    save_model(fitted["hier-pca"], db)
    clip = split[1][0]
    wav = tmp_path / "speech.wav"
    write_wav(wav, clip.audio.astype(np.float32) / 32767, clip.sample_rate)
    out = tmp_path / "out.npz"
    assert main(["synth", str(wav), "--db", str(db), "--method", "hier-pca", "-o",
                 str(out)]) == 0
    assert "hier-pca model ready" in capsys.readouterr().err
    with np.load(out) as f:
        assert f["motion"].shape[1] == 216 and str(f["method"]) == "hier-pca"
        assert abs(len(f["motion"]) - len(clip.motion)) <= 1
    assert main(["synth", str(wav), "--db", str(db), "--method", "hier-pca", "-o",
                 str(tmp_path / "out.c3d")]) == 0
    capsys.readouterr()
    for emotion, needle in (("bored", "unknown emotion 'bored'"), ("auto", "only applies"),
                            ("happy=0.5,sad=0.5", "only applies")):
        bad = tmp_path / f"{emotion}.npz"
        assert main(["synth", str(wav), "--db", str(db), "--method", "hier-pca",
                     "--emotion", emotion, "-o", str(bad)]) != 0
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and needle in err[0] and not bad.exists()


def test_info_lists_the_stored_models(fitted, tiny_db, tmp_path, capsys):
    import json

    db = tmp_path / "db"
    shutil.copytree(tiny_db[0], db, ignore=AS_INGESTED)
    assert main(["info", "--db", str(db)]) == 0
    assert "baselines:  none fitted" in capsys.readouterr().out
    save_model(fitted["hier-pca"], db)
    stale = db / "baselines" / "v000000"  # a model of an older version, left behind
    stale.mkdir()
    shutil.copy(model_path(db, "hier-pca"), stale / "hier-pca.parquet")
    (stale / "mu-mlp.parquet").write_bytes(b"junk")
    assert main(["info", "--db", str(db)]) == 0
    lines = [x for x in capsys.readouterr().out.splitlines()[-3:]]
    assert lines[0].startswith("baselines:  hier-pca (") and "n_clusters=8" in lines[0]
    assert "216 channels" in lines[0] and "stale" not in lines[0]
    assert "stale, fitted on v000000" in lines[1]
    assert "mu-mlp" in lines[2] and "unreadable" in lines[2]
    assert main(["info", "--db", str(db), "--json"]) == 0
    models = json.loads(capsys.readouterr().out)["baselines"]
    assert [(m["method"], m["current"]) for m in models] == [
        ("hier-pca", True), ("hier-pca", False), ("mu-mlp", False)]
    assert models[0]["params"]["n_clusters"] == 8


def test_cli_fit_refuses_too_little_data_in_one_line(tiny_db, tmp_path, capsys):
    db = tmp_path / "db"
    shutil.copytree(tiny_db[0], db, ignore=AS_INGESTED)
    assert main(["fit", "--db", str(db), "--method", "mu-mlp"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "too little data" in err[0]
    assert not model_path(db, "mu-mlp").exists()  # nothing written


@pytest.mark.parametrize("method", sorted(SMALL))
def test_stored_model_with_arrays_that_do_not_fit_is_one_line(method, fitted, tiny_db,
                                                              tiny_corpus, tmp_path, capsys):
    """A stored model is someone else's data: an array cut short (shapes that no longer
    chain), or every value of one made negative, gives synth --method one error line
    (when read, or when its prediction reaches it), never a traceback. Arrays picked at
    random (fixed seed) from the model's own."""
    import pyarrow.parquet as pq

    from db.store import arrays_from_table, arrays_to_table

    db = tmp_path / "db"
    shutil.copytree(tiny_db[0], db, ignore=AS_INGESTED)
    save_model(fitted[method], db)
    path = model_path(db, method)
    table = pq.read_table(path)
    arrays = arrays_from_table(table)
    names = [k for k, v in arrays.items() if v.dtype.kind == "f" and v.ndim >= 1
             and v.shape[-1] >= 2]
    rng = np.random.default_rng(0)
    wav = sorted((tiny_corpus / "clips").glob("*_neutral_1.wav"))[0]
    for name in rng.choice(names, size=min(4, len(names)), replace=False):
        for bad in (arrays[name][..., :-1], -np.abs(arrays[name]) - 1.0):
            corrupt = {**arrays, name: bad}
            pq.write_table(arrays_to_table(corrupt).replace_schema_metadata(
                table.schema.metadata), path)
            out = tmp_path / "out.npz"
            out.unlink(missing_ok=True)
            code = main(["synth", str(wav), "--db", str(db), "--method", method, "-o",
                         str(out)])
            err = capsys.readouterr().err.strip().splitlines()
            assert not any("Traceback" in e for e in err), (name, err)
            if code != 0:  # a change the model tolerates may still predict
                assert code == 1 and err[-1].startswith("animegraph: error:") \
                    and not out.exists(), (name, err)


@pytest.mark.parametrize(("method", "params"), [
    ("mu-mlp", {"context": 10**9}), ("mu-mlp", {"frame_rate": 0.0}),
    ("ppg-ridge", {"step_s": 1e-12}), ("ppg-ridge", {"context_s": float("nan")}),
    ("hier-pca", {"n_mfcc": 10**9}), ("hier-pca", {"frame_rate": 0.0}),
    ("hier-pca", {"average_frames": 10**9}), ("av-hmm", {"context": 10**9}),
    ("av-hmm", {"feature_fps": 0.0}), ("av-hmm", {"n_mfcc": 10**9}),
    ("av-hmm", {"max_iter": 10**12, "inversion_tol": 1e-300})])
def test_stored_settings_that_do_not_fit_the_arrays_are_one_line(method, params, fitted, split,
                                                                 tiny_db, tiny_corpus,
                                                                 tmp_path, capsys):
    """A stored model's description is someone else's data too: a context of 10**9 frames
    (or a step of 1e-12 s) would have the dry run build features for ever. Read as the
    model of ``synth --method`` and as a stored guide, it is one error line."""
    import json

    import pyarrow.parquet as pq

    from animegraph.baselines.stored import META_KEY

    small = SMALL.get(method, {"n_states": 3, "n_mix": 2, "n_iter": 5})  # av-hmm
    est = fitted.get(method) or make_estimator(method, **small).fit(split[0])
    db = tmp_path / "db"
    shutil.copytree(tiny_db[0], db, ignore=AS_INGESTED)
    path = save_model(est, db)
    table = pq.read_table(path)
    meta = json.loads(table.schema.metadata[META_KEY])
    meta["params"] |= params
    pq.write_table(table.replace_schema_metadata({META_KEY: json.dumps(meta).encode()}), path)
    wav = sorted((tiny_corpus / "clips").glob("*_neutral_1.wav"))[0]
    from animegraph.synthesis.guide import GUIDES

    for flags in (["--method", method], ["--guide", method, "--phones-engine", "pocketsphinx"]
                  )[:2 if method in GUIDES else 1]:
        out = tmp_path / "out.npz"
        assert main(["synth", str(wav), "--db", str(db), *flags, "-o", str(out)]) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert err[-1].startswith("animegraph: error:") and not out.exists(), err
        assert not any("Traceback" in e for e in err)


def test_gmm_loglik_equals_one_component_at_a_time():
    # mu-mlp's mixtures are scored with all components stacked in one call each: the same
    # factorisation and solve per component as a call a component, bit for bit.
    from animegraph.baselines.mu_mlp_forward import gmm_loglik

    def one_at_a_time(x, g):
        d = x.shape[1]
        parts = []
        for w, mu, cov in zip(g["weights"], g["means"], g["covariances"], strict=True):
            chol = np.linalg.cholesky(cov)
            sol = np.linalg.solve(chol, (x - mu).T)
            logdet = 2.0 * np.log(np.diag(chol)).sum()
            parts.append(np.log(w) - 0.5 * (d * np.log(2 * np.pi) + logdet
                                            + (sol**2).sum(axis=0)))
        stacked = np.stack(parts, axis=1)
        top = stacked.max(axis=1)
        return top + np.log(np.exp(stacked - top[:, None]).sum(axis=1))

    rng = np.random.default_rng(0)
    for k, d, n in [(1, 13, 1), (4, 13, 40), (8, 13, 7), (3, 5, 200)]:
        a = rng.standard_normal((k, d, d))
        g = {"weights": rng.dirichlet(np.ones(k)), "means": rng.standard_normal((k, d)),
             "covariances": a @ a.transpose(0, 2, 1) + d * np.eye(d)}
        x = rng.standard_normal((n, d))
        got = gmm_loglik(x, g)
        assert got.shape == (n,)
        np.testing.assert_array_equal(got, one_at_a_time(x, g))


def test_mixtures_factorised_once_score_as_each_mixture_alone():
    # mu-mlp's classifier scores all its mixtures in one stacked solve with factors
    # computed once: bit for bit each mixture's own gmm_loglik, for mixtures of
    # different sizes, and after its mixtures are replaced (refitted) the new ones.
    from animegraph.baselines.mu_mlp_forward import (
        Mixtures,
        MuMlpForward,
        gmm_loglik,
        mixtures_loglik,
    )

    rng = np.random.default_rng(1)
    d = 13

    def mixture(k):
        a = rng.standard_normal((k, d, d))
        return {"weights": rng.dirichlet(np.ones(k)), "means": rng.standard_normal((k, d)),
                "covariances": a @ a.transpose(0, 2, 1) + d * np.eye(d)}

    gmms = [mixture(k) for k in (1, 4, 8, 3)]
    for n in (1, 9, 60):
        x = rng.standard_normal((n, d))
        got = mixtures_loglik(x, Mixtures(gmms))
        assert got.shape == (n, len(gmms))
        np.testing.assert_array_equal(got, np.stack([gmm_loglik(x, g) for g in gmms], axis=1))

    model = MuMlpForward()
    model.n_mfcc, model.context = d, 0
    x = rng.standard_normal((30, d))
    for gmms in ([mixture(2), mixture(5)], [mixture(3), mixture(1), mixture(4)]):
        model.gmms_ = gmms
        want = np.argmax(np.stack([gmm_loglik(x, g) for g in gmms], axis=1), axis=1)
        np.testing.assert_array_equal(model._classify(x), want)
