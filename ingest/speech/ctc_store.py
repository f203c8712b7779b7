"""The phone model's outputs kept in the user's cache folder (``<cache>/phones/``).

Ingest's clip preparation, and a command's synthesis within
:func:`ingest.speech.heard.remembered`, keep hama's posteriors (:mod:`ingest.speech.ctc`)
as a video's tracking is kept, so that hearing the same audio again does not run the
model: ``.npy`` files (read without pickles, checked against the audio's length), named
by a digest of the 16 kHz audio, hama's version and the piece layout; and, for audio of
another rate, a small file naming the digest of its 16 kHz version, so that it is found
without resampling.
"""

from __future__ import annotations

import contextvars
import functools
import hashlib
import logging
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from db.errors import DataError
from ingest.speech.ctc_timing import FRAME_RATE, SAMPLE_RATE
from ingest.speech.phones import PHONES

logger = logging.getLogger(__name__)

__all__ = ["alias_path", "audio_key", "disk_path", "from_disk", "hama_version", "kept_on_disk",
           "on_disk", "read_alias", "to_disk", "write_alias"]

#: Set (:func:`kept_on_disk`) while ingest prepares clips: the model's outputs are then
#: also kept in the user's cache, as a video's tracking is, so that a re-ingest does not
#: run the model again (GRID's 800 clips: about 200 CPU-s).
_ON_DISK: contextvars.ContextVar[bool] = contextvars.ContextVar("hama_on_disk", default=False)


@contextmanager
def kept_on_disk() -> Iterator[None]:
    """Within this block, keep the model's outputs in ``<cache>/phones/`` by a digest of
    their 16 kHz input (and reuse them): ingest's clip preparation, not one-off synthesis."""
    token = _ON_DISK.set(True)
    try:
        yield
    finally:
        _ON_DISK.reset(token)


def on_disk() -> bool:
    """True within :func:`kept_on_disk`."""
    return _ON_DISK.get()


def disk_path(key: bytes, layout: int) -> Path:
    """Where the posteriors of the 16 kHz audio of digest ``key`` (:func:`audio_key`),
    heard in the pieces of layout ``layout`` (:data:`ingest.speech.ctc.PIECE_LAYOUT`),
    are kept."""
    from ingest.cache import cache_dir

    return (cache_dir() / "phones"
            / f"{key.hex()}-hama{hama_version()}-pieces{layout}.npy")


@functools.cache  # read once a process, not once a clip
def hama_version() -> str:
    from importlib.metadata import version

    return version("hama")


def from_disk(path: Path, n_samples: int) -> np.ndarray | None:
    """Posteriors kept by :func:`to_disk`, if they are what the model would give for
    ``n_samples`` of audio (a damaged or foreign file is ignored and replaced)."""
    most = n_samples // (SAMPLE_RATE // FRAME_RATE) + 2
    try:
        # never more than this audio's posteriors (and npy's header) is read into memory
        if path.stat().st_size > most * len(PHONES) * 8 + 4096:
            raise ValueError(f"{path.stat().st_size} bytes, more than this audio's")
        probs = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as exc:
        logger.warning("%s: unreadable (%s); running the phone model again", path, exc)
        return None
    if (probs.dtype != np.float64 or probs.ndim != 2 or probs.shape[1] != len(PHONES)
            or not 0 < len(probs) <= most or not np.isfinite(probs).all()
            or np.any(probs < 0) or np.abs(probs.sum(axis=1) - 1).max() > 1e-3):
        logger.warning("%s: not this audio's phone posteriors; running the model again", path)
        return None
    return probs


def to_disk(path: Path, probs: np.ndarray) -> None:
    import io

    from db.atomic import atomic_write

    buffer = io.BytesIO()
    np.save(buffer, probs, allow_pickle=False)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_write(path) as handle:
            handle.write(buffer.getvalue())
        # the same audio's posteriors of another hama or piece layout are never read again
        for stale in path.parent.glob(f"{path.name.split('-', 1)[0]}-*.npy"):
            if stale != path:
                stale.unlink(missing_ok=True)
    except OSError as exc:  # a cache that cannot be written costs time, not the result
        logger.warning("%s: cannot keep the phone posteriors (%s)", path, exc)


def audio_key(samples16: np.ndarray) -> bytes:
    """The digest the model's outputs for ``samples16`` are remembered and kept by."""
    return hashlib.blake2b(np.ascontiguousarray(samples16).tobytes(), digest_size=16).digest()


def alias_path(samples: np.ndarray, sample_rate: int) -> Path:
    """Where the digest of ``samples``' 16 kHz version (as hama hears them) is kept, by a
    digest of ``samples`` (float32, as :func:`ingest.speech.inputs.check_audio` gives
    them) and their rate."""
    from ingest.cache import cache_dir

    digest = hashlib.blake2b(np.ascontiguousarray(samples).tobytes(), digest_size=16)
    digest.update(f"/{int(sample_rate)}".encode())
    return cache_dir() / "phones" / f"{digest.hexdigest()}.at16k"


def read_alias(path: Path) -> bytes | None:
    """The digest :func:`write_alias` kept at ``path``, or None (absent or not one)."""
    try:
        if not path.is_file() or path.stat().st_size != 32:  # a file of 32 hex digits
            return None
        text = path.read_text(encoding="ascii")
        return bytes.fromhex(text) if len(text) == 32 else None
    except (OSError, ValueError):
        return None


def write_alias(path: Path, key: bytes) -> None:
    from db.atomic import atomic_write

    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_write(path) as handle:
            handle.write(key.hex().encode("ascii"))
    except (OSError, DataError) as exc:  # a cache that cannot be written costs time, not the result
        logger.warning("%s: cannot keep the digest of the resampled audio (%s)", path, exc)
