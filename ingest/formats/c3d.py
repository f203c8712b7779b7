"""C3D motion-capture files, read and written through the PyPI ``c3d`` package.

Marker data crosses this boundary as :class:`MarkerData`: positions of shape
``(n_frames, n_markers, 3)`` in millimetres, NaN where a marker is missing. Missing
markers are stored with the C3D convention for invalid points (residual -1,
coordinates 0). Points are stored as 32-bit floats (``POINT:SCALE`` -1), so a round
trip is exact to float32 precision.
"""

from __future__ import annotations

import io
import logging
import math
import os
import struct
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import c3d
import numpy as np

from db.atomic import atomic_write
from db.errors import DataError, ParameterError

logger = logging.getLogger(__name__)

#: Longest marker label written. The C3D spec allows longer labels but recommends at
#: most 16 characters; 32 is the width common motion-capture software writes.
MAX_LABEL_LENGTH = 32
#: Most markers one ``POINT:LABELS`` parameter can name (a parameter's dimensions are
#: one byte each). More are named on in ``POINT:LABELS2``, ``LABELS3`` ... (and their
#: ``DESCRIPTIONS2`` ...), as C3D.org's manual and Vicon write it, so that a face tracked
#: from video (468 landmarks) fits one file.
LABELS_PER_PARAMETER = 255
#: Most markers a file holds: ``POINT:USED`` is a 16-bit signed integer.
MAX_MARKERS = 32767

#: Second byte of every C3D file (the header's key).
_C3D_MAGIC = 0x50
#: Factors from the ``POINT:UNITS`` values accepted on read to millimetres.
_UNIT_TO_MM = {"mm": 1.0, "cm": 10.0, "m": 1000.0}


@dataclass(frozen=True)
class MarkerData:
    """Marker trajectories of one clip.

    Attributes
    ----------
    points : np.ndarray, shape (n_frames, n_markers, 3), float64
        Marker positions in ``units``; NaN in all three coordinates where a marker
        is missing.
    labels : tuple of str, length n_markers
        Unique marker names, ASCII, at most :data:`MAX_LABEL_LENGTH` characters.
    rate : float
        Frames per second, finite and > 0.
    units : str
        Length unit of ``points``; always ``"mm"`` for data read from files.

    Raises
    ------
    ParameterError
        If any field has the wrong shape, type or value.
    """

    points: np.ndarray
    labels: tuple[str, ...]
    rate: float
    units: str = "mm"

    def __post_init__(self) -> None:
        try:
            points = np.array(self.points, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ParameterError(f"points: not a numeric array ({exc})") from exc
        if points.ndim != 3 or points.shape[2] != 3:
            raise ParameterError(
                f"points: expected shape (n_frames, n_markers, 3), got {points.shape}"
            )
        n_frames, n_markers, _ = points.shape
        if n_frames < 1 or n_markers < 1:
            raise ParameterError(
                f"points: need at least one frame and one marker, got shape {points.shape}"
            )
        if np.isinf(points).any():
            raise ParameterError("points: infinite coordinates (use NaN for a missing marker)")
        # A marker missing in one coordinate is missing in all three.
        points[np.isnan(points).any(axis=2)] = np.nan

        if isinstance(self.labels, str) or not isinstance(self.labels, Sequence):
            raise ParameterError(
                f"labels: expected a sequence of str, got {type(self.labels).__name__}"
            )
        labels = tuple(self.labels)
        if len(labels) != n_markers:
            raise ParameterError(
                f"labels: expected {n_markers} labels (one per marker), got {len(labels)}"
            )
        for label in labels:
            _check_label(label)
        if len(set(labels)) != len(labels):
            dupes = sorted({lab for lab in labels if labels.count(lab) > 1})
            raise ParameterError(f"labels: must be unique, repeated {dupes}")

        if isinstance(self.rate, bool) or not isinstance(self.rate, int | float | np.number):
            raise ParameterError(f"rate: expected a number, got {self.rate!r}")
        rate = float(self.rate)
        if not math.isfinite(rate) or rate <= 0:
            raise ParameterError(f"rate: must be finite and > 0, got {self.rate!r}")
        if not isinstance(self.units, str) or not self.units.strip():
            raise ParameterError(f"units: expected a non-empty str, got {self.units!r}")

        object.__setattr__(self, "points", points)
        object.__setattr__(self, "labels", labels)
        object.__setattr__(self, "rate", rate)
        object.__setattr__(self, "units", self.units.strip())

    @property
    def n_frames(self) -> int:
        """Number of frames."""
        return int(self.points.shape[0])

    @property
    def n_markers(self) -> int:
        """Number of markers."""
        return int(self.points.shape[1])

    @property
    def missing(self) -> np.ndarray:
        """Boolean mask of missing markers, shape (n_frames, n_markers)."""
        return np.isnan(self.points[:, :, 0])


def _check_label(label: object) -> None:
    if not isinstance(label, str):
        raise ParameterError(f"labels: expected str, got {label!r}")
    if not label or label != label.strip():
        raise ParameterError(f"labels: empty or padded label {label!r}")
    if len(label) > MAX_LABEL_LENGTH:
        raise ParameterError(
            f"labels: {label!r} is {len(label)} characters, more than {MAX_LABEL_LENGTH}"
        )
    if not label.isascii() or not label.isprintable():
        raise ParameterError(f"labels: {label!r} is not printable ASCII")


def write_c3d(path: str | os.PathLike[str], data: MarkerData) -> None:
    """Write marker data to a C3D file (float storage, no analog channels).

    Parameters
    ----------
    path : str or os.PathLike
        Target file; written atomically (temporary file, then rename).
    data : MarkerData
        Points of shape (n_frames, n_markers, 3) in millimetres; NaN marks a missing
        marker, written as residual -1 with coordinates 0.

    Raises
    ------
    ParameterError
        If ``data`` is not valid :class:`MarkerData` in millimetres, has more than
        :data:`MAX_MARKERS` markers, or values that do not fit a float32.
    DataError
        If the file cannot be written.
    """
    if not isinstance(data, MarkerData):
        raise ParameterError(f"data: expected MarkerData, got {type(data).__name__}")
    if data.units != "mm":
        raise ParameterError(f"data.units: C3D files are written in 'mm', got {data.units!r}")
    if data.n_markers > MAX_MARKERS:
        raise ParameterError(f"a C3D file holds at most {MAX_MARKERS} markers, got "
                             f"{data.n_markers}")
    rate32 = np.float32(data.rate)
    if not np.isfinite(rate32):
        raise ParameterError(f"data.rate: does not fit a float32, got {data.rate!r}")

    missing = data.missing
    with np.errstate(over="ignore", invalid="ignore"):
        xyz = data.points.astype(np.float32)
    if not np.isfinite(xyz[~missing]).all():
        raise ParameterError("data.points: coordinates do not fit a float32")

    # c3d frame layout: x, y, z, residual, camera mask; residual -1 marks an invalid point.
    frames = np.zeros((data.n_frames, data.n_markers, 5), dtype=np.float32)
    frames[:, :, :3] = np.where(missing[:, :, None], np.float32(0.0), xyz)
    frames[:, :, 3] = np.where(missing, np.float32(-1.0), np.float32(0.0))
    no_analog = np.zeros((0, 0), dtype=np.float32)

    writer = c3d.Writer(point_rate=float(rate32), analog_rate=0.0, point_scale=-1.0,
                        point_units="mm  ")
    for start in range(0, data.n_markers, LABELS_PER_PARAMETER):
        part = list(data.labels[start:start + LABELS_PER_PARAMETER])
        text, width = c3d.Writer.pack_labels(part)
        number = "" if start == 0 else str(1 + start // LABELS_PER_PARAMETER)
        writer.point_group.add_str(f"LABELS{number}", "Point labels.", text, width, len(part))
        # Written here, or the writer would make one DESCRIPTIONS for every marker.
        writer.point_group.add_str(f"DESCRIPTIONS{number}", "Point descriptions.",
                                   " " * len(part), 1, len(part))
    writer.add_frames([(frame, no_analog) for frame in frames])
    buffer = io.BytesIO()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "No analog data found in file." and the like
        writer.write(buffer)
    blob = buffer.getbuffer()

    # c3d 0.6.0 reuses one frame buffer and never clears the coordinates of invalid
    # points, so a missing marker would carry its last valid position: zero them.
    start = 512 * (int(writer.header.data_block) - 1)
    stored = np.frombuffer(blob, dtype="<f4", count=frames.size // 5 * 4, offset=start)
    stored = stored.reshape(data.n_frames, data.n_markers, 4)
    stored[missing, :3] = 0.0

    with atomic_write(path) as handle:
        handle.write(blob)
    logger.debug("wrote %s: %d frames x %d markers at %g fps", path, data.n_frames,
                 data.n_markers, data.rate)


#: numpy float32 of each C3D processor type whose floats are IEEE (DEC's are not).
_IEEE_FLOAT = {"INTEL": "<f4", "MIPS": ">f4"}


def _read_point_block(handle, reader, n_points: int, n_frames: int) -> np.ndarray | None:
    """All frames at once, shape (n_frames_read, n_points, 4), for IEEE-float files
    without analog data; else None.

    The ``c3d`` package parses one frame per Python call (about 0.1 s per second of
    120 fps capture); most files (float points, no analog) are one plain array.
    """
    dtype = _IEEE_FLOAT.get(reader.proc_type)
    if dtype is None or reader.point_scale >= 0 or reader.analog_used:
        return None
    handle.seek((reader.header.data_block - 1) * 512)
    n_values = n_frames * n_points * 4
    block = handle.read(4 * n_values)
    whole = len(block) // (16 * n_points)
    data = np.frombuffer(block[: whole * 16 * n_points], dtype=dtype)
    data = data.reshape(whole, n_points, 4).astype(np.float32)
    # The fourth word holds camera bits and residual; a negative word marks an invalid
    # point, and so does a NaN coordinate (as the c3d package treats them).
    invalid = (data[:, :, 3].astype(np.int32) < 0) | np.isnan(data[:, :, :3]).any(axis=2)
    data[:, :, 3] = np.where(invalid, -1.0, 0.0)
    # One array, not a list of per-frame views: a view costs about 100 bytes of its own,
    # 6 times the 16 of a one-marker frame's values (a 16 MB file took 414 MB to read).
    return data


def _point_labels(reader, n_points: int) -> list[str]:
    """``POINT:LABELS``, then ``LABELS2``, ``LABELS3`` ... while ``n_points`` need more."""
    labels: list[str] = []
    number = 1
    while len(labels) < n_points:
        param = reader.get(f"POINT:LABELS{number if number > 1 else ''}")
        if param is None:
            break
        labels += list(param.string_array)
        number += 1
    return labels


def read_c3d(path: str | os.PathLike[str]) -> MarkerData:
    """Read marker data from a C3D file.

    Both float and scaled-integer point storage are read; positions in ``cm`` or
    ``m`` are converted to millimetres.

    Parameters
    ----------
    path : str or os.PathLike
        The C3D file.

    Returns
    -------
    MarkerData
        Points of shape (n_frames, n_markers, 3), float64 millimetres, NaN in all three
        coordinates where the file marks a point invalid (negative residual).

    Raises
    ------
    DataError
        If the file is missing, empty, truncated, corrupt or inconsistent (no points,
        missing or repeated labels, bad rate, unknown units).
    """
    path = Path(path)
    if not path.is_file():
        raise DataError(f"C3D file not found: {path}")
    if path.stat().st_size == 0:
        raise DataError(f"C3D file is empty: {path}")
    try:
        with open(path, "rb") as handle, warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            magic = handle.read(2)
            if len(magic) < 2 or magic[1] != _C3D_MAGIC:
                raise DataError(f"not a C3D file (bad header key): {path}")
            handle.seek(0)
            reader = c3d.Reader(handle)
            n_points = int(reader.point_used)
            n_expected = int(reader.frame_count)
            if n_points < 1:
                raise DataError(f"C3D file has no marker points: {path}")
            if n_expected < 1:
                raise DataError(f"C3D file has no frames: {path}")
            raw = _read_point_block(handle, reader, n_points, n_expected)
            if raw is None:
                frames = [pts[:, :4].copy() for _, pts, _ in reader.read_frames(copy=False)]
                raw = np.stack(frames) if frames else np.empty((0, n_points, 4))
                del frames
            rate = float(reader.point_rate)
            labels = _point_labels(reader, n_points)
            units_param = reader.get("POINT:UNITS")
            units = "" if units_param is None else units_param.string_value
    except DataError:
        raise
    except Exception as exc:  # the c3d package raises anything on a corrupt file
        # struct.error ("unpack requires a buffer of 1 bytes") where the file ends inside
        # its header or parameters; a field that points nowhere, anything else.
        if isinstance(exc, (struct.error, EOFError)):
            why = "truncated: it ends inside its header or parameters"
        else:
            detail = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
            why = f"damaged{f' ({detail[:200]})' if detail else ''}"
        raise DataError(f"{path} is not a readable C3D file: {why}") from exc
    for warning in caught:
        logger.debug("c3d warning reading %s: %s", path, warning.message)

    if len(raw) != n_expected:
        raise DataError(
            f"truncated C3D file {path}: header promises {n_expected} frames, found {len(raw)}"
        )
    labels = [str(label).strip() for label in labels[:n_points]]
    if len(labels) < n_points:
        raise DataError(f"C3D file {path}: {n_points} points but only {len(labels)} labels")
    units = units.strip().lower()
    if not units:
        logger.warning("C3D file %s has no POINT:UNITS; assuming mm", path)
        units = "mm"
    if units not in _UNIT_TO_MM:
        raise DataError(f"C3D file {path}: unknown POINT:UNITS {units!r}")
    if units != "mm":
        logger.info("C3D file %s is in %s; converting to mm", path, units)

    stacked = raw.astype(np.float64)  # (n_frames, n_markers, 4)
    points = stacked[:, :, :3] * _UNIT_TO_MM[units]
    points[stacked[:, :, 3] < 0] = np.nan
    try:
        return MarkerData(points=points, labels=tuple(labels), rate=rate, units="mm")
    except ParameterError as exc:
        raise DataError(f"C3D file {path}: {exc}") from exc
