"""mu-mlp's prediction (Hong, Wen & Huang 2002, §VI) from its stored arrays, NumPy only.

:class:`MuMlpForward` is the prediction half of :class:`animegraph.baselines.mu_mlp.MuMlp`:
a frame's MFCCs with context pick the phoneme subset whose Gaussian mixture scores them
highest (§VI-A), its perceptron (or the pooled one) estimates the utterance MUPs, and an
expression's perceptron maps those to UMUPs and EMUPs (§VI-B). :class:`StoredMuMlp`
restores a stored model (:func:`animegraph.baselines.base.save_model`) without
scikit-learn, so that a one-shot ``synth`` guided by mu-mlp
(:mod:`animegraph.synthesis.guide`) does not import it (tests/test_startup.py).
"""

from __future__ import annotations

import numpy as np

from animegraph.baselines.data import audio_features_at
from animegraph.baselines.predicting import Stored


def mlp_forward(x: np.ndarray, weights: list[np.ndarray], biases: list[np.ndarray]) -> np.ndarray:
    """Forward pass of a tanh MLP with a linear output layer.

    ``x`` shape (n, n_in); ``weights[i]`` (n_i, n_{i+1}); returns (n, n_out).
    """
    h = x
    for i, (w, b) in enumerate(zip(weights, biases, strict=True)):
        h = h @ w + b
        if i < len(weights) - 1:
            h = np.tanh(h)
    return h


def gmm_loglik(x: np.ndarray, g: dict) -> np.ndarray:
    """Log-likelihood of rows of ``x`` (n, d) under a full-covariance Gaussian mixture
    (``weights`` (k,), ``means`` (k, d), ``covariances`` (k, d, d)); shape (n,)."""
    return mixtures_loglik(x, Mixtures([g]))[:, 0]


class Mixtures:
    """Gaussian mixtures (dicts as :func:`gmm_loglik` takes) factorised once: each
    component's Cholesky factor, log-determinant and log-weight, all mixtures'
    components stacked. A live stream classifies every window's frames with the same
    mixtures; factorising them again on each call was a quarter of the scoring."""

    def __init__(self, gmms) -> None:
        chol = [np.linalg.cholesky(np.asarray(g["covariances"])) for g in gmms]  # (k, d, d)
        self.chol = np.concatenate(chol)
        self.means = np.concatenate([np.asarray(g["means"]) for g in gmms])
        self.logdet = [2.0 * np.log(np.diagonal(c, axis1=1, axis2=2)).sum(axis=1)
                       for c in chol]  # (k,) each
        self.log_weights = [np.log(np.asarray(g["weights"])) for g in gmms]
        self.bounds = np.cumsum([0] + [len(c) for c in chol])


def mixtures_loglik(x: np.ndarray, mixtures: Mixtures) -> np.ndarray:
    """Log-likelihood of rows of ``x`` (n, d) under each of ``mixtures``: shape
    (n, n_mixtures)."""
    d = x.shape[1]
    # All components of all mixtures in one stacked solve (the same factorisation and
    # solve per component as one call a component): the calls' overhead was most of the
    # time on a live window's few frames.
    sol = np.linalg.solve(mixtures.chol, (x[None] - mixtures.means[:, None]).transpose(0, 2, 1))
    quad = (sol**2).sum(axis=1)  # (k_total, n)
    out = []
    for i, (logdet, log_w) in enumerate(zip(mixtures.logdet, mixtures.log_weights,
                                            strict=True)):
        a, b = mixtures.bounds[i], mixtures.bounds[i + 1]
        stacked = (log_w[:, None] - 0.5 * (d * np.log(2 * np.pi) + logdet[:, None]
                                           + quad[a:b])).T
        top = stacked.max(axis=1)
        out.append(top + np.log(np.exp(stacked - top[:, None]).sum(axis=1)))
    return np.stack(out, axis=1)


class MuMlpForward:
    """Prediction from restored arrays (a mixin; see the module docstring).

    Needs the hyper-parameters ``n_mfcc``, ``context``, ``frame_rate`` and ``emotions_``;
    :meth:`_restore` sets the learned state.
    """

    def _features(self, audio, sample_rate, times) -> np.ndarray:
        return audio_features_at(audio, sample_rate, times, n_mfcc=self.n_mfcc,
                                 context=self.context, context_hop_s=1.0 / self.frame_rate)

    def _current(self, z: np.ndarray) -> np.ndarray:
        """The current frame's MFCCs (the middle block of the context window)."""
        c = self.context * self.n_mfcc
        return z[:, c:c + self.n_mfcc]

    def _classify(self, z: np.ndarray) -> np.ndarray:
        """Index of the subset whose mixture gives the highest log-likelihood."""
        kept = getattr(self, "_mixtures", None)
        if kept is None or kept[0] is not self.gmms_:  # factorised once per fitted set
            kept = self._mixtures = (self.gmms_, Mixtures(self.gmms_))
        return np.argmax(mixtures_loglik(self._current(z), kept[1]), axis=1)

    def _utterance_mups(self, z: np.ndarray) -> np.ndarray:
        """Estimated UMUPs (n, A0) of standardised audio features ``z``."""
        subset = self._classify(z)
        out = _forward(self.pooled_mlp_, z)
        for i, net in enumerate(self.subset_mlps_):
            mask = subset == i
            if net is not None and mask.any():
                out[mask] = _forward(net, z[mask])
        return out * self.u_std_ + self.u_mean_

    def _predict(self, audio, sample_rate, times, emotion):
        z = (self._features(audio, sample_rate, times) - self.x_mean_) / self.x_std_
        u = self._utterance_mups(z)
        if emotion is None or emotion == self.neutral_ or emotion not in self.expressions_:
            return self.m00_ + u @ self.m0_.T
        e = self.expressions_[emotion]
        v = _forward(e, (u - self.u_mean_) / self.u_std_) * e["v_std"] + e["v_mean"]
        a0 = self.m0_.shape[1]
        return self.m00_ + v[:, :a0] @ self.m0_.T + e["mk0"] + v[:, a0:] @ e["mk"].T

    def _restore(self, arrays: dict[str, np.ndarray]) -> None:
        # Checked before any prediction: a stored context out of step with the features'
        # mean (e.g. a context of 10**9 frames) would build features no weight reads.
        width = self.n_mfcc * (2 * self.context + 1)
        if not (self.n_mfcc >= 1 and self.context >= 0 and np.isfinite(self.frame_rate)
                and self.frame_rate > 0 and np.shape(arrays["x_mean"]) == (width,)):
            raise ValueError(f"n_mfcc {self.n_mfcc}, context {self.context} and frame rate "
                             f"{self.frame_rate} do not fit its features' mean of shape "
                             f"{np.shape(arrays['x_mean'])}")
        for name in ("m00", "m0", "x_mean", "x_std", "u_mean", "u_std"):
            setattr(self, f"{name}_", arrays[name])
        self.utterance_variance_ = float(arrays["utterance_variance"])
        self.subset_frames_ = arrays["subset_frames"].astype(np.int64)
        self.neutral_ = self.emotions_[int(arrays["neutral_index"])]
        self.gmms_ = [group(arrays, f"gmm/{i:03d}/") for i in range(len(self.subset_frames_))]
        self.pooled_mlp_ = group(arrays, "pooled/")
        self.subset_mlps_ = [group(arrays, f"subset/{i:03d}/") or None
                             for i in range(len(self.subset_frames_))]
        self.expressions_ = {e: group(arrays, f"expr/{e}/") for e in self.emotions_
                             if group(arrays, f"expr/{e}/")}


class StoredMuMlp(MuMlpForward, Stored):
    """A stored mu-mlp model that predicts (:meth:`Predicting.predict`) without
    scikit-learn; built by :meth:`Stored.from_arrays` from what
    :func:`animegraph.baselines.base.save_model` wrote."""

    method = "mu-mlp"

    def _set_params(self, params: dict) -> None:
        self.n_mfcc, self.context = int(params["n_mfcc"]), int(params["context"])
        self.frame_rate = float(params["frame_rate"])


def group(arrays: dict[str, np.ndarray], prefix: str) -> dict[str, np.ndarray]:
    """The arrays named ``prefix...``, keyed by the rest of their names."""
    return {k[len(prefix):]: v for k, v in arrays.items() if k.startswith(prefix)}


def _forward(net: dict, x: np.ndarray) -> np.ndarray:
    y = mlp_forward(x, [net["W0"], net["W1"]], [net["b0"], net["b1"]])
    return y if y.ndim == 2 else y[:, None]
