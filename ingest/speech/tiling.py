"""Phone segments that tile a clip exactly: onsets made segments (:func:`tile`), and
labels given by the user checked and snapped to the audio (:func:`snap_labels`); every
phone engine's segments pass through here."""

from __future__ import annotations

import math
from collections.abc import Sequence

from db.errors import ParameterError
from ingest.formats.phones_csv import Segment
from ingest.speech.phones import PHONE_SET, SILENCE

__all__ = ["SNAP_TOLERANCE", "check_label", "silence", "snap_labels", "tile"]

#: Default tolerance (seconds) of :func:`snap_labels` for gaps and overlaps.
SNAP_TOLERANCE = 0.05
#: Interior boundaries are rounded to microseconds, as ``.phones.csv`` files store them.
_TIME_DECIMALS = 6


def tile(onsets: Sequence[tuple[str, float]], duration: float) -> list[Segment]:
    """(phone, onset seconds) in order -> segments tiling ``[0, duration]``.

    The first onset is moved to 0, each segment ends where the next starts, the last at
    ``duration``. Onsets are clipped to the clip and made non-decreasing; segments shorter
    than a microsecond are dropped (their neighbours close the gap), adjacent SIL merged.
    Interior boundaries are rounded to microseconds.
    """
    if duration <= 0:
        return []
    eps = 10.0**-_TIME_DECIMALS
    starts: list[float] = []
    for k, (_, onset) in enumerate(onsets):
        start = 0.0 if k == 0 else min(max(round(onset, _TIME_DECIMALS), starts[-1]), duration)
        starts.append(start)
    pieces: list[list] = []
    for k, (phone, _) in enumerate(onsets):
        end = starts[k + 1] if k + 1 < len(onsets) else duration
        if end - starts[k] < eps:
            continue
        if pieces and pieces[-1][0] == SILENCE and phone == SILENCE:
            pieces[-1][2] = end
            continue
        pieces.append([phone, starts[k], end])
    if not pieces:
        return [Segment(SILENCE, 0.0, duration)]
    pieces[0][1] = 0.0
    pieces[-1][2] = duration
    for prev, cur in zip(pieces, pieces[1:], strict=False):
        prev[2] = cur[1]
    return [Segment(phone, start, end) for phone, start, end in pieces]


def silence(duration: float) -> list[Segment]:
    """One SIL segment over ``[0, duration]`` (none for an empty clip)."""
    return [Segment(SILENCE, 0.0, duration)] if duration > 0 else []


def check_label(item: object, index: int) -> Segment:
    """``labels[index]``, a ``(phone, start, end)`` item or an object with those
    attributes, checked (a phone of the set, ``0 <= start < end``) as a Segment."""
    if all(hasattr(item, name) for name in ("phone", "start", "end")):
        phone, start, end = item.phone, item.start, item.end  # type: ignore[attr-defined]
    elif isinstance(item, tuple | list) and len(item) == 3:
        phone, start, end = item
    else:
        raise ParameterError(f"labels[{index}]: expected (phone, start, end), got {item!r}")
    if not isinstance(phone, str) or phone not in PHONE_SET:
        raise ParameterError(f"labels[{index}].phone: unknown phone {phone!r}")
    try:
        start, end = float(start), float(end)
    except (TypeError, ValueError) as exc:
        raise ParameterError(f"labels[{index}]: bad times {start!r}, {end!r}") from exc
    if not (math.isfinite(start) and math.isfinite(end)) or start < 0 or end <= start:
        raise ParameterError(f"labels[{index}]: expected 0 <= start < end, got {start}, {end}")
    return Segment(phone, start, end)


def snap_labels(
    labels: Sequence[Segment], duration: float, *, tolerance: float = SNAP_TOLERANCE
) -> list[Segment]:
    """Check phone labels and snap them to tile ``[0, duration]`` exactly.

    Gaps and overlaps between neighbours up to ``tolerance`` are closed at their middle;
    larger gaps (and a start or end further than ``tolerance`` from the clip's edges)
    are filled with ``SIL``. Labels running past the end by up to ``tolerance`` are cut.

    Parameters
    ----------
    labels : sequence of Segment
        ``(phone, start, end)`` items (or objects with those attributes), phones from
        :data:`ingest.speech.phones.PHONE_SET`, in time order.
    duration : float
        Length of the audio in seconds.
    tolerance : float, optional
        Largest gap, overlap or overrun (seconds) snapped without complaint.

    Returns
    -------
    list of Segment
        Segments tiling ``[0, duration]``, adjacent SIL merged, none empty.

    Raises
    ------
    ParameterError
        No labels; a bad item; labels out of order, overlapping by more than
        ``tolerance`` or reaching past ``duration + tolerance``.
    """
    if isinstance(labels, str | bytes) or not isinstance(labels, Sequence):
        raise ParameterError(f"labels: expected a sequence of segments, got {labels!r}")
    if not labels:
        raise ParameterError("labels: expected at least one segment, got none")
    items = [check_label(item, k) for k, item in enumerate(labels)]
    for k in range(1, len(items)):
        if items[k].start < items[k - 1].start:
            raise ParameterError(
                f"labels[{k}]: starts at {items[k].start} before labels[{k - 1}] "
                f"({items[k - 1].start})"
            )
        if items[k - 1].end - items[k].start > tolerance:
            raise ParameterError(
                f"labels[{k}]: overlaps labels[{k - 1}] by "
                f"{items[k - 1].end - items[k].start:.3f} s (tolerance {tolerance} s)"
            )
    if items[-1].end > duration + tolerance:
        raise ParameterError(
            f"labels: end at {items[-1].end} s, past the audio's {duration:.3f} s "
            f"(tolerance {tolerance} s)"
        )
    onsets: list[tuple[str, float]] = []
    if items[0].start > tolerance:
        onsets.append((SILENCE, 0.0))
    for k, item in enumerate(items):
        if k == 0:
            start = item.start if items[0].start > tolerance else 0.0
        else:
            gap = item.start - items[k - 1].end
            if gap > tolerance:
                onsets.append((SILENCE, items[k - 1].end))
                start = item.start
            else:
                start = (item.start + items[k - 1].end) / 2
        onsets.append((item.phone, start))
    if duration - items[-1].end > tolerance:
        onsets.append((SILENCE, items[-1].end))
    return tile(onsets, duration)
