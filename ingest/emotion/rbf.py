"""The mapping F_ij between two emotion spaces, fitted, as plain arrays (Cao et al. 2005,
§5.2, Eqs. 10-11), NumPy only.

:class:`RbfMapping` applies F_ij(e) = e + sum_r c_r phi(||e - e^r||) from the arrays the
database stores; :class:`ingest.emotion.mapping.EmotionMapping` is the scikit-learn
estimator that learns them (K-means centres, LU solve). Synthesis restores the mappings
without importing scikit-learn or SciPy.
"""

from __future__ import annotations

import numpy as np

from db.errors import ParameterError

#: K-means centres the correspondences are reduced to (§5.2: 250 clusters).
N_CENTRES = 250
#: Radial basis functions of Eq. 11: "exp" is exp(-x/d), "gauss" exp(-x^2/d).
KERNELS = ("exp", "gauss")
#: Default kernel: the paper gives both forms of Eq. 11 without preferring one; in the
#: paper's cross-validation on the default synthetic corpus (docs/results/emotion.md, "Emotion
#: mapping: cross-validation") the Gaussian
#: form has the lower error (unit-cube RMS 0.0077 against 0.0084 for exp(-x/d)).
KERNEL = "gauss"


def rbf(distance: np.ndarray, d: float, kernel: str) -> np.ndarray:
    """phi of Eq. 11 applied to distances (any shape)."""
    if kernel == "exp":
        return np.exp(-distance / d)
    if kernel == "gauss":
        return np.exp(-(distance**2) / d)
    raise ParameterError(f"kernel must be one of {KERNELS}, got {kernel!r}")


def distances(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Euclidean distances between the rows of X (n, k) and Y (m, k): shape (n, m).

    The same sums as ``scipy.spatial.distance.cdist(X, Y)``, in NumPy.
    """
    return np.sqrt(((X[:, None, :] - Y[None, :, :]) ** 2).sum(axis=2))


class RbfMapping:
    """A fitted RBF mapping of emotion components from emotion space i to j (§5.2, Eq. 10).

    Parameters and attributes: see :class:`ingest.emotion.mapping.EmotionMapping`, the
    estimator that learns it.
    """

    def __init__(self, n_centres: int = N_CENTRES, kernel: str = KERNEL, random_state: int = 0,
                 offset: bool = False):
        self.n_centres = n_centres
        self.kernel = kernel
        self.random_state = random_state
        self.offset = offset

    def _check_fitted(self) -> None:
        if not hasattr(self, "coef_"):
            raise ParameterError(f"this {type(self).__name__} is not fitted yet")

    def transform(self, X):
        """Map emotion components: F(e) = e + sum_r c_r phi(||e - e^r||) (Eq. 10).

        Parameters
        ----------
        X : array-like, shape (n_frames, n_emotion_components)

        Returns
        -------
        np.ndarray, shape (n_frames, n_emotion_components)
        """
        self._check_fitted()
        X = checked_matrix("X", X)
        if X.shape[1] != self.centres_.shape[1]:
            raise ParameterError(f"X has {X.shape[1]} emotion components, the mapping "
                                 f"{self.centres_.shape[1]}")
        phi = rbf(distances(X, self.centres_), self.d_, self.kernel)
        return X + self.offset_ + phi @ self.coef_

    def to_arrays(self) -> dict[str, np.ndarray]:
        """The fitted mapping as float arrays (for the database)."""
        self._check_fitted()
        return {
            "centres": self.centres_, "targets": self.targets_, "coef": self.coef_,
            "offset": self.offset_,
            "params": np.array([self.d_, KERNELS.index(self.kernel), self.n_centres,
                                self.random_state, self.n_samples_fit_], dtype=np.float64),
        }

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray]):
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


def checked_matrix(name: str, a) -> np.ndarray:
    """``a`` as a finite, non-empty float array of shape (n_samples, n_components), or a
    ParameterError naming it ``name``."""
    a = np.asarray(a, dtype=np.float64)
    if a.ndim != 2 or a.shape[0] == 0 or a.shape[1] == 0:
        raise ParameterError(f"{name} must be a non-empty (n_samples, n_components) array, "
                             f"got shape {a.shape}")
    if not np.isfinite(a).all():
        raise ParameterError(f"{name} has NaN or infinite values")
    return a
