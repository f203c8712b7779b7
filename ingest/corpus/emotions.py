"""The five emotions of Cao et al. (2005, §3.1), in the voice and in the face.

Each emotion has an eSpeak NG voice preset (rate, pitch, pitch range, loudness, pauses
between words) and a facial style: static levels of the emotion controls of
:mod:`ingest.corpus.face`, a gain on articulation amplitude, and gains on the
prosody-driven gestures (brow raises on pitch peaks, head nods on energy peaks).
Every (sentence, emotion) pair is recorded in several *variations*; each variation
jitters the voice and the face around the preset (:func:`vary`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from db.errors import ParameterError
from ingest.speech.espeak import Voice

#: Emotion labels, in the paper's order of database size (§3.1: 59 frustrated,
#: 85 happy, 86 neutral, 100 sad, 112 angry sentences).
EMOTIONS: tuple[str, ...] = ("neutral", "happy", "angry", "sad", "frustrated")


@dataclass(frozen=True)
class EmotionStyle:
    """How one emotion sounds and looks."""

    voice: Voice
    expression: dict[str, float] = field(default_factory=dict)  # static emotion-control levels
    articulation: float = 1.0  # gain on jaw opening, rounding and spreading
    brow_gain: float = 1.0  # height of the brow raises on pitch peaks
    nod_gain: float = 1.0  # depth of the head nods on energy peaks
    blink_rate: float = 0.25  # blinks per second
    head_pitch: float = 0.0  # posture, degrees (positive: head down)


#: The per-emotion presets. Articulation gains order the emotions
#: angry > happy > neutral > frustrated > sad, which the tests check on the markers.
STYLES: dict[str, EmotionStyle] = {
    "neutral": EmotionStyle(
        voice=Voice(rate=165, pitch=50, pitch_range=50, volume=100),
    ),
    "happy": EmotionStyle(
        voice=Voice(rate=180, pitch=64, pitch_range=85, volume=115),
        expression={"smile": 0.8, "brow_raise": 0.15},
        articulation=1.12, brow_gain=1.3, nod_gain=1.2, blink_rate=0.3,
    ),
    "angry": EmotionStyle(
        voice=Voice(rate=180, pitch=56, pitch_range=75, volume=150),
        expression={"brow_lower": 0.8, "lip_press": 0.3},
        articulation=1.3, brow_gain=0.5, nod_gain=1.5, blink_rate=0.15, head_pitch=-1.0,
    ),
    "sad": EmotionStyle(
        voice=Voice(rate=130, pitch=38, pitch_range=20, volume=75, word_gap=2),
        expression={"lip_corner_depress": 0.7, "inner_brow_raise": 0.6},
        articulation=0.7, brow_gain=0.4, nod_gain=0.5, blink_rate=0.35, head_pitch=5.0,
    ),
    "frustrated": EmotionStyle(
        voice=Voice(rate=155, pitch=45, pitch_range=40, volume=110, word_gap=3),
        expression={"brow_lower": 0.45, "lip_corner_depress": 0.35, "lip_press": 0.4},
        articulation=0.88, brow_gain=0.8, nod_gain=0.9, blink_rate=0.3, head_pitch=1.5,
    ),
}


@dataclass(frozen=True)
class Jitter:
    """Spread of one variation around its emotion's preset (uniform, +/-)."""

    rate: float = 0.06  # relative
    pitch: int = 4  # eSpeak pitch units
    pitch_range: int = 6
    volume: float = 0.05  # relative
    expression: float = 0.15  # relative, per control
    articulation: float = 0.04  # relative


def style(emotion: str) -> EmotionStyle:
    """Return the preset of ``emotion`` (one of :data:`EMOTIONS`)."""
    try:
        return STYLES[emotion]
    except KeyError:
        raise ParameterError(
            f"emotion must be one of {', '.join(EMOTIONS)}, got {emotion!r}"
        ) from None


def vary(emotion: str, rng: np.random.Generator, jitter: Jitter | None = None) -> EmotionStyle:
    """A variation of an emotion's preset: voice and face jittered by ``rng``.

    Parameters
    ----------
    emotion : str
        One of :data:`EMOTIONS`.
    rng : numpy.random.Generator
        Source of the variation (seed it for a deterministic corpus).
    jitter : Jitter, optional
        How far a variation may stray from the preset.
    """
    base, j = style(emotion), jitter or Jitter()

    def u(scale: float) -> float:
        return float(rng.uniform(-scale, scale))

    v = base.voice
    voice = replace(
        v,
        rate=int(round(v.rate * (1 + u(j.rate)))),
        pitch=int(np.clip(v.pitch + round(u(j.pitch)), 0, 100)),
        pitch_range=int(np.clip(v.pitch_range + round(u(j.pitch_range)), 0, 100)),
        volume=int(np.clip(round(v.volume * (1 + u(j.volume))), 0, 200)),
    )
    expression = {k: max(0.0, x * (1 + u(j.expression))) for k, x in base.expression.items()}
    return replace(
        base,
        voice=voice,
        expression=expression,
        articulation=base.articulation * (1 + u(j.articulation)),
    )
