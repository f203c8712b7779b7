"""The mapping F_ij between two emotion spaces (Cao et al. 2005, §5.2, Eqs. 10-11).

Given corresponding, time-aligned emotion components (e_i^r, e_j^r) of recordings of the
same sentences in emotions i and j, F_ij is a radial-basis-function interpolant in
residual form (Eq. 10)::

    e_j = F_ij(e_i) = e_i + sum_r c_r phi(||e_i - e_i^r||)

with phi(x) = exp(-x / d) or exp(-x^2 / d) (Eq. 11), d the distance between the two
closest samples. The samples are first reduced by K-means to 250 centres (the paper's
number), and the coefficients c_r solve the interpolation conditions F_ij(e_i^r) = e_j^r
by LU decomposition (``scipy.linalg.lu_factor`` / ``lu_solve``).

Choices where the paper is silent
---------------------------------
* K-means clusters the *source* samples e_i; each centre's target is the mean of the
  targets e_j of the samples in its cluster (clustering source and target jointly could
  give two centres with nearly the same source and different targets, an ill-posed
  interpolation).
* d is the distance between the two closest *centres* (the samples of the linear system).
* ``x^2 / d`` is taken literally (d is a length, so the Gaussian's width is sqrt(d) in
  component units; the components have unit variance over the corpus).
* ``offset=True`` (not in the paper, off by default) adds the mean offset of the samples,
  e_j = e_i + b + sum_r c_r phi(.), b = mean(e_j - e_i), the constant term RBF
  interpolation is often augmented with: far from every centre the paper's form falls back
  to the identity, this one to the mean offset.
"""

from __future__ import annotations

import hashlib

import numpy as np
from scipy.linalg import lu_factor, lu_solve
from scipy.spatial.distance import cdist, pdist
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.cluster import KMeans
from sklearn.utils.validation import check_is_fitted

from db.errors import DataError, ParameterError
from ingest.emotion.rbf import KERNEL, KERNELS, N_CENTRES, RbfMapping, checked_matrix, rbf

__all__ = ["KERNEL", "KERNELS", "N_CENTRES", "EmotionMapping", "rbf"]


def _kmeans(X: np.ndarray, n_centres: int, random_state, memo: dict
            ) -> tuple[np.ndarray, np.ndarray]:
    """K-means of the samples ``X`` (labels (n,), centres (k, d)), k = ``n_centres`` or
    the number of distinct samples if fewer; taken from ``memo`` when ``X`` was already
    clustered with the same ``n_centres`` and ``random_state``."""
    key = (X.shape, hashlib.sha1(np.ascontiguousarray(X).tobytes()).hexdigest(),
           n_centres, repr(random_state))
    if key not in memo:
        n_distinct = len(np.unique(X, axis=0))
        k = min(n_centres, n_distinct)
        if k < 2:
            raise DataError(f"need at least 2 distinct correspondences to learn a mapping, "
                            f"got {n_distinct}")
        km = KMeans(n_clusters=k, n_init=1, random_state=random_state).fit(X)
        memo[key] = (km.labels_, km.cluster_centers_)
    return memo[key]


class EmotionMapping(RbfMapping, TransformerMixin, BaseEstimator):
    """RBF mapping of emotion components from emotion space i to j (§5.2, Eq. 10).

    Parameters
    ----------
    n_centres : int, optional
        K-means centres the samples are reduced to (paper: 250); fewer if there are fewer
        distinct samples.
    kernel : {"exp", "gauss"}, optional
        phi(x) = exp(-x/d) or exp(-x^2/d) (Eq. 11); default :data:`KERNEL` ("gauss",
        chosen by cross-validation).
    random_state : int, optional
        Seed of K-means.
    offset : bool, optional
        Add the samples' mean offset as a constant term (not in the paper).

    Attributes
    ----------
    centres_ : np.ndarray, shape (k, n_emotion_components)
        Source samples e_i^r of the interpolation (K-means centres; k <= ``n_centres``).
    targets_ : np.ndarray, shape (k, n_emotion_components)
        Their targets e_j^r (mean target of each cluster).
    coef_ : np.ndarray, shape (k, n_emotion_components)
        Coefficients c_r of Eq. 10.
    d_ : float
        Distance between the two closest centres.
    offset_ : np.ndarray, shape (n_emotion_components,)
        The constant term (zeros unless ``offset``).
    n_samples_fit_ : int
        Correspondences the mapping was learned from.
    """

    def fit(self, X, y, *, clusters: dict | None = None):
        """Learn F from corresponding emotion components.

        Parameters
        ----------
        X : array-like, shape (n_samples, n_emotion_components)
            Source emotion components e_i(t), time-aligned with ``y``.
        y : array-like, shape (n_samples, n_emotion_components)
            Target emotion components e_j(t).
        clusters : dict, optional
            Shared between fits: the K-means of a source ``X`` already clustered (the same
            samples, centres and seed) is taken from it instead of being computed again.
            The mappings from one emotion to every other emotion of a parallel corpus
            cluster the same source frames (issue #16: 20 K-means on the demo corpus, 5
            distinct); the result is the same as without it.

        Returns
        -------
        EmotionMapping
            ``self``.
        """
        if self.kernel not in KERNELS:
            raise ParameterError(f"kernel must be one of {KERNELS}, got {self.kernel!r}")
        if isinstance(self.n_centres, bool) or not isinstance(self.n_centres, (int, np.integer)) \
                or self.n_centres < 2:
            raise ParameterError(f"n_centres must be an integer >= 2, got {self.n_centres!r}")
        X = checked_matrix("X", X)
        y = checked_matrix("y", y)
        if y.shape != X.shape:
            raise ParameterError(f"y must have the shape of X {X.shape}, got {y.shape}")
        labels, centres = _kmeans(X, int(self.n_centres), self.random_state,
                                  {} if clusters is None else clusters)
        k = centres.shape[0]
        counts = np.bincount(labels, minlength=k)
        keep = counts > 0
        targets = np.zeros((k, X.shape[1]))
        np.add.at(targets, labels, y)
        centres = centres[keep]
        targets = targets[keep] / counts[keep, None]
        d = float(pdist(centres).min())
        if not d > 0:
            raise DataError("two K-means centres coincide: cannot set the RBF width")
        phi = rbf(cdist(centres, centres), d, self.kernel)
        self.offset_ = (y - X).mean(axis=0) if self.offset else np.zeros(X.shape[1])
        self.coef_ = lu_solve(lu_factor(phi), targets - centres - self.offset_)
        self.centres_ = centres
        self.targets_ = targets
        self.d_ = d
        self.n_samples_fit_ = int(X.shape[0])
        self.n_features_in_ = int(X.shape[1])
        return self

    def _check_fitted(self) -> None:
        check_is_fitted(self, "coef_")
