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

import numpy as np
from scipy.linalg import lu_factor, lu_solve
from scipy.spatial.distance import cdist, pdist
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.cluster import KMeans
from sklearn.utils.validation import check_is_fitted

from db.errors import DataError, ParameterError

#: K-means centres the correspondences are reduced to (§5.2: 250 clusters).
N_CENTRES = 250
#: Radial basis functions of Eq. 11: "exp" is exp(-x/d), "gauss" exp(-x^2/d).
KERNELS = ("exp", "gauss")
#: Default kernel: the paper gives both forms of Eq. 11 without preferring one; in the
#: paper's cross-validation on the default synthetic corpus (docs/results.md) the Gaussian
#: form has the lower error (unit-cube RMS 0.0077 against 0.0084 for exp(-x/d)).
KERNEL = "gauss"


def rbf(distance: np.ndarray, d: float, kernel: str) -> np.ndarray:
    """phi of Eq. 11 applied to distances (any shape)."""
    if kernel == "exp":
        return np.exp(-distance / d)
    if kernel == "gauss":
        return np.exp(-(distance**2) / d)
    raise ParameterError(f"kernel must be one of {KERNELS}, got {kernel!r}")


class EmotionMapping(TransformerMixin, BaseEstimator):
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
    centres_ : np.ndarray, shape (n_centres_, n_emotion_components)
        Source samples e_i^r of the interpolation (K-means centres).
    targets_ : np.ndarray, shape (n_centres_, n_emotion_components)
        Their targets e_j^r (mean target of each cluster).
    coef_ : np.ndarray, shape (n_centres_, n_emotion_components)
        Coefficients c_r of Eq. 10.
    d_ : float
        Distance between the two closest centres.
    offset_ : np.ndarray, shape (n_emotion_components,)
        The constant term (zeros unless ``offset``).
    n_samples_fit_ : int
        Correspondences the mapping was learned from.
    """

    def __init__(self, n_centres: int = N_CENTRES, kernel: str = KERNEL, random_state: int = 0,
                 offset: bool = False):
        self.n_centres = n_centres
        self.kernel = kernel
        self.random_state = random_state
        self.offset = offset

    def fit(self, X, y):
        """Learn F from corresponding emotion components.

        Parameters
        ----------
        X : array-like, shape (n_samples, n_emotion_components)
            Source emotion components e_i(t), time-aligned with ``y``.
        y : array-like, shape (n_samples, n_emotion_components)
            Target emotion components e_j(t).

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
        X = _matrix("X", X)
        y = _matrix("y", y)
        if y.shape != X.shape:
            raise ParameterError(f"y must have the shape of X {X.shape}, got {y.shape}")
        n_distinct = len(np.unique(X, axis=0))
        k = min(int(self.n_centres), n_distinct)
        if k < 2:
            raise DataError(f"need at least 2 distinct correspondences to learn a mapping, "
                            f"got {n_distinct}")
        km = KMeans(n_clusters=k, n_init=1, random_state=self.random_state).fit(X)
        labels = km.labels_
        counts = np.bincount(labels, minlength=k)
        keep = counts > 0
        targets = np.zeros((k, X.shape[1]))
        np.add.at(targets, labels, y)
        centres = km.cluster_centers_[keep]
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

    def transform(self, X):
        """Map emotion components: F(e) = e + sum_r c_r phi(||e - e^r||) (Eq. 10).

        Parameters
        ----------
        X : array-like, shape (n_frames, n_emotion_components)

        Returns
        -------
        np.ndarray, shape (n_frames, n_emotion_components)
        """
        check_is_fitted(self, "coef_")
        X = _matrix("X", X)
        if X.shape[1] != self.centres_.shape[1]:
            raise ParameterError(f"X has {X.shape[1]} emotion components, the mapping "
                                 f"{self.centres_.shape[1]}")
        return X + self.offset_ + rbf(cdist(X, self.centres_), self.d_, self.kernel) @ self.coef_

    def to_arrays(self) -> dict[str, np.ndarray]:
        """The fitted mapping as float arrays (for the database)."""
        check_is_fitted(self, "coef_")
        return {
            "centres": self.centres_, "targets": self.targets_, "coef": self.coef_,
            "offset": self.offset_,
            "params": np.array([self.d_, KERNELS.index(self.kernel), self.n_centres,
                                self.random_state, self.n_samples_fit_], dtype=np.float64),
        }

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray]) -> EmotionMapping:
        """Rebuild a fitted mapping from :meth:`to_arrays`."""
        d, kernel, n_centres, seed, n_samples = arrays["params"]
        offset = np.asarray(arrays.get("offset", [0.0]), dtype=np.float64).ravel()
        self = cls(n_centres=int(n_centres), kernel=KERNELS[int(kernel)],
                   random_state=int(seed), offset=bool(np.any(offset != 0)))
        width = np.asarray(arrays["centres"]).shape[-1]
        self.centres_ = np.asarray(arrays["centres"], dtype=np.float64).reshape(-1, width)
        self.targets_ = np.asarray(arrays["targets"], dtype=np.float64).reshape(-1, width)
        self.coef_ = np.asarray(arrays["coef"], dtype=np.float64).reshape(-1, width)
        self.d_ = float(d)
        self.offset_ = offset if offset.size == width else np.zeros(width)
        self.n_samples_fit_ = int(n_samples)
        self.n_features_in_ = width
        return self


def _matrix(name: str, a) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    if a.ndim != 2 or a.shape[0] == 0 or a.shape[1] == 0:
        raise ParameterError(f"{name} must be a non-empty (n_samples, n_components) array, "
                             f"got shape {a.shape}")
    if not np.isfinite(a).all():
        raise ParameterError(f"{name} has NaN or infinite values")
    return a
