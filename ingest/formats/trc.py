"""TRC marker files (Motion Analysis / OpenSim "track row column" text format).

Layout (tab-separated)::

    PathFileType  4  (X/Y/Z)  clip.trc
    DataRate  CameraRate  NumFrames  NumMarkers  Units  OrigDataRate  ...
    120       120         480        72          mm     120           ...
    Frame#  Time  lip_corner_r        lip_corner_l        ...
                  X1    Y1    Z1      X2    Y2    Z2      ...
    <blank line>
    1       0.000 12.3  -4.5  60.1    ...

An empty cell (or a row cut short) is a missing coordinate; a marker with any coordinate
missing is missing in all three (NaN), as in :class:`MarkerData`. Units ``mm``, ``cm``
and ``m`` are read and converted to millimetres; files are written in ``mm``.
"""

from __future__ import annotations

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

#: Factors from the units a TRC header may give to millimetres.
UNIT_TO_MM = {"mm": 1.0, "millimeters": 1.0, "cm": 10.0, "centimeters": 10.0,
              "m": 1000.0, "meters": 1000.0}
#: Decimals of the coordinates written (a hundredth of a micrometre).
COORD_DECIMALS = 5
_HEADER_KEYS = ("DataRate", "CameraRate", "NumFrames", "NumMarkers", "Units", "OrigDataRate",
                "OrigDataStartFrame", "OrigNumFrames")


def _cells(line: str) -> list[str]:
    """Split a TRC line: on tabs if it has any, else on runs of white space."""
    line = line.rstrip("\r\n")
    return line.split("\t") if "\t" in line else line.split()


def read_trc(path: str | os.PathLike[str]) -> MarkerData:
    """Read marker trajectories from a TRC file.

    Parameters
    ----------
    path : str or os.PathLike
        The ``.trc`` file.

    Returns
    -------
    MarkerData
        Points of shape (n_frames, n_markers, 3), float64 millimetres, NaN where a
        marker is missing; the rate is the header's ``DataRate``.

    Raises
    ------
    DataError
        If the file is missing, empty, not a TRC file, truncated (fewer frames than
        ``NumFrames``) or inconsistent (marker count, units, rate, a row with too many
        or non-numeric cells; the message names the line).
    """
    path = Path(path)
    text = read_utf8(path, "TRC file", limit=MAX_MOTION_TABLE_BYTES)
    lines = text.splitlines()
    if not lines or not lines[0].strip():
        raise DataError(f"TRC file is empty: {path}")
    if not lines[0].startswith("PathFileType"):
        raise DataError(f"{path}:1: not a TRC file (no PathFileType header)")
    if len(lines) < 5:
        raise DataError(f"truncated TRC file {path}: {len(lines)} lines, the header needs 5")

    keys = [k.strip() for k in _cells(lines[1])]
    values = [v.strip() for v in _cells(lines[2])]
    header = {k.lower(): v for k, v in zip(keys, values, strict=False) if k}
    for key in ("datarate", "numframes", "nummarkers"):
        if key not in header:
            raise DataError(f"{path}:2: TRC header has no {key!r} (keys: {keys})")
    try:
        rate = float(header["datarate"])
        n_frames = int(header["numframes"])
        n_markers = int(header["nummarkers"])
    except ValueError:
        raise DataError(f"{path}:3: bad DataRate/NumFrames/NumMarkers in {values}") from None
    if not math.isfinite(rate) or rate <= 0:
        raise DataError(f"{path}:3: DataRate must be > 0, got {header['datarate']!r}")
    units = header.get("units", "").lower()
    if not units:
        logger.warning("TRC file %s gives no Units; assuming mm", path)
        units = "mm"
    if units not in UNIT_TO_MM:
        raise DataError(f"{path}:3: unknown Units {header['units']!r}")

    names_row = _cells(lines[3])
    if not names_row or names_row[0].strip().lower() not in ("frame#", "frame"):
        raise DataError(f"{path}:4: expected 'Frame#  Time  <marker names>'")
    labels = [name.strip() for name in names_row[2:] if name.strip()]
    if len(labels) != n_markers:
        raise DataError(f"{path}:4: NumMarkers is {n_markers} but {len(labels)} names are given")

    width = 3 * n_markers
    rows: list[list[float]] = []
    for number, line in enumerate(lines[5:], 6):
        if not line.strip():
            continue
        cells = _cells(line)
        values_ = [c.strip() for c in cells[2:]]
        while len(values_) > width and not values_[-1]:
            values_.pop()
        if len(values_) > width:
            raise DataError(f"{path}:{number}: {len(values_)} coordinates for {n_markers} markers")
        row = []
        for column, cell in enumerate(values_):
            if not cell:
                row.append(math.nan)
                continue
            try:
                row.append(float(cell))
            except ValueError:
                raise DataError(
                    f"{path}:{number}: coordinate {column + 1} is not a number: {cell!r}"
                ) from None
        row += [math.nan] * (width - len(row))
        rows.append(row)
    if len(rows) < n_frames:
        raise DataError(f"truncated TRC file {path}: NumFrames is {n_frames}, found {len(rows)}")
    if len(rows) > n_frames:
        raise DataError(f"TRC file {path}: NumFrames is {n_frames} but {len(rows)} rows follow")
    if n_frames < 1:
        raise DataError(f"TRC file has no frames: {path}")
    points = np.asarray(rows, dtype=np.float64).reshape(n_frames, n_markers, 3)
    points *= UNIT_TO_MM[units]
    try:
        return MarkerData(points=points, labels=tuple(labels), rate=rate, units="mm")
    except ParameterError as exc:
        raise DataError(f"TRC file {path}: {exc}") from None


def write_trc(path: str | os.PathLike[str], data: MarkerData) -> None:
    """Write marker trajectories as a TRC file in millimetres, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Target file.
    data : MarkerData
        Points of shape (n_frames, n_markers, 3) in mm; missing markers (NaN) are
        written as empty cells. Frames are numbered from 1; coordinates keep
        :data:`COORD_DECIMALS` decimals.

    Raises
    ------
    ParameterError
        If ``data`` is not MarkerData in millimetres.
    DataError
        If the file cannot be written.
    """
    if not isinstance(data, MarkerData):
        raise ParameterError(f"data: expected MarkerData, got {type(data).__name__}")
    if data.units != "mm":
        raise ParameterError(f"data.units: TRC files are written in 'mm', got {data.units!r}")
    rate = repr(float(data.rate))
    n, m = data.n_frames, data.n_markers
    lines = [
        f"PathFileType\t4\t(X/Y/Z)\t{Path(path).name}",
        "\t".join(_HEADER_KEYS),
        "\t".join((rate, rate, str(n), str(m), "mm", rate, "1", str(n))),
        "\t".join(["Frame#", "Time"] + [f"{label}\t\t" for label in data.labels]),
        "\t".join(["", ""] + [f"X{i}\tY{i}\tZ{i}" for i in range(1, m + 1)]),
        "",
    ]
    flat = data.points.reshape(n, 3 * m)
    for frame in range(n):
        cells = ["" if math.isnan(v) else f"{v:.{COORD_DECIMALS}f}" for v in flat[frame]]
        lines.append(f"{frame + 1}\t{frame / data.rate:.6f}\t" + "\t".join(cells))
    with atomic_write(path) as handle:
        handle.write(("\n".join(lines) + "\n").encode("utf-8"))
    logger.debug("wrote %s: %d frames x %d markers at %g fps", path, n, m, data.rate)
