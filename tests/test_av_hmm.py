"""The av-hmm baseline (Terissi et al. 2013): training, HMM inversion (Eq. 7), storage."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from animegraph.baselines.av_hmm import AVHMM, forward_backward, n_free_parameters
from db.errors import DataError, ParameterError


def _linear_gaussian(rng, n_seq=12, length=120, n_states=3):
    """Sequences from a 3-state Markov chain: audio = state mean + noise (3-D); visual =
    a fixed linear map of the audio + a state offset + small noise (2-D)."""
    means = np.array([[0.0, 0.0, 0.0], [3.0, -2.0, 1.0], [-2.0, 3.0, -1.0]])[:n_states]
    offsets = np.array([[0.0, 0.0], [1.0, -1.0], [-1.0, 2.0]])[:n_states]
    lin = np.array([[1.0, 0.5, 0.0], [-0.5, 0.0, 1.0]])
    trans = np.full((n_states, n_states), 0.05 / (n_states - 1)) + np.eye(n_states) * (
        0.95 - 0.05 / (n_states - 1))
    seqs = []
    for _ in range(n_seq):
        s = [rng.integers(n_states)]
        for _ in range(length - 1):
            s.append(rng.choice(n_states, p=trans[s[-1]]))
        s = np.array(s)
        a = means[s] + rng.standard_normal((length, 3))
        v = a @ lin.T + offsets[s] + 0.1 * rng.standard_normal((length, 2))
        seqs.append((a, v))
    return seqs


@pytest.fixture(scope="module")
def data():
    return _linear_gaussian(np.random.default_rng(3))


@pytest.fixture(scope="module")
def fitted(data):
    return AVHMM(n_states=3, n_mix=1, n_iter=30, random_state=0).fit(data[:10])


def test_single_gaussian_inversion_is_the_conditional_mean(rng):
    # N = M = 1: Eq. 7 is the Gaussian conditional mean μv + Σva Σa⁻¹ (oa - μa), reached in
    # one update whatever the start.
    x = rng.standard_normal((400, 4)) @ rng.standard_normal((4, 4))
    model = AVHMM(n_states=1, n_mix=1, n_iter=2, init="random").fit([(x[:, :3], x[:, 3:])])
    z = (x - model.feature_mean_) / model.feature_scale_
    mu, cov = model.means_[0, 0], model.covars_[0, 0]
    expect_z = mu[3:] + (z[:, :3] - mu[:3]) @ np.linalg.solve(cov[:3, :3], cov[:3, 3:])
    got = model.invert(x[:50, :3])
    expect = expect_z[:50] * model.feature_scale_[3:] + model.feature_mean_[3:]
    np.testing.assert_allclose(got, expect, atol=1e-8)
    assert model.n_iter_ == 2  # the second update moves nothing


def test_inversion_recovers_a_linear_gaussian_relation(data, fitted):
    from animegraph.motion.measures import acc, amse

    for audio, visual in data[10:]:
        est = fitted.invert(audio)
        assert est.shape == visual.shape
        mean_only = np.broadcast_to(visual.mean(axis=0), visual.shape)
        assert amse(est, visual) < 0.1 < 0.9 < amse(mean_only + 1e-9, visual)
        assert acc(est, visual) > 0.95


def test_inversion_is_monotone_and_converges(data, fitted):
    for init in ("audio", "random"):
        model = AVHMM.from_arrays({**fitted.to_arrays(), "init": np.asarray(init)})
        model.invert(data[11][0])
        hist = np.array(model.history_)
        assert np.all(np.diff(hist) >= -1e-6 * np.abs(hist[:-1])), hist
        assert model.n_iter_ < model.max_iter


def test_random_and_audio_starts_agree(data, fitted):
    audio = data[10][0]
    est = fitted.invert(audio)
    rnd = AVHMM.from_arrays({**fitted.to_arrays(), "init": np.asarray("random")})
    np.testing.assert_allclose(rnd.invert(audio), est, atol=0.05)


def test_joint_likelihood_matches_hmmlearn(data, fitted):
    from hmmlearn.hmm import GMMHMM

    def reference(means, covars):
        ref = GMMHMM(n_components=3, n_mix=1, covariance_type="full", init_params="")
        ref.startprob_, ref.transmat_ = fitted.startprob_, fitted.transmat_
        ref.weights_, ref.means_, ref.covars_ = fitted.weights_, means, covars
        return ref

    audio, visual = data[10]
    z = (np.hstack([audio, visual]) - fitted.feature_mean_) / fitted.feature_scale_
    ref = reference(fitted.means_, fitted.covars_)
    assert fitted.score(audio, visual) == pytest.approx(ref.score(z), rel=1e-9)
    # The audio marginal: the audio block of every mean and covariance.
    ref = reference(fitted.means_[..., :3], fitted.covars_[..., :3, :3])
    assert fitted.score(audio) == pytest.approx(ref.score(z[:, :3]), rel=1e-9)


def test_baum_welch_is_monotone(data):
    model = AVHMM(n_states=2, n_mix=2, n_iter=8, tol=1e-9, reg_covar=1e-9).fit(data[:4])
    assert model.train_iter_ >= 2
    from animegraph.baselines import av_hmm

    hmm = av_hmm._hmm_class()(n_components=2, n_mix=2, covariance_type="full", n_iter=8,
                              tol=1e-9, random_state=0)
    hmm.reg_covar = 1e-9
    x = np.vstack([np.hstack(p) for p in data[:4]])
    hmm.fit((x - x.mean(0)) / x.std(0), [len(p[0]) for p in data[:4]])
    hist = np.array(hmm.monitor_.history)
    assert np.all(np.diff(hist) > -1e-6 * np.abs(hist[:-1])), hist


def test_em_step_through_hmmlearn_hooks_is_exact_em():
    """One Baum-Welch step of our GMMHMM subclass against stock hmmlearn and by hand.

    Guards the hmmlearn hooks we override (``_compute_log_likelihood``,
    ``_initialize/_accumulate_sufficient_statistics``, ``_do_mstep``; pinned to
    hmmlearn 0.3): start, transition, weight and mean updates must equal stock
    ``GMMHMM``'s, and the covariance must be the exact EM update around the new means
    (stock hmmlearn centres on the previous means and adds a prior).
    """
    from hmmlearn.hmm import GMMHMM
    from scipy.special import logsumexp
    from scipy.stats import multivariate_normal

    from animegraph.baselines import av_hmm

    rng = np.random.default_rng(0)
    x = rng.standard_normal((400, 3))
    x[200:] += 2.0
    lengths = [150, 250]
    init = GMMHMM(n_components=2, n_mix=2, covariance_type="full", random_state=0)
    init._init(x, lengths)

    def start(cls):
        m = cls(n_components=2, n_mix=2, covariance_type="full", n_iter=1, init_params="")
        for a in ("startprob_", "transmat_", "weights_", "means_", "covars_"):
            setattr(m, a, getattr(init, a).copy())
        return m

    ref, ours = start(GMMHMM), start(av_hmm._hmm_class())
    ours.reg_covar = 0.0
    gamma = ref.predict_proba(x, lengths)  # state posteriors under the initial model
    comp = np.array([[np.log(init.weights_[j, k]) + multivariate_normal(
        init.means_[j, k], init.covars_[j, k]).logpdf(x) for k in range(2)]
        for j in range(2)]).transpose(2, 0, 1)  # (T, N, M)
    w = gamma[:, :, None] * np.exp(comp - logsumexp(comp, axis=2, keepdims=True))
    ref.fit(x, lengths)
    ours.fit(x, lengths)
    for a in ("startprob_", "transmat_", "weights_", "means_"):
        np.testing.assert_allclose(getattr(ours, a), getattr(ref, a), atol=1e-10)
    for j in range(2):
        for k in range(2):
            d = x - ours.means_[j, k]
            want = (w[:, j, k, None] * d).T @ d / w[:, j, k].sum()
            np.testing.assert_allclose(ours.covars_[j, k], want, atol=1e-10)


def test_forward_backward_matches_brute_force(rng):
    n_t, n = 5, 3
    log_b = rng.normal(size=(n_t, n)) * 3
    start = rng.dirichlet(np.ones(n))
    trans = rng.dirichlet(np.ones(n), size=n)
    gamma, loglik = forward_backward(log_b, start, trans)
    import itertools

    joint = np.zeros((n_t, n))
    total = 0.0
    for path in itertools.product(range(n), repeat=n_t):
        p = start[path[0]] * np.exp(log_b[0, path[0]])
        for t in range(1, n_t):
            p *= trans[path[t - 1], path[t]] * np.exp(log_b[t, path[t]])
        total += p
        joint[np.arange(n_t), path] += p
    assert loglik == pytest.approx(np.log(total), rel=1e-10)
    np.testing.assert_allclose(gamma, joint / total, atol=1e-12)


def test_arrays_round_trip(data, fitted):
    arrays = fitted.to_arrays()
    assert all(isinstance(v, np.ndarray) and v.dtype != object for v in arrays.values())
    back = AVHMM.from_arrays(arrays)
    np.testing.assert_array_equal(back.invert(data[10][0]), fitted.invert(data[10][0]))
    broken = dict(arrays)
    del broken["covars"]
    with pytest.raises(DataError, match="covars"):
        AVHMM.from_arrays(broken)
    broken = {**arrays, "transmat": arrays["transmat"][:2]}
    with pytest.raises(DataError, match="transmat"):
        AVHMM.from_arrays(broken)


def test_too_little_data(rng):
    a, v = rng.standard_normal((30, 77)), rng.standard_normal((30, 4))
    assert n_free_parameters(28, 5, 81) > a.size + v.size
    with pytest.raises(DataError, match="fewer than the .* free parameters"):
        AVHMM().fit([(a, v)])


def test_bad_input(rng, fitted):
    with pytest.raises(ParameterError, match="n_states"):
        AVHMM(n_states=0).fit([(np.zeros((9, 1)), np.zeros((9, 1)))])
    with pytest.raises(ParameterError, match="same number"):
        AVHMM(n_states=1, n_mix=1).fit([(np.zeros((9, 1)), np.zeros((8, 1)))])
    with pytest.raises(ParameterError, match="shape"):
        fitted.invert(np.zeros((5, 4)))
    with pytest.raises(DataError, match="NaN"):
        fitted.invert(np.full((5, 3), np.nan))
    with pytest.raises(ParameterError, match="not fitted"):
        AVHMM().invert(np.zeros((5, 3)))


# --- the estimator on a motion database -----------------------------------------------
@pytest.fixture(scope="module")
def small_baseline(tiny_db):
    from animegraph.baselines.av_hmm import AVHMMBaseline

    path, _ = tiny_db
    return AVHMMBaseline(n_states=3, n_mix=2, n_iter=5).fit(path), path


def test_baseline_predicts_motion(small_baseline):
    from animegraph.baselines.data import training_set

    model, path = small_baseline
    clip = training_set(path).clips[0]
    pred = model.predict(clip.audio, clip.sample_rate, n_frames=clip.n_frames)
    assert pred.shape == clip.motion.shape and np.isfinite(pred).all()
    # The visual vector is 4 PCA components; the audio 11 non-DC MFCCs x 7 frames.
    assert model.components_.shape == (4, len(model.channels_))
    assert model.hmm_.n_audio_ == 77 and model.hmm_.n_visual_ == 4
    audio = model.audio_vectors(clip.audio, clip.sample_rate, np.arange(10) / 30.0)
    from animegraph.baselines.data import audio_features_at

    full = audio_features_at(clip.audio, clip.sample_rate, np.arange(10) / 30.0, n_mfcc=12,
                             context=3, context_hop_s=1 / 30.0)
    np.testing.assert_array_equal(audio[:, :11], full[:, 1:12])  # c0 dropped
    np.testing.assert_array_equal(audio[:, 33:44], full[:, 37:48])  # the centre frame


def test_baseline_beats_the_mean_pose_on_training_audio(small_baseline):
    from animegraph.baselines.data import training_set
    from animegraph.motion.measures import acc

    model, path = small_baseline
    rs = []
    for clip in training_set(path).clips[:6]:
        pred = model.predict(clip.audio, clip.sample_rate, n_frames=clip.n_frames)
        rs.append(acc((pred - model.motion_mean_) @ model.components_[:1].T,
                      (clip.motion - model.motion_mean_) @ model.components_[:1].T))
    assert np.mean(rs) > 0.3, rs


def test_baseline_stored_as_arrays(small_baseline, tmp_path):
    from animegraph.baselines.av_hmm import AVHMMBaseline
    from animegraph.baselines.base import read_model, save_model
    from animegraph.baselines.data import training_set

    model, path = small_baseline
    arrays = model.to_arrays()
    assert all(v.dtype == np.float64 for v in arrays.values())
    back = AVHMMBaseline.from_arrays(arrays, model.describe())
    clip = training_set(path).clips[1]
    np.testing.assert_allclose(back.predict(clip.audio, clip.sample_rate),
                               model.predict(clip.audio, clip.sample_rate))
    db = tmp_path / "db"  # a copy: the session's database stays as ingested
    shutil.copytree(path, db)
    stored = read_model(save_model(model, db))
    assert isinstance(stored, AVHMMBaseline) and stored.get_params() == model.get_params()
    bad = {**arrays, "components": arrays["components"][:, :-1]}
    with pytest.raises(DataError, match="PCA and channels"):
        AVHMMBaseline.from_arrays(bad, model.describe())
    with pytest.raises(DataError, match="channels"):
        model.check_channels(model.channels_[:-1])


def test_baseline_too_little_data(tiny_db):
    from animegraph.baselines.av_hmm import AVHMMBaseline
    from animegraph.baselines.data import training_set

    data = training_set(tiny_db[0])
    one = type(data)(clips=data.clips[:1], names=data.names, groups=data.groups,
                     kind=data.kind, fps=data.fps)
    with pytest.raises(DataError, match="free parameters"):
        AVHMMBaseline().fit(one)
