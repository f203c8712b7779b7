"""WAV audio, through ``soundfile`` (libsndfile).

Audio crosses this boundary as float32 samples in [-1, 1]: shape ``(n_samples,)``
for mono, ``(n_samples, n_channels)`` otherwise. Any sample rate and any PCM or
float subtype libsndfile reads is accepted; files are written as 16-bit PCM.
"""

from __future__ import annotations

import logging
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
        Samples per second.

    Raises
    ------
    DataError
        If the file is missing, empty (no samples), truncated, corrupt, or holds
        non-finite samples.
    """
    path = Path(path)
    if not path.is_file():
        raise DataError(f"audio file not found: {path}")
    try:
        info = soundfile.info(str(path))
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
    if audio.shape[0] == 0:
        raise DataError(f"audio file has no samples: {path}")
    if not np.isfinite(audio).all():
        raise DataError(f"audio file has non-finite samples: {path}")
    peak = float(np.abs(audio).max())
    if peak > 1.0:
        logger.warning("%s: samples up to %.3f outside [-1, 1]; clipping", path, peak)
        np.clip(audio, -1.0, 1.0, out=audio)
    if mono:
        audio = audio.mean(axis=1, dtype=np.float32) if audio.shape[1] > 1 else audio[:, 0]
    logger.debug("read %s: %s at %d Hz (%s)", path, audio.shape, sample_rate, info.subtype)
    return np.ascontiguousarray(audio, dtype=np.float32), int(sample_rate)


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
