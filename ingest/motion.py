"""Clean-up of recorded motion: filling marker dropouts, changing the frame rate.

Cao et al. (2005, §3.2) fill capture gaps with a commercial tool (DIVA) before anything
else; here gaps are filled per channel with shape-preserving cubic interpolation
(PCHIP), which neither overshoots nor invents motion that the neighbouring frames do
not show.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import PchipInterpolator

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


def resample_motion(motion: np.ndarray, fps: float, target_fps: float) -> np.ndarray:
    """Resample motion (shape (n_frames, n_channels)) to ``target_fps`` by linear interpolation.

    Frame ``k`` of the output is at time ``k / target_fps``; the output covers the
    input's duration ``n_frames / fps``.
    """
    if fps == target_fps:
        return np.asarray(motion, dtype=np.float64)
    n_out = max(1, int(round(len(motion) * target_fps / fps)))
    t_in = np.arange(len(motion)) / fps
    t_out = np.arange(n_out) / target_fps
    return np.stack([np.interp(t_out, t_in, col) for col in np.asarray(motion).T], axis=1)
