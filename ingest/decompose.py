"""Motion compression and decomposition: PCA, then FastICA (Cao et al. 2005, §4.1, §5.1).

The motion of the whole corpus, concatenated (§5.1.2, Eq. 8), is first reduced by PCA
to the components that keep a given share of its variance (95 %, §4.1; 95-98 %,
§5.1.2), then unmixed by FastICA into independent components ``u`` with ``x = A u``
(Eq. 7). Every learned quantity is a plain array (:meth:`MotionDecomposer.to_arrays`),
so the database stores it without pickles.

Per independent component, the low-pass cutoff is the frequency below which 99 % of
its energy lies over the whole corpus (§4.3, Smoothing).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np
from scipy.signal import butter, sosfiltfilt, welch
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.decomposition import PCA, FastICA
from sklearn.exceptions import ConvergenceWarning
from sklearn.utils.validation import check_is_fitted

from db.errors import DataError, ParameterError

#: Share of the motion's variance the PCA keeps (Cao et al. §4.1).
VARIANCE_KEPT = 0.95
#: Share of each independent component's energy below its low-pass cutoff (§4.3).
ENERGY_KEPT = 0.99


class MotionDecomposer(TransformerMixin, BaseEstimator):
    """PCA keeping ``variance`` of the motion, then FastICA on the principal components.

    Parameters
    ----------
    variance : float
        Share of variance the PCA keeps, in (0, 1] (Cao et al. §4.1: 0.95; §5.1.2:
        0.95-0.98).
    max_iter : int
        FastICA iterations.
    tol : float
        FastICA tolerance.
    random_state : int
        Seed of FastICA's initial unmixing matrix.

    Attributes
    ----------
    mean_ : np.ndarray, shape (n_channels,)
    components_ : np.ndarray, shape (n_pcs, n_channels)
        Principal axes (orthonormal rows).
    explained_variance_ratio_ : np.ndarray, shape (n_pcs,)
    unmixing_ : np.ndarray, shape (n_ics, n_pcs)
        ``u = unmixing_ @ (p - ica_mean_)`` for principal-component scores ``p``.
    mixing_ : np.ndarray, shape (n_pcs, n_ics)
        The mixing matrix A of Eq. 7 in principal-component space.
    ica_mean_ : np.ndarray, shape (n_pcs,)
    """

    def __init__(self, variance: float = VARIANCE_KEPT, max_iter: int = 1000,
                 tol: float = 1e-4, random_state: int = 0):
        self.variance = variance
        self.max_iter = max_iter
        self.tol = tol
        self.random_state = random_state

    def fit(self, X, y=None):
        """Learn the PCA and the ICA from motion ``X`` of shape (n_frames, n_channels)."""
        X = self._check(X)
        if not (0.0 < self.variance <= 1.0):
            raise ParameterError(f"variance must be in (0, 1], got {self.variance}")
        if X.shape[0] < 3:
            raise DataError(f"need at least 3 frames to decompose motion, got {X.shape[0]}")
        n_max = min(X.shape)
        # Eigen-decomposition of the channel covariance: exact like a full SVD, and
        # fast for motion's tall (many frames, few channels) matrices.
        pca = PCA(n_components=n_max, svd_solver="covariance_eigh").fit(X)
        cumulative = np.cumsum(pca.explained_variance_ratio_)
        n_pcs = int(np.searchsorted(cumulative, self.variance - 1e-12) + 1)
        n_pcs = min(n_pcs, n_max)
        self.mean_ = pca.mean_
        self.components_ = pca.components_[:n_pcs]
        self.explained_variance_ratio_ = pca.explained_variance_ratio_[:n_pcs]
        scores = (X - self.mean_) @ self.components_.T
        ica = FastICA(n_components=n_pcs, whiten="unit-variance", max_iter=self.max_iter,
                      tol=self.tol, random_state=self.random_state)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", ConvergenceWarning)
            ica.fit(scores)
        self.ica_converged_ = not any(issubclass(w.category, ConvergenceWarning)
                                      for w in caught)
        self.unmixing_ = ica.components_
        self.mixing_ = ica.mixing_
        self.ica_mean_ = ica.mean_
        return self

    def transform(self, X):
        """Independent components of motion ``X``: shape (n_frames, n_ics)."""
        return self.sources_from_pcs(self.to_pcs(X))

    def inverse_transform(self, U):
        """Motion (n_frames, n_channels) from independent components (n_frames, n_ics)."""
        return self.from_pcs(self.pcs_from_sources(U))

    def to_pcs(self, X):
        """Principal-component scores of ``X``: shape (n_frames, n_pcs)."""
        check_is_fitted(self, "components_")
        return (self._check(X) - self.mean_) @ self.components_.T

    def from_pcs(self, P):
        """Motion from principal-component scores (n_frames, n_pcs)."""
        check_is_fitted(self, "components_")
        return np.asarray(P) @ self.components_ + self.mean_

    def sources_from_pcs(self, P):
        check_is_fitted(self, "unmixing_")
        return (np.asarray(P) - self.ica_mean_) @ self.unmixing_.T

    def pcs_from_sources(self, U):
        check_is_fitted(self, "mixing_")
        return np.asarray(U) @ self.mixing_.T + self.ica_mean_

    @property
    def n_pcs_(self) -> int:
        return int(self.components_.shape[0])

    def to_arrays(self) -> dict[str, np.ndarray]:
        """The learned state as named float arrays (for the database)."""
        check_is_fitted(self, "unmixing_")
        return {
            "channel_mean": self.mean_, "pca_components": self.components_,
            "pca_explained_variance_ratio": self.explained_variance_ratio_,
            "ica_unmixing": self.unmixing_, "ica_mixing": self.mixing_,
            "ica_mean": self.ica_mean_,
            "decomposer_params": np.array([self.variance, self.max_iter, self.tol,
                                           self.random_state, float(self.ica_converged_)]),
        }

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray]) -> MotionDecomposer:
        """Rebuild a fitted decomposer from :meth:`to_arrays`."""
        variance, max_iter, tol, seed, converged = arrays["decomposer_params"]
        self = cls(variance=float(variance), max_iter=int(max_iter), tol=float(tol),
                   random_state=int(seed))
        self.mean_ = arrays["channel_mean"]
        self.components_ = arrays["pca_components"].reshape(-1, self.mean_.shape[0])
        self.explained_variance_ratio_ = arrays["pca_explained_variance_ratio"]
        n = self.components_.shape[0]
        self.unmixing_ = arrays["ica_unmixing"].reshape(n, n)
        self.mixing_ = arrays["ica_mixing"].reshape(n, n)
        self.ica_mean_ = arrays["ica_mean"]
        self.ica_converged_ = bool(converged)
        return self

    @staticmethod
    def _check(X) -> np.ndarray:
        X = np.asarray(X, dtype=np.float64)
        if X.ndim != 2:
            raise ParameterError(f"motion must be (n_frames, n_channels), got shape {X.shape}")
        if not np.isfinite(X).all():
            raise DataError("motion has NaN or infinite values: fill gaps first")
        return X


#: Frames projected at once by :func:`pcs_of_clips` (bounds its float64 copies, ~0.7 GB
#: for 1,400 channels).
PROJECT_BLOCK_FRAMES = 65536


def pcs_of_clips(model: MotionDecomposer, motions: list[np.ndarray]) -> list[np.ndarray]:
    """:meth:`MotionDecomposer.to_pcs` of each clip's motion, computed for many clips at a
    time: one product per block of up to :data:`PROJECT_BLOCK_FRAMES` frames instead of
    one a clip (800 small products cost more in overhead than in arithmetic).

    Returns
    -------
    list of np.ndarray
        ``out[i]``, shape (len(motions[i]), n_pcs).
    """
    out: list[np.ndarray] = []
    start = 0
    while start < len(motions):
        stop, frames = start, 0
        while stop < len(motions) and (stop == start or frames + len(motions[stop])
                                       <= PROJECT_BLOCK_FRAMES):
            frames += len(motions[stop])
            stop += 1
        pcs = model.to_pcs(np.concatenate(motions[start:stop]))
        out += np.split(pcs, np.cumsum([len(m) for m in motions[start:stop - 1]]))
        start = stop
    return out


def cutoff_frequencies(sources: Sequence[np.ndarray], fps: float, *,
                       energy: float = ENERGY_KEPT) -> np.ndarray:
    """Per component, the frequency below which ``energy`` of its energy lies (§4.3).

    Parameters
    ----------
    sources : sequence of np.ndarray, each (n_frames_k, n_ics)
        Independent components of every clip (clips are not concatenated, so the joins
        between them add no false high frequencies).
    fps : float
        Frame rate.
    energy : float
        Share of energy below the cutoff.

    Returns
    -------
    np.ndarray, shape (n_ics,)
        Cutoff frequencies in Hz (at most the Nyquist frequency).
    """
    nperseg = int(min(256, max(8, min(len(s) for s in sources))))
    total = None
    freqs = None
    for s in sources:
        if len(s) < nperseg:
            continue
        freqs, psd = welch(s, fs=fps, nperseg=nperseg, axis=0, detrend="constant")
        weighted = psd * len(s)  # long clips weigh more: energy, not clip count
        total = weighted if total is None else total + weighted
    if total is None:
        raise DataError("clips are too short to measure their frequency content")
    cumulative = np.cumsum(total, axis=0)
    cumulative /= np.maximum(cumulative[-1], 1e-300)
    index = np.array([np.searchsorted(cumulative[:, k], energy) for k in range(total.shape[1])])
    return freqs[np.minimum(index, len(freqs) - 1)]


#: Order of the zero-phase Butterworth low-pass of the smoothing step (§4.3).
SMOOTHING_ORDER = 2


def smooth(motion: np.ndarray, cutoffs: np.ndarray, fps: float) -> np.ndarray:
    """Zero-phase low-pass of each column at its cutoff (Hz); columns at Nyquist pass."""
    out = motion.copy()
    nyquist = fps / 2
    if len(motion) < 3 * (2 * SMOOTHING_ORDER + 1):
        return out  # too short to filter without edge artefacts swamping it
    for k, cut in enumerate(cutoffs):
        if 0 < cut < 0.99 * nyquist:
            sos = butter(SMOOTHING_ORDER, cut / nyquist, output="sos")
            out[:, k] = sosfiltfilt(sos, motion[:, k])
    return out
