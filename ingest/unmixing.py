"""A fitted PCA + FastICA as plain arrays (Cao et al. 2005, §4.1, §5.1, Eq. 7), NumPy only.

:class:`Unmixing` maps motion to principal-component scores and to independent
components ``u`` with ``x = A u`` and back. It is what synthesis needs of the
decomposition, restored from the database's arrays without importing scikit-learn
(a one-shot ``animegraph synth`` would spend more time importing it than working);
:class:`ingest.decompose.MotionDecomposer` is the scikit-learn estimator that learns it.
"""

from __future__ import annotations

import numpy as np

from db.errors import DataError, ParameterError

#: Share of the motion's variance the PCA keeps (Cao et al. §4.1).
VARIANCE_KEPT = 0.95
#: Slack of the rule "the fewest components whose ratios reach ``variance``" (cumulative
#: sums of ratios carry round-off).
VARIANCE_SLACK = 1e-12


class Unmixing:
    """Motion <-> principal components <-> independent components, from fitted arrays.

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
    ica_converged_ : bool
    """

    def __init__(self, variance: float = VARIANCE_KEPT, max_iter: int = 1000,
                 tol: float = 1e-4, random_state: int = 0):
        self.variance = variance
        self.max_iter = max_iter
        self.tol = tol
        self.random_state = random_state

    def _check_fitted(self, attribute: str) -> None:
        if not hasattr(self, attribute):
            raise DataError(f"this {type(self).__name__} is not fitted yet")

    def transform(self, X):
        """Independent components of motion ``X``: shape (n_frames, n_ics)."""
        return self.sources_from_pcs(self.to_pcs(X))

    def inverse_transform(self, U):
        """Motion (n_frames, n_channels) from independent components (n_frames, n_ics)."""
        return self.from_pcs(self.pcs_from_sources(U))

    def to_pcs(self, X):
        """Principal-component scores of ``X``: shape (n_frames, n_pcs)."""
        self._check_fitted("components_")
        return (self._check(X) - self.mean_) @ self.components_.T

    def from_pcs(self, P):
        """Motion from principal-component scores (n_frames, n_pcs)."""
        self._check_fitted("components_")
        return np.asarray(P) @ self.components_ + self.mean_

    def sources_from_pcs(self, P):
        """Independent components (n_frames, n_ics) from principal-component scores."""
        self._check_fitted("unmixing_")
        return (np.asarray(P) - self.ica_mean_) @ self.unmixing_.T

    def pcs_from_sources(self, U):
        """Principal-component scores (n_frames, n_pcs) from independent components."""
        self._check_fitted("mixing_")
        return np.asarray(U) @ self.mixing_.T + self.ica_mean_

    @property
    def n_pcs_(self) -> int:
        return int(self.components_.shape[0])

    def to_arrays(self) -> dict[str, np.ndarray]:
        """The learned state as named float arrays (for the database)."""
        self._check_fitted("unmixing_")
        return {
            "channel_mean": self.mean_, "pca_components": self.components_,
            "pca_explained_variance_ratio": self.explained_variance_ratio_,
            "ica_unmixing": self.unmixing_, "ica_mixing": self.mixing_,
            "ica_mean": self.ica_mean_,
            "decomposer_params": np.array([self.variance, self.max_iter, self.tol,
                                           self.random_state, float(self.ica_converged_)]),
        }

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray]):
        """Rebuild a fitted decomposition from :meth:`to_arrays` (an instance of ``cls``)."""
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
