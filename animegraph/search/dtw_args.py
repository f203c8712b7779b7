"""Checks of the arguments of :mod:`animegraph.search.dtw`'s public functions.

Its kernels assume valid input (finite, non-empty, matching widths): every public
function checks its arguments here first. A graph's curves, checked once when it is
loaded, are marked (:func:`mark_finite`) so that the pair functions do not scan them for
NaN on every call.
"""

from __future__ import annotations

import weakref
from numbers import Integral

import numpy as np

from db.errors import ParameterError

#: ``id`` -> weak reference of the values arrays :func:`mark_finite` checked whole.
_FINITE: dict[int, weakref.ref] = {}


def mark_finite(values: np.ndarray) -> None:
    """Check ``values`` (shape (n_frames, d)) finite once, and make it read-only (and the
    arrays it is a view of) so that it stays so: the pair functions then skip their
    per-call check of its curves.

    A graph's curves are checked when it is loaded; without this mark each call of
    :func:`animegraph.search.dtw.audio_costs_many` rescanned every candidate's curve (a
    live stream scores a window's phones every hop). Arrays not marked, or made
    writeable again, are still checked on every call.

    Raises
    ------
    ParameterError
        ``values`` is not a NumPy array of real numbers, or holds NaN or inf.
    """
    if not isinstance(values, np.ndarray) or values.dtype.kind not in "iuf":
        raise ParameterError("mark_finite takes a NumPy array of real numbers, got "
                             f"{getattr(values, 'dtype', type(values).__name__)}")
    if not np.isfinite(values).all():
        raise ParameterError("values must be finite, got NaN or inf")
    a = values
    while isinstance(a, np.ndarray):  # a graph's curves are a view of the rows read
        a.flags.writeable = False
        a = a.base
    key = id(values)
    _FINITE[key] = weakref.ref(values, lambda _, key=key: _FINITE.pop(key, None))


def known_finite(values: np.ndarray) -> bool:
    """True if :func:`mark_finite` checked this very array and it is still read-only
    (through it and every array it views: no one can have written NaN since)."""
    ref = _FINITE.get(id(values))
    if ref is None or ref() is not values:
        return False
    a = values
    while isinstance(a, np.ndarray):
        if a.flags.writeable:
            return False
        a = a.base
    return True


def curve_array(name: str, a, dtype) -> np.ndarray:
    """A finite, non-empty (n_frames, n_features) array, C-contiguous.

    ``dtype``: cast to it; None keeps float32 and float64 (and casts others to float64).
    """
    try:
        arr = np.asarray(a)
    except (TypeError, ValueError):
        raise ParameterError(f"{name} must be a (n_frames, n_features) array, got a ragged "
                             f"or non-numeric {type(a).__name__}") from None
    if arr.ndim != 2:
        raise ParameterError(
            f"{name} must be a (n_frames, n_features) array, got shape {arr.shape}")
    if arr.shape[0] == 0 or arr.shape[1] == 0:
        raise ParameterError(f"{name} must not be empty, got shape {arr.shape}")
    if arr.dtype.kind not in "iuf":
        raise ParameterError(f"{name} must hold real numbers, got dtype {arr.dtype}")
    if dtype is None:
        dtype = arr.dtype if arr.dtype in (np.float32, np.float64) else np.float64
    arr = np.ascontiguousarray(arr, dtype=dtype)
    finite = np.isfinite(arr)
    if not finite.all():
        frame = int(np.flatnonzero(~finite.all(axis=1))[0])
        raise ParameterError(f"{name} must be finite, got {arr[frame][~finite[frame]][0]} "
                             f"in frame {frame}")
    return arr


def values_array(a) -> np.ndarray:
    """The ragged values array: 2-D, float32 or float64 (finiteness is checked per node)."""
    arr = np.asarray(a)
    if arr.ndim != 2 or arr.shape[1] == 0:
        raise ParameterError(
            f"values must be a (n_frames, n_features) array, got shape {arr.shape}")
    if arr.dtype.kind not in "iuf":
        raise ParameterError(f"values must hold real numbers, got dtype {arr.dtype}")
    dtype = arr.dtype if arr.dtype in (np.float32, np.float64) else np.float64
    return np.ascontiguousarray(arr, dtype=dtype)


def int_vector(name: str, a) -> np.ndarray:
    arr = np.asarray(a)
    if arr.ndim != 1 or (arr.dtype.kind not in "iu" and arr.size):
        raise ParameterError(
            f"{name} must be a 1-D integer array, got shape {arr.shape} dtype {arr.dtype}")
    return np.ascontiguousarray(arr, dtype=np.int64)


def same_width(name: str, a: np.ndarray, ref_name: str, ref: np.ndarray) -> None:
    if a.shape[1] != ref.shape[1]:
        raise ParameterError(
            f"{name} must have {ref.shape[1]} features like {ref_name}, got {a.shape[1]}")


def band_radius(band) -> int:
    if band is None:
        return -1
    if isinstance(band, bool) or not isinstance(band, Integral) or band < 0:
        raise ParameterError(f"band must be None or a non-negative integer, got {band!r}")
    return int(band)


def count(name: str, n) -> int:
    if isinstance(n, bool) or not isinstance(n, Integral) or n < 1:
        raise ParameterError(f"{name} must be a positive integer, got {n!r}")
    return int(n)


def path_array(path, n: int, m: int | None) -> np.ndarray:
    """A DTW path from (0, 0) to (n-1, m-1) of unit steps (any m when ``m`` is None)."""
    arr = np.asarray(path)
    if arr.ndim != 2 or arr.shape[1] != 2 or len(arr) == 0 or arr.dtype.kind not in "iu":
        raise ParameterError(
            f"path must be a non-empty (L, 2) integer array, got shape {arr.shape} "
            f"dtype {arr.dtype}")
    arr = arr.astype(np.int64, copy=False)
    end = (n - 1, arr[-1, 1] if m is None else m - 1)
    if tuple(arr[0]) != (0, 0) or tuple(arr[-1]) != end:
        raise ParameterError(
            f"path must run from (0, 0) to {end}, got {tuple(arr[0].tolist())} to "
            f"{tuple(arr[-1].tolist())}")
    steps = np.diff(arr, axis=0)
    bad = np.flatnonzero((steps < 0).any(axis=1) | (steps > 1).any(axis=1)
                         | (steps == 0).all(axis=1))
    if len(bad):
        k = int(bad[0])
        raise ParameterError(
            f"path must move by (1, 0), (0, 1) or (1, 1), got {tuple(arr[k].tolist())} -> "
            f"{tuple(arr[k + 1].tolist())}")
    return arr
