"""Motion files an animator hands the tool: C3D, channel CSV, NPZ; and phone tracks.

Motion crosses this boundary as :class:`Motion`: ``(n_frames, n_channels)`` values
with channel names (``<marker>.x/.y/.z`` for points, curve names for curves) and a
frame rate — the layout of the database's ``frames`` table and of what
``animegraph synth`` writes.
"""

from __future__ import annotations

import io
import json
import logging
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from animegraph.motion.suffixes import EXPORT_FORMATS, LIVELINK_SUFFIX
from db.atomic import atomic_write
from db.errors import DataError, ParameterError
from ingest.formats.phones_csv import Segment
from ingest.formats.text import MAX_MOTION_TABLE_BYTES, MAX_SIDE_FILE_BYTES, read_utf8

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class Motion:
    """Motion of one take.

    Attributes
    ----------
    values : np.ndarray, shape (n_frames, n_channels)
    names : tuple of str, length n_channels
    fps : float
    """

    values: np.ndarray
    names: tuple[str, ...]
    fps: float

    @property
    def n_frames(self) -> int:
        return len(self.values)

    @property
    def duration(self) -> float:
        return self.n_frames / self.fps

    @property
    def has_points(self) -> bool:
        """True if the channels hold 3-D points (markers or landmarks)."""
        return bool(point_labels(self.names))


def read_motion(path: str | os.PathLike) -> Motion:
    """Read a motion file by its extension.

    ``.c3d`` (markers), ``.csv`` (``frame,time,<channel>...``: what ``synth``, ``query
    --export`` and the corpus write; or Live Link Face's ``Timecode,BlendshapeCount,...``,
    told by its header: ARKit channels, dropped frames interpolated), ``.npz``
    (``motion``, ``fps``, ``channels``, as ``synth`` writes).

    Raises
    ------
    DataError
        If the file is missing, of another kind, or malformed.
    """
    path = Path(path)
    if not path.is_file():
        raise DataError(f"motion file {path} does not exist")
    suffix = path.suffix.lower()
    if suffix == ".c3d":
        from ingest.formats.c3d import read_c3d

        data = read_c3d(path)
        names = tuple(f"{lab}.{a}" for lab in data.labels for a in "xyz")
        return Motion(values=data.points.reshape(data.n_frames, -1), names=names,
                      fps=float(data.rate))
    if suffix == ".csv":
        from ingest.formats.livelink import sniff_livelink

        if sniff_livelink(path):
            from ingest.readers.livelink import read_livelink_motion

            values, names, fps = read_livelink_motion(path)
            return Motion(values=values, names=names, fps=fps)
        return _read_channel_csv(path)
    if suffix == ".npz":
        from db.npyfile import REAL_KINDS, TEXT_KINDS, check_npz, holds

        check_npz(path)  # sizes its headers declare, before numpy allocates them
        try:
            with np.load(path, allow_pickle=False) as z:
                values, fps, names = z["motion"], z["fps"], z["channels"]
        except (OSError, ValueError, KeyError) as exc:
            raise DataError(f"cannot read motion {path}: needs arrays motion, fps, channels "
                            f"({exc})") from None
        # numpy would cast text of numbers to them, and numbers to names, without a word
        for key, array, kinds, what in (("motion", values, REAL_KINDS, "real numbers"),
                                        ("fps", fps, REAL_KINDS, "real numbers"),
                                        ("channels", names, TEXT_KINDS, "text")):
            if array.dtype.kind not in kinds:
                raise DataError(f"cannot read motion {path}: {key} holds "
                                f"{holds(array.dtype)}, not {what}")
        if fps.size != 1 or names.ndim != 1:
            raise DataError(f"cannot read motion {path}: needs one fps (got {fps.size}) and "
                            f"a list of channel names (got shape {names.shape})")
        return _checked(Motion(values=values.astype(np.float64), names=tuple(names.tolist()),
                               fps=float(fps.item())), path)
    raise DataError(f"motion file {path} must be .c3d, .csv or .npz")


def _read_channel_csv(path: Path) -> Motion:
    handle = io.StringIO(read_utf8(path, "motion CSV", limit=MAX_MOTION_TABLE_BYTES))
    header = handle.readline().strip().split(",")
    try:
        values = np.loadtxt(handle, delimiter=",", ndmin=2)
    except ValueError as exc:
        raise DataError(f"cannot read motion {path}: {exc}") from None
    if header[:2] != ["frame", "time"] or len(header) < 3:
        raise DataError(f"{path}:1: motion CSV must start 'frame,time,' then channel names")
    if values.shape[1] != len(header) or len(values) < 1:
        raise DataError(f"{path}: rows have {values.shape[1]} cells, the header "
                        f"{len(header)}")
    times = values[:, 1]
    if len(times) > 1:
        step = np.median(np.diff(times))
        if not step > 0:
            raise DataError(f"{path}: times do not increase")
        fps = 1.0 / step
        if abs(fps - round(fps)) < 0.01:
            fps = float(round(fps))
    else:
        fps = 30.0
    return _checked(Motion(values=values[:, 2:], names=tuple(header[2:]), fps=fps), path)


def _checked(motion: Motion, path: Path) -> Motion:
    if motion.values.ndim != 2 or motion.values.shape[1] != len(motion.names):
        raise DataError(f"{path}: {motion.values.shape} values for {len(motion.names)} "
                        "channels")
    if not (np.isfinite(motion.fps) and motion.fps > 0):
        raise DataError(f"{path}: frame rate must be > 0, got {motion.fps}")
    if len(motion.values) < 1:
        raise DataError(f"{path}: no frames")
    return motion


def write_channel_csv(path: str | os.PathLike, values: np.ndarray, names, fps: float,
                      *, start_frame: int = 0) -> None:
    """Write ``frame,time,<channel>...`` (atomically); frames numbered from ``start_frame``."""
    n = len(values)
    frames = np.arange(start_frame, start_frame + n)
    table = np.column_stack([frames, frames / fps, values])
    with atomic_write(path) as handle:
        np.savetxt(handle, table, delimiter=",", header="frame,time," + ",".join(names),
                   comments="", fmt=["%d", "%.6f"] + ["%.6g"] * len(names))


def read_phone_track(*, labels: str | os.PathLike | None = None,
                     explain: str | os.PathLike | None = None) -> list[dict]:
    """Phones over time, from a label file or ``synth --explain-json``.

    Returns
    -------
    list of dict
        ``phone``, ``start``, ``end`` (s), and from an explanation ``clip_id`` and
        ``jump`` (a jump match into this phone).
    """
    if explain is not None:
        path = Path(explain)
        try:
            # bounded: a phone's entry is ~300 bytes, parsed ~17 times that
            record = json.loads(read_utf8(path, "explanation", limit=MAX_SIDE_FILE_BYTES))
            rows = record["phones"]
            return [{"phone": str(r["phone"]), "start": float(r["start"]),
                     "end": float(r["end"]), "clip_id": r.get("clip_id"),
                     "jump": bool(r.get("jump", False)),
                     "emotion": r.get("emotion")} for r in rows]
        except OSError as exc:
            raise DataError(f"cannot read {path}: {exc.strerror or exc}") from None
        except (ValueError, KeyError, TypeError, RecursionError) as exc:  # nested deeply
            raise DataError(f"{path} is not an explanation written by 'animegraph synth "
                            f"--explain-json' ({exc})") from None
    if labels is not None:
        from ingest.readers.common import read_labels

        segments: list[Segment] = read_labels(Path(labels))
        return [{"phone": s.phone, "start": float(s.start), "end": float(s.end),
                 "clip_id": None, "jump": False} for s in segments]
    return []




def write_channels(motion: np.ndarray, fps: float, names, kind: str, path: Path, *,
                   extra: dict | None = None, timecode: str | None = None) -> Path:
    """Write motion (n_frames, n_channels) as C3D (point databases), CSV or NPZ.

    C3D holds the points only (:func:`channels_left_out`; :func:`check_output` says so
    before the work). A name ending in :data:`LIVELINK_SUFFIX` (``take.livelink.csv``)
    writes Live Link Face CSV (:func:`ingest.formats.livelink.write_livelink`: ARKit
    channels only, blendshapes clamped to [0, 1], the timecode running from ``timecode``,
    default ``00:00:00:00``). ``extra`` arrays go into an NPZ beside ``motion``, ``fps``
    and ``channels``.
    """
    path = Path(path)
    motion = np.asarray(motion, dtype=np.float64)
    names = tuple(names)
    check_format(path.name, names, kind, timecode=timecode)
    suffix = path.suffix.lower()
    if path.name.lower().endswith(LIVELINK_SUFFIX):
        from ingest.formats.livelink import write_livelink

        write_livelink(path, motion, names, fps, start=timecode or "00:00:00:00")
    elif suffix == ".c3d":
        from ingest.formats.c3d import MarkerData, write_c3d

        point_cols = point_columns(names)
        labels = tuple(names[i][:-2] for i in point_cols[::3])
        points = motion[:, point_cols].reshape(len(motion), -1, 3)
        write_c3d(path, MarkerData(points=points, labels=labels, rate=fps))
    elif suffix == ".csv":
        header = "frame,time," + ",".join(names)
        n = len(motion)
        table = np.column_stack([np.arange(n), np.arange(n) / fps, motion])
        with atomic_write(path) as handle:
            np.savetxt(handle, table, delimiter=",", header=header, comments="",
                       fmt=["%d", "%.5f"] + ["%.6g"] * len(names))
    else:
        with atomic_write(path) as handle:
            np.savez(handle, motion=motion, fps=fps, channels=np.array(names),
                     **(extra or {}))
    return path


def check_output(path: Path, names, kind: str, *, timecode: str | None = None) -> None:
    """ParameterError (DataError for a missing folder) unless :func:`write_channels` can
    write motion of these channels to ``path``: what it would refuse after the work, said
    before it, with a warning of the channels it would leave out (a landmark database's
    head pose in C3D: said, not dropped in silence).

    Parameters
    ----------
    path : Path
        ``.c3d`` (point databases: markers, landmarks), ``.csv``, ``.npz``, or
        :data:`LIVELINK_SUFFIX` (ARKit databases).
    names : sequence of str
        The motion's channels.
    kind : str
        The database's kind (``markers``, ``landmarks``, ``curves``).
    timecode : str, optional
        Goes only into Live Link CSV.
    """
    from db.atomic import check_folder

    check_folder(path)  # synth -o in a missing folder failed after the synthesis
    check_format(Path(path).name, names, kind, timecode=timecode)
    left_out = channels_left_out(Path(path).name, names)
    if left_out:
        logger.warning("%s", left_out)


def check_format(name: str, names, kind: str, *, timecode: str | None = None) -> None:
    """ParameterError unless a motion file named ``name`` can hold motion of these
    channels (:func:`check_output` without its folder: ``batch`` checks its formats
    before it makes its output folder)."""
    from ingest.formats.livelink import is_arkit

    if name.lower().endswith(LIVELINK_SUFFIX):
        if not is_arkit(names):
            raise ParameterError("Live Link Face CSV needs a database of ARKit blendshapes "
                                 "(an iPhone capture); this one has other channels (write "
                                 ".csv or .npz)")
        return
    if timecode is not None:
        raise ParameterError(f"a timecode goes only into Live Link CSV (-o NAME"
                             f"{LIVELINK_SUFFIX}), not {name!r}")
    suffix = Path(name).suffix.lower()
    if suffix not in (".c3d", ".csv", ".npz"):
        raise ParameterError(f"output must end in .c3d, .csv or .npz, got {name!r}")
    if suffix == ".c3d" and (kind not in ("markers", "landmarks") or not point_labels(names)):
        raise ParameterError(f"C3D holds 3D points; this database has {kind} "
                             "(write .csv or .npz)")


def channels_left_out(name: str, names) -> str:
    """What a motion file named ``name`` leaves out of motion of channels ``names``, in a
    line for the user (empty when it keeps them all): C3D holds points only, so a
    landmark database's head pose is not in it."""
    if Path(name).suffix.lower() != ".c3d":
        return ""
    names = tuple(names)
    in_points = set(point_columns(names))
    others = [n for i, n in enumerate(names) if i not in in_points]
    if not others:
        return ""
    return (f"{name} holds the {len(point_labels(names))} points; the {len(others)} "
            f"channels that are not a point's ({', '.join(others[:4])}"
            f"{' ...' if len(others) > 4 else ''}) are left out: write .csv or .npz to "
            "keep them")


def motion_suffix(names, kind: str) -> str:
    """The file type that keeps every channel of such motion, in the format its users'
    tools read: Live Link Face CSV (:data:`LIVELINK_SUFFIX`) for ARKit blendshapes, C3D
    when every channel is a coordinate of a point (marker databases; landmark databases
    carry their head pose as channels, which C3D has no place for), else CSV."""
    from ingest.formats.c3d import MAX_MARKERS
    from ingest.formats.livelink import is_arkit

    livelink, points, channels = EXPORT_FORMATS  # the table query --help lists
    if is_arkit(names):
        return livelink
    labels = point_labels(names)
    if kind in ("markers", "landmarks") and labels and 3 * len(labels) == len(names) \
            and len(labels) <= MAX_MARKERS:
        return points
    return channels


def point_columns(names) -> list[int]:
    """Columns of the points of :func:`point_labels`, x, y, z a point: a channel that
    ends in ``.x`` without its ``.y`` and ``.z`` is no point's (reshaped into points, it
    was a traceback)."""
    names = list(names)
    index = {n: i for i, n in enumerate(names)}
    return [index[f"{label}.{axis}"] for label in point_labels(names) for axis in "xyz"]


def point_labels(names) -> tuple[str, ...]:
    """Point labels of x/y/z channel triples, in order (other channels ignored)."""
    seen = dict.fromkeys(n[:-2] for n in names if n.endswith((".x", ".y", ".z")))
    return tuple(lab for lab in seen if all(f"{lab}.{a}" in names for a in "xyz"))
