"""``hier-pca``: a hierarchical non-linear speech-appearance model, after Cosker et al.

D. Cosker, D. Marshall, P. Rosin, Y. Hicks, "Hierarchical non-linear speech-appearance
model for video-realistic facial animation" (``../shared/papers/cosker-*.txt``).

* §2, §5: a hierarchy of facial areas — the whole face at the root, the mouth as a
  sub-node; each node synthesises its area from speech and the sub-node's result
  replaces the root's mouth region. Here the mouth is the database's ``lips`` motion
  group (:func:`animegraph.motion.measures.lip_channels`: lip markers or landmarks; jaw, mouth
  and lip curves).
* §4.1: per node an appearance model; our analogue is a PCA of the node's motion
  channels (:data:`APPEARANCE_VARIANCE` of the variance kept), giving appearance
  parameters ``c``.
* §4.2: the distribution of ``c`` is modelled by a mixture of Gaussians initialised by
  k-means, :data:`N_CLUSTERS` ≈ 60 clusters.
* §4.3: speech vectors (Mel-cepstra, :data:`N_MFCC` per frame, every 40 ms —
  :data:`FRAME_RATE` = 25 fps) are reduced by PCA to speech parameters ``s`` (Eq. 4); the
  concatenation ``M = [W s; c]`` (``W`` the ratio of the appearance and speech
  eigen-variances, Eq. 6) of each cluster's frames gets its own PCA (Eq. 7).
* §4.4: at synthesis the cluster whose mean speech parameter is nearest in Mahalanobis
  distance (Eq. 8, the covariance of the speech training set) is chosen; the speech part
  of its eigenvectors gives the speech-appearance parameter ``d``, the appearance part
  gives ``c`` (Eq. 9), clamped to ±3 s.d. of the cluster (:data:`CLAMP_SD`). The
  equation for ``d`` is lost in our copy of the paper; we take the mean of ``d`` given
  the speech under the cluster's joint PCA read as a probabilistic PCA, the discarded
  modes' variance as isotropic noise (:func:`_speech_to_d`). Conditioning the truncated
  model without that noise fits ``d`` to the speech by least squares and extrapolates: on
  the synthetic corpus Eq. 9 then explained -350 % (face) and -850 % (mouth) of the
  within-cluster appearance variance on the training frames themselves, against +20 % and
  +37 % with the noise term (docs/results/lipsync.md, "Baseline settings").
* §4.5: local averaging of the synthesised frames (:data:`AVERAGE_FRAMES`).

Choices the paper leaves open, and fallbacks (ours): the number of Mel-cepstra (12) and
the share of variance the PCAs keep; ``W`` as one scalar (the square root of the ratio
of total variances, as in Cootes' combined appearance models); clusters are the hard
assignments of the mixture. The number of clusters is capped at the frames available
(:data:`MIN_CLUSTER_FRAMES` per cluster, the paper's model needing ≈ 400-700 samples for
stability, §4.2); a cluster that ends up with fewer than ``MIN_CLUSTER_FRAMES`` frames has
no joint model and is never chosen. The method has no notion of emotion: ``emotion`` is
ignored at synthesis.
"""

from __future__ import annotations

import numpy as np
from sklearn.mixture import GaussianMixture

from animegraph.baselines.base import BaselineModel, check_enough, fit_progress, sample_times
from animegraph.baselines.data import TrainingSet, audio_features_at, resample_to
from animegraph.baselines.predicting import MAX_STORED_COUNT, MAX_STORED_RATE, check_stored_setting
from animegraph.motion.measures import lip_channels
from db.errors import DataError, ParameterError

#: Clusters of the non-linear appearance model (§4.2: "approximately 60").
N_CLUSTERS = 60
#: Synthesis rate: one frame every 40 ms (§2, §4.5).
FRAME_RATE = 25.0
#: Appearance parameters are clamped to this many s.d. of their cluster (§4.4).
CLAMP_SD = 3.0
#: Ours: Mel-cepstra per frame, share of variance kept by the appearance, speech and
#: per-cluster joint PCAs, frames a cluster needs, and the local averaging window (frames
#: at FRAME_RATE, centred).
N_MFCC = 12
APPEARANCE_VARIANCE = 0.98
SPEECH_VARIANCE = 0.95
JOINT_VARIANCE = 0.98
MIN_CLUSTER_FRAMES = 10
AVERAGE_FRAMES = 3
#: The hierarchy: node names, the root first.
NODES = ("face", "mouth")
#: Stored arrays of a cluster's joint model.
CLUSTER_KEYS = ("c_mean", "s_mean", "rc", "rs", "d_var", "noise_var", "c_sd")


def _pca(x: np.ndarray, variance: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(mean (d,), components (d, k), s.d. per component (k,), mean variance of the
    discarded components (0 if none)) keeping ``variance``."""
    mean = x.mean(axis=0)
    _, s, vt = np.linalg.svd(x - mean, full_matrices=False)
    var = s**2 / max(len(x) - 1, 1)
    if var.sum() <= 0:
        return mean, vt[:1].T, np.ones(1), 0.0
    k = int(np.searchsorted(np.cumsum(var) / var.sum(), variance - 1e-12) + 1)
    k = min(k, len(var))
    rest = var[k:]
    return (mean, vt[:k].T, np.sqrt(np.maximum(var[:k], 1e-12)),
            float(rest.mean()) if len(rest) else 0.0)


def _speech_to_d(rs: np.ndarray, d_var: np.ndarray, noise_var: float,
                 ds: np.ndarray) -> np.ndarray:
    """Speech-appearance parameters ``d`` (n, k) from scaled speech offsets ``ds`` (n, n_s).

    The mean of ``d`` given the speech part under the cluster's joint PCA read as a
    probabilistic PCA (Tipping & Bishop 1999): ``M = M̄ + R d + ε`` with ``d ~ N(0, Λ -
    σ²)``, ``ε ~ N(0, σ² I)``, ``Λ`` the kept modes' variances and ``σ²`` the mean
    variance of the discarded ones (``noise_var``)::

        d = (Λ - σ²) Rs^T (Rs (Λ - σ²) Rs^T + σ² I)^+ ds

    Without the noise term the truncated model claims the speech offset lies exactly in
    the span of the kept modes' speech parts: speech variance the discarded modes held is
    then explained by large ``d`` along kept modes with a small speech part, which
    extrapolates the appearance (with no more kept modes than speech dimensions ``d`` is
    the plain least-squares fit of ``Rs``, whatever ``Λ``). On the synthetic corpus that
    made the appearance fit worse than the cluster mean on the training frames themselves
    (docs/results/lipsync.md, "Baseline settings").
    """
    lam = np.maximum(d_var - noise_var, 0.0)
    lam_rt = lam[:, None] * rs.T  # (k, n_s)
    cov = rs @ lam_rt + noise_var * np.eye(rs.shape[0])
    return ds @ np.linalg.pinv(cov, rcond=1e-6).T @ lam_rt.T


class HierPca(BaselineModel):
    """Cosker et al.'s hierarchical speech-appearance model (see the module docstring).

    Parameters
    ----------
    n_clusters : int
        Gaussian-mixture clusters per node (§4.2).
    n_mfcc : int
        Mel-cepstra per speech frame.
    frame_rate : float
        Synthesis rate (frames/s).
    clamp_sd : float
        Appearance clamp in cluster standard deviations (§4.4).
    average_frames : int
        Width of the local average (§4.5), frames at ``frame_rate``; 1 = none.
    speech_variance : float
        Share of the speech vectors' variance the speech PCA keeps (Eq. 4; the paper gives
        none). Unnormalised Mel-cepstra are dominated by ``c_0``: the default 0.95 keeps 6
        of 12 dimensions on the synthetic corpus, 0.999 all 12 (mouth R 0.10 → 0.33 there,
        docs/results/lipsync.md, "Baseline settings").
    random_state : int
        Seed of k-means and the mixture.
    """

    FIT_WHAT = ("PCA and Gaussian-mixture clusters of every clip's speech and motion: "
                "it can take minutes")


    method = "hier-pca"

    def __init__(self, n_clusters: int = N_CLUSTERS, n_mfcc: int = N_MFCC,
                 frame_rate: float = FRAME_RATE, clamp_sd: float = CLAMP_SD,
                 average_frames: int = AVERAGE_FRAMES,
                 speech_variance: float = SPEECH_VARIANCE, random_state: int = 0):
        self.n_clusters = n_clusters
        self.n_mfcc = n_mfcc
        self.frame_rate = frame_rate
        self.clamp_sd = clamp_sd
        self.average_frames = average_frames
        self.speech_variance = speech_variance
        self.random_state = random_state

    def _speech_vectors(self, audio, sample_rate, times) -> np.ndarray:
        return audio_features_at(audio, sample_rate, times, n_mfcc=self.n_mfcc, context=0,
                                 context_hop_s=1.0 / self.frame_rate)

    def _check_params(self) -> None:
        """ParameterError unless the hyper-parameters are valid (on fit and on restore)."""
        for name in ("n_clusters", "n_mfcc", "average_frames"):
            value = getattr(self, name)
            if not isinstance(value, int | np.integer) or value < 1:
                raise ParameterError(f"{name} must be a positive integer, got {value!r}")
        if not self.frame_rate > 0 or not self.clamp_sd > 0:
            raise ParameterError("frame_rate and clamp_sd must be positive")
        if not 0 < self.speech_variance <= 1:
            raise ParameterError(f"speech_variance must be in (0, 1], got {self.speech_variance!r}")

    def _fit(self, data: TrainingSet) -> None:
        self._check_params()
        speech, motion = [], []
        with fit_progress(len(data.clips), "hier-pca: speech features") as bar:
            for clip, times, m in sample_times(data.clips, self.frame_rate):
                speech.append(self._speech_vectors(clip.audio, clip.sample_rate, times))
                motion.append(m)
                bar.update(1)
        a, x = np.concatenate(speech), np.concatenate(motion)
        check_enough(len(x), MIN_CLUSTER_FRAMES, "the hier-pca PCA models")
        # Eq. 4: speech parameters.
        self.a_mean_, self.a_p_, _, _ = _pca(a, self.speech_variance)
        s = (a - self.a_mean_) @ self.a_p_
        self.s_icov_ = np.linalg.pinv(np.cov(s, rowvar=False).reshape(s.shape[1], -1))
        mouth = lip_channels(data.names, data.groups)
        if len(mouth) == 0 or len(mouth) == data.n_channels:
            self.node_channels_ = {"face": np.arange(data.n_channels)}
        else:
            self.node_channels_ = {"face": np.arange(data.n_channels), "mouth": mouth}
        with fit_progress(len(self.node_channels_), "hier-pca: Gaussian mixtures") as bar:
            self.nodes_ = {}
            for seed, (name, ch) in enumerate(self.node_channels_.items()):
                self.nodes_[name] = self._fit_node(x[:, ch], s, seed)
                bar.update(1)

    def _fit_node(self, x: np.ndarray, s: np.ndarray, seed: int) -> dict:
        mean, p, sd, _ = _pca(x, APPEARANCE_VARIANCE)
        c = (x - mean) @ p
        w = np.sqrt((sd**2).sum() / max(s.var(axis=0).sum(), 1e-300))  # Eq. 6, scalar W
        k = max(1, min(self.n_clusters, len(x) // MIN_CLUSTER_FRAMES))
        gm = GaussianMixture(n_components=k, covariance_type="full", init_params="kmeans",
                             reg_covar=1e-3, max_iter=200,
                             random_state=self.random_state + seed).fit(c / sd)
        label = gm.predict(c / sd)
        node = {"mean": mean, "p": p, "w": np.array(w), "clusters": []}
        for i in range(k):
            sel = label == i
            if sel.sum() < MIN_CLUSTER_FRAMES:
                continue  # documented fallback: too few frames for a joint model
            m = np.hstack([c[sel], w * s[sel]])
            m_mean, r, sd_d, noise = _pca(m, JOINT_VARIANCE)
            nc = c.shape[1]
            node["clusters"].append({
                "c_mean": m_mean[:nc], "s_mean": m_mean[nc:] / w, "rc": r[:nc], "rs": r[nc:],
                "d_var": sd_d**2, "noise_var": np.array(noise),
                "c_sd": c[sel].std(axis=0) + 1e-9,
            })
        if not node["clusters"]:
            raise DataError(f"too little data for hier-pca: no cluster has "
                            f"{MIN_CLUSTER_FRAMES} frames")
        return node

    def _synthesize_node(self, node: dict, s: np.ndarray) -> np.ndarray:
        clusters = node["clusters"]
        s_means = np.stack([cl["s_mean"] for cl in clusters])
        diff = s[:, None, :] - s_means[None]
        dist = np.einsum("nki,ij,nkj->nk", diff, self.s_icov_, diff)  # Eq. 8
        choice = np.argmin(dist, axis=1)
        w = float(node["w"])
        c = np.empty((len(s), node["p"].shape[1]))
        for i in np.unique(choice):
            cl, sel = clusters[i], choice == i
            d = _speech_to_d(cl["rs"], cl["d_var"], float(cl["noise_var"]),
                             w * (s[sel] - cl["s_mean"]))
            ci = cl["c_mean"] + d @ cl["rc"].T  # Eq. 9
            lim = self.clamp_sd * cl["c_sd"]
            c[sel] = np.clip(ci, cl["c_mean"] - lim, cl["c_mean"] + lim)
        return node["mean"] + c @ node["p"].T

    def _predict(self, audio, sample_rate, times, emotion):
        grid = np.arange(0.0, times[-1] + 1.0 / self.frame_rate + 1e-9, 1.0 / self.frame_rate)
        s = (self._speech_vectors(audio, sample_rate, grid) - self.a_mean_) @ self.a_p_
        out = self._synthesize_node(self.nodes_["face"], s)
        if "mouth" in self.nodes_:  # §5: the sub-node replaces the root's mouth
            out[:, self.node_channels_["mouth"]] = self._synthesize_node(self.nodes_["mouth"], s)
        if self.average_frames > 1:  # §4.5: local averaging
            k = int(self.average_frames)
            padded = np.pad(out, ((k // 2, k - 1 - k // 2), (0, 0)), mode="edge")
            out = np.stack([padded[j:j + len(out)] for j in range(k)]).mean(axis=0)
        return resample_to(out, self.frame_rate, times)

    def _arrays(self) -> dict[str, np.ndarray]:
        out = {"a_mean": self.a_mean_, "a_p": self.a_p_, "s_icov": self.s_icov_}
        for name, node in self.nodes_.items():
            out[f"{name}/channels"] = self.node_channels_[name]
            out |= {f"{name}/{k}": node[k] for k in ("mean", "p", "w")}
            for i, cl in enumerate(node["clusters"]):
                out |= {f"{name}/cluster/{i:03d}/{k}": v for k, v in cl.items()}
        return out

    def _restore(self, arrays: dict[str, np.ndarray]) -> None:
        self.a_mean_, self.a_p_, self.s_icov_ = arrays["a_mean"], arrays["a_p"], arrays["s_icov"]
        # Checked before any prediction: stored settings are someone else's data (a rate
        # of 10**12 Hz, 10**9 cepstra or frames averaged would be a hang, 0 Hz a crash).
        self._check_params()
        check_stored_setting("frame_rate", self.frame_rate, MAX_STORED_RATE)
        check_stored_setting("average_frames", self.average_frames, MAX_STORED_COUNT)
        if np.shape(self.a_mean_) != (self.n_mfcc,):
            raise ValueError(f"a speech mean of shape {np.shape(self.a_mean_)} does not fit "
                             f"{self.n_mfcc} cepstra")
        self.node_channels_, self.nodes_ = {}, {}
        for name in NODES:
            if f"{name}/mean" not in arrays:
                continue
            self.node_channels_[name] = arrays[f"{name}/channels"].astype(np.int64)
            node = {k: arrays[f"{name}/{k}"] for k in ("mean", "p", "w")}
            prefix = f"{name}/cluster/"
            ids = sorted({k[len(prefix):].split("/")[0] for k in arrays if k.startswith(prefix)})
            if ids and f"{prefix}{ids[0]}/noise_var" not in arrays:
                raise DataError("the stored hier-pca model predates its noise term (Eq. 9 "
                                "fix): refit it (synth --refit)")
            node["clusters"] = [{k: arrays[f"{prefix}{i}/{k}"] for k in CLUSTER_KEYS}
                                for i in ids]
            self.nodes_[name] = node
