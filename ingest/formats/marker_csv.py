"""Marker trajectories as CSV: ``frame,time,<label>.x,<label>.y,<label>.z,...``.

One header line, then one line per frame: an integer frame number, the time in
seconds, and x/y/z in millimetres per marker; an empty cell is a missing coordinate
(the marker is then missing in all three). The frame rate is not stored: it is inferred
from the times (and frame numbers), and snapped to a whole number of frames per second
when the times' rounding cannot tell the two apart. Frame numbers must increase; a
frame number skipped is a frame with every marker missing.
"""

from __future__ import annotations

import csv
import io
import logging
import math
import os
from pathlib import Path

import numpy as np

from db.atomic import atomic_write
from db.errors import DataError, ParameterError
from ingest.formats.c3d import MarkerData
from ingest.formats.text import MAX_MOTION_TABLE_BYTES, read_utf8

logger = logging.getLogger(__name__)

#: Decimals of the coordinates written (a hundredth of a micrometre).
COORD_DECIMALS = 5
#: Decimals of the times written (a microsecond).
TIME_DECIMALS = 6
_AXES = ("x", "y", "z")


def _labels_from_header(header: list[str], path: Path) -> list[str]:
    fields = [f.strip() for f in header]
    if len(fields) < 5 or [f.lower() for f in fields[:2]] != ["frame", "time"]:
        raise DataError(f"{path}:1: expected header 'frame,time,<label>.x,<label>.y,<label>.z,...'")
    columns = fields[2:]
    if len(columns) % 3:
        raise DataError(f"{path}:1: {len(columns)} coordinate columns, not a multiple of 3")
    labels = []
    for i in range(0, len(columns), 3):
        triple = columns[i:i + 3]
        stems = [c.rpartition(".")[0] for c in triple]
        axes = [c.rpartition(".")[2].lower() for c in triple]
        if axes != list(_AXES) or len(set(stems)) != 1 or not stems[0]:
            raise DataError(f"{path}:1: columns {triple} are not '<label>.x,<label>.y,<label>.z'")
        labels.append(stems[0])
    return labels


def infer_rate(frames: np.ndarray, times: np.ndarray, decimals: int, path: Path) -> float:
    """Frame rate from frame numbers and times rounded to ``decimals`` decimals.

    Parameters
    ----------
    frames : np.ndarray, shape (n,)
        Increasing integer frame numbers.
    times : np.ndarray, shape (n,)
        Their times in seconds.
    decimals : int
        Decimals the times were written with (their rounding error is half a unit).
    path : Path
        Named in errors.

    Returns
    -------
    float
        Frames per second; a whole number if it is one within the times' rounding.

    Raises
    ------
    DataError
        With fewer than two frames, times that do not increase, or times off a regular
        grid by more than a quarter frame.
    """
    if len(frames) < 2:
        raise DataError(f"{path}: cannot infer the frame rate from fewer than 2 frames")
    span = float(times[-1] - times[0])
    steps = int(frames[-1] - frames[0])
    if not span > 0:
        raise DataError(f"{path}: times do not increase ({times[0]} .. {times[-1]})")
    rate = steps / span
    slack = 0.5 * 10.0 ** -decimals  # rounding error of one time
    if abs(rate - round(rate)) <= 2 * rate * slack / span + 1e-9 and round(rate) > 0:
        rate = float(round(rate))
    grid = times[0] + (frames - frames[0]) / rate
    worst = float(np.max(np.abs(times - grid)))
    if worst > 0.25 / rate + slack:
        raise DataError(
            f"{path}: irregular times (off a {rate:g} fps grid by up to {worst * 1000:.1f} ms)"
        )
    return rate


def read_marker_csv(path: str | os.PathLike[str]) -> MarkerData:
    """Read marker trajectories from a marker CSV file.

    Parameters
    ----------
    path : str or os.PathLike
        The CSV file (UTF-8).

    Returns
    -------
    MarkerData
        Points of shape (n_frames, n_markers, 3), float64 millimetres, NaN where a
        marker is missing; ``n_frames`` spans the first to the last frame number.

    Raises
    ------
    DataError
        If the file is missing, empty or not UTF-8, the header is wrong, a line (named)
        has the wrong number of fields, a non-numeric value or a frame number that does
        not increase, or the times are irregular or give no rate.
    """
    path = Path(path)
    text = read_utf8(path, "marker CSV file", limit=MAX_MOTION_TABLE_BYTES)
    reader = csv.reader(io.StringIO(text))
    try:
        header = next(reader, None)
        if header is None:
            raise DataError(f"marker CSV file is empty: {path}")
        labels = _labels_from_header(header, path)
        width = 2 + 3 * len(labels)
        frames: list[int] = []
        times: list[float] = []
        decimals = 0
        rows: list[list[float]] = []
        for row in reader:
            line = reader.line_num
            if not row or (len(row) == 1 and not row[0].strip()):
                continue
            if len(row) != width:
                raise DataError(f"{path}:{line}: expected {width} fields, got {len(row)}")
            try:
                frame_value = float(row[0])
                time_text = row[1].strip()
                seconds = float(time_text)
                values = [float(c) if c.strip() else math.nan for c in row[2:]]
            except ValueError:
                raise DataError(f"{path}:{line}: a value is not a number") from None
            if not frame_value.is_integer():
                raise DataError(f"{path}:{line}: frame number {row[0].strip()!r} is not whole")
            frame = int(frame_value)
            if not math.isfinite(seconds):
                raise DataError(f"{path}:{line}: time must be finite, got {time_text!r}")
            if frames and frame <= frames[-1]:
                raise DataError(f"{path}:{line}: frame {frame} does not follow frame {frames[-1]}")
            if "." in time_text and "e" not in time_text.lower():
                decimals = max(decimals, len(time_text.partition(".")[2]))
            frames.append(frame)
            times.append(seconds)
            rows.append(values)
    except csv.Error as exc:
        raise DataError(f"{path}:{reader.line_num}: malformed CSV: {exc}") from None
    if not rows:
        raise DataError(f"marker CSV file has no frames: {path}")
    frame_arr = np.asarray(frames, dtype=np.int64)
    rate = infer_rate(frame_arr, np.asarray(times), decimals or 6, path)
    n_frames = int(frame_arr[-1] - frame_arr[0]) + 1
    points = np.full((n_frames, len(labels), 3), np.nan)
    points[frame_arr - frame_arr[0]] = np.asarray(rows).reshape(len(rows), len(labels), 3)
    if n_frames != len(rows):
        logger.info("%s: %d frame numbers skipped; those frames are missing",
                    path, n_frames - len(rows))
    try:
        return MarkerData(points=points, labels=tuple(labels), rate=rate, units="mm")
    except ParameterError as exc:
        raise DataError(f"marker CSV file {path}: {exc}") from None


def write_marker_csv(path: str | os.PathLike[str], data: MarkerData) -> None:
    """Write marker trajectories as a marker CSV file, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Target file.
    data : MarkerData
        Points of shape (n_frames, n_markers, 3) in mm; frames are numbered from 0,
        times are ``frame / rate``; missing markers are written as empty cells.

    Raises
    ------
    ParameterError
        If ``data`` is not MarkerData in millimetres or a label contains a comma or quote.
    DataError
        If the file cannot be written.
    """
    if not isinstance(data, MarkerData):
        raise ParameterError(f"data: expected MarkerData, got {type(data).__name__}")
    if data.units != "mm":
        raise ParameterError(f"data.units: marker CSV is written in 'mm', got {data.units!r}")
    for label in data.labels:
        if any(c in label for c in ',"\n'):
            raise ParameterError(f"data.labels: {label!r} cannot be a CSV column name")
    header = ["frame", "time"] + [f"{label}.{axis}" for label in data.labels for axis in _AXES]
    lines = [",".join(header)]
    flat = data.points.reshape(data.n_frames, -1)
    for frame in range(data.n_frames):
        cells = ["" if math.isnan(v) else f"{v:.{COORD_DECIMALS}f}" for v in flat[frame]]
        lines.append(f"{frame},{frame / data.rate:.{TIME_DECIMALS}f}," + ",".join(cells))
    with atomic_write(path) as handle:
        handle.write(("\n".join(lines) + "\n").encode("utf-8"))
    logger.debug("wrote %s: %d frames x %d markers", path, data.n_frames, data.n_markers)
