"""``mu-mlp``: Motion Units and phoneme-class MLPs, after Hong, Wen & Huang (2002).

P. Hong, Z. Wen, T. S. Huang, "Real-time speech-driven face animation with expressions
using neural networks", IEEE Trans. Neural Networks 13(4), 2002
(``../shared/papers/hong2002-*.txt``).

* §IV-A, Motion Units (MUs) by PCA of facial deformations: the *utterance* MUs ``M0``
  are the mean ``m00`` and the first ``A0`` eigenvectors of the neutral frames
  (:data:`N_UTTERANCE_MUS` = 7, 97.56 % of the variance in the paper); for each
  expression k the residual beyond ``M0`` (Eq. 1) gets its own PCA, the *expression*
  MUs ``Mk`` (:data:`N_EXPRESSION_MUS` = 2 each). A frame's MU parameters (MUPs) are its
  coordinates: UMUPs (on ``M0``) and EMUPs (on ``Mk``).
* §VI-A, audio-to-UMUP: audio features are :data:`N_MFCC` = 10 MFCCs per frame with
  :data:`CONTEXT` = 3 frames each side at :data:`FRAME_RATE` = 30 fps (≈ 100 ms of
  delay); the neutral data are split into subsets, one per phoneme (44 in the paper),
  each modelled by a Gaussian mixture on the audio; every sample goes to the subset whose
  mixture scores its audio highest, and each subset gets a three-layer perceptron
  (15–25 hidden units, :data:`SUBSET_HIDDEN`). At synthesis a frame's audio picks the
  subset, whose MLP estimates the UMUPs.
* §VI-B, audio-to-UMUP+EMUP: for each expression k the subset MLPs estimate UMUPs of
  that expression's frames, and one MLP ``Υk`` (:data:`EXPRESSION_HIDDEN` = 30 hidden
  units) maps them to the final UMUPs and EMUPs.
* §VII-A: evaluation by Pearson R (Eq. 6) and MSE (Eq. 8) of normalised displacements:
  :func:`animegraph.motion.measures.hong_r`, :func:`~animegraph.motion.measures.hong_nmse`.

Choices the paper leaves open (ours): the phoneme classes are the phone labels present
in the training data (ARPAbet 39 + SIL, not the paper's 44); a class with fewer than
:data:`MIN_SUBSET_FRAMES` frames gets no mixture of its own; a subset whose MLP would
have more parameters than it has frames, or fewer than ``MIN_SUBSET_FRAMES`` frames,
falls back to one MLP fitted on all neutral frames (the *pooled* MLP); the subset's
hidden units grow from 15 to 25 with its size (log scale); MLPs use tanh units and L-BFGS
(scikit-learn's ``MLPRegressor``, at most :data:`MLP_MAX_ITER` iterations, in float32:
:data:`MLP_DTYPE`), inputs and outputs standardised; the MUs from the eigenvectors of the
frames' Gram matrix (:func:`principal_axes`). Deformations are the database's channels
relative to the neutral mean. With no clip labelled :data:`NEUTRAL` but a single emotion
label (real corpora without labels), that label's clips are the neutral data; otherwise a
missing neutral set is an error.
"""

from __future__ import annotations

import warnings
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from sklearn.exceptions import ConvergenceWarning
from sklearn.mixture import GaussianMixture
from sklearn.neural_network import MLPRegressor

from animegraph.baselines.base import BaselineModel, check_enough, sample_times
from animegraph.baselines.data import TrainingSet, phone_at
from animegraph.baselines.mu_mlp_forward import MuMlpForward
from db.errors import DataError, ParameterError
from db.system import usable_cpus

#: Utterance MUs kept, A0 (§IV-A: 7, 97.56 % of the neutral deformation variance).
N_UTTERANCE_MUS = 7
#: Expression MUs per expression, Ak (§IV-A: 2, ≥ 98.13 % of the residual).
N_EXPRESSION_MUS = 2
#: MFCCs per audio frame (§VI).
N_MFCC = 10
#: Context frames each side (§VI-A: 3 backward, current, 3 forward).
CONTEXT = 3
#: Audio-visual frame rate of the paper's data (§VI, §VII-A: 30 fps).
FRAME_RATE = 30.0
#: Number of subsets in the paper (§VI-A, footnote 2: one per phoneme of its 44-phoneme set).
PAPER_SUBSETS = 44
#: Hidden units of the subset MLPs, smallest and largest (§VI-A: 15 and 25).
SUBSET_HIDDEN = (15, 25)
#: Hidden units of each expression MLP Υk (§VI-B: thirty).
EXPRESSION_HIDDEN = 30
#: Label of the neutral clips the utterance MUs and subset MLPs are learned from.
NEUTRAL = "neutral"
#: Ours: Gaussians per subset mixture; frames a class needs for its own mixture and MLP.
GMM_COMPONENTS = 2
MIN_SUBSET_FRAMES = 40
#: Ours: MLP training (L2 penalty on standardised data, L-BFGS iterations, tanh units).
MLP_ALPHA = 1e-2
MLP_MAX_ITER = 400
#: Ours: the perceptrons' training precision. float32 halves the products' cost, most of
#: the fit on a large database; "float64" is the fit before that choice.
MLP_DTYPE = "float32"


def mlp_params(n_in: int, n_hidden: int, n_out: int) -> int:
    """Weights and biases of a three-layer perceptron."""
    return (n_in + 1) * n_hidden + (n_hidden + 1) * n_out


def principal_axes(centred: np.ndarray, k: int) -> tuple[np.ndarray, float]:
    """The first ``k`` principal axes of ``centred`` rows, and the share of the variance
    they hold.

    From the eigendecomposition of the p x p matrix ``XᵀX``, not an SVD of the n x p
    data: the same axes (to rounding) at a fraction of the cost on many frames (GRID
    s1's 72,000 neutral frames of 1,411 channels: 2.7 CPU-s against 21.6). Each axis's
    sign is fixed so that its largest coordinate is positive (an SVD's is arbitrary).

    Parameters
    ----------
    centred : np.ndarray, shape (n_samples, n_features)
    k : int

    Returns
    -------
    axes : np.ndarray, shape (n_features, min(k, n_samples, n_features))
    share : float
    """
    values, vectors = np.linalg.eigh(centred.T @ centred)
    values, vectors = np.maximum(values[::-1], 0.0), vectors[:, ::-1]
    k = min(k, *centred.shape)
    axes = vectors[:, :k]
    axes = axes * np.where(axes[np.abs(axes).argmax(axis=0), np.arange(k)] < 0, -1.0, 1.0)
    return axes, float(values[:k].sum() / max(values.sum(), 1e-300))


class MuMlp(MuMlpForward, BaselineModel):
    """Hong et al. (2002) iFACE audio-to-MUP mapping (see the module docstring).

    Parameters
    ----------
    n_utterance_mus, n_expression_mus : int
        A0 and Ak of §IV-A.
    n_mfcc, context : int
        Audio features of §VI-A.
    frame_rate : float
        Rate (frames/s) of training samples and of the context window.
    subset_hidden : tuple of int
        (smallest, largest) hidden units of the subset MLPs.
    expression_hidden : int
        Hidden units of each expression MLP.
    neutral : str
        Emotion label of the utterance (neutral) data.
    random_state : int
        Seed of the mixtures and MLPs.
    mlp_dtype : {"float32", "float64"}
        Precision the perceptrons are trained in (:data:`MLP_DTYPE`).
    """

    method = "mu-mlp"

    def __init__(self, n_utterance_mus: int = N_UTTERANCE_MUS,
                 n_expression_mus: int = N_EXPRESSION_MUS, n_mfcc: int = N_MFCC,
                 context: int = CONTEXT, frame_rate: float = FRAME_RATE,
                 subset_hidden: tuple[int, int] = SUBSET_HIDDEN,
                 expression_hidden: int = EXPRESSION_HIDDEN, neutral: str = NEUTRAL,
                 random_state: int = 0, mlp_dtype: str = MLP_DTYPE):
        self.n_utterance_mus = n_utterance_mus
        self.n_expression_mus = n_expression_mus
        self.n_mfcc = n_mfcc
        self.context = context
        self.frame_rate = frame_rate
        self.subset_hidden = subset_hidden
        self.expression_hidden = expression_hidden
        self.neutral = neutral
        self.random_state = random_state
        self.mlp_dtype = mlp_dtype

    # -- fitting ---------------------------------------------------------------------
    def _samples(self, clips):
        """Audio features (n, n_feat), motion (n, n_channels), phone labels at frame_rate."""
        feats, motion, phones = [], [], []
        for clip, times, m in sample_times(clips, self.frame_rate):
            feats.append(self._features(clip.audio, clip.sample_rate, times))
            motion.append(m)
            phones += phone_at(clip.phones, times)
        return np.concatenate(feats), np.concatenate(motion), np.array(phones)

    def _check_params(self) -> None:
        lo, hi = (tuple(self.subset_hidden) + (0, 0))[:2]
        checks = (("n_utterance_mus", self.n_utterance_mus), ("n_expression_mus",
                  self.n_expression_mus), ("n_mfcc", self.n_mfcc),
                  ("expression_hidden", self.expression_hidden), ("subset_hidden", lo))
        for name, value in checks:
            if not isinstance(value, int | np.integer) or value < 1:
                raise ParameterError(f"{name} must be a positive integer, got {value!r}")
        if len(tuple(self.subset_hidden)) != 2 or hi < lo:
            raise ParameterError(f"subset_hidden must be (smallest, largest), got "
                                 f"{self.subset_hidden!r}")
        if self.mlp_dtype not in ("float32", "float64"):
            raise ParameterError(f"mlp_dtype must be float32 or float64, got {self.mlp_dtype!r}")
        if not self.frame_rate > 0 or self.context < 0:
            raise ParameterError("frame_rate must be positive and context >= 0")

    def _neutral_label(self, data: TrainingSet) -> str:
        if data.of_emotion(self.neutral):
            return self.neutral
        if len(data.emotions) == 1:
            return data.emotions[0]
        raise DataError(f"mu-mlp learns its utterance MUs from {self.neutral!r} clips "
                        f"(Hong et al. §IV-A) and the data has none (it has "
                        f"{', '.join(data.emotions)})")

    def _fit(self, data: TrainingSet) -> None:
        # An iteration cap reached is not an error here. Set once around the whole fit:
        # the perceptrons are fitted on threads, and catch_warnings is not thread-safe.
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            self._fit_all(data)

    def _fit_all(self, data: TrainingSet) -> None:
        self._check_params()
        rng = np.random.RandomState(self.random_state)
        neutral = self._neutral_label(data)
        self.neutral_ = neutral
        x0, d0, ph0 = self._samples(data.of_emotion(neutral))
        a0 = self.n_utterance_mus
        check_enough(len(d0), a0 + 1, f"{a0} utterance MUs (PCA)")
        # §IV-A: utterance MUs.
        self.m00_ = d0.mean(axis=0)
        d0 -= self.m00_  # in place: GRID s1's neutral frames are 0.8 GB
        self.m0_, self.utterance_variance_ = principal_axes(d0, a0)  # (n_channels, A0)
        a0 = self.m0_.shape[1]
        u0 = d0 @ self.m0_
        del d0
        self.x_mean_, self.x_std_ = x0.mean(axis=0), x0.std(axis=0) + 1e-8
        z0 = (x0 - self.x_mean_) / self.x_std_
        self.u_mean_, self.u_std_ = u0.mean(axis=0), u0.std(axis=0) + 1e-8
        # §VI-A: subsets by per-phoneme Gaussian mixtures on the current frame's audio.
        self.gmms_ = self._fit_mixtures(self._current(z0), ph0, rng)
        subset = self._classify(z0)
        self.subset_frames_ = np.bincount(subset, minlength=len(self.gmms_))
        u0n = (u0 - self.u_mean_) / self.u_std_
        lo, hi = self.subset_hidden
        check_enough(len(z0), mlp_params(z0.shape[1], lo, a0),
                     f"mu-mlp's speech-to-face network (the paper's pooled audio-to-UMUP "
                     f"MLP) on the {neutral!r} clips", rate=self.frame_rate)
        # The pooled MLP and every subset's own, each with the seed it would have had
        # fitted one after another, on one thread a core: the products release the GIL
        # (GRID s1: 15 CPU-s of perceptrons, most of the fit).
        jobs = [(z0, u0n, lo)]
        sizes = self.subset_frames_
        span = np.log(max(sizes.max(), 2)) - np.log(MIN_SUBSET_FRAMES)
        own = []
        for i, n in enumerate(sizes):
            hidden = lo + int(round((hi - lo) * np.clip(
                (np.log(max(n, 1)) - np.log(MIN_SUBSET_FRAMES)) / max(span, 1e-9), 0, 1)))
            if n < MIN_SUBSET_FRAMES or n < mlp_params(z0.shape[1], hidden, a0):
                continue  # documented fallback: the pooled MLP
            mask = subset == i
            jobs.append((z0[mask], u0n[mask], hidden))
            own.append(i)
        seeds = [rng.randint(2**31 - 1) for _ in jobs]
        with ThreadPoolExecutor(min(usable_cpus(), len(jobs)),
                                thread_name_prefix="mu-mlp") as pool:
            nets = list(pool.map(lambda job: self._fit_mlp(*job[0], seed=job[1]),
                                 zip(jobs, seeds, strict=True)))
        self.pooled_mlp_ = nets[0]
        self.subset_mlps_ = [None] * len(sizes)
        for i, net in zip(own, nets[1:], strict=True):
            self.subset_mlps_[i] = net
        # §IV-A and §VI-B: expression MUs and the UMUP -> UMUP+EMUP MLPs.
        self.expressions_ = {}
        for emotion in data.emotions:
            if emotion == neutral:
                continue
            xk, dk, _ = self._samples(data.of_emotion(emotion))
            ak = self.n_expression_mus
            n_params = mlp_params(a0, self.expression_hidden, a0 + ak)
            check_enough(len(dk), n_params, f"the {emotion} expression MLP")
            uk = (dk - self.m00_) @ self.m0_
            rk = dk - self.m00_ - uk @ self.m0_.T  # Eq. 1, residual beyond M0
            mk0 = rk.mean(axis=0)
            rk -= mk0
            mk, _ = principal_axes(rk, ak)
            vk = np.hstack([uk, rk @ mk])
            est = self._utterance_mups((xk - self.x_mean_) / self.x_std_)
            v_mean, v_std = vk.mean(axis=0), vk.std(axis=0) + 1e-8
            net = self._fit_mlp((est - self.u_mean_) / self.u_std_, (vk - v_mean) / v_std,
                                self.expression_hidden, seed=rng.randint(2**31 - 1))
            self.expressions_[emotion] = {"mk0": mk0, "mk": mk, "v_mean": v_mean,
                                          "v_std": v_std, **net}

    def _fit_mixtures(self, z: np.ndarray, phones: np.ndarray, rng) -> list[dict]:
        out = []
        for phone in sorted(set(phones.tolist())):
            sel = z[phones == phone]
            k = min(GMM_COMPONENTS, len(sel) // (4 * z.shape[1]) or 1)
            if len(sel) < MIN_SUBSET_FRAMES:
                continue
            gm = GaussianMixture(n_components=k, covariance_type="full", reg_covar=1e-3,
                                 random_state=rng.randint(2**31 - 1)).fit(sel)
            out.append({"weights": gm.weights_, "means": gm.means_,
                        "covariances": gm.covariances_})
        if not out:
            raise DataError(f"too little data for mu-mlp: no phoneme class has "
                            f"{MIN_SUBSET_FRAMES} frames at {self.frame_rate:g} fps")
        return out

    def _fit_mlp(self, x, y, hidden, *, seed: int) -> dict:
        x, y = x.astype(self.mlp_dtype), y.astype(self.mlp_dtype)
        net = MLPRegressor(hidden_layer_sizes=(int(hidden),), activation="tanh",
                           solver="lbfgs", alpha=MLP_ALPHA, max_iter=MLP_MAX_ITER,
                           random_state=seed)
        net.fit(x, y if y.shape[1] > 1 else y.ravel())  # warnings: see _fit
        return {"W0": net.coefs_[0], "b0": net.intercepts_[0],
                "W1": net.coefs_[1], "b1": net.intercepts_[1]}

    # -- prediction: MuMlpForward (NumPy only, animegraph.baselines.mu_mlp_forward) --

    # -- storage ---------------------------------------------------------------------
    def _arrays(self) -> dict[str, np.ndarray]:
        out = {"m00": self.m00_, "m0": self.m0_, "x_mean": self.x_mean_, "x_std": self.x_std_,
               "u_mean": self.u_mean_, "u_std": self.u_std_,
               "utterance_variance": np.array(self.utterance_variance_),
               "subset_frames": self.subset_frames_,
               "neutral_index": np.array(self.emotions_.index(self.neutral_))}
        for i, g in enumerate(self.gmms_):
            out |= {f"gmm/{i:03d}/{k}": v for k, v in g.items()}
        for k, v in self.pooled_mlp_.items():
            out[f"pooled/{k}"] = v
        for i, net in enumerate(self.subset_mlps_):
            for k, v in (net or {}).items():
                out[f"subset/{i:03d}/{k}"] = v
        for emotion, e in self.expressions_.items():
            out |= {f"expr/{emotion}/{k}": v for k, v in e.items()}
        return out
