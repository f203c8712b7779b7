"""Live Link Face CSV: an iPhone's ARKit face capture (52 blendshapes, head and eye rotations).

Epic Games' Live Link Face app records ARKit's face tracking and exports it as CSV::

    Timecode,BlendshapeCount,EyeBlinkLeft,...,TongueOut,HeadYaw,HeadPitch,HeadRoll,
        LeftEyeYaw,LeftEyePitch,LeftEyeRoll,RightEyeYaw,RightEyePitch,RightEyeRoll
    10:13:39:01.936,61,0.0000645827,...

- ``Timecode`` is ``HH:MM:SS:FF.mmm``: hours, minutes, seconds, the frame within the
  second at the timecode rate, and the fraction of a frame (sub-frame);
- ``BlendshapeCount`` is the number of value columns that follow (61 = 52 blendshapes +
  3 head + 6 eye rotations);
- the 52 blendshapes are ARKit's (``ARFaceAnchor.BlendShapeLocation``), weights in
  [0, 1]; the app capitalises ARKit's names (``eyeBlinkLeft`` -> ``EyeBlinkLeft``).
  "Left"/"Right" are the subject's own left and right (ARKit's convention);
- the rotations are angles in radians (as the app exports them; not clamped): a
  reader refuses a column in another unit (:func:`rotation_limit`).

Inside the project a take's channels carry ARKit's own names (:data:`ARKIT_BLENDSHAPES`,
lower camel case) followed by :data:`ROTATIONS`; :func:`livelink_column` gives the CSV's
spelling. :func:`read_livelink` reads a take, :func:`write_livelink` writes one (atomic).
"""

from __future__ import annotations

import io
import math
import os
import re
from dataclasses import dataclass
from numbers import Real
from pathlib import Path

import numpy as np

from db.atomic import atomic_write
from db.errors import DataError, ParameterError
from ingest.formats.text import read_csv_rows

#: ARKit's 52 blendshapes in the order Live Link Face writes them.
ARKIT_BLENDSHAPES: tuple[str, ...] = (
    "eyeBlinkLeft", "eyeLookDownLeft", "eyeLookInLeft", "eyeLookOutLeft", "eyeLookUpLeft",
    "eyeSquintLeft", "eyeWideLeft", "eyeBlinkRight", "eyeLookDownRight", "eyeLookInRight",
    "eyeLookOutRight", "eyeLookUpRight", "eyeSquintRight", "eyeWideRight",
    "jawForward", "jawRight", "jawLeft", "jawOpen",
    "mouthClose", "mouthFunnel", "mouthPucker", "mouthRight", "mouthLeft",
    "mouthSmileLeft", "mouthSmileRight", "mouthFrownLeft", "mouthFrownRight",
    "mouthDimpleLeft", "mouthDimpleRight", "mouthStretchLeft", "mouthStretchRight",
    "mouthRollLower", "mouthRollUpper", "mouthShrugLower", "mouthShrugUpper",
    "mouthPressLeft", "mouthPressRight", "mouthLowerDownLeft", "mouthLowerDownRight",
    "mouthUpperUpLeft", "mouthUpperUpRight",
    "browDownLeft", "browDownRight", "browInnerUp", "browOuterUpLeft", "browOuterUpRight",
    "cheekPuff", "cheekSquintLeft", "cheekSquintRight", "noseSneerLeft", "noseSneerRight",
    "tongueOut",
)
#: Head and eye rotations (radians) after the blendshapes.
ROTATIONS: tuple[str, ...] = (
    "headYaw", "headPitch", "headRoll",
    "leftEyeYaw", "leftEyePitch", "leftEyeRoll", "rightEyeYaw", "rightEyePitch", "rightEyeRoll",
)
#: Every channel of a take, in Live Link Face's column order.
ARKIT_CHANNELS: tuple[str, ...] = ARKIT_BLENDSHAPES + ROTATIONS
#: The two columns before the values.
LEAD_COLUMNS = ("Timecode", "BlendshapeCount")
#: Timecode rates a Live Link Face take may use (frames per second of ``FF``).
TIMECODE_RATES = (24.0, 25.0, 30.0, 48.0, 50.0, 60.0)
#: Live Link Face's capture rate: ARKit tracks faces at 60 Hz.
LIVELINK_FPS = 60.0
#: Decimals of the values in Live Link Face's export (written the same way).
DECIMALS = 10
#: How far outside [0, 1] a blendshape weight may stray before the file is refused.
WEIGHT_SLACK = 0.05
#: Largest head yaw or roll, radians: an angle of a rotation in radians lies within a
#: half turn either way; beyond it, the column is in another unit (degrees, say).
MAX_HEAD_ANGLE_RAD = math.pi
#: Largest head pitch, radians: Euler pitch lies within a quarter turn either way.
MAX_HEAD_PITCH_RAD = math.pi / 2
#: Largest eye yaw, pitch or roll, radians: no eye turns a quarter turn in its socket
#: (its range is about 50 degrees; a real take's eyes reach 38). Eyes in degrees are
#: refused as soon as they move more than 1.6 degrees, as a speaker's always do.
MAX_EYE_ANGLE_RAD = math.pi / 2

_TIMECODE = re.compile(r"^(\d{1,2}):(\d{2}):(\d{2})[:;](\d{2}(?:\.\d+)?)$")


def is_arkit(names) -> bool:
    """True if ``names`` hold all 52 ARKit blendshapes (either spelling)."""
    have = {str(n).lower() for n in names}
    return all(n.lower() in have for n in ARKIT_BLENDSHAPES)


def livelink_column(name: str) -> str:
    """Live Link Face's column name of an ARKit channel (``jawOpen`` -> ``JawOpen``)."""
    return name[:1].upper() + name[1:]


@dataclass(frozen=True, eq=False)
class LiveLinkTake:
    """One Live Link Face take as read.

    Attributes
    ----------
    values : np.ndarray, shape (n_frames, n_channels)
        Blendshape weights then rotations, float64, one row per CSV row.
    names : tuple of str
        ARKit channel names (:data:`ARKIT_CHANNELS`, or the subset the file has).
    frames : np.ndarray, shape (n_frames,)
        Each row's timecode as a (fractional) frame count at ``timecode_rate`` since
        midnight.
    timecode_rate : float
        Frames per second of the timecode's ``FF`` field.
    """

    values: np.ndarray
    names: tuple[str, ...]
    frames: np.ndarray
    timecode_rate: float

    @property
    def seconds(self) -> np.ndarray:
        """Each row's time (s) since the first row."""
        return (self.frames - self.frames[0]) / self.timecode_rate


def parse_timecode(text: str) -> tuple[int, int, int, float]:
    """``"10:13:39:01.936"`` -> ``(10, 13, 39, 1.936)``; ValueError if not a timecode."""
    match = _TIMECODE.match(text.strip())
    if not match:
        raise ValueError(f"not a HH:MM:SS:FF.mmm timecode: {text!r}")
    hours, minutes, secs = (int(g) for g in match.groups()[:3])
    frame = float(match.group(4))
    if hours > 23 or minutes > 59 or secs > 59:
        raise ValueError(f"timecode out of range: {text!r}")
    return hours, minutes, secs, frame


def format_timecode(frame: float, rate: float) -> str:
    """A frame count at ``rate`` since midnight as ``HH:MM:SS:FF.mmm`` (wraps at 24 h)."""
    rate_i = int(round(rate))
    total = round(float(frame) * 1000)  # thousandths of a frame
    whole, milli = divmod(total, 1000)
    secs, ff = divmod(whole, rate_i)
    minutes, ss = divmod(secs, 60)
    hours, mm = divmod(minutes, 60)
    return f"{hours % 24:02d}:{mm:02d}:{ss:02d}:{ff:02d}.{milli:03d}"


def timecode_frames(text: str, rate: float) -> float:
    """A timecode as a frame count at ``rate`` since midnight."""
    hours, minutes, secs, frame = parse_timecode(text)
    if frame >= rate:
        raise ValueError(f"timecode {text!r}: frame {frame:g} is not below the rate {rate:g}")
    return ((hours * 60 + minutes) * 60 + secs) * rate + frame


def is_livelink_header(fields: list[str]) -> bool:
    """True if a CSV header starts ``Timecode,BlendshapeCount``."""
    return [f.strip().lower() for f in fields[:2]] == [c.lower() for c in LEAD_COLUMNS]


def sniff_livelink(path: str | os.PathLike) -> bool:
    """True if the file's first line is a Live Link Face header (reads one line)."""
    try:
        with open(path, "rb") as handle:
            first = handle.readline(65536).decode("utf-8-sig", errors="replace")
    except OSError:
        return False
    return is_livelink_header(first.split(","))


def _timecode_rate(parts: list[tuple[int, int, int, float]]) -> float:
    """The timecode rate that puts the rows on the most regular grid.

    Every rate above the largest ``FF`` is a candidate; a wrong one shows as a jump
    where the seconds roll over. Without a roll-over (a take shorter than a second)
    every candidate fits equally and Live Link Face's 60 is taken.
    """
    top = max(p[3] for p in parts)
    candidates = [r for r in TIMECODE_RATES if r > top]
    if not candidates:
        raise ValueError(f"timecode frame {top:g} is not below any timecode rate "
                         f"({', '.join(f'{r:g}' for r in TIMECODE_RATES)})")
    best, best_spread = LIVELINK_FPS if LIVELINK_FPS in candidates else candidates[-1], None
    for rate in reversed(candidates):
        frames = np.array([((h * 60 + m) * 60 + s) * rate + f for h, m, s, f in parts])
        steps = np.diff(frames)
        spread = float(steps.max() - steps.min()) if len(steps) else 0.0
        if best_spread is None or spread < best_spread - 1e-6:
            best, best_spread = rate, spread
    return best


def _check_ranges(values: np.ndarray, names, lines: list[int], path: Path) -> None:
    """Plausibility: blendshape weights in [0, 1] (within :data:`WEIGHT_SLACK`), rotations
    in radians (:func:`rotation_limit`); DataError at the first value outside."""
    shapes = np.array([n in ARKIT_BLENDSHAPES for n in names])
    limit = np.array([1.0 + WEIGHT_SLACK if shape else rotation_limit(n)
                      for n, shape in zip(names, shapes, strict=True)])
    low = np.where(shapes, -WEIGHT_SLACK, -limit)
    bad = (values > limit) | (values < low)
    if bad.any():
        i, j = (int(k[0]) for k in np.nonzero(bad))
        what = ("an ARKit weight lies in [0, 1]" if shapes[j] else
                f"its angles are radians, within ±{limit[j]:.4g}")
        raise DataError(f"{path}:{lines[i]}: {livelink_column(names[j])} is {values[i, j]:g}; "
                        f"{what} (another unit, or not Live Link Face's data?)")


def rotation_limit(name: str) -> float:
    """The largest plausible magnitude of rotation ``name`` (:data:`ROTATIONS`), radians:
    :data:`MAX_EYE_ANGLE_RAD`, :data:`MAX_HEAD_PITCH_RAD` or :data:`MAX_HEAD_ANGLE_RAD`."""
    if "Eye" in name:
        return MAX_EYE_ANGLE_RAD
    return MAX_HEAD_PITCH_RAD if name == "headPitch" else MAX_HEAD_ANGLE_RAD


def read_livelink(path: str | os.PathLike) -> LiveLinkTake:
    """Read a Live Link Face CSV.

    Parameters
    ----------
    path : path
        The CSV.

    Returns
    -------
    LiveLinkTake

    Raises
    ------
    DataError
        One line naming the file (and line) if it is not a Live Link Face CSV (another
        app's columns), lacks ARKit columns, has a ``BlendshapeCount`` that does not match
        its columns, a bad timecode, a value that is not a number or is NaN/infinite, a
        blendshape weight outside [0, 1] (by more than :data:`WEIGHT_SLACK`) or a rotation
        beyond :func:`rotation_limit` (radians: a column in degrees), or no rows.
        Timecode order (repeats, steps back) is checked by the reader of a clip
        (:func:`ingest.readers.livelink.frame_steps`).
    """
    path = Path(path)
    rows = read_csv_rows(path, "Live Link Face CSV")
    if not rows:
        raise DataError(f"{path}: empty file, not a Live Link Face CSV")
    header = [h.strip() for h in rows[0][1]]
    if not is_livelink_header(header):
        raise DataError(f"{path}: not a Live Link Face CSV (its header starts "
                        f"{','.join(header[:2])!r}, not 'Timecode,BlendshapeCount')")
    by_lower = {livelink_column(n).lower(): n for n in ARKIT_CHANNELS}
    columns = header[2:]
    unknown = [c for c in columns if c.lower() not in by_lower]
    if unknown:
        raise DataError(f"{path}: columns that are not ARKit channels: "
                        f"{', '.join(unknown[:4])}{' ...' if len(unknown) > 4 else ''}")
    names = tuple(by_lower[c.lower()] for c in columns)
    if len(set(names)) != len(names):
        raise DataError(f"{path}: a column appears twice")
    missing = [livelink_column(n) for n in ARKIT_BLENDSHAPES if n not in names]
    if missing:
        raise DataError(f"{path}: missing ARKit blendshape column(s) "
                        f"{', '.join(missing[:4])}{' ...' if len(missing) > 4 else ''}")
    body = rows[1:]
    if not body:
        raise DataError(f"{path}: no frames (a header only)")
    width = len(header)
    values = np.empty((len(body), len(columns)))
    parts = []
    for i, (line, row) in enumerate(body):
        if len(row) != width:
            raise DataError(f"{path}:{line}: expected {width} fields, got {len(row)}")
        try:
            parts.append(parse_timecode(row[0]))
        except ValueError as exc:
            raise DataError(f"{path}:{line}: {exc}") from None
        count = row[1].strip()
        if not count.isdigit() or int(count) != len(columns):
            raise DataError(f"{path}:{line}: BlendshapeCount {count!r} but {len(columns)} "
                            f"value columns")
        try:
            values[i] = [float(c) for c in row[2:]]
        except ValueError:
            raise DataError(f"{path}:{line}: a value is not a number") from None
        if not np.isfinite(values[i]).all():
            bad = columns[int(np.flatnonzero(~np.isfinite(values[i]))[0])]
            raise DataError(f"{path}:{line}: {bad} is {values[i][columns.index(bad)]} "
                            "(NaN or infinite)")
    _check_ranges(values, names, [line for line, _ in body], path)
    try:
        rate = _timecode_rate(parts)
    except ValueError as exc:
        raise DataError(f"{path}: {exc}") from None
    frames = np.array([((h * 60 + m) * 60 + s) * rate + f for h, m, s, f in parts])
    return LiveLinkTake(values=values, names=names, frames=frames, timecode_rate=rate)


def write_livelink(path: str | os.PathLike, values: np.ndarray, names, fps: float, *,
                   start: str = "00:00:00:00.000", timecode_rate: float | None = None,
                   clamp: bool = True) -> Path:
    """Write a take as Live Link Face CSV (atomically).

    Parameters
    ----------
    path : path
        The CSV to write.
    values : np.ndarray, shape (n_frames, n_channels)
        Motion; channels named ``names``.
    names : sequence of str
        ARKit channel names (:data:`ARKIT_CHANNELS`, either spelling); all 52
        blendshapes are needed, missing rotations are written as 0, other channels are
        left out.
    fps : float
        Frames per second of ``values``.
    start : str
        Timecode of the first frame (``HH:MM:SS:FF`` or ``HH:MM:SS:FF.mmm``); frame ``k``
        is at ``start + k * timecode_rate / fps`` timecode frames, so the timecode runs on
        without a break.
    timecode_rate : float, optional
        Frames per second of the timecode (default: ``fps`` if it is one of
        :data:`TIMECODE_RATES`, else 60).
    clamp : bool
        Clamp blendshape weights to [0, 1] (what ARKit rigs expect; rotations are never
        clamped).

    Raises
    ------
    ParameterError
        If the channels lack ARKit blendshapes, ``values`` does not match ``names``, holds
        NaN, ``fps`` is not > 0, or ``start`` is not a timecode.
    """
    values = np.asarray(values, dtype=np.float64)
    names = tuple(names)
    if values.ndim != 2 or values.shape[1] != len(names) or len(values) < 1:
        raise ParameterError(f"values: expected (n_frames, {len(names)}) with at least one "
                             f"frame, got {values.shape}")
    if isinstance(fps, bool) or not (isinstance(fps, Real) and math.isfinite(fps) and fps > 0):
        raise ParameterError(f"fps: expected a number > 0, got {fps!r}")
    if not np.isfinite(values).all():
        raise ParameterError("values: NaN or infinite values cannot go into a Live Link CSV")
    index = {n.lower(): i for i, n in enumerate(names)}
    missing = [n for n in ARKIT_BLENDSHAPES if n.lower() not in index]
    if missing:
        raise ParameterError(f"not ARKit motion: {len(missing)} of the 52 blendshapes are "
                             f"missing ({', '.join(missing[:3])} ...)")
    rate = float(timecode_rate) if timecode_rate else (
        float(fps) if float(fps) in TIMECODE_RATES else LIVELINK_FPS)
    if rate not in TIMECODE_RATES:
        raise ParameterError(f"timecode_rate: expected one of "
                             f"{', '.join(f'{r:g}' for r in TIMECODE_RATES)}, got {rate:g}")
    try:
        first = timecode_frames(start, rate)
    except ValueError as exc:
        raise ParameterError(f"start: {exc}") from None
    out = np.zeros((len(values), len(ARKIT_CHANNELS)))
    for j, name in enumerate(ARKIT_CHANNELS):
        if name.lower() in index:
            out[:, j] = values[:, index[name.lower()]]
    n_shapes = len(ARKIT_BLENDSHAPES)
    if clamp:
        out[:, :n_shapes] = np.clip(out[:, :n_shapes], 0.0, 1.0)
    buffer = io.StringIO()
    buffer.write(",".join(LEAD_COLUMNS + tuple(livelink_column(n) for n in ARKIT_CHANNELS)))
    buffer.write("\n")
    step = rate / float(fps)
    count = str(len(ARKIT_CHANNELS))
    fmt = f"%.{DECIMALS}f"
    for k, row in enumerate(out):
        cells = [format_timecode(first + k * step, rate), count]
        cells.extend(fmt % v for v in row)
        buffer.write(",".join(cells))
        buffer.write("\n")
    with atomic_write(path) as handle:
        handle.write(buffer.getvalue().encode("utf-8"))
    return Path(path)
