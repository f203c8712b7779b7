"""What says a line of ``animegraph batch`` (:mod:`animegraph.apps.batch`) is finished: the
keys of its inputs (:func:`line_key`) and of its render (:func:`render_key`), and its
marker ``done.json`` in its folder, read as coming from anyone (:func:`finished`)."""

from __future__ import annotations

import hashlib
import json
import os
import stat
from collections.abc import Callable, Iterable
from pathlib import Path

from animegraph import __version__
from animegraph.apps.script import ScriptLine
from animegraph.motion.files import LIVELINK_SUFFIX
from db.atomic import atomic_write
from db.errors import AnimeGraphError, DataError, ParameterError
from db.store import current_version
from ingest.readers.common import read_json_object

#: Version of the per-line layout and key; a change redoes every line.
FORMAT = 2
DONE = "done.json"
PREVIEW = "preview.mp4"
#: ``motion_formats`` a batch writes, and the ending of their files (``synth -o``'s).
MOTION_FORMATS = {"c3d": ".c3d", "csv": ".csv", "npz": ".npz", "livelink": LIVELINK_SUFFIX}
#: Every file a line's folder holds from a run: removed before it is made again, so that
#: no file of an earlier run (another motion format, a preview) is taken for this one's.
LINE_FILES = ("speech.wav", "phones.csv", "explain.json", PREVIEW,
              *(f"motion{suffix}" for suffix in MOTION_FORMATS.values()))


class LineError(AnimeGraphError):
    """One line cannot be made; the batch goes on."""


def database_identity(db: Path) -> tuple[str, str]:
    """(live version name, a digest of that version's manifest): a rebuilt database in
    the same folder, even with the same version name, has another digest."""
    version = current_version(db)
    try:
        manifest = (db / version / "manifest.json").read_bytes()
    except OSError as exc:
        raise DataError(f"database {db} is damaged: cannot read its manifest") from exc
    return version, f"{version}:{hashlib.sha256(manifest).hexdigest()[:16]}"


def motion_files(formats: Iterable[str], names, kind: str) -> tuple[str, ...]:
    """The motion files of a line: ``motion`` with the ending of each of ``formats``
    (:data:`MOTION_FORMATS`, in its order), or, for none, of the database's own format
    (:func:`animegraph.motion.files.motion_suffix`).

    Raises
    ------
    ParameterError
        A format is unknown, or cannot hold this database's motion (C3D of curves, Live
        Link CSV of other than ARKit blendshapes), as ``synth -o`` says it.
    """
    from animegraph.motion.files import check_format, motion_suffix

    unknown = [name for name in formats if name not in MOTION_FORMATS]
    if unknown:
        raise ParameterError(f"motion format must be one of {', '.join(MOTION_FORMATS)}, "
                             f"got {unknown[0]!r}")
    # in one order, whatever the order given: c3d,csv and csv,c3d make the same lines
    chosen = [name for name in MOTION_FORMATS if name in formats]
    for name in chosen:
        try:
            check_format(f"motion{MOTION_FORMATS[name]}", names, kind)
        except ParameterError as exc:
            raise ParameterError(f"--motion-format {name}: {exc}") from None
    files = [f"motion{MOTION_FORMATS[name]}" for name in chosen]
    return tuple(files) or (f"motion{motion_suffix(names, kind)}",)


def line_key(line: ScriptLine, db_identity: str, files: tuple[str, ...]) -> str:
    """Hash of everything a line's motion and its other synthesized files depend on:
    its inputs, the recording's bytes, the database and the motion ``files`` written
    (not the render: :func:`render_key`).

    Raises
    ------
    LineError
        The recording is missing or unreadable.
    """
    audio = None
    if line.audio is not None:
        audio = file_digest(line.audio)
    inputs = {
        "format": FORMAT, "animegraph": __version__, "db": db_identity, "files": list(files),
        "id": line.id, "text": line.text, "audio_sha256": audio,
        "emotion": line.emotion.text, "voice": line.voice, "speaker": line.speaker,
        "method": line.method, "window": line.window, "k_best": line.synthesis_path()[0],
    }
    return hashlib.sha256(json.dumps(inputs, sort_keys=True).encode()).hexdigest()


def render_key(key: str, render: str) -> str:
    """Hash of what a line's render depends on: its motion (the :func:`line_key` it was
    made with) and the render options."""
    inputs = {"motion": key, "render": render}
    return hashlib.sha256(json.dumps(inputs, sort_keys=True).encode()).hexdigest()


def file_digest(path: Path) -> str:
    """SHA-256 (hex) of a file's bytes; LineError if it is missing or unreadable."""
    if not path.exists():
        raise LineError(f"audio file not found: {path}")
    if not path.is_file():
        raise LineError(f"audio is not a file: {path}")
    digest = hashlib.sha256()
    try:
        with path.open("rb") as handle:
            for block in iter(lambda: handle.read(1 << 20), b""):
                digest.update(block)
    except OSError as exc:
        raise LineError(f"cannot read audio file {path}: {exc.strerror or exc}") from None
    return digest.hexdigest()


def finished(folder: Path, key: str,
             guides: Callable[[list[str]], dict] | None = None) -> dict | None:
    """The saved report row of a line finished with this ``key`` (every output still
    there), else None.

    ``guides(parts)`` gives the stored state of guide parts now (:func:`guide_state`):
    a line that went as speech alone is finished only if the guide it had (or lacked)
    is still what is stored, so fitting the guide after a batch remakes its lines.

    The output folder may come from someone else: a marker or an output that is not a
    regular file in ``folder`` (a symbolic link out, a FIFO, a name with a path in it), a
    marker larger or deeper than a JSON side file may be
    (:func:`ingest.readers.common.read_json_object`) or of the wrong types is not a
    finished line: the line is made again, and its files replace these.
    """
    marker = read_marker(folder)
    if marker is None:
        return None
    outputs = marker.get("outputs", [])
    if marker.get("key") != key or not isinstance(outputs, list) or not all(
            isinstance(name, str) and Path(name).name == name and name not in ("", ".", "..")
            and _regular_file(folder / name) for name in outputs):
        return None
    used = marker.get("guides")
    if guides is not None and used is not None:
        from animegraph.baselines.stored import FORWARD

        # The names come from a file in the output folder: only stored guides' names.
        if not isinstance(used, dict) or not set(used) <= set(FORWARD) or \
                used != guides(sorted(used)):
            return None
    row = marker.get("row")
    return row if isinstance(row, dict) else None


def _regular_file(path: Path) -> bool:
    """True if ``path`` is a regular file itself (not a symbolic link to one)."""
    try:
        return stat.S_ISREG(os.lstat(path).st_mode)
    except (OSError, ValueError):  # absent, or a name with a NUL
        return False


def rendered(folder: Path, key: str, render: str) -> bool:
    """True if ``folder`` holds the render ``render`` asks for (nothing for ``none``:
    turning the render off keeps a preview), made from the motion of ``key``."""
    if render == "none":
        return True
    marker = read_marker(folder) or {}
    return (marker.get("render") == render_key(key, render)
            and _regular_file(folder / PREVIEW))


def read_marker(folder: Path) -> dict | None:
    """The line's ``done.json``, or None if there is none that reads as one: a marker that
    is not a regular file in ``folder`` (a symbolic link out, a FIFO), or larger or deeper
    than a JSON side file may be (:func:`ingest.readers.common.read_json_object`), is
    none (the output folder may come from someone else)."""
    if not _regular_file(folder / DONE):
        return None
    try:
        return read_json_object(folder / DONE)
    except DataError:
        return None


def write_marker(folder: Path, marker: dict) -> None:
    """Write a line's ``done.json``, atomically."""
    with atomic_write(folder / DONE) as handle:
        handle.write(json.dumps(marker, indent=1).encode())


def guide_state(db: str | Path, parts: Iterable[str]) -> dict[str, str | None]:
    """What is stored of each guide part with ``db``'s live version: part -> the SHA-256
    of its model file, or None if there is none."""
    from animegraph.baselines.stored import model_path

    state = {}
    for part in parts:
        try:
            state[part] = file_digest(model_path(db, part))
        except LineError:
            state[part] = None
    return state


def remove_temporaries(folder: Path) -> None:
    """Temporary files a killed run left (hidden, so they never look finished)."""
    for path in folder.glob(".*.tmp*"):
        path.unlink(missing_ok=True)
