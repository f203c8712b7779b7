"""WAV audio, through ``soundfile`` (libsndfile).

Audio crosses this boundary as float32 samples in [-1, 1]: shape ``(n_samples,)``
for mono, ``(n_samples, n_channels)`` otherwise. Any PCM or float subtype libsndfile
reads is accepted; files are written as 16-bit PCM. Speech is read at a rate in
:data:`SPEECH_RATE_RANGE`: faster files are resampled down to its top, slower ones refused
(:func:`speech_samples`, shared with the sound tracks of :mod:`ingest.formats.media`).
"""

from __future__ import annotations

import logging
import math
import os
import re
from pathlib import Path

import numpy as np
import soundfile

from db.atomic import atomic_write
from db.errors import DataError, ParameterError

logger = logging.getLogger(__name__)

#: libsndfile logs ``data : <declared> (should be <actual>)`` when a chunk is cut short.
_SHORT_DATA = re.compile(r"^data\s*:\s*(\d+)\s*\(should be (\d+)\)", re.MULTILINE)
#: Declared sizes streaming writers use when the length is unknown (not truncation).
_SIZE_PLACEHOLDERS = (0, 0xFFFFFFFF, 0x7FFFFFFF)
#: Sample rates speech is read at (Hz): those the prosody features are tested at
#: (:mod:`ingest.speech.features`). Above 48 kHz there is nothing for speech (its
#: spectrum ends far below 24 kHz), so faster recordings are resampled down to 48 kHz;
#: below 8 kHz even the telephone band (to 3.4 kHz) is cut, so slower ones are refused.
SPEECH_RATE_RANGE: tuple[int, int] = (8000, 48000)
#: Most samples (all channels together) a speech file may hold: an hour of stereo at
#: 48 kHz (1.3 GiB as float32; a lecture recorded by a camera is stereo). Compressed
#: sound (FLAC, AAC, Opus) of silence takes a few bytes a second, so a small file may
#: decode to any size: the bound is checked before decoding (:func:`check_speech_size`).
MAX_SPEECH_SAMPLES = 2 * 3600 * 48000
#: Share of the channels' mean energy below which their average has cancelled them:
#: channels carrying the same speech keep all of it, unrelated ones 1 / n_channels
#: (half for stereo), an opposite-phase pair (right = -left) almost none.
CANCELLED_MIX = 0.1


def read_wav(path: str | os.PathLike[str], *, mono: bool = True) -> tuple[np.ndarray, int]:
    """Read an audio file as float32 samples in [-1, 1].

    Parameters
    ----------
    path : str or os.PathLike
        A WAV (or other libsndfile-readable) file.
    mono : bool, optional
        Average all channels into one (default). If False, keep the channels.

    Returns
    -------
    audio : np.ndarray, float32
        Shape (n_samples,) if ``mono``, else (n_samples, n_channels).
    sample_rate : int
        Samples per second, in :data:`SPEECH_RATE_RANGE` (see :func:`speech_samples`).

    Raises
    ------
    DataError
        If the file is missing, empty (no samples), truncated, corrupt, holds
        non-finite samples, is sampled below 8 kHz, or declares more than
        :data:`MAX_SPEECH_SAMPLES`.
    """
    path = Path(path)
    if not path.is_file():
        raise DataError(f"audio file not found: {path}")
    if path.stat().st_size == 0:  # libsndfile would say "Format not recognised"
        raise DataError(f"empty audio file {path} (0 bytes)")
    try:
        info = soundfile.info(str(path))
        # the length the header declares, which is what soundfile allocates for
        check_speech_size(info.frames, info.channels, info.samplerate, path)
        audio, sample_rate = soundfile.read(str(path), dtype="float32", always_2d=True)
    except (soundfile.SoundFileError, RuntimeError, ValueError, TypeError) as exc:
        raise DataError(f"corrupt or unreadable audio file {path}: {exc}") from exc

    short = _SHORT_DATA.search(info.extra_info or "")
    if short is not None:
        declared, actual = int(short.group(1)), int(short.group(2))
        if declared > actual and declared not in _SIZE_PLACEHOLDERS:
            raise DataError(
                f"truncated audio file {path}: data chunk declares {declared} bytes, "
                f"holds {actual}"
            )
    audio, sample_rate = speech_samples(audio, int(sample_rate), path, mono=mono)
    logger.debug("read %s: %s at %d Hz (%s)", path, audio.shape, sample_rate, info.subtype)
    return audio, sample_rate


def check_speech_size(n_frames: int, n_channels: int, sample_rate: float,
                      where: str | os.PathLike[str]) -> None:
    """Refuse sound of more than :data:`MAX_SPEECH_SAMPLES` (frames x channels).

    Raises
    ------
    DataError
        One line naming ``where``, its length and the bound.
    """
    if n_frames * n_channels > MAX_SPEECH_SAMPLES:
        minutes = n_frames / max(sample_rate, 1) / 60
        raise DataError(f"{where}: at least {minutes:.0f} min of sound in {n_channels} "
                        f"channel(s) at {sample_rate:g} Hz; speech is read up to "
                        f"{MAX_SPEECH_SAMPLES:,} samples (an hour of stereo at 48 kHz)")


def speech_samples(audio: np.ndarray, sample_rate: int, where: str | os.PathLike[str], *,
                   mono: bool = True) -> tuple[np.ndarray, int]:
    """Decoded speech made ready for the speech code: checked, clipped, resampled, mixed.

    The one place these rules live, for WAV files (:func:`read_wav`) and the sound tracks
    of videos (:func:`ingest.formats.media.read_audio`) alike.

    Parameters
    ----------
    audio : np.ndarray, float32, shape (n_samples, n_channels)
        Samples as decoded, nominally in [-1, 1].
    sample_rate : int
        Their rate in Hz.
    where : str or os.PathLike
        The file they came from, named in errors and warnings.
    mono : bool, optional
        Mix the channels into one (default; :func:`to_mono`).

    Returns
    -------
    audio : np.ndarray, float32
        Shape (n_out,) if ``mono``, else (n_out, n_channels); ``n_out`` is
        ``n_samples`` unless resampled. Samples outside [-1, 1] are clipped (with a
        warning).
    sample_rate : int
        ``sample_rate``, or the top of :data:`SPEECH_RATE_RANGE` if it was faster.

    Raises
    ------
    DataError
        If there are no samples, a sample is not finite, or ``sample_rate`` is below
        :data:`SPEECH_RATE_RANGE`.
    """
    if audio.shape[0] == 0:
        raise DataError(f"audio file has no samples: {where}")
    if not np.isfinite(audio).all():
        raise DataError(f"audio file has non-finite samples: {where}")
    low, high = SPEECH_RATE_RANGE
    if sample_rate < low:
        raise DataError(f"{where}: sampled at {sample_rate} Hz; speech needs at least "
                        f"{low} Hz")
    peak = float(np.abs(audio).max())
    if peak > 1.0:
        logger.warning("%s: samples up to %.3f outside [-1, 1]; clipping", where, peak)
        audio = np.clip(audio, -1.0, 1.0)
    if sample_rate > high:
        g = math.gcd(high, sample_rate)
        from scipy.signal import resample_poly  # deferred: a second of a one-shot synth

        logger.info("%s: resampling from %d Hz to %d Hz", where, sample_rate, high)
        audio = resample_poly(audio, high // g, sample_rate // g, axis=0)
        # the anti-aliasing filter can ring past full scale next to a loud transient
        audio = np.clip(audio, -1.0, 1.0)
        sample_rate = high
    if mono:
        audio = to_mono(audio, where)
    return np.ascontiguousarray(audio, dtype=np.float32), int(sample_rate)


def to_mono(audio: np.ndarray, where: str | os.PathLike[str]) -> np.ndarray:
    """The channels of ``audio`` mixed into one: their mean, unless that cancels them.

    Channels in opposite phase (right = -left, a miswired microphone or a swapped
    polarity) average to silence, which would be taken for "no speech". When the mean
    keeps less than :data:`CANCELLED_MIX` of the channels' mean energy, the loudest
    channel alone is used instead, and a warning says so.

    Parameters
    ----------
    audio : np.ndarray, shape (n_samples, n_channels)
    where : str or os.PathLike
        The file they came from, named in the warning.

    Returns
    -------
    np.ndarray, float32, shape (n_samples,)
    """
    if audio.shape[1] == 1:
        return audio[:, 0]
    mix = audio.mean(axis=1, dtype=np.float32)
    energy = np.einsum("ij,ij->j", audio, audio, dtype=np.float64)  # per channel
    mixed = float(np.einsum("i,i->", mix, mix, dtype=np.float64))
    kept = mixed / float(energy.mean()) if energy.any() else 1.0
    if kept >= CANCELLED_MIX:
        return mix
    loudest = int(np.argmax(energy))
    logger.warning("%s: its %d channels cancel when averaged (opposite phase?): the mix "
                   "keeps %.1f %% of their energy; using channel %d alone", where,
                   audio.shape[1], 100 * kept, loudest + 1)
    return audio[:, loudest]


def write_wav(path: str | os.PathLike[str], audio: np.ndarray, sample_rate: int) -> None:
    """Write audio as a 16-bit PCM WAV file, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Target file; written to a temporary file beside it, then renamed.
    audio : np.ndarray
        Float samples in [-1, 1] (values outside are clipped, with a warning), shape
        (n_samples,) or (n_samples, n_channels); or int16 PCM samples.
    sample_rate : int
        Samples per second, > 0.

    Raises
    ------
    ParameterError
        If ``audio`` is empty, has the wrong shape or dtype or non-finite values, or
        ``sample_rate`` is not a positive integer.
    DataError
        If the file cannot be written.
    """
    if isinstance(sample_rate, bool) or not isinstance(sample_rate, int | np.integer):
        raise ParameterError(f"sample_rate: expected a positive int, got {sample_rate!r}")
    if not 0 < sample_rate < 2**31:
        raise ParameterError(f"sample_rate: expected a positive int, got {sample_rate!r}")
    audio = np.asarray(audio)
    if audio.ndim not in (1, 2) or audio.shape[0] == 0 or (audio.ndim == 2 and audio.shape[1] == 0):
        raise ParameterError(
            f"audio: expected a non-empty (n_samples,) or (n_samples, n_channels) array, "
            f"got shape {audio.shape}"
        )
    if audio.dtype == np.int16:
        samples = audio
    elif np.issubdtype(audio.dtype, np.floating):
        if not np.isfinite(audio).all():
            raise ParameterError("audio: non-finite samples")
        peak = float(np.abs(audio).max())
        if peak > 1.0:
            logger.warning("writing %s: samples up to %.3f outside [-1, 1]; clipping", path, peak)
        samples = np.clip(audio, -1.0, 1.0).astype(np.float32)
    else:
        raise ParameterError(f"audio: expected float or int16 samples, got dtype {audio.dtype}")

    with atomic_write(path) as handle:
        soundfile.write(handle, samples, int(sample_rate), subtype="PCM_16", format="WAV")
    logger.debug("wrote %s: %s at %d Hz", path, samples.shape, sample_rate)
