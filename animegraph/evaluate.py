"""Measures of synthesized motion against recorded motion, and naive baselines.

The measures follow the lip-sync literature: RMSE over channels, the *lip vertex error*
(for each frame the largest error over the lip points, averaged over frames), and the
Pearson correlation of mouth opening. The baselines show what the search adds: a random
anime of the right phoneme for every phone, and phoneme matching that ignores every
cost (always the first anime of the phoneme).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

#: Point pairs whose distance is the mouth opening, per kind of database.
MOUTH_POINTS = {"markers": ("ulip_in_c", "llip_in_c"), "landmarks": ("lm13", "lm14")}
#: Curve names that are the mouth opening in curve databases (first present wins).
MOUTH_CURVES = ("jaw", "jawOpen", "jaw_open", "mouth_open", "mouthOpen")


def _points(motion: np.ndarray, names: Sequence[str], label: str) -> np.ndarray:
    idx = [list(names).index(f"{label}.{a}") for a in "xyz"]
    return motion[:, idx]


def mouth_opening(motion: np.ndarray, names: Sequence[str], kind: str) -> np.ndarray:
    """Mouth opening over time: shape (n_frames,).

    Distance between the inner-lip midpoints for point databases; the jaw-open curve
    for curve databases.
    """
    if kind in MOUTH_POINTS:
        a, b = MOUTH_POINTS[kind]
        return np.linalg.norm(_points(motion, names, a) - _points(motion, names, b), axis=1)
    for name in MOUTH_CURVES:
        if name in names:
            return motion[:, list(names).index(name)]
    raise KeyError(f"no mouth-opening channel among {MOUTH_CURVES}")


def lip_channels(names: Sequence[str], groups: Sequence[str]) -> np.ndarray:
    """Indices of the channels of the lip motion group."""
    return np.array([i for i, g in enumerate(groups) if g == "lips"], dtype=np.int64)


def rmse(pred: np.ndarray, truth: np.ndarray, channels: np.ndarray | None = None) -> float:
    """Root-mean-square error over frames and ``channels`` (NaN in truth ignored)."""
    n = min(len(pred), len(truth))
    p, t = pred[:n], truth[:n]
    if channels is not None:
        p, t = p[:, channels], t[:, channels]
    return float(np.sqrt(np.nanmean((p - t) ** 2)))


def lip_vertex_error(pred: np.ndarray, truth: np.ndarray, names: Sequence[str],
                     groups: Sequence[str]) -> float:
    """Per frame the largest Euclidean error over the lip points, averaged over frames."""
    n = min(len(pred), len(truth))
    cols = [i for i, (nm, g) in enumerate(zip(names, groups, strict=True))
            if g == "lips" and nm.endswith((".x", ".y", ".z"))]
    if not cols:
        return float("nan")
    d = (pred[:n, cols] - truth[:n, cols]).reshape(n, -1, 3)
    err = np.linalg.norm(d, axis=2)
    return float(np.nanmean(np.nanmax(err, axis=1)))


def pearson(a: np.ndarray, b: np.ndarray) -> float:
    """Pearson correlation of two curves over their common frames (NaN-safe)."""
    n = min(len(a), len(b))
    a, b = a[:n], b[:n]
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 3 or np.std(a[ok]) == 0 or np.std(b[ok]) == 0:
        return float("nan")
    return float(np.corrcoef(a[ok], b[ok])[0, 1])


def baseline_nodes(candidate_nodes: Sequence[np.ndarray], kind: str,
                   rng: np.random.Generator | None = None) -> np.ndarray:
    """A naive anime sequence: ``"random"`` candidate per phone, or the ``"first"``."""
    if kind == "random":
        rng = rng or np.random.default_rng(0)
        return np.array([int(rng.choice(c)) for c in candidate_nodes], dtype=np.int64)
    if kind == "first":
        return np.array([int(c[0]) for c in candidate_nodes], dtype=np.int64)
    raise ValueError(f"unknown baseline {kind!r}")
