"""Clean-up of recorded motion: filling marker dropouts, changing the frame rate.

Cao et al. (2005, §3.2) fill capture gaps with a commercial tool (DIVA) before anything
else; here gaps are filled per channel with shape-preserving cubic interpolation
(PCHIP), which neither overshoots nor invents motion that the neighbouring frames do
not show.
"""

from __future__ import annotations

import numpy as np

from db.errors import DataError


def fill_gaps(motion: np.ndarray, names=None) -> tuple[np.ndarray, np.ndarray]:
    """Fill NaN gaps of every channel.

    Parameters
    ----------
    motion : np.ndarray, shape (n_frames, n_channels)
        Motion with NaN where a channel is missing.
    names : sequence of str, optional
        Channel names, for the error message.

    Returns
    -------
    filled : np.ndarray, shape (n_frames, n_channels)
        Gaps interpolated inside, held constant at the clip's ends.
    missing : np.ndarray of bool, shape (n_frames, n_channels)
        Where values were filled.

    Raises
    ------
    DataError
        If a channel is missing throughout.
    """
    motion = np.asarray(motion, dtype=np.float64)
    missing = np.isnan(motion)
    if not missing.any():
        return motion.copy(), missing
    from scipy.interpolate import PchipInterpolator  # deferred: only gaps need it

    filled = motion.copy()
    frames = np.arange(len(motion))
    for c in np.flatnonzero(missing.any(axis=0)):
        valid = ~missing[:, c]
        if not valid.any():
            name = names[c] if names is not None else f"channel {c}"
            raise DataError(f"{name} is missing in every frame")
        if valid.sum() == 1:
            filled[:, c] = motion[valid, c][0]
            continue
        interp = PchipInterpolator(frames[valid], motion[valid, c], extrapolate=False)
        values = interp(frames)
        first, last = np.flatnonzero(valid)[[0, -1]]
        values[:first] = motion[first, c]
        values[last + 1:] = motion[last, c]
        filled[:, c] = values
    return filled, missing


def interpolate(times_in: np.ndarray, values: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Frames ``values`` (shape (n_in, d), at ``times_in``) linearly interpolated at
    ``times``, held at the ends; shape (len(times), d), float64 (zeros without input)."""
    values = np.asarray(values, dtype=np.float64)
    if len(times_in) == 0:
        return np.zeros((len(times), values.shape[1]))
    # np.interp's result for every channel at once (``times_in`` increasing): one
    # np.interp a channel cost the baselines' fits on GRID s1 (1,411 channels, 799
    # clips) 12 CPU-s of Python calls.
    times_in = np.asarray(times_in, dtype=np.float64)
    times = np.asarray(times, dtype=np.float64)
    lo = np.clip(np.searchsorted(times_in, times, side="right") - 1, 0, len(times_in) - 1)
    hi = np.minimum(lo + 1, len(times_in) - 1)  # past the end: lo == hi, the last frame
    span = times_in[hi] - times_in[lo]
    frac = np.clip(np.divide(times - times_in[lo], span, out=np.zeros_like(times),
                             where=span > 0), 0.0, 1.0)[:, None]
    low = values[lo]
    return low + (values[hi] - low) * frac


def resample_motion(motion: np.ndarray, fps: float, target_fps: float) -> np.ndarray:
    """Resample motion (shape (n_frames, n_channels)) to ``target_fps`` by linear interpolation.

    Frame ``k`` of the output is at time ``k / target_fps``; the output covers the
    input's duration ``n_frames / fps``.
    """
    if fps == target_fps:
        return np.asarray(motion, dtype=np.float64)
    n_out = max(1, int(round(len(motion) * target_fps / fps)))
    return interpolate(np.arange(len(motion)) / fps, motion, np.arange(n_out) / target_fps)


def rigid_fit(points: np.ndarray, reference: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame rotation and translation taking ``points`` onto ``reference`` (Kabsch).

    Parameters
    ----------
    points : np.ndarray, shape (n_frames, n_points, 3)
    reference : np.ndarray, shape (n_points, 3)

    Returns
    -------
    rotation : np.ndarray, shape (n_frames, 3, 3)
    translation : np.ndarray, shape (n_frames, 3)
        ``reference ~= points @ rotation.T + translation`` frame by frame.
    """
    pc = points.mean(axis=1, keepdims=True)
    rc = reference.mean(axis=0)
    cov = np.einsum("fki,kj->fij", points - pc, reference - rc)
    u, _, vt = np.linalg.svd(cov)
    d = np.sign(np.linalg.det(np.einsum("fij,fjk->fik", u, vt)))
    fix = np.ones((len(points), 3))
    fix[:, 2] = d  # no reflections
    rotation = np.einsum("fji,fj,fkj->fik", vt, fix, u)
    translation = rc - np.einsum("fij,fj->fi", rotation, pc[:, 0])
    return rotation, translation


def stabilize_points(motion: np.ndarray, groups, reference: np.ndarray) -> np.ndarray:
    """Remove rigid head motion from every point but the head group's own.

    Cao et al. (2005, §3.2) organise the markers into three motion groups: rigid head
    motion, upper face and lips. Here the head group's markers keep their world
    trajectories (they carry the rigid motion), and every other point is expressed in
    the head's frame, so facial deformation (speech, expression) is not swamped by the
    head turning.

    Parameters
    ----------
    motion : np.ndarray, shape (n_frames, 3 * n_points)
        x/y/z triples.
    groups : sequence of str, length 3 * n_points
        Motion group of each channel; ``"head"`` marks the rigid group (>= 3 points).
    reference : np.ndarray, shape (n_head_points, 3)
        Head-group positions defining the head frame (the same for a whole database).

    Returns
    -------
    np.ndarray, shape (n_frames, 3 * n_points)
    """
    pts = np.asarray(motion, dtype=np.float64).reshape(len(motion), -1, 3)
    head = np.asarray(groups[::3]) == "head"
    rotation, translation = rigid_fit(pts[:, head], reference)
    out = pts.copy()
    out[:, ~head] = np.einsum("fij,fkj->fki", rotation, pts[:, ~head]) + translation[:, None]
    return out.reshape(len(motion), -1)


def unstabilize_points(motion: np.ndarray, groups, reference: np.ndarray) -> np.ndarray:
    """Inverse of :func:`stabilize_points`: put the face back on the moving head."""
    pts = np.asarray(motion, dtype=np.float64).reshape(len(motion), -1, 3)
    head = np.asarray(groups[::3]) == "head"
    rotation, translation = rigid_fit(pts[:, head], reference)
    out = pts.copy()
    local = pts[:, ~head] - translation[:, None]
    out[:, ~head] = np.einsum("fji,fkj->fki", rotation, local)
    return out.reshape(len(motion), -1)


def head_points(groups) -> int:
    """Number of points in the rigid head group of x/y/z-triple channels."""
    return int(np.sum(np.asarray(groups[::3]) == "head"))
