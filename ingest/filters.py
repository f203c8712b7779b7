"""Digital filters in NumPy alone: the few :mod:`scipy.signal` calls synthesis makes.

Importing :mod:`scipy.signal` takes about a second (SciPy 1.17 wraps every function of
the package for alternative array backends at import and pulls in :mod:`scipy.stats`),
several times the work of a one-shot ``animegraph synth``, which only needs three small
filters on short signals: the Butterworth low-pass of the smoothing step (Cao et al.
2005, §4.3), its zero-phase application, and the RASTA filter of the audio features
(Hermansky & Morgan 1994). They are written here with the same algorithms and the same
order of floating-point operations as SciPy's (``butter``/``zpk2sos``, ``sosfilt`` and
``sosfiltfilt`` with odd padding and steady-state initial conditions, ``lfilter`` in
transposed direct form II), and ``tests/test_filters.py`` checks that their output equals
SciPy's to within rounding.

Signals are ``(n_samples, n_channels)`` arrays filtered along axis 0; a loop over the
samples (vectorised over the channels) is fast enough for motion and feature frames
(hundreds to thousands of samples), not meant for audio samples.
"""

from __future__ import annotations

import numpy as np

from db.errors import ParameterError


def butter_lowpass(order: int, cutoff: float) -> np.ndarray:
    """Second-order sections of a digital Butterworth low-pass (``scipy.signal.butter``).

    The analog prototype's poles are pre-warped and mapped by the bilinear transform, as
    in :func:`scipy.signal.butter` (``output="sos"``): all zeros at z = -1, the gain in
    the first section, sections ordered by their poles' distance to the unit circle
    (farthest first).

    Parameters
    ----------
    order : int
        Filter order (>= 1).
    cutoff : float
        -3 dB frequency as a fraction of the Nyquist frequency, in (0, 1).

    Returns
    -------
    np.ndarray, shape (ceil(order / 2), 6)
        Rows ``[b0, b1, b2, 1, a1, a2]``.
    """
    if isinstance(order, bool) or not isinstance(order, (int, np.integer)) or order < 1:
        raise ParameterError(f"filter order must be an integer >= 1, got {order!r}")
    if not 0.0 < cutoff < 1.0:
        raise ParameterError(f"cutoff must be in (0, 1) of the Nyquist frequency, got {cutoff}")
    fs = 2.0
    warped = 2 * fs * np.tan(np.pi * cutoff / fs)
    # Analog prototype (scipy.signal.buttap), scaled to the warped cutoff (lp2lp_zpk).
    m = np.arange(-order + 1, order, 2)
    poles = warped * -np.exp(1j * np.pi * m / (2 * order))
    gain = warped**order
    # Bilinear transform (bilinear_zpk): zeros at the analog infinity go to z = -1.
    fs2 = 2.0 * fs
    z_poles = (fs2 + poles) / (fs2 - poles)
    gain = gain * np.real(1.0 / np.prod(fs2 - poles))
    # One section per conjugate pair (and one for a lone real pole), nearest-to-unit-
    # circle last, as zpk2sos pairs them.
    upper = z_poles[np.imag(z_poles) > 0]
    real = z_poles[np.imag(z_poles) == 0]
    pairs = sorted(upper, key=lambda p: abs(p))
    n_sections = (order + 1) // 2
    sos = np.zeros((n_sections, 6))
    first = 0
    if real.size:
        sos[0] = [1.0, 1.0, 0.0, 1.0, -float(np.real(real[0])), 0.0]
        first = 1
    for k, p in enumerate(pairs):
        sos[first + k] = [1.0, 2.0, 1.0, 1.0, -2.0 * p.real, abs(p) ** 2]
    sos[0, :3] *= gain
    return sos


def _check_signal(x) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 2:
        raise ParameterError(f"signal must be (n_samples, n_channels), got shape {x.shape}")
    return x


def sosfilt(sos: np.ndarray, x: np.ndarray, zi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cascaded second-order sections along axis 0 (``scipy.signal.sosfilt``).

    Parameters
    ----------
    sos : np.ndarray, shape (n_sections, 6, n_channels) or (n_sections, 6)
        Per channel, or shared.
    x : np.ndarray, shape (n_samples, n_channels)
    zi : np.ndarray, shape (n_sections, 2, n_channels)
        Initial state.

    Returns
    -------
    y : np.ndarray, shape (n_samples, n_channels)
    zf : np.ndarray, shape (n_sections, 2, n_channels)
        Final state.
    """
    x = _check_signal(x)
    sos = np.asarray(sos, dtype=np.float64)
    if sos.ndim == 2:
        sos = np.repeat(sos[:, :, None], x.shape[1], axis=2)
    z = np.array(zi, dtype=np.float64, copy=True)
    b0, b1, b2, a1, a2 = (sos[:, i] for i in (0, 1, 2, 4, 5))
    y = np.empty_like(x)
    for n in range(x.shape[0]):
        cur = x[n]
        for s in range(sos.shape[0]):
            new = b0[s] * cur + z[s, 0]
            z[s, 0] = b1[s] * cur - a1[s] * new + z[s, 1]
            z[s, 1] = b2[s] * cur - a2[s] * new
            cur = new
        y[n] = cur
    return y, z


def _lfilter_zi(b: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Steady-state state of a step response (``scipy.signal.lfilter_zi``), a[0] == 1."""
    n = len(a)
    companion = np.zeros((n - 1, n - 1))
    companion[0] = -a[1:]
    companion[np.arange(1, n - 1), np.arange(n - 2)] = 1.0
    return np.linalg.solve(np.eye(n - 1) - companion.T, b[1:] - a[1:] * b[0])


def sosfilt_zi(sos: np.ndarray) -> np.ndarray:
    """Initial state for a step response's steady state (``scipy.signal.sosfilt_zi``).

    Returns
    -------
    np.ndarray, shape (n_sections, 2)
    """
    zi = np.empty((sos.shape[0], 2))
    scale = 1.0
    for s in range(sos.shape[0]):
        b, a = sos[s, :3], sos[s, 3:]
        zi[s] = scale * _lfilter_zi(b, a)
        scale *= b.sum() / a.sum()
    return zi


def sosfiltfilt(sos: np.ndarray, x) -> np.ndarray:
    """Zero-phase forward-backward filtering (``scipy.signal.sosfiltfilt``, ``padtype="odd"``).

    Parameters
    ----------
    sos : np.ndarray, shape (n_sections, 6, n_channels) or (n_sections, 6)
        Per channel (every channel with as many sections), or shared.
    x : array-like, shape (n_samples, n_channels)

    Returns
    -------
    np.ndarray, shape (n_samples, n_channels)

    Raises
    ------
    ParameterError
        If the signal is not longer than the padding (3 x the filter's taps).
    """
    x = _check_signal(x)
    sos = np.asarray(sos, dtype=np.float64)
    shared = sos.ndim == 2
    per = sos[:, :, None] if shared else sos
    n_sections = per.shape[0]
    ntaps = 2 * n_sections + 1
    ntaps -= min(int((per[:, 2, 0] == 0).sum()), int((per[:, 5, 0] == 0).sum()))
    edge = 3 * ntaps
    if x.shape[0] <= edge:
        raise ParameterError(f"the signal has {x.shape[0]} samples: zero-phase filtering "
                             f"needs more than {edge}")
    # Odd extension (scipy.signal._arraytools.odd_ext).
    ext = np.concatenate((2 * x[:1] - x[edge:0:-1], x, 2 * x[-1:] - x[-2:-(edge + 2):-1]))
    zi = np.stack([sosfilt_zi(per[:, :, c]) for c in range(per.shape[2])], axis=2)
    if shared:
        zi = np.repeat(zi, x.shape[1], axis=2)
    y, _ = sosfilt(sos, ext, zi * ext[0])
    y, _ = sosfilt(sos, y[::-1], zi * y[-1])
    return y[::-1][edge:-edge].copy()


def lfilter(b, a, x, zi) -> tuple[np.ndarray, np.ndarray]:
    """Rational filter along axis 0 in transposed direct form II (``scipy.signal.lfilter``).

    Parameters
    ----------
    b, a : array-like, shape (n_b,) and (n_a,)
        Numerator and denominator (``a[0] != 0``; both are divided by it).
    x : array-like, shape (n_samples, n_channels)
    zi : array-like, shape (max(n_a, n_b) - 1, n_channels)
        Initial state.

    Returns
    -------
    y : np.ndarray, shape (n_samples, n_channels)
    zf : np.ndarray, shape (max(n_a, n_b) - 1, n_channels)
        Final state.
    """
    x = _check_signal(x)
    b = np.asarray(b, dtype=np.float64)
    a = np.asarray(a, dtype=np.float64)
    if a.ndim != 1 or b.ndim != 1 or a.size == 0 or b.size == 0 or a[0] == 0:
        raise ParameterError("lfilter needs 1-d coefficients with a[0] != 0")
    n = max(len(a), len(b))
    b = np.pad(b, (0, n - len(b))) / a[0]
    a = np.pad(a, (0, n - len(a))) / a[0]
    z = np.array(zi, dtype=np.float64, copy=True)
    if z.shape != (n - 1, x.shape[1]):
        raise ParameterError(f"zi must have shape {(n - 1, x.shape[1])}, got {z.shape}")
    y = np.empty_like(x)
    for t in range(x.shape[0]):
        xt = x[t]
        yt = z[0] + b[0] * xt if n > 1 else b[0] * xt
        for i in range(n - 2):
            z[i] = z[i + 1] + xt * b[i + 1] - yt * a[i + 1]
        if n > 1:
            z[n - 2] = xt * b[n - 1] - yt * a[n - 1]
        y[t] = yt
    return y, z
