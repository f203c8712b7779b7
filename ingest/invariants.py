"""What a database's stored model arrays satisfy by construction, checked when read.

A database comes from other people (the brief: trust no input), and its model arrays
(``model_arrays.parquet``) are plain numbers: a zeroed, negated or rescaled array still
has the right shape and finite values, and synthesis would turn it into garbage motion
without a word. Each array is made by a known computation, so it satisfies relations
that a damaged one breaks; these are checked here, cheaply (no frame is read, nothing is
refitted), and a broken one is a ``ValueError`` naming the array and the relation (the
readers turn it into :meth:`db.store.Database.damaged`'s one line).

The relations, by where the arrays come from:

* PCA (:class:`ingest.decompose.MotionDecomposer`, Cao et al. 2005, §4.1): the
  components are orthonormal rows; the explained-variance ratios are in (0, 1],
  non-increasing (eigenvalues sorted), sum to at most 1, and are the fewest that reach
  the stored ``variance`` (the rule of ``fit``); the channel mean is a mean of the stored
  frames, so it lies within each channel's recorded range (the ``min`` and ``max`` of
  the channels table, written by ingest; a database written before them has no range
  to check against).
* FastICA on the principal-component scores (§5.1, Eq. 7): the mixing matrix is the
  (pseudo-)inverse of the unmixing one (``ica_unmixing @ ica_mixing = I``); ``ica_mean``
  is the mean of the scores, which are centred by construction (about 0).
* Cutoffs (§4.3, :func:`ingest.lowpass.cutoff_frequencies`): frequencies of a Welch grid,
  in (0, fps/2].
* Head reference (:func:`ingest.motion.rigid_fit`): one point per head-group point, not
  collinear (a rigid fit to collinear points is undetermined).
* Emotion model (§5.1.3, §5.2, :mod:`ingest.emotion.model`): the emotion components are
  distinct component indices, the same in the array, the manifest and the ``components``
  table. The independent components have zero mean and unit variance over the N frames
  of the corpus (FastICA's ``whiten="unit-variance"``), so by Samuelson's inequality any
  frame's component, and any mean of frames (a centroid, a K-means centre, an RBF target),
  lies within sqrt(N - 1); the mean of m of the N frames within sqrt((N - m) / m); and
  the frame-weighted centroids of the emotions sum to zero when every frame has an
  emotion. An RBF mapping's width is the distance between its two closest centres, and
  its coefficients solve the interpolation conditions (Eq. 10) at the centres.

What no relation constrains is not checked (and not guessed): the RBF coefficients only
through the interpolation conditions; the head reference's position (one clip's mean
head pose, a clip that need not be in the database); the mean offsets e_j - e_i of the
offset baseline beyond the bound above.

Tolerances: a k-term sum of float64 products carries a round-off of at most
k * eps * (sum of the terms' magnitudes) (Higham, *Accuracy and Stability of Numerical
Algorithms*, 2nd ed., §3.1); :func:`roundoff` allows :data:`SAFETY` times that, for the
round-off of the stored values' own computation (eigen-decomposition, inverse, LU solve).
The measured deviations of real databases are 2-4 orders of magnitude smaller
(docs/results/robustness.md, "Stored model arrays checked when read").
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from ingest.emotion.rbf import KERNELS, distances, rbf
from ingest.motion import head_points
from ingest.unmixing import VARIANCE_SLACK

EPS = float(np.finfo(np.float64).eps)
#: Multiple of the round-off bound of a sum allowed for the stored values' computation.
SAFETY = 16.0
#: Seeds NumPy's RandomState accepts (FastICA's and K-means' ``random_state``).
SEED_LIMIT = 2**32
#: Prefix of the emotion model's arrays (ingest.emotion.model.PREFIX).
_EMOTION = "emotion/"


def roundoff(n_terms: int, magnitude) -> np.ndarray | float:
    """Allowed float64 round-off of a sum of ``n_terms`` terms of total ``magnitude``."""
    return SAFETY * max(int(n_terms), 1) * EPS * np.asarray(magnitude, dtype=np.float64)


def channel_ranges(channels: list[dict]) -> dict[str, tuple[float, float]] | None:
    """Each channel's (min, max) over the database's frames, from the channels table; None
    for a database written before it held them (its frames' Parquet statistics would
    tell, but reading them costs 0.1-0.4 s for a database of per-clip row groups)."""
    if channels and "min" in channels[0] and "max" in channels[0]:
        return {str(c["name"]): (float(c["min"]), float(c["max"])) for c in channels}
    return None


def check_stored_decomposition(db, arrays: Mapping[str, np.ndarray],
                               channels: list[dict]) -> None:
    """:func:`check_decomposition` of a database's stored model, as every reader of it
    needs: ``db`` (:class:`db.store.Database`) gives the frame rate and frame count,
    ``channels`` (its channels table's rows) the names, head group and ranges.

    Raises
    ------
    DataError
        ``db.damaged(...)``: one line naming the array (or the manifest's missing count).
    """
    n_frames = db.manifest.get("n_frames")
    if n_frames is None:
        raise db.damaged("manifest.json", "n_frames is missing")
    try:
        names = [str(c["name"]) for c in channels]
        groups = [str(c["group"]) for c in channels]
        check_decomposition(arrays, names, float(db.manifest["fps"]), n_frames,
                            head_points(groups), channel_ranges(channels))
    except (KeyError, TypeError, ValueError) as exc:
        what = f"no array {exc}" if isinstance(exc, KeyError) else str(exc)
        raise db.damaged("model_arrays", what) from None


def check_decomposition(arrays: Mapping[str, np.ndarray], names: Sequence[str], fps: float,
                        n_frames: int, head_points: int,
                        ranges: Mapping[str, tuple[float, float]] | None = None) -> None:
    """Check the stored PCA/ICA model, cutoffs and head reference (module docstring).

    Parameters
    ----------
    arrays : mapping of str to np.ndarray
        The database's model arrays.
    names : sequence of str, length n_channels
        The channels' names.
    fps : float
        The database's frame rate.
    n_frames : int
        Frames of the corpus the model was learned from.
    head_points : int
        Points of the channels' rigid head group.
    ranges : mapping of str to (float, float), optional
        Each channel's recorded (min, max) over those frames, if known (None: not
        checked).

    Raises
    ------
    ValueError
        Naming the first array that breaks a relation, and the relation.
    """
    variance, max_iter, tol, seed, converged = _sized(arrays, "decomposer_params", 5)
    if not (0.0 < variance <= 1.0 and tol > 0 and max_iter >= 1 and _whole(max_iter)
            and _whole(seed) and 0 <= seed < SEED_LIMIT and converged in (0.0, 1.0)):
        raise ValueError(f"decomposer_params: {arrays['decomposer_params'].tolist()} is not "
                         "(variance in (0, 1], max_iter >= 1, tol > 0, a seed, 0 or 1)")
    n_channels = len(names)
    mean = _sized(arrays, "channel_mean", n_channels)
    components = np.asarray(arrays["pca_components"], dtype=np.float64)
    if components.size % n_channels or not 0 < components.size <= n_channels**2:
        raise ValueError(f"pca_components: {components.size} values are not rows of "
                         f"{n_channels} channels")
    components = components.reshape(-1, n_channels)
    k = components.shape[0]
    gram = components @ components.T
    _near(gram, np.eye(k), roundoff(n_channels, 1.0), "pca_components",
          "its rows are not orthonormal")
    ratio = _sized(arrays, "pca_explained_variance_ratio", k)
    slack = float(roundoff(n_channels, 1.0))
    if not ((ratio > 0).all() and (ratio <= 1).all() and (np.diff(ratio) <= 0).all()
            and ratio.sum() <= 1 + slack):
        raise ValueError("pca_explained_variance_ratio: not ratios in (0, 1], non-increasing, "
                         "summing to at most 1")
    every = k == min(n_channels, n_frames)  # every component: the ratios sum to 1
    if not (ratio[:-1].sum() < variance - VARIANCE_SLACK + slack
            and (ratio.sum() >= variance - VARIANCE_SLACK - slack or every)):
        raise ValueError(f"pca_explained_variance_ratio: {k} components keeping "
                         f"{ratio.sum():.6g} of the variance are not the fewest that keep "
                         f"the stored {variance:.6g}")
    unmixing = _sized(arrays, "ica_unmixing", k * k).reshape(k, k)
    mixing = _sized(arrays, "ica_mixing", k * k).reshape(k, k)
    # FastICA's mixing is the pseudo-inverse of its unmixing, computed through an SVD:
    # the residual W A - I of such an inverse is bounded by eps times the condition
    # number times a low-degree polynomial in k (Higham, §14.1); k^2 here.
    condition = np.linalg.norm(unmixing, 2) * np.linalg.norm(mixing, 2)
    _near(unmixing @ mixing, np.eye(k), roundoff(k * k, condition), "ica_mixing",
          "it is not the inverse of ica_unmixing")
    # Unit-variance sources: A A^T is the scores' covariance, its trace their variance.
    spread = np.linalg.norm(mean) + np.sqrt(max(n_frames - 1, 0) * np.sum(mixing**2)
                                            / ratio.sum())
    ica_mean = _sized(arrays, "ica_mean", k)
    if (np.abs(ica_mean) > roundoff(n_frames + n_channels, spread)).any():
        raise ValueError(f"ica_mean: {np.abs(ica_mean).max():.3g} is not the mean of "
                         "centred principal-component scores (about 0)")
    if ranges is not None:
        for c, name in enumerate(names):
            if name in ranges:
                lo, hi = ranges[name]
                margin = roundoff(n_frames, max(abs(lo), abs(hi)))
                if not lo - margin <= mean[c] <= hi + margin:
                    raise ValueError(f"channel_mean: {name} = {mean[c]:.6g} is outside the "
                                     f"range of its frames [{lo:.6g}, {hi:.6g}]")
    cutoffs = _sized(arrays, "ic_cutoff_hz", k)
    if not ((cutoffs > 0).all() and (cutoffs <= fps / 2 * (1 + 4 * EPS)).all()):
        raise ValueError(f"ic_cutoff_hz: not frequencies in (0, {fps / 2:g}] Hz (fps/2)")
    if "head_reference" in arrays:
        reference = np.asarray(arrays["head_reference"], dtype=np.float64)
        if reference.shape != (head_points, 3):
            raise ValueError(f"head_reference: shape {reference.shape}, the channels have "
                             f"{head_points} head points")
        sv = np.linalg.svd(reference - reference.mean(axis=0), compute_uv=False)
        if head_points >= 3 and not sv[1] > roundoff(head_points, sv[0]):
            raise ValueError("head_reference: its points are collinear or coincide (no "
                             "rigid head frame)")


def check_emotion(arrays: Mapping[str, np.ndarray], entry: Mapping, emotion_components,
                  n_ics: int, frames: Mapping[str, int]) -> None:
    """Check the stored emotion model (module docstring); the classifier is not checked.

    Parameters
    ----------
    arrays : mapping of str to np.ndarray
        The database's model arrays.
    entry : mapping
        The manifest's ``emotion`` entry.
    emotion_components : np.ndarray of int
        The emotion components by the ``components`` table.
    n_ics : int
        Independent components.
    frames : mapping of str to int
        Frames of the corpus by emotion (``unknown`` included).

    Raises
    ------
    ValueError
        Naming the first array that breaks a relation, and the relation.
    """
    e = np.asarray(emotion_components, dtype=np.int64)
    n_e = e.size
    name = _EMOTION + "emotion_components"
    stored = np.asarray(arrays.get(name, e), dtype=np.float64).ravel()
    listed = np.asarray(entry.get("emotion_components", e), dtype=np.float64).ravel()
    if not (stored.shape == listed.shape == e.shape and (stored == e).all()
            and (listed == e).all()):
        raise ValueError(f"{name}: {stored.tolist()} differs from the manifest's "
                         f"{listed.tolist()} or the components table's {e.tolist()}")
    if n_e and not (0 <= e[0] and e[-1] < n_ics and (np.diff(e) > 0).all()):
        raise ValueError(f"{name}: {e.tolist()} are not distinct components of {n_ics}")
    n = int(sum(frames.values()))
    bound = np.sqrt(max(n - 1, 0)) * (1 + roundoff(n, 1.0))  # Samuelson's inequality
    weighted = np.zeros(n_e)
    for emotion in entry.get("emotions", ()):
        key = f"{_EMOTION}centroid/{emotion}"
        if key not in arrays:
            continue
        centroid = _sized(arrays, key, n_e)
        m = int(frames.get(emotion, 0))
        limit = np.sqrt(max(n - m, 0) / m) * (1 + roundoff(n, 1.0)) if m else 0.0
        if (np.abs(centroid) > limit).any():
            raise ValueError(f"{key}: {np.abs(centroid).max():.3g} is not a mean of {m} of "
                             f"the {n} frames' unit-variance components (at most "
                             f"{limit:.3g})")
        weighted += m * centroid
    everyone = set(frames) <= set(entry.get("emotions", ()))
    if n_e and everyone and (np.abs(weighted) > roundoff(n, n * bound)).any():
        raise ValueError(f"{_EMOTION}centroid/*: the emotions' frame-weighted centroids sum "
                         f"to {np.abs(weighted).max() / n:.3g} a frame, not 0 (the "
                         "components' mean)")
    shared: dict = {}  # one source emotion's mappings share their centres and kernel
    for pair in entry.get("mappings", ()):
        src, _, dst = str(pair).partition("->")
        _check_mapping(arrays, f"{_EMOTION}map/{src}/{dst}/", n_e, n, bound, shared)
        key = f"{_EMOTION}offset/{src}/{dst}"
        if (np.abs(_sized(arrays, key, n_e)) > 2 * bound).any():
            raise ValueError(f"{key}: larger than a difference of two frames' components "
                             f"can be (2 sqrt(N - 1) = {2 * bound:.3g})")


def _check_mapping(arrays: Mapping[str, np.ndarray], prefix: str, n_e: int, n: int,
                   bound: float, shared: dict) -> None:
    """One stored RBF mapping (:class:`ingest.emotion.rbf.RbfMapping`); ``shared`` holds
    the distances between the centres of the mappings checked before (by centres) and
    their kernel matrices (by centres, width and kernel)."""
    d, kernel, n_centres, seed, n_samples = _sized(arrays, prefix + "params", 5)
    centres = np.asarray(arrays[prefix + "centres"], dtype=np.float64)
    k = centres.size // max(n_e, 1)
    if not (n_e and centres.size == k * n_e and k >= 2):
        raise ValueError(f"{prefix}centres: {centres.size} values are not two or more centres "
                         f"of {n_e} emotion components")
    if not (_whole(kernel) and 0 <= kernel < len(KERNELS) and _whole(n_centres)
            and k <= n_centres and _whole(seed) and 0 <= seed < SEED_LIMIT
            and _whole(n_samples) and k <= n_samples <= n):
        raise ValueError(f"{prefix}params: {[d, kernel, n_centres, seed, n_samples]} do not "
                         f"fit {k} centres from at most {n} frames")
    centres = centres.reshape(k, n_e)
    targets = _sized(arrays, prefix + "targets", k * n_e).reshape(k, n_e)
    coef = _sized(arrays, prefix + "coef", k * n_e).reshape(k, n_e)
    offset = np.asarray(arrays.get(prefix + "offset", np.zeros(n_e)), dtype=np.float64)
    if offset.size == 1 and not offset.any():
        offset = np.zeros(n_e)  # written before mappings had offsets
    offset = _sized({"offset": offset}, "offset", n_e, prefix + "offset")
    for what, values, limit in (("centres", centres, bound), ("targets", targets, bound),
                                ("offset", offset, 2 * bound)):
        if (np.abs(values) > limit).any():
            raise ValueError(f"{prefix}{what}: {np.abs(values).max():.3g} is beyond what a "
                             f"mean of unit-variance components of {n} frames can be "
                             f"({limit:.3g})")
    key = centres.tobytes()
    if key not in shared:
        dist = distances(centres, centres)
        shared[key] = dist, dist[np.triu_indices(k, 1)].min()
    dist, closest = shared[key]
    if not (d > 0 and abs(d - closest) <= roundoff(n_e, closest)):
        raise ValueError(f"{prefix}params: width d = {d:.6g} is not the distance between "
                         f"the two closest centres ({closest:.6g})")
    if (key, d, kernel) not in shared:
        shared[(key, d, kernel)] = rbf(dist, d, KERNELS[int(kernel)])
    phi = shared[(key, d, kernel)]
    rhs = targets - centres - offset
    residual = phi @ coef - rhs
    if (np.abs(residual) > roundoff(k, np.abs(phi) @ np.abs(coef) + np.abs(rhs))).any():
        raise ValueError(f"{prefix}coef: the mapping does not take its centres to their "
                         f"targets (Eq. 10; off by {np.abs(residual).max():.3g})")


def _sized(arrays: Mapping[str, np.ndarray], name: str, size: int,
           label: str | None = None) -> np.ndarray:
    """``arrays[name]`` flattened, or a ValueError unless it has ``size`` values."""
    values = np.asarray(arrays[name], dtype=np.float64).ravel()
    if values.size != size:
        raise ValueError(f"{label or name}: {values.size} values, expected {size}")
    return values


def _whole(x: float) -> bool:
    return bool(np.isfinite(x) and x == np.floor(x))


def _near(actual: np.ndarray, expected: np.ndarray, tolerance, name: str, what: str) -> None:
    """ValueError naming ``name`` unless ``actual`` is within ``tolerance`` of ``expected``."""
    off = np.abs(actual - expected)
    if (off > tolerance).any():
        raise ValueError(f"{name}: {what} (off by {off.max():.3g})")
