"""Readers and writers for the standard file formats clips come in.

- :mod:`ingest.formats.c3d`: marker trajectories (:class:`MarkerData`, millimetres).
- :mod:`ingest.formats.wav`: audio as float32 in [-1, 1].
- :mod:`ingest.formats.phones_csv`: phone labels (``<clip>.phones.csv``).

Every writer replaces its target atomically (:func:`atomic_write`); every reader
raises :class:`db.errors.DataError` naming the file for a missing or bad file.
"""

from collections.abc import Callable

from db.atomic import atomic_write
from ingest.formats.c3d import MarkerData, read_c3d, write_c3d
from ingest.formats.phones_csv import Segment, read_phones_csv, write_phones_csv
from ingest.formats.wav import read_wav, write_wav

#: Motion readers by lower-case file extension (with the dot).
MOTION_READERS: dict[str, Callable[..., MarkerData]] = {".c3d": read_c3d}

__all__ = [
    "MOTION_READERS",
    "MarkerData",
    "Segment",
    "atomic_write",
    "read_c3d",
    "read_phones_csv",
    "read_wav",
    "write_c3d",
    "write_phones_csv",
    "write_wav",
]
