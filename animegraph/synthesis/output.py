"""A synthesis written to a motion file, and a motion file read in a database's channels."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from animegraph.motion.files import point_columns, read_motion, write_channels
from db.errors import DataError


def write_motion(synth, model, path: Path, *, timecode: str | None = None) -> Path:
    """Write the motion as C3D (point databases), CSV, NPZ or, for ``.livelink.csv``,
    Live Link Face CSV starting at ``timecode`` (ARKit databases), by ``path``'s name."""
    return write_channels(synth.motion, synth.fps, model.names, model.kind, path,
                          extra={"ics": synth.ics, "nodes": synth.result.nodes},
                          timecode=timecode)


def read_database_motion(path: Path, model) -> tuple[np.ndarray, float]:
    """Read a motion file (.c3d, .csv, .npz; :func:`animegraph.motion.files.read_motion`) in
    ``model``'s channels: (motion of shape (n_frames, n_channels), frames per second).

    A C3D holds the point channels only: any other channel of the database is set to its
    mean over the database.

    Raises
    ------
    DataError
        Unreadable file, or channels that are not the database's.
    """
    path = Path(path)
    motion = read_motion(path)
    names = list(model.names)
    index = {c: i for i, c in enumerate(motion.names)}
    points = point_columns(names)
    only_points = path.suffix.lower() == ".c3d"
    wanted = [names[i] for i in points] if only_points else names
    missing = [c for c in wanted if c not in index]
    if missing:
        raise DataError(f"{path.name} lacks {len(missing)} of the database's channels "
                        f"(first: {missing[0]}): it is not motion of this database")
    values = np.asarray(motion.values, dtype=np.float64)
    if only_points:
        out = np.tile(model.decomposer.mean_, (len(values), 1))
        for i in points:
            out[:, i] = values[:, index[names[i]]]
        return out, motion.fps
    return values[:, [index[c] for c in names]], motion.fps
