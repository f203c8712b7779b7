"""A small dynamic time warping for aligning two recordings of one sentence (§5.2).

Cao et al. (2005, §5.2) align the emotion components of two recordings of the same
sentence with the time correspondence that DTW [Sankoff and Kruskal 1983] finds on their
*speech* components. Ingest needs this alignment to learn the component split and the
emotion mappings, and may not import :mod:`animegraph` (whose numba DTW scores prosody
curves at search time), hence this plain NumPy version: Euclidean local cost, steps
(1, 0), (0, 1), (1, 1) of weight 1, no band, computed one anti-diagonal at a time.
Ties while backtracking go to the diagonal, then (i-1, j), then (i, j-1), the convention of
:func:`animegraph.search.dtw.dtw`, whose paths it reproduces (checked by the tests).
"""

from __future__ import annotations

import numpy as np

from db.errors import ParameterError


def dtw_path(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """An optimal DTW alignment of ``y`` to ``x``.

    Parameters
    ----------
    x : np.ndarray, shape (n, d)
    y : np.ndarray, shape (m, d)

    Returns
    -------
    np.ndarray of int64, shape (L, 2)
        Pairs (i, j) of aligned frames from (0, 0) to (n-1, m-1).
    """
    from scipy.spatial.distance import cdist  # deferred: only learning emotion mappings aligns

    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if x.ndim != 2 or y.ndim != 2 or x.shape[1] != y.shape[1] or not len(x) or not len(y):
        raise ParameterError(f"dtw_path needs two non-empty (n, d) curves of one width, got "
                             f"{x.shape} and {y.shape}")
    n, m = len(x), len(y)
    cost = cdist(x, y)
    acc = np.full((n + 1, m + 1), np.inf)
    acc[0, 0] = 0.0
    for k in range(n + m - 1):  # anti-diagonal i + j = k
        i = np.arange(max(0, k - m + 1), min(n - 1, k) + 1)
        j = k - i
        best = np.minimum(np.minimum(acc[i, j + 1], acc[i + 1, j]), acc[i, j])
        acc[i + 1, j + 1] = cost[i, j] + best
    path = [(n - 1, m - 1)]
    i, j = n, m
    while (i, j) != (1, 1):
        diag, up, left = acc[i - 1, j - 1], acc[i - 1, j], acc[i, j - 1]
        if diag <= up and diag <= left:
            i, j = i - 1, j - 1
        elif up <= left:
            i -= 1
        else:
            j -= 1
        path.append((i - 1, j - 1))
    return np.array(path[::-1], dtype=np.int64)


def path_positions(path: np.ndarray, n: int) -> np.ndarray:
    """Fractional frame of the second curve matched to each of the first curve's ``n`` frames.

    Frame i gets the mean of the frames j matched to it along ``path``.

    Returns
    -------
    np.ndarray, shape (n,)
    """
    sums = np.bincount(path[:, 0], weights=path[:, 1].astype(np.float64), minlength=n)
    return sums / np.bincount(path[:, 0], minlength=n)


def warp_positions(path: np.ndarray, n: int, m: int, step: int) -> np.ndarray:
    """Positions (frames of y, fractional) for every frame of x, from a path found on
    every ``step``-th frame of both curves.

    Parameters
    ----------
    path : np.ndarray of int, shape (L, 2)
        Alignment of ``x[::step]`` and ``y[::step]``.
    n, m : int
        Frames of x and y at the full rate.
    step : int
        Decimation of the path's frames.

    Returns
    -------
    np.ndarray, shape (n,)
        Non-decreasing, in [0, m - 1].
    """
    coarse = path_positions(path, int(path[-1, 0]) + 1)
    fine = step * np.interp(np.arange(n) / step, np.arange(len(coarse)), coarse)
    return np.clip(fine, 0.0, m - 1.0)


def sample_at(y: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """Rows of ``y`` (m, d) at fractional ``positions`` (n,), linearly interpolated."""
    y = np.asarray(y, dtype=np.float64)
    lo = np.floor(positions).astype(int)
    hi = np.minimum(lo + 1, len(y) - 1)
    w = (positions - lo)[:, None]
    return (1 - w) * y[lo] + w * y[hi]
