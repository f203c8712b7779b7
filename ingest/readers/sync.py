"""Lip-audio synchronisation: estimate the lag between lip motion and speech, shift motion.

Real recordings are not always in sync: in some of the talking-face clips the lips move
130-300 ms before the sound they make. :func:`estimate_lag` finds such a lag by
cross-correlating a lip-activity signal with the loudness of the audio over lags of
+-0.5 s. Convention throughout: **a positive lag means the lips lead the audio**
(a lip event at time t is heard at t + lag); :func:`shift_motion` delays the motion by
that lag to put it in sync.

Signals (chosen on the 13 talking-face clips, where they reproduce the lags of the
clips' own ``meta.json`` estimates best):

- lip activity: ``|d opening/dt| + |d width/dt|`` (inner-lip midpoints 13-14, mouth
  corners 61-291), smoothed over 3 frames: the lips move most at syllable onsets and
  offsets, where the loudness changes;
- audio loudness: RMS in a window of two frame periods centred on each frame's time
  ``i / fps``, in dB, floored 50 dB below its peak (so pauses do not dominate).

The mouth opening itself correlates less well (its level drifts with expression).

When a lag is identifiable (issue #14): on a 3 s utterance the correlation of lip activity
with loudness has side peaks one syllable (~0.2 s) either side of the true lag that are
nearly as high as the true peak, and a per-clip estimate locks onto them (on GRID s1 it
shifted 320 of 800 clips by up to +-0.48 s, where one speaker in one session has one
lag). So the correlation is kept per clip as *evidence* (:func:`lag_evidence`: sums of
products and powers of the standardised signals at every lag of :data:`LAG_GRID_S`),
evidence of all the clips of one speaker and session is pooled
(:func:`pooled_lag`), and an estimate is used only when it is *identifiable*
(:meth:`LagEstimate.identifiable`): at least :data:`MIN_EVIDENCE_S` seconds of speech
behind it and a peak that beats the best side peak (local maximum further than
:data:`SIDE_PEAK_EXCLUSION_S` from it) by :data:`MIN_PEAK_MARGIN` in correlation.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass
from numbers import Real

import numpy as np

from db.errors import ParameterError
from ingest.facemesh import LIP_CORNERS, LOWER_LIP_MID, UPPER_LIP_MID

logger = logging.getLogger(__name__)

#: Largest lag searched (s).
MAX_LAG_S = 0.5
#: Loudness floor below the clip's peak (dB).
FLOOR_DB = 50.0
#: Lags (s) at which evidence is kept, whatever a clip's frame rate (10 ms steps).
LAG_GRID_S = np.round(np.arange(-50, 51) * 0.01, 2)
#: Side peaks are local maxima of the correlation at least this far from its peak (s):
#: past the main lobe (its half width is about half a syllable).
SIDE_PEAK_EXCLUSION_S = 0.12
#: An estimate is identifiable when its peak correlation beats the best side peak by
#: this much ...
MIN_PEAK_MARGIN = 0.05
#: ... and it rests on at least this many seconds of audio (one clip or a pool).
MIN_EVIDENCE_S = 20.0


def audio_envelope(audio: np.ndarray, sample_rate: int, fps: float, n_frames: int) -> np.ndarray:
    """RMS loudness of the audio at each video frame.

    Parameters
    ----------
    audio : np.ndarray, shape (n_samples,)
        Mono audio.
    sample_rate : int
        Audio samples per second.
    fps : float
        Video frames per second.
    n_frames : int
        Frames wanted (frame i is at time ``i / fps``; windows past the audio's end
        read silence).

    Returns
    -------
    np.ndarray, shape (n_frames,)
        RMS over a window of two frame periods centred on each frame.
    """
    hop = sample_rate / fps
    half = max(1, int(round(hop)))
    padded = np.pad(np.asarray(audio, dtype=np.float64), (half, half + int(math.ceil(hop)) + 1))
    power = np.concatenate(([0.0], np.cumsum(padded ** 2)))
    centres = np.round(np.arange(n_frames) * hop).astype(np.int64) + half
    lo = np.clip(centres - half, 0, len(padded))
    hi = np.clip(centres + half, 0, len(padded))
    return np.sqrt((power[hi] - power[lo]) / (2 * half))


def lip_activity(points: np.ndarray) -> np.ndarray:
    """How much the lips move at each frame.

    Parameters
    ----------
    points : np.ndarray, shape (n_frames, n_points, 3)
        Face points in canonical mesh order (at least 468), head pose removed.

    Returns
    -------
    np.ndarray, shape (n_frames,)
        ``|d opening| + |d width|`` per frame (mm per frame), smoothed over 3 frames;
        NaN frames are filled with the mean.
    """
    opening = np.linalg.norm(points[:, UPPER_LIP_MID] - points[:, LOWER_LIP_MID], axis=1)
    width = np.linalg.norm(points[:, LIP_CORNERS[0]] - points[:, LIP_CORNERS[1]], axis=1)
    return opening_width_activity(opening, width)


def opening_width_activity(opening: np.ndarray, width: np.ndarray) -> np.ndarray:
    """``|d opening| + |d width|`` per frame, smoothed over 3 frames (NaN -> the mean).

    Parameters
    ----------
    opening, width : np.ndarray, shape (n_frames,)
        Mouth opening and width, in any one unit (mm for points, blendshape weight for
        ARKit curves).

    Returns
    -------
    np.ndarray, shape (n_frames,)
    """
    opening = np.asarray(opening, dtype=np.float64)
    width = np.asarray(width, dtype=np.float64)
    if len(opening) < 2:
        return np.zeros(len(opening))
    activity = np.abs(np.gradient(opening)) + np.abs(np.gradient(width))
    valid = np.isfinite(activity)
    activity[~valid] = activity[valid].mean() if valid.any() else 0.0
    padded = np.pad(activity, 1, mode="edge")
    return np.convolve(padded, np.ones(3) / 3.0, mode="valid")


def estimate_lag(
    lips: np.ndarray, loudness: np.ndarray, fps: float, *, max_lag_s: float = MAX_LAG_S
) -> tuple[float, float]:
    """Lag between a lip signal and an audio loudness signal at the same frame rate.

    Parameters
    ----------
    lips : np.ndarray, shape (n_frames,)
        Lip activity (:func:`lip_activity`).
    loudness : np.ndarray, shape (n_frames,)
        Audio RMS per frame (:func:`audio_envelope`); converted to dB here.
    fps : float
        Frames per second of both.
    max_lag_s : float
        Lags searched: -max_lag_s .. +max_lag_s.

    Returns
    -------
    lag_s : float
        Lag in seconds, positive when the lips lead the audio; refined below a frame
        by a parabola through the correlation peak.
    confidence : float
        Pearson correlation at the peak (0 when a signal is constant).
    """
    lips = np.asarray(lips, dtype=np.float64)
    db = 20.0 * np.log10(np.asarray(loudness, dtype=np.float64) + 1e-10)
    db = np.maximum(db, db.max() - FLOOR_DB)
    n = min(len(lips), len(db))
    max_lag = min(int(round(max_lag_s * fps)), max(n - 3, 0))
    lags = np.arange(-max_lag, max_lag + 1)
    corr = np.zeros(len(lags))
    for k, lag in enumerate(lags):
        # lips at t against audio at t + lag
        a = lips[max(0, -lag):n - max(0, lag)]
        b = db[max(0, lag):n - max(0, -lag)]
        if a.std() > 0 and b.std() > 0:
            corr[k] = float(np.corrcoef(a, b)[0, 1])
    best = int(np.argmax(corr))
    return float((lags[best] + _peak_offset(corr, best)) / fps), float(corr[best])


def _peak_offset(corr: np.ndarray, best: int) -> float:
    """Offset (in steps, within +-0.5) of the top of a parabola through ``corr``'s peak."""
    if 0 < best < len(corr) - 1:
        left, mid, right = corr[best - 1], corr[best], corr[best + 1]
        curvature = left - 2 * mid + right
        if curvature < 0:
            return float(0.5 * (left - right) / curvature)
    return 0.0


def lip_audio_lag(
    points: np.ndarray, audio: np.ndarray, sample_rate: int, fps: float
) -> tuple[float, float]:
    """Estimate the lip-audio lag of a landmark clip.

    Parameters
    ----------
    points : np.ndarray, shape (n_frames, n_points, 3)
        Normalised face points (canonical mesh order).
    audio : np.ndarray, shape (n_samples,)
        Mono speech.
    sample_rate : int
        Audio rate (Hz).
    fps : float
        Frame rate of ``points``.

    Returns
    -------
    lag_s : float
        Seconds, positive when the lips lead the audio.
    confidence : float
        Peak correlation.
    """
    loudness = audio_envelope(audio, sample_rate, fps, len(points))
    return estimate_lag(lip_activity(points), loudness, fps)


def shift_motion(motion: np.ndarray, lag_s: float, fps: float) -> np.ndarray:
    """Delay motion by ``lag_s`` seconds (advance it if negative), padding with edge frames.

    With the lag of :func:`estimate_lag` (positive: lips lead the audio) this brings
    the motion in sync with the audio. Fractional frames are interpolated linearly.

    Parameters
    ----------
    motion : np.ndarray, shape (n_frames, n_channels) or (n_frames,)
        Motion; NaN spreads to the frames interpolated from it.
    lag_s : float
        Seconds to delay by.
    fps : float
        Frames per second of ``motion``.

    Returns
    -------
    np.ndarray, same shape as ``motion``
        ``out[t] = motion[t - lag_s * fps]``, frames before the start repeating the
        first frame and frames after the end the last.

    Raises
    ------
    ParameterError
        If ``motion`` is empty or not 1-D/2-D, or ``lag_s``/``fps`` are not finite
        (``fps`` > 0).
    """
    motion = np.asarray(motion)
    if motion.ndim not in (1, 2) or motion.shape[0] == 0:
        raise ParameterError(f"motion: expected a non-empty (n_frames, n_channels) array, "
                             f"got shape {motion.shape}")
    if not (isinstance(fps, Real) and math.isfinite(fps) and fps > 0):
        raise ParameterError(f"fps: expected a number > 0, got {fps!r}")
    if not (isinstance(lag_s, Real) and math.isfinite(lag_s)):
        raise ParameterError(f"lag_s: expected a finite number, got {lag_s!r}")
    n = motion.shape[0]
    position = np.clip(np.arange(n) - lag_s * fps, 0, n - 1)
    lo = np.floor(position).astype(np.int64)
    hi = np.minimum(lo + 1, n - 1)
    weight = position - lo
    if motion.ndim == 2:
        weight = weight[:, None]
    with np.errstate(invalid="ignore"):
        blended = motion[lo] + weight * (motion[hi] - motion[lo])
    return np.where(weight > 0, blended, motion[lo])


@dataclass(frozen=True)
class LagEstimate:
    """A lip-audio lag read off pooled or single-clip evidence.

    Attributes
    ----------
    lag_s : float
        Seconds, positive when the lips lead the audio.
    confidence : float
        Correlation at the peak.
    margin : float
        Peak correlation minus the best side peak's (:data:`SIDE_PEAK_EXCLUSION_S`).
    seconds : float
        Duration of the audio behind the estimate.
    n_clips : int
        Clips pooled.
    """

    lag_s: float
    confidence: float
    margin: float
    seconds: float
    n_clips: int = 1

    def identifiable(self, *, min_margin: float = MIN_PEAK_MARGIN,
                     min_seconds: float = MIN_EVIDENCE_S) -> bool:
        """Whether the peak clearly beats its side peaks on enough audio."""
        return self.seconds >= min_seconds and self.margin >= min_margin


def lag_evidence(lips: np.ndarray, loudness: np.ndarray, fps: float) -> np.ndarray:
    """Cross-correlation sums of one clip at the lags of :data:`LAG_GRID_S`.

    Both signals are standardised over the clip (loudness in dB, floored as in
    :func:`estimate_lag`); at each frame lag the sums over the overlapping frames of
    ``lips[t] * loud[t + lag]``, ``lips[t]**2`` and ``loud[t + lag]**2`` are taken and
    interpolated linearly onto the grid, so clips of any frame rate pool.

    Parameters
    ----------
    lips : np.ndarray, shape (n_frames,)
        Lip activity (:func:`lip_activity`).
    loudness : np.ndarray, shape (n_frames,)
        Audio RMS per frame (:func:`audio_envelope`).
    fps : float
        Frames per second of both.

    Returns
    -------
    np.ndarray, shape (3, len(LAG_GRID_S))
        Rows: sum of products, lip power, loudness power. Zero where the clip is too
        short for the lag or a signal is constant.
    """
    lips = np.asarray(lips, dtype=np.float64)
    db = 20.0 * np.log10(np.asarray(loudness, dtype=np.float64) + 1e-10)
    db = np.maximum(db, db.max() - FLOOR_DB) if len(db) else db
    n = min(len(lips), len(db))
    out = np.zeros((3, len(LAG_GRID_S)))
    if n < 4 or lips[:n].std() == 0 or db[:n].std() == 0:
        return out
    a = (lips[:n] - lips[:n].mean()) / lips[:n].std()
    b = (db[:n] - db[:n].mean()) / db[:n].std()
    max_lag = min(int(math.ceil(LAG_GRID_S[-1] * fps)) + 1, n - 2)
    lags = np.arange(-max_lag, max_lag + 1)
    sums = np.zeros((3, len(lags)))
    for k, lag in enumerate(lags):
        x = a[max(0, -lag):n - max(0, lag)]
        y = b[max(0, lag):n - max(0, -lag)]
        sums[:, k] = (x @ y, x @ x, y @ y)
    seconds = lags / fps
    inside = np.abs(LAG_GRID_S) <= seconds[-1] + 1e-9
    for row in range(3):
        out[row, inside] = np.interp(LAG_GRID_S[inside], seconds, sums[row])
    return out


def lag_from_evidence(evidence: Sequence[np.ndarray], seconds: float) -> LagEstimate:
    """The lag at the peak of pooled correlation evidence.

    Parameters
    ----------
    evidence : sequence of np.ndarray, each shape (3, len(LAG_GRID_S))
        :func:`lag_evidence` of the clips pooled.
    seconds : float
        Their total duration.

    Returns
    -------
    LagEstimate
        Pooled correlation ``sum(products) / sqrt(sum(lip power) * sum(loud power))``;
        the lag refined below the grid step by a parabola through the peak.
    """
    total = np.sum(np.asarray(evidence, dtype=np.float64).reshape(-1, 3, len(LAG_GRID_S)),
                   axis=0)
    denom = np.sqrt(total[1] * total[2])
    corr = np.divide(total[0], denom, out=np.zeros(len(LAG_GRID_S)), where=denom > 0)
    best = int(np.argmax(corr))
    step = float(LAG_GRID_S[1] - LAG_GRID_S[0])
    offset = _peak_offset(corr, best)
    # side peaks: local maxima (edges included) outside the main lobe
    padded = np.concatenate(([-np.inf], corr, [-np.inf]))
    local = (corr >= padded[:-2]) & (corr >= padded[2:])
    far = np.abs(LAG_GRID_S - LAG_GRID_S[best]) >= SIDE_PEAK_EXCLUSION_S - 1e-9
    sides = corr[local & far]
    margin = float(corr[best] - sides.max()) if len(sides) else float(corr[best])
    return LagEstimate(lag_s=float(LAG_GRID_S[best] + offset * step),
                       confidence=float(corr[best]), margin=margin, seconds=float(seconds),
                       n_clips=len(evidence))
