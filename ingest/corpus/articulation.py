"""Articulatory targets per phone, blended across neighbours by dominance functions.

Each phone asks the speech controls of :mod:`ingest.corpus.face` for a target
(jaw opening, lip rounding and spreading, bilabial closure, labiodental tuck) with a
*dominance*: how strongly it holds that control against its neighbours. Following
Cohen & Massaro's coarticulation model, a phone's dominance over a control decays
with time from the centre of the phone as ``alpha * exp(-(|t - t_c| / tau) ** c)``
(longer ahead of it than behind: anticipation), and each control at time ``t`` is the
dominance-weighted mean of all targets. Bilabials dominate closure so strongly that
the lips meet whatever the vowels around them do; schwa and ``HH`` barely dominate
anything, so they take the shape of their context.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from db.errors import ParameterError
from ingest.corpus.face import SPEECH_CONTROLS
from ingest.speech.phones import PHONE_SET

# A target is a value per control; diphthongs give (onset, offset) pairs.
Target = dict[str, float | tuple[float, float]]

#: Articulatory targets of every phone. Unlisted controls have target 0.
PHONE_TARGETS: dict[str, Target] = {
    "AA": {"jaw_open": 0.75}, "AE": {"jaw_open": 0.6, "lip_spread": 0.4},
    "AH": {"jaw_open": 0.5}, "AO": {"jaw_open": 0.6, "lip_round": 0.4},
    "AW": {"jaw_open": (0.7, 0.3), "lip_round": (0.0, 0.7)},
    "AY": {"jaw_open": (0.7, 0.25), "lip_spread": (0.0, 0.5)},
    "EH": {"jaw_open": 0.45, "lip_spread": 0.3}, "ER": {"jaw_open": 0.3, "lip_round": 0.4},
    "EY": {"jaw_open": (0.45, 0.25), "lip_spread": (0.3, 0.5)},
    "IH": {"jaw_open": 0.3, "lip_spread": 0.4}, "IY": {"jaw_open": 0.2, "lip_spread": 0.7},
    "OW": {"jaw_open": (0.5, 0.3), "lip_round": (0.4, 0.8)},
    "OY": {"jaw_open": (0.5, 0.25), "lip_round": (0.6, 0.0), "lip_spread": (0.0, 0.5)},
    "UH": {"jaw_open": 0.3, "lip_round": 0.5}, "UW": {"jaw_open": 0.2, "lip_round": 0.9},
    "B": {"jaw_open": 0.1, "lip_close": 1.0}, "P": {"jaw_open": 0.1, "lip_close": 1.0},
    "M": {"jaw_open": 0.1, "lip_close": 1.0},
    "F": {"jaw_open": 0.12, "lip_tuck": 1.0}, "V": {"jaw_open": 0.12, "lip_tuck": 1.0},
    "TH": {"jaw_open": 0.18}, "DH": {"jaw_open": 0.18},
    "T": {"jaw_open": 0.15}, "D": {"jaw_open": 0.15}, "N": {"jaw_open": 0.15},
    "L": {"jaw_open": 0.2}, "S": {"jaw_open": 0.1, "lip_spread": 0.3},
    "Z": {"jaw_open": 0.1, "lip_spread": 0.3},
    "SH": {"jaw_open": 0.15, "lip_round": 0.6}, "ZH": {"jaw_open": 0.15, "lip_round": 0.6},
    "CH": {"jaw_open": 0.15, "lip_round": 0.6}, "JH": {"jaw_open": 0.15, "lip_round": 0.6},
    "K": {"jaw_open": 0.25}, "G": {"jaw_open": 0.25}, "NG": {"jaw_open": 0.2},
    "HH": {"jaw_open": 0.3}, "R": {"jaw_open": 0.2, "lip_round": 0.5},
    "W": {"jaw_open": 0.1, "lip_round": 1.0}, "Y": {"jaw_open": 0.15, "lip_spread": 0.4},
    "SIL": {},
}

#: Dominance magnitude ``alpha`` per phone and control (default 1).
PHONE_DOMINANCE: dict[str, dict[str, float]] = {
    **{p: {"lip_close": 20.0, "jaw_open": 2.0} for p in ("B", "P", "M")},
    **{p: {"lip_tuck": 15.0, "jaw_open": 2.0} for p in ("F", "V")},
    **{p: {"lip_round": 3.0} for p in ("W", "UW", "SH", "ZH", "CH", "JH")},
    "AH": {c: 0.6 for c in SPEECH_CONTROLS},
    "HH": {c: 0.2 for c in SPEECH_CONTROLS},
    "SIL": {c: 0.5 for c in SPEECH_CONTROLS},
}


@dataclass(frozen=True)
class CoarticulationParams:
    """Shape of the dominance functions (Cohen & Massaro 1993)."""

    tau_base: float = 0.03  # s; time constant of a vanishingly short phone
    tau_per_duration: float = 0.5  # tau grows with the phone: tau = base + this * duration
    anticipation: float = 1.3  # the dominance reaches this much further ahead than behind
    exponent: float = 1.5  # c in exp(-(|t - t_c| / tau) ** c)
    rest_dominance: float = 0.02  # a faint pull to the rest pose keeps the blend defined
    # Lip contacts (closure, tuck) are brief, strong gestures: high magnitude, fast decay,
    # so a bilabial closes the lips without holding them shut through its neighbours.
    contact_controls: tuple[str, ...] = ("lip_close", "lip_tuck")
    contact_tau_base: float = 0.015  # s
    contact_tau_per_duration: float = 0.35
    contact_exponent: float = 2.0
    diphthong_points: tuple[float, float] = (0.25, 0.8)  # where in a diphthong its two targets sit


def speech_controls(
    phones: Sequence[tuple[str, float, float]],
    times: np.ndarray,
    *,
    params: CoarticulationParams | None = None,
) -> np.ndarray:
    """Speech control curves for a phone sequence.

    Parameters
    ----------
    phones : sequence of (phone, start, end)
        ARPAbet phones with start and end times in seconds.
    times : np.ndarray, shape (n_frames,)
        Frame times in seconds.
    params : CoarticulationParams, optional
        Dominance function shape.

    Returns
    -------
    np.ndarray, shape (n_frames, len(SPEECH_CONTROLS))
        Control values in :data:`ingest.corpus.face.SPEECH_CONTROLS` order.

    Raises
    ------
    ParameterError
        If a phone is not in the phone set or a segment is empty.
    """
    p = params or CoarticulationParams()
    centres, durations, alphas, targets = [], [], [], []
    for phone, start, end in phones:
        if phone not in PHONE_SET:
            raise ParameterError(f"phone must be an ARPAbet phone, got {phone!r}")
        dur = end - start
        if not dur > 0:
            raise ParameterError(f"phone {phone!r} at {start:.3f}s has duration {dur}")
        tgt = PHONE_TARGETS[phone]
        dom = PHONE_DOMINANCE.get(phone, {})
        alpha = [dom.get(c, 1.0) for c in SPEECH_CONTROLS]
        two = any(isinstance(v, tuple) for v in tgt.values())
        points = p.diphthong_points if two else (0.5,)
        for k, frac in enumerate(points):
            centres.append(start + frac * dur)
            durations.append(dur / len(points))
            alphas.append(alpha)
            targets.append([_value(tgt.get(c, 0.0), k) for c in SPEECH_CONTROLS])
    dt = times[:, None] - np.asarray(centres)[None, :]
    dur = np.asarray(durations)[None, :]
    smooth = _dominance(dt, p.tau_base + p.tau_per_duration * dur, p.anticipation, p.exponent)
    contact = _dominance(dt, p.contact_tau_base + p.contact_tau_per_duration * dur,
                         p.anticipation, p.contact_exponent)
    alpha = np.asarray(alphas)  # (n_targets, n_controls)
    weighted = alpha * np.asarray(targets)
    out = np.empty((len(times), len(SPEECH_CONTROLS)))
    for i, name in enumerate(SPEECH_CONTROLS):
        shape = contact if name in p.contact_controls else smooth  # (n_frames, n_targets)
        out[:, i] = (shape @ weighted[:, i]) / (shape @ alpha[:, i] + p.rest_dominance)
    return out


def _dominance(dt: np.ndarray, tau: np.ndarray, anticipation: float, exponent: float):
    """Dominance shape exp(-(|dt| / tau) ** c), reaching further ahead than behind."""
    scale = np.where(dt < 0, tau * anticipation, tau)
    return np.exp(-((np.abs(dt) / scale) ** exponent))


def _value(v: float | tuple[float, float], k: int) -> float:
    return v[k] if isinstance(v, tuple) else v
