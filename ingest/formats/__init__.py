"""Readers and writers for the standard file formats clips come in.

- :mod:`ingest.formats.c3d`: marker trajectories (:class:`MarkerData`, millimetres).
- :mod:`ingest.formats.wav`: audio as float32 in [-1, 1].
- :mod:`ingest.formats.phones_csv`: phone labels (``<clip>.phones.csv``).
- :mod:`ingest.formats.textgrid`, :mod:`ingest.formats.htk_lab`: phone labels from Praat
  and HTK, mapped to ARPAbet by :func:`ingest.formats.labels.to_arpabet`.
- :mod:`ingest.formats.trc`, :mod:`ingest.formats.marker_csv`: marker trajectories as text.
- :mod:`ingest.formats.livelink`: an iPhone's ARKit face capture as Live Link Face CSV
  (52 blendshapes, head and eye rotations, timecode).

Every writer replaces its target atomically (:func:`atomic_write`); every reader
raises :class:`db.errors.DataError` naming the file for a missing or bad file.
"""

from collections.abc import Callable

from db.atomic import atomic_write
from ingest.formats.c3d import MarkerData, read_c3d, write_c3d
from ingest.formats.htk_lab import read_htk_lab, write_htk_lab
from ingest.formats.labels import to_arpabet
from ingest.formats.livelink import read_livelink, write_livelink
from ingest.formats.marker_csv import read_marker_csv, write_marker_csv
from ingest.formats.phones_csv import Segment, read_phones_csv, write_phones_csv
from ingest.formats.textgrid import read_textgrid, write_textgrid
from ingest.formats.trc import read_trc, write_trc
from ingest.formats.wav import read_wav, write_wav

#: Motion readers by lower-case file extension (with the dot).
MOTION_READERS: dict[str, Callable[..., MarkerData]] = {
    ".c3d": read_c3d,
    ".trc": read_trc,
    ".csv": read_marker_csv,
}

__all__ = [
    "MOTION_READERS",
    "MarkerData",
    "Segment",
    "atomic_write",
    "read_c3d",
    "read_htk_lab",
    "read_livelink",
    "read_marker_csv",
    "read_phones_csv",
    "read_textgrid",
    "read_trc",
    "read_wav",
    "to_arpabet",
    "write_c3d",
    "write_htk_lab",
    "write_livelink",
    "write_marker_csv",
    "write_phones_csv",
    "write_textgrid",
    "write_trc",
    "write_wav",
]
