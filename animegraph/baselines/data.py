"""Training data of the baseline methods: per clip its speech, motion, emotion and phones.

Every baseline learns a frame-wise audio-to-visual mapping, so what it needs of a clip is
the speech (float samples), the motion in the database's channels at the database's
frame rate, the clip's emotion label and its phone segments (used by ``mu-mlp`` to form
its phoneme-class subsets, Hong et al. 2002 §VI-A). :func:`training_set` takes these from
a database or from :class:`ingest.prepare.PreparedClip` objects (the evaluation builds
its folds from prepared clips), and :func:`audio_features` computes the short-time
spectral features (MFCCs) at motion-frame times with a symmetric context window.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from db.errors import DataError, ParameterError
from ingest.formats.phones_csv import Segment
from ingest.motion import interpolate
from ingest.speech.features import mfcc

#: Frame hop of the MFCC analysis (s) before it is interpolated to the requested times.
MFCC_HOP_S = 0.010
#: MFCC analysis window (s).
MFCC_WIN_S = 0.025


@dataclass(frozen=True, eq=False)
class TrainingClip:
    """One utterance as the baselines see it.

    Attributes
    ----------
    audio : np.ndarray, shape (n_samples,), float32
        Speech in [-1, 1].
    motion : np.ndarray, shape (n_frames, n_channels), float64
        Motion in the database's channels at ``fps``.
    phones : tuple of Segment
        ARPAbet phone segments tiling the audio.
    posteriors, posterior_blank : np.ndarray or None
        hama's posteriorgram, shape (n, 39), and CTC blank, shape (n,), of the audio as
        ingest stored them (:class:`ingest.prepare.PreparedClip`); None when not stored.
        Another person's data: :func:`animegraph.baselines.ppg_forward.stored_posteriors`
        checks them before use.
    """

    clip_id: str
    audio: np.ndarray
    sample_rate: int
    motion: np.ndarray
    fps: float
    emotion: str
    phones: tuple[Segment, ...]
    posteriors: np.ndarray | None = None
    posterior_blank: np.ndarray | None = None

    @property
    def n_frames(self) -> int:
        return len(self.motion)


@dataclass(frozen=True, eq=False)
class TrainingSet:
    """Clips sharing one channel layout and frame rate.

    Attributes
    ----------
    names, groups : tuple of str
        Channel names and motion groups (``"head"``, ``"upper_face"``, ``"lips"`` ...).
    kind : str
        ``"markers"``, ``"curves"`` or ``"landmarks"``.
    """

    clips: tuple[TrainingClip, ...]
    names: tuple[str, ...]
    groups: tuple[str, ...]
    kind: str
    fps: float

    @property
    def n_channels(self) -> int:
        return len(self.names)

    @property
    def n_frames(self) -> int:
        return sum(c.n_frames for c in self.clips)

    @property
    def emotions(self) -> tuple[str, ...]:
        """Emotion labels present, sorted."""
        return tuple(sorted({c.emotion for c in self.clips}))

    def of_emotion(self, emotion: str) -> tuple[TrainingClip, ...]:
        return tuple(c for c in self.clips if c.emotion == emotion)


def training_set(source) -> TrainingSet:
    """The training data of ``source``.

    Parameters
    ----------
    source : db.store.Database, path of a database, TrainingSet, or sequence of
        ingest.prepare.PreparedClip
        Prepared clips must share one channel layout and frame rate.

    Raises
    ------
    DataError
        No clips, clips with different channels or frame rates, or an unreadable database.
    """
    if isinstance(source, TrainingSet):
        return source
    from db.store import Database

    if isinstance(source, str | os.PathLike):
        source = Database.open(source)
    if isinstance(source, Database):
        from ingest.tables import prepared_from_database

        source = prepared_from_database(source)
    clips = list(source)
    if not clips:
        raise DataError("no clips to train on")
    schema, fps = clips[0].schema, float(clips[0].fps)
    out = []
    for c in clips:
        if c.schema.names != schema.names or c.schema.kind != schema.kind:
            raise DataError(f"clip {c.clip_id} has other channels than {clips[0].clip_id}: "
                            "a model is trained on one channel layout")
        if float(c.fps) != fps:
            raise DataError(f"clip {c.clip_id} is at {c.fps} fps, {clips[0].clip_id} at {fps}")
        audio = np.asarray(c.audio)
        audio = (audio.astype(np.float32) / 32767.0 if audio.dtype == np.int16
                 else audio.astype(np.float32))
        out.append(TrainingClip(clip_id=c.clip_id, audio=audio, sample_rate=int(c.sample_rate),
                                motion=np.asarray(c.motion, dtype=np.float64), fps=fps,
                                emotion=c.emotion, phones=tuple(c.phones),
                                posteriors=getattr(c, "posteriors", None),
                                posterior_blank=getattr(c, "posterior_blank", None)))
    return TrainingSet(clips=tuple(out), names=tuple(schema.names),
                       groups=tuple(schema.groups), kind=schema.kind, fps=fps)


def frame_times(n_frames: int, fps: float) -> np.ndarray:
    """Times (s) of ``n_frames`` frames at ``fps``: shape (n_frames,)."""
    return np.arange(n_frames, dtype=np.float64) / float(fps)


def audio_features_at(audio: np.ndarray, sample_rate: int, times: np.ndarray, *,
                      n_mfcc: int, context: int, context_hop_s: float) -> np.ndarray:
    """MFCCs at ``times`` with ``context`` frames each side, ``context_hop_s`` apart.

    The MFCCs (:func:`ingest.speech.features.mfcc`, 10 ms hop, 25 ms window) are linearly
    interpolated to ``times + k * context_hop_s`` for k = -context..context; times before
    the start or after the end take the first or last frame (edge padding).

    Returns
    -------
    np.ndarray, shape (n_times, n_mfcc * (2 * context + 1)), float64
        Column block k (0-based) holds the coefficients at offset ``k - context``.
    """
    if context < 0:
        raise ParameterError(f"context must be >= 0 frames, got {context}")
    audio = np.asarray(audio, dtype=np.float32)
    coeffs = mfcc(audio, sample_rate, n_mfcc=n_mfcc, hop_s=MFCC_HOP_S,
                  win_s=MFCC_WIN_S).astype(np.float64)
    grid = np.arange(len(coeffs)) * MFCC_HOP_S
    times = np.asarray(times, dtype=np.float64)
    blocks = []
    for k in range(-context, context + 1):
        t = times + k * context_hop_s
        blocks.append(np.stack([np.interp(t, grid, coeffs[:, j]) for j in range(n_mfcc)],
                               axis=1))
    return np.concatenate(blocks, axis=1)


def audio_features(audio: np.ndarray, sample_rate: int, n_frames: int, fps: float, *,
                   n_mfcc: int, context: int) -> np.ndarray:
    """MFCCs at the times of ``n_frames`` frames at ``fps``, ``context`` frames each side.

    Hong et al. (2002, §VI-A) use 10 MFCCs with 3 frames of context each side at 30 fps;
    Terissi et al. (2013, §3) 11 MFCCs with tc = 3.

    Returns
    -------
    np.ndarray, shape (n_frames, n_mfcc * (2 * context + 1)), float64
    """
    return audio_features_at(audio, sample_rate, frame_times(n_frames, fps), n_mfcc=n_mfcc,
                             context=context, context_hop_s=1.0 / fps)


def resample_to(values: np.ndarray, fps: float, times: np.ndarray) -> np.ndarray:
    """Frames ``values`` (shape (n, d), at ``fps``) linearly interpolated at ``times``.

    Returns
    -------
    np.ndarray, shape (len(times), d), float64
    """
    return interpolate(frame_times(len(values), fps), values, times)


def phone_at(phones: Sequence[Segment], times: np.ndarray) -> list[str]:
    """The phone label at each time (the last segment for times past the end)."""
    if not phones:
        return ["SIL"] * len(times)
    starts = np.array([p.start for p in phones])
    idx = np.clip(np.searchsorted(starts, np.asarray(times), side="right") - 1, 0,
                  len(phones) - 1)
    return [phones[i].phone for i in idx]


#: Length (s) of the window each RMS value is taken over, centred on its frame.
RMS_WINDOW = 0.04
#: Length (s) of the moving average smoothing the envelope (the issue's 80 ms).
SMOOTH_SECONDS = 0.08


def rms_envelope(audio: np.ndarray, sample_rate: int, times: np.ndarray, *,
                 window: float = RMS_WINDOW, smooth: float = SMOOTH_SECONDS) -> np.ndarray:
    """Smoothed RMS loudness of ``audio`` at ``times``.

    Parameters
    ----------
    audio : np.ndarray, shape (n_samples,)
        Mono speech, float.
    sample_rate : int
        Hz.
    times : np.ndarray, shape (n_frames,)
        Seconds.
    window, smooth : float
        RMS window and moving-average length (s).

    Returns
    -------
    np.ndarray, shape (n_frames,), float64
    """
    x = np.asarray(audio, dtype=np.float64)
    if x.size == 0:
        return np.zeros(len(times))
    power = np.concatenate(([0.0], np.cumsum(x * x)))
    half = max(1, int(round(window * sample_rate / 2)))
    centre = np.clip(np.round(np.asarray(times) * sample_rate).astype(np.int64), 0, len(x))
    lo, hi = np.clip(centre - half, 0, len(x)), np.clip(centre + half, 0, len(x))
    env = np.sqrt((power[hi] - power[lo]) / np.maximum(hi - lo, 1))
    if len(times) > 1 and smooth > 0:
        step = float(np.median(np.diff(times)))
        width = max(1, int(round(smooth / step)))
        if width > 1:
            kernel = np.ones(width) / width
            env = np.convolve(np.pad(env, (width // 2, width - 1 - width // 2), mode="edge"),
                              kernel, mode="valid")
    return env
