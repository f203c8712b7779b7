"""Motion compression and decomposition: PCA, then FastICA (Cao et al. 2005, §4.1, §5.1).

The motion of the whole corpus, concatenated (§5.1.2, Eq. 8), is first reduced by PCA
to the components that keep a given share of its variance (95 %, §4.1; 95-98 %,
§5.1.2), then unmixed by FastICA into independent components ``u`` with ``x = A u``
(Eq. 7). Every learned quantity is a plain array (:meth:`MotionDecomposer.to_arrays`),
so the database stores it without pickles; :class:`ingest.unmixing.Unmixing` applies
them without scikit-learn.

Per independent component, the low-pass cutoff is the frequency below which 99 % of
its energy lies over the whole corpus (§4.3, Smoothing): :mod:`ingest.lowpass`.
"""

from __future__ import annotations

import warnings

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.decomposition import PCA, FastICA
from sklearn.exceptions import ConvergenceWarning
from sklearn.utils.validation import check_is_fitted

from db.errors import DataError, ParameterError
from ingest.lowpass import ENERGY_KEPT, SMOOTHING_ORDER, cutoff_frequencies, smooth
from ingest.unmixing import VARIANCE_KEPT, VARIANCE_SLACK, Unmixing

__all__ = ["ENERGY_KEPT", "SMOOTHING_ORDER", "VARIANCE_KEPT", "MotionDecomposer",
           "cutoff_frequencies", "smooth"]


class MotionDecomposer(Unmixing, TransformerMixin, BaseEstimator):
    """PCA keeping ``variance`` of the motion, then FastICA on the principal components.

    The scikit-learn estimator that learns an :class:`~ingest.unmixing.Unmixing` (its
    parameters, attributes and transforms are documented there).
    """

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
        n_pcs = int(np.searchsorted(cumulative, self.variance - VARIANCE_SLACK) + 1)
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

    def _check_fitted(self, attribute: str) -> None:
        check_is_fitted(self, attribute)


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
