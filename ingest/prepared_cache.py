"""Prepared clips kept in the cache folder while an ingest runs, so that a killed one,
run again, redoes only the clips it had not finished.

An entry is ``<cache>/prepared/<key>.npz``: the clip's arrays and one JSON document
(``meta``, UTF-8 bytes), read back with ``allow_pickle=False``. The key is a SHA-256 of
the clip's bytes (its checksum) and of every setting the preparation depends on
(:func:`entry_key`: for an ingest, the clip's name and the database's folder too), so an
entry is used only for the same clip of the same bytes prepared the same way.
Entries are written atomically as the clips are prepared (by the process pool's workers,
which share this machine's cache folder, or by the Dask client, whose workers may not),
and removed once their clips are in the database.

The folder is bounded (:class:`Bound`, :data:`MAX_BYTES`): what an ingest killed and never
run again left behind, or kept with other settings, is evicted least recently used first.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import logging
import os
import time
from dataclasses import asdict, fields
from pathlib import Path

import numpy as np

from db.atomic import atomic_write
from db.errors import DataError
from ingest.cache import cache_dir
from ingest.clip import ChannelSchema
from ingest.formats.phones_csv import Segment
from ingest.prepare import PreparedClip

logger = logging.getLogger(__name__)

#: Bumped whenever what an entry holds, or how a clip is prepared, changes.
FORMAT = 2
#: The arrays of a :class:`PreparedClip` kept as they are (None ones are left out).
_ARRAYS = ("motion", "missing", "audio", "prosody", "posteriors", "posterior_blank")
#: Bytes the entries may take in all (:class:`Bound`). A prepared GRID video of 3 s takes
#: 0.64 MB (its face points at 25 fps, its 16 kHz audio): 8 GiB keep 13,000 of them, 11
#: hours of such clips. An ingest holds all of its prepared clips in memory before it
#: writes them, so the bound is of the size of a large ingest's memory.
MAX_BYTES = 8 << 30
#: Age (s) after which a half-written entry (``atomic_write``'s temporary file, left by a
#: worker ended as it wrote) is removed.
STALE_WRITE_S = 3600.0


def folder() -> Path:
    """``<cache>/prepared``: where the entries are."""
    return cache_dir() / "prepared"


def entry_key(checksum: str, settings: dict, reference: np.ndarray | None) -> str:
    """The entry of a clip with these bytes (``checksum``) prepared with ``settings`` (a
    JSON-able dict: frame rate, phone engine, limits, schema, the package's version (a
    new one prepares anew), the clip's name and its database's folder) and head
    ``reference``, shape (n_head_points, 3)."""
    digest = hashlib.sha256()
    head = {"format": FORMAT, "checksum": checksum, **settings}
    digest.update(json.dumps(head, sort_keys=True, default=str).encode())
    if reference is not None:
        ref = np.ascontiguousarray(reference, dtype=np.float64)
        digest.update(repr(ref.shape).encode() + ref.tobytes())
    return digest.hexdigest()


def save(key: str, clip: PreparedClip, report: dict) -> None:
    """Keep ``clip`` (and its ingest ``report`` row, a dict) under ``key``; a failure to
    write is logged, not raised: the ingest goes on, only its resume is poorer."""
    arrays = {name: np.asarray(getattr(clip, name)) for name in _ARRAYS
              if getattr(clip, name) is not None}
    meta = {f.name: getattr(clip, f.name) for f in fields(PreparedClip)
            if f.name not in _ARRAYS and f.name not in ("schema", "phones",
                                                        "emotion_features")}
    meta["schema"] = asdict(clip.schema)
    meta["phones"] = [[p.phone, float(p.start), float(p.end)] for p in clip.phones]
    meta["report"] = report
    features = clip.emotion_features
    if features is None or isinstance(features, str):
        meta["emotion_features"] = features
    else:  # SpeechFeatures: the functionals, and the frame descriptors when computed
        arrays["features_functionals"] = np.asarray(features.functionals)
        frames = features.frames
        meta["emotion_features"] = {"frames": None if frames is None else len(frames)}
        for k, block in enumerate(frames or ()):
            arrays[f"features_frames_{k}"] = np.asarray(block)
    arrays["meta"] = np.frombuffer(json.dumps(meta, default=float).encode(), dtype=np.uint8)
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    try:
        folder().mkdir(parents=True, exist_ok=True)
        with atomic_write(folder() / f"{key}.npz") as handle:
            handle.write(buffer.getbuffer())
    except (OSError, DataError) as exc:
        logger.warning("cannot keep a prepared clip in %s: %s", folder(), exc)


def load(key: str) -> tuple[PreparedClip, dict] | None:
    """(the clip, its report row) kept under ``key``, or None when there is none, or it
    cannot be read (it is then prepared again)."""
    path = folder() / f"{key}.npz"
    if not path.is_file():
        return None
    with contextlib.suppress(OSError):
        os.utime(path)  # used now: the last to be evicted (Bound)
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {name: data[name] for name in data.files}
        meta = json.loads(arrays.pop("meta").tobytes().decode())
        report = meta.pop("report")
        return _clip(meta, arrays), report
    except (OSError, ValueError, KeyError, TypeError, DataError) as exc:
        logger.warning("a prepared clip in the cache cannot be read (%s); preparing it "
                       "again: %s", path.name, exc)
        return None


def remove(keys) -> None:
    """Drop the entries of ``keys`` (their clips are in the database now)."""
    for key in keys:
        try:
            (folder() / f"{key}.npz").unlink(missing_ok=True)
        except OSError as exc:  # a left entry costs disk only
            logger.debug("cannot remove %s: %s", key, exc)


class Bound:
    """Keeps the entries' bytes under ``max_bytes``: the least recently used (written or
    taken) are removed first.

    Made once an ingest (it reads the folder's entries then); :meth:`used` is called in
    the process that writes the database for each entry written or taken since, which
    may evict the oldest. Another ingest sharing the folder at the same time may have
    it over the bound for a while; an entry evicted under it is prepared again.
    """

    def __init__(self, max_bytes: int = MAX_BYTES) -> None:
        self.max_bytes = max_bytes
        found = []
        with contextlib.suppress(OSError):  # no folder yet: nothing kept
            for path in folder().glob("*.npz"):
                with contextlib.suppress(OSError):
                    stat = path.stat()
                    found.append((stat.st_mtime, path.stem, stat.st_size))
            # A write takes milliseconds: older ones are of workers ended while writing.
            stale = time.time() - STALE_WRITE_S
            for path in folder().glob(".*.tmp"):
                with contextlib.suppress(OSError):
                    if path.stat().st_mtime < stale:
                        path.unlink()
        #: key -> size, oldest first (dicts keep their order of insertion)
        self.sizes = {key: size for _, key, size in sorted(found)}
        self.total = sum(self.sizes.values())
        self.evicted = 0

    def used(self, key: str) -> None:
        """``key``'s entry was just written or taken: the newest now; then the oldest
        entries are removed until the folder is under the bound (never this one)."""
        self.total -= self.sizes.pop(key, 0)
        try:
            self.sizes[key] = (folder() / f"{key}.npz").stat().st_size
        except OSError:  # not written (logged by save): nothing to count
            return
        self.total += self.sizes[key]
        while self.total > self.max_bytes and len(self.sizes) > 1:
            oldest = next(iter(self.sizes))
            self.total -= self.sizes.pop(oldest)
            remove([oldest])
            self.evicted += 1


def _clip(meta: dict, arrays: dict) -> PreparedClip:
    from ingest.emotion.classifier import SpeechFeatures

    features = meta.pop("emotion_features")
    if isinstance(features, dict):
        n = features["frames"]
        features = SpeechFeatures(
            arrays.pop("features_functionals"),
            None if n is None else [arrays.pop(f"features_frames_{k}") for k in range(n)])
    schema = meta.pop("schema")
    schema = ChannelSchema(kind=schema["kind"], names=tuple(schema["names"]),
                           groups=tuple(schema["groups"]), units=schema["units"])
    phones = tuple(Segment(str(p), float(s), float(e)) for p, s, e in meta.pop("phones"))
    kept = {name: arrays.get(name) for name in _ARRAYS}
    return PreparedClip(**meta, **kept, schema=schema, phones=phones,
                        emotion_features=features)
