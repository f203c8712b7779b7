"""Per-component low-pass cutoffs and the zero-phase smoothing of synthesis (§4.3).

Per independent component, the low-pass cutoff is the frequency below which 99 % of its
energy lies over the whole corpus (Cao et al. 2005, §4.3, Smoothing); synthesized
components are smoothed by a zero-phase Butterworth low-pass at their cutoff. NumPy only
at import (:mod:`ingest.filters`): a one-shot ``synth`` does not pay for
:mod:`scipy.signal`, which only learning the cutoffs needs.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache

import numpy as np

from db.errors import DataError
from ingest.filters import butter_lowpass, sosfiltfilt

#: Share of each independent component's energy below its low-pass cutoff (§4.3).
ENERGY_KEPT = 0.99
#: Order of the zero-phase Butterworth low-pass of the smoothing step (§4.3).
SMOOTHING_ORDER = 2


def cutoff_frequencies(sources: Sequence[np.ndarray], fps: float, *,
                       energy: float = ENERGY_KEPT) -> np.ndarray:
    """Per component, the frequency below which ``energy`` of its energy lies (§4.3).

    Parameters
    ----------
    sources : sequence of np.ndarray, each (n_frames_k, n_ics)
        Independent components of every clip (clips are not concatenated, so the joins
        between them add no false high frequencies).
    fps : float
        Frame rate.
    energy : float
        Share of energy below the cutoff.

    Returns
    -------
    np.ndarray, shape (n_ics,)
        Cutoff frequencies in Hz (at most the Nyquist frequency).
    """
    from scipy.signal import welch  # deferred: only learning the model needs it

    nperseg = int(min(256, max(8, min(len(s) for s in sources))))
    total = None
    freqs = None
    for s in sources:
        if len(s) < nperseg:
            continue
        freqs, psd = welch(s, fs=fps, nperseg=nperseg, axis=0, detrend="constant")
        weighted = psd * len(s)  # long clips weigh more: energy, not clip count
        total = weighted if total is None else total + weighted
    if total is None:
        raise DataError("clips are too short to measure their frequency content")
    cumulative = np.cumsum(total, axis=0)
    cumulative /= np.maximum(cumulative[-1], 1e-300)
    index = np.array([np.searchsorted(cumulative[:, k], energy) for k in range(total.shape[1])])
    return freqs[np.minimum(index, len(freqs) - 1)]


def smooth(motion: np.ndarray, cutoffs: np.ndarray, fps: float) -> np.ndarray:
    """Zero-phase low-pass of each column at its cutoff (Hz); columns at Nyquist pass.

    Parameters
    ----------
    motion : np.ndarray, shape (n_frames, n_columns)
    cutoffs : np.ndarray, shape (n_columns,)
        Cutoff of each column in Hz; columns with a cutoff <= 0 or within 1 % of the
        Nyquist frequency are left as they are.
    fps : float
        Frame rate.

    Returns
    -------
    np.ndarray, shape (n_frames, n_columns)
        The Butterworth low-pass of order :data:`SMOOTHING_ORDER` applied forward and
        backward (``scipy.signal.sosfiltfilt`` of ``butter(..., output="sos")``, computed
        by :mod:`ingest.filters`).
    """
    out = motion.copy()
    nyquist = fps / 2
    if len(motion) < 3 * (2 * SMOOTHING_ORDER + 1):
        return out  # too short to filter without edge artefacts swamping it
    columns = [k for k, cut in enumerate(cutoffs) if 0 < cut < 0.99 * nyquist]
    if columns:
        sos = _sections(*(cutoffs[k] / nyquist for k in columns))
        out[:, columns] = sosfiltfilt(sos, motion[:, columns])
    return out


@lru_cache(maxsize=64, typed=True)  # typed: a float32 cutoff is designed in float32
def _sections(*cutoffs: float) -> np.ndarray:
    """The Butterworth sections of each cutoff (a fraction of Nyquist), shape
    (n_sections, 6, len(cutoffs)), read-only. Designed once per set of cutoffs: a live
    stream smooths every window with the database's same cutoffs, and designing the
    filters again was about 1 % of its update."""
    sos = np.stack([butter_lowpass(SMOOTHING_ORDER, c) for c in cutoffs], axis=2)
    sos.flags.writeable = False
    return sos
