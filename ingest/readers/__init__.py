"""Readers: source folders of every corpus kind -> :class:`ingest.clip.RawClip`.

Usage::

    sources = discover([Path("corpora")])   # cheap: names, listings, small JSON
    for source in sources:
        try:
            clip = load(source)               # reads motion, audio, labels, metadata
        except DataError as exc:
            reject(source, str(exc))          # one line naming the file and the problem

Kinds and layouts (see each module):

- ``"markers"``: :mod:`ingest.readers.markers` (the synthetic corpus; generic folders of
  ``.c3d``/``.trc``/marker ``.csv`` + ``.wav``);
- ``"curves"``: :mod:`ingest.readers.curves` (FACEGOOD; generic ``.npy``/``.curves.csv``);
- ``"curves"`` from an iPhone: :mod:`ingest.readers.livelink` (Live Link Face CSV, ARKit
  blendshapes; timecode gaps filled, lip-audio lag estimated);
- ``"landmarks"``: :mod:`ingest.readers.landmarks` (talking-face clip folders; head pose
  removed by Procrustes to the canonical mesh, lip-audio lag evidence kept, not applied:
  :mod:`ingest.lag` decides it over a speaker's clips) and :mod:`ingest.readers.video`
  (videos, the face tracked on every frame, the tracking cached).

Checks common to all kinds, and their tolerances, are in :mod:`ingest.readers.common`.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

from db.errors import AnimeGraphError, DataError, ParameterError
from ingest.clip import RawClip
from ingest.readers.common import (
    DURATION_TOLERANCE_REL,
    DURATION_TOLERANCE_S,
    ClipSource,
    duration_tolerance,
)
from ingest.readers.curves import load_curves
from ingest.readers.discovery import discover
from ingest.readers.landmarks import load_talkingface, normalise_landmarks
from ingest.readers.livelink import load_livelink
from ingest.readers.markers import load_markers
from ingest.readers.sync import estimate_lag, lip_audio_lag, shift_motion
from ingest.readers.video import load_video

logger = logging.getLogger(__name__)

_LOADERS = {
    "synthetic": load_markers,
    "markers": load_markers,
    "facegood": load_curves,
    "curves": load_curves,
    "talkingface": load_talkingface,
    "livelink": load_livelink,
    "video": load_video,
}


def load(source: ClipSource) -> RawClip:
    """Read one clip found by :func:`discover`.

    Parameters
    ----------
    source : ClipSource
        The clip.

    Returns
    -------
    RawClip
        Motion (n_frames, n_channels) float64 with its schema, mono float32 audio, and
        whatever text, phones and metadata the clip has; ``checksum`` covers the clip's
        files in :data:`ingest.readers.common.ROLES` order.

    Raises
    ------
    ParameterError
        If ``source`` is not a ClipSource of a known layout.
    DataError
        On any problem with the clip's files, as one line naming the file and the
        problem; the caller can reject the clip and go on.
    """
    if not isinstance(source, ClipSource):
        raise ParameterError(f"source: expected a ClipSource, got {type(source).__name__}")
    loader = _LOADERS.get(source.layout)
    if loader is None:
        raise ParameterError(f"source.layout: unknown layout {source.layout!r}")
    _check_links(source)
    try:
        clip = loader(source)
    except DataError:
        raise
    except (AnimeGraphError, OSError, ValueError, EOFError) as exc:
        # Anything a file can cause that a reader did not already phrase.
        reason = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
        raise DataError(f"{source.source}: cannot read clip {source.clip_id!r}: {reason}") from exc
    logger.debug("loaded %s/%s: %d frames x %d channels at %g fps", clip.corpus, clip.clip_id,
                 clip.n_frames, clip.schema.n_channels, clip.fps)
    return clip


def _check_links(source: ClipSource) -> None:
    """DataError if one of the clip's files is a symbolic link to a file outside the
    folder that holds the clip's files: a clip from someone else would otherwise carry
    any file the user can read (a key, a document) into the database as its transcript
    or metadata. Links within that folder, and folders reached through links above it,
    are read as before."""
    paths = [Path(path) for _, path in source.files]
    place = Path(os.path.commonpath([p.parent.absolute() for p in paths])).resolve()
    for path in paths:
        if path.is_symlink() and not path.resolve().is_relative_to(place):
            raise DataError(f"{path} is a symbolic link to {path.resolve()}, outside the "
                            f"clip's folder {place}; refused: copy the file in instead")


__all__ = [
    "DURATION_TOLERANCE_REL",
    "DURATION_TOLERANCE_S",
    "ClipSource",
    "discover",
    "duration_tolerance",
    "estimate_lag",
    "lip_audio_lag",
    "load",
    "normalise_landmarks",
    "shift_motion",
]
