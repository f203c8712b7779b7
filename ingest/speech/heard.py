"""Phones heard once: a recording's segmentation kept in the user's cache folder.

Finding the phones of recorded speech (hama naming them, PocketSphinx placing them, or
aligning a transcript) is nearly all of an audio-only synthesis (5.4 s of 6.1 s for 49 s
of speech). A user trying options on one recording would pay it every time; within
:func:`remembered` the segmentation is kept under ``<cache>/heard/`` (the folder of
:func:`ingest.cache.cache_dir`) and the phone model's outputs under ``<cache>/phones/``
(:func:`ingest.speech.ctc.kept_on_disk`), so the second run runs neither engine.

An entry is named by a digest of what decides the segmentation: the audio's samples and
rate, the transcript, the phone engine, the engines' versions and :data:`FORMAT` (raised
when this project's segmentation changes). It is JSON (no code is ever read from the
cache), written atomically, checked when read (phones of the phone set, finite times
tiling the audio): an entry that fails is ignored and written again. Both folders are
bounded (:data:`MAX_BYTES`): the entries used longest ago are removed first.
"""

from __future__ import annotations

import contextvars
import functools
import hashlib
import json
import logging
import math
import os
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ingest.formats.phones_csv import Segment

logger = logging.getLogger(__name__)

__all__ = ["FORMAT", "MAX_BYTES", "Uses", "bound_folder", "entry_path", "remembered",
           "segment_once"]

#: Raised whenever this project's segmentation gives other phones for the same input.
FORMAT = 1
#: Most bytes each cache folder (``heard/``, ``phones/``) keeps. A segmentation is ~5 KB a
#: minute of speech and the phone model's outputs ~1.3 MB a minute: this keeps hours.
MAX_BYTES = 256 << 20
#: Largest entry read (a 15-minute recording's segments are under 200 KB).
_MAX_ENTRY_BYTES = 4 << 20
_METHODS = ("aligned", "recognized")


@dataclass
class Uses:
    """What :func:`segment_once` did within one :func:`remembered` block."""

    #: Segmentations read from the cache (no phone engine ran for them).
    hits: int = 0
    #: Segmentations found by the engines (and kept).
    misses: int = 0


_ON: contextvars.ContextVar[Uses | None] = contextvars.ContextVar("heard_on", default=None)


@contextmanager
def remembered() -> Iterator[Uses]:
    """Within this block :func:`segment_once` keeps and reuses segmentations, and the
    phone model's outputs are kept too (a command's one synthesis, not a benchmark's).
    Yields the block's :class:`Uses`."""
    from ingest.speech import ctc

    with ExitStack() as stack:
        uses = Uses()
        token = _ON.set(uses)
        stack.callback(_ON.reset, token)
        stack.enter_context(ctc.kept_on_disk())
        try:
            yield uses
        finally:
            from ingest.cache import cache_dir

            for name in ("heard", "phones"):
                bound_folder(cache_dir() / name)


@functools.cache
def _versions() -> str:
    from importlib.metadata import PackageNotFoundError, version

    found = []
    for package in ("hama", "pocketsphinx"):
        try:
            found.append(f"{package}{version(package)}")
        except PackageNotFoundError:
            found.append(f"{package}-")
    return "-".join(found)


def entry_path(samples: np.ndarray, sample_rate: int, text: str | None,
               engine: str) -> Path:
    """Where the segmentation of ``samples`` (mono float32, shape (n_samples,)) at
    ``sample_rate`` with ``text`` (None: none) by ``engine`` is kept."""
    from ingest.cache import cache_dir

    digest = hashlib.blake2b(digest_size=16)
    digest.update(np.ascontiguousarray(samples, dtype=np.float32).tobytes())
    digest.update(json.dumps([int(sample_rate), text, engine, _versions(), FORMAT]).encode())
    return cache_dir() / "heard" / f"{digest.hexdigest()}.json"


def segment_once(audio: np.ndarray, sample_rate: int, *, text: str | None = None,
                 engine: str | None = None, on_fallback: Callable[[str], object] | None = None
                 ) -> tuple[list[Segment], str, bool]:
    """:func:`ingest.speech.segment.segment` of speech without labels, kept and reused
    within :func:`remembered` (outside it, always run).

    Returns
    -------
    segments : list of Segment
    method : str
        ``"aligned"`` or ``"recognized"``.
    cached : bool
        True if the segmentation was read from the cache (no phone engine ran for it).
        The lines the segmentation said (a failed alignment's fallback, a doubted
        transcript) are said again from the cache.
    """
    from ingest.speech import ctc
    from ingest.speech.engines import check_engine
    from ingest.speech.inputs import check_audio
    from ingest.speech.segment import segment

    uses = _ON.get()
    if uses is None:
        return (*segment(audio, sample_rate, text=text, engine=engine,
                         on_fallback=on_fallback), False)
    samples, sample_rate = check_audio(audio, sample_rate)
    engine = check_engine(engine)
    path = entry_path(samples, sample_rate, text, engine)
    entry = _read(path, len(samples) / sample_rate) if path.is_file() else None
    if entry is not None:
        uses.hits += 1
        try:  # the entry read last is the last to go (bound_folder)
            os.utime(path)
        except OSError:
            pass
        segments, method, fallback, doubts = entry
        for line in fallback:
            if on_fallback is None:
                logger.warning("%s", line)
            else:
                on_fallback(line)
        for line in doubts:
            ctc.doubt(line)
        return segments, method, True
    fallback: list[str] = []

    def fell_back(line: str) -> None:
        fallback.append(line)
        if on_fallback is None:
            logger.warning("%s", line)
        else:
            on_fallback(line)

    with ctc.doubts() as doubted:
        segments, method = segment(samples, sample_rate, text=text, engine=engine,
                                   on_fallback=fell_back)
    for line in doubted:  # said where the caller collects them, as segment would have
        ctc.doubt(line)
    uses.misses += 1
    _write(path, segments, method, fallback, doubted)
    return segments, method, False


def _read(path: Path, duration: float):
    """(segments, method, fallback lines, doubt lines) of a kept entry, or None (said in
    the log) if it is not a segmentation of ``duration`` seconds of audio."""
    from ingest.speech.phones import PHONE_SET

    try:
        if path.stat().st_size > _MAX_ENTRY_BYTES:
            raise ValueError(f"{path.stat().st_size} bytes, more than any segmentation")
        data = json.loads(path.read_bytes())
        method, rows = data["method"], data["segments"]
        lines = [data["fallback"], data["doubts"]]
        if data.get("format") != FORMAT or method not in _METHODS:
            raise ValueError("another format")
        if not all(isinstance(x, list) and all(isinstance(s, str) and len(s) < 1000
                                               for s in x) for x in lines):
            raise ValueError("lines are not strings")
        segments = [Segment(str(p), float(a), float(b)) for p, a, b in rows]
        end = 0.0
        for s in segments:
            if (s.phone not in PHONE_SET or not math.isfinite(s.start)
                    or not math.isfinite(s.end) or abs(s.start - end) > 1e-6
                    or s.end <= s.start):
                raise ValueError(f"segment {s} does not tile the audio")
            end = s.end
        if not segments or abs(end - duration) > 1e-3:
            raise ValueError(f"segments end at {end:.3f} s, the audio at {duration:.3f} s")
    except (OSError, ValueError, KeyError, TypeError) as exc:
        logger.warning("%s: not a segmentation of this audio (%s); finding the phones "
                       "again", path, exc)
        return None
    return segments, method, *lines


def _write(path: Path, segments, method: str, fallback, doubts) -> None:
    from db.atomic import atomic_write
    from db.errors import DataError

    body = json.dumps({"format": FORMAT, "method": method, "fallback": list(fallback),
                       "doubts": list(doubts),
                       "segments": [[s.phone, s.start, s.end] for s in segments]})
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_write(path) as handle:
            handle.write(body.encode())
    except (OSError, DataError) as exc:  # a cache that cannot be written costs time only
        logger.warning("%s: cannot keep the segmentation (%s)", path, exc)


def bound_folder(folder: Path, max_bytes: int | None = None) -> int:
    """Remove the files of ``folder`` written (segmentations: or read) longest ago until
    it holds at most ``max_bytes`` (default :data:`MAX_BYTES`); returns how many went.

    Only regular files directly in it are counted and removed (not folders, not links).
    """
    limit = MAX_BYTES if max_bytes is None else max_bytes
    try:
        entries = [e for e in os.scandir(folder) if e.is_file(follow_symlinks=False)]
    except OSError:
        return 0
    stats = []
    for e in entries:
        try:
            st = e.stat(follow_symlinks=False)
        except OSError:
            continue
        stats.append((st.st_mtime_ns, e.name, st.st_size))
    total, removed = sum(s[2] for s in stats), 0
    for _, name, size in sorted(stats):
        if total <= limit:
            break
        try:
            os.unlink(folder / name)
        except OSError:
            continue
        total -= size
        removed += 1
    return removed
