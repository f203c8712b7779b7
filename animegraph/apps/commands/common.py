"""What the commands share: the usage error, progress bars and lines on stderr, the
phone labels found beside a speech or motion file, and the check of a motion output."""

from __future__ import annotations

import sys
from pathlib import Path


class UsageError(Exception):
    """The command line itself is wrong (exit status 2)."""


def progress(total: int, quiet: bool, unit: str, step: str):
    """A progress bar factory labelled with its step (every step over ~2 s has one)."""
    from functools import partial

    from tqdm import tqdm

    return partial(tqdm, total=total, unit=unit, desc=step, disable=quiet, file=sys.stderr,
                   dynamic_ncols=True)


def interruptible(work, *args):
    """``work(*args)`` in a worker thread while the main thread waits for it
    (:func:`db.system.in_worker_thread`), so that a Ctrl-C inside a long compiled call
    ends the command at once (``cli.entry`` exits after a Ctrl-C, the daemon worker with
    it). From a thread other than the main one, where no Ctrl-C arrives, it just runs."""
    import threading

    from db.system import in_worker_thread

    if threading.current_thread() is not threading.main_thread():
        return work(*args)
    return in_worker_thread(lambda: work(*args))


def say(line: str) -> None:
    print(f"animegraph: {line}", file=sys.stderr)


#: Phone-label files looked for beside a speech or motion file, in this order (what
#: 'corpus synth', 'demo', 'query --export' and 'batch' write; the formats ingest reads).
SIDECAR_LABELS = (".phones.csv", ".TextGrid", ".lab")


def sidecar_labels(path: Path) -> Path | None:
    """``<stem>.phones.csv`` (or ``.TextGrid``, ``.lab``) beside ``path`` (speech for
    ``synth``, motion for ``render`` and ``plot``), if there is one. The stem of a Live
    Link take ``hit.livelink.csv`` is ``hit``: 'query --export' writes ``hit.phones.csv``
    beside it."""
    from animegraph.motion.files import LIVELINK_SUFFIX

    name = path.name
    stem = (name[:-len(LIVELINK_SUFFIX)] if name.lower().endswith(LIVELINK_SUFFIX)
            else path.stem)
    for suffix in SIDECAR_LABELS:
        beside = path.with_name(stem + suffix)
        if beside.is_file():
            return beside
    return None


def check_output(command: str, output: Path, names, kind: str) -> None:
    """``-o`` must hold the database's motion (C3D its points, Live Link CSV ARKit
    blendshapes): said before the work, not after it."""
    from animegraph.motion.files import check_output as check_motion_output
    from db.errors import ParameterError

    try:
        check_motion_output(output, names, kind)
    except ParameterError as exc:
        raise UsageError(f"animegraph {command}: -o {output.name}: {exc}") from None


#: What ``synth`` and ``map-emotion`` write with ``-o`` (``.livelink.csv`` is a ``.csv``).
MOTION_SUFFIXES = (".c3d", ".csv", ".npz")


def check_motion_suffix(command: str, output: Path) -> None:
    """``-o`` of a motion-writing command names a motion file; an animator who asks for
    a video or a glTF is told which command makes one."""
    if output.suffix.lower() not in MOTION_SUFFIXES:
        raise UsageError(f"animegraph {command}: -o must end in .c3d, .csv or .npz, got "
                         f"{output.name!r} ('animegraph render' makes .mp4, .gif, .png or "
                         ".glb of the motion)")
