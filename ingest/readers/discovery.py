"""Find clips in folders: which files make up each clip, and which reader loads it.

Discovery reads file names, folder listings and small JSON files only (and the first
line of a ``.csv`` to tell a marker CSV from other tables); the motion and audio are
read by :func:`ingest.readers.load`. Hidden files and folders (``.name``) are skipped.

Per folder, the first layout that fits wins:

1. **synthetic corpus**: ``corpus.json`` (format ``animegraph-corpus``), ``markers.csv``
   and ``clips/``: every ``clips/<id>.c3d`` (also when ``clips/`` itself is given);
2. **FACEGOOD**: folders ``bs_value/`` (``bs_value_<clip>.npy``) and ``wav/``;
3. **talking-face clip**: a folder with ``landmarks.npy``; its transcript, phone labels
   and word alignment are ``transcript.txt`` / ``<clip>.txt``, ``phones.csv`` /
   ``<clip>.phones.csv`` / ``<clip>.TextGrid`` / ``<clip>.lab`` and ``<clip>.align``,
   in the folder or beside it;
4. **generic**: per file stem, a marker file (``.c3d`` > ``.trc`` > marker ``.csv``),
   else a Live Link Face ``.csv`` (header ``Timecode,BlendshapeCount,...``: an iPhone
   capture, :mod:`ingest.readers.livelink`; its speech is ``<stem>.wav``, else the sound
   track of the app's ``<stem>.mov``/``.mp4``), else a curve file (``.npy`` >
   ``.curves.csv``), else a video (:data:`VIDEO_SUFFIXES`, faces tracked by
   :mod:`ingest.readers.video`), with its side files (``.align``: a GRID word alignment).
   A marker or Live Link file without ``<stem>.wav`` is still a clip (``load`` then
   rejects it);
   a ``.npy`` or ``.curves.csv`` without one is not taken for a clip.
"""

from __future__ import annotations

import json
import logging
import os
from collections.abc import Iterable, Sequence
from pathlib import Path

from db.errors import ParameterError
from ingest.formats.livelink import sniff_livelink
from ingest.formats.media import MEDIA_SUFFIXES, VIDEO_SUFFIXES
from ingest.readers.common import ClipSource
from ingest.readers.landmarks import AUDIO_NAMES

logger = logging.getLogger(__name__)

CORPUS_FORMAT = "animegraph-corpus"
#: Two-part suffixes of side files (lower case), checked before the plain suffix.
COMPOUND_SUFFIXES = (".phones.csv", ".controls.csv", ".curves.csv", ".channels.txt")
MARKER_SUFFIXES = (".c3d", ".trc", ".csv")  # in order of preference
CURVE_SUFFIXES = (".npy", ".curves.csv")
LABEL_SUFFIXES = (".phones.csv", ".textgrid", ".lab")  # in order of preference
#: Corpus-level files that are never clips.
RESERVED_NAMES = frozenset({"markers.csv", "curves.json", "corpus.json", "channels.txt"})
FACEGOOD_NAMES = ("shirley_1119_bs_name.npy", "bsname.txt")


def split_name(name: str) -> tuple[str, str]:
    """``"a.phones.csv" -> ("a", ".phones.csv")``; ``"a.C3D" -> ("a", ".c3d")``."""
    lower = name.lower()
    for suffix in COMPOUND_SUFFIXES:
        if lower.endswith(suffix) and len(name) > len(suffix):
            return name[: -len(suffix)], suffix
    stem, ext = os.path.splitext(name)
    return stem, ext.lower()


def _is_marker_csv(path: Path) -> bool:
    """True if the first line reads ``frame,time,<label>.x,...``."""
    try:
        with open(path, "rb") as handle:
            first = handle.readline(65536).decode("utf-8-sig", errors="replace")
    except OSError:
        return False
    fields = [f.strip().lower() for f in first.split(",")]
    return len(fields) >= 5 and fields[:2] == ["frame", "time"] and fields[2].endswith(".x")


def _first_existing(*paths: Path) -> Path | None:
    for path in paths:
        if path.is_file():
            return path
    return None


def _synthetic_root(folder: Path) -> bool:
    corpus = folder / "corpus.json"
    if not (corpus.is_file() and (folder / "markers.csv").is_file()
            and (folder / "clips").is_dir()):
        return False
    try:
        return json.loads(corpus.read_text(encoding="utf-8")).get("format") == CORPUS_FORMAT
    except (OSError, ValueError, AttributeError, RecursionError):
        logger.warning("%s: unreadable corpus.json; not read as a synthetic corpus", corpus)
        return False


#: Files a folder may hold that are no clip's: macOS's Finder settings and the
#: AppleDouble "._<name>" forks it writes beside every file copied to a foreign disk.
NOT_CLIP_FILES = (".DS_Store",)
NOT_CLIP_PREFIX = "._"


def _files(folder: Path) -> list[Path]:
    """The files of ``folder`` that may be a clip's. A name starting with a dot is one
    (a clip ``..dots`` was neither added nor rejected: skipped as hidden, in silence)."""
    try:
        return sorted(p for p in folder.iterdir() if p.is_file()
                      and p.name not in NOT_CLIP_FILES
                      and not p.name.startswith(NOT_CLIP_PREFIX))
    except OSError as exc:
        logger.warning("cannot list %s: %s", folder, exc.strerror)
        return []


def _stem_clips(folder: Path, corpus: str, layout_markers: str,
                marker_table: Path | None, settings: Path | None,
                stems: set[str] | None = None) -> list[ClipSource]:
    """Generic per-stem clips of one folder (also the synthetic corpus's clips/); only
    those of ``stems`` if given (what is said of the others is not asked for)."""
    by_stem: dict[str, dict[str, Path]] = {}
    for path in _files(folder):
        if path.name.lower() in RESERVED_NAMES:
            continue
        stem, suffix = split_name(path.name)
        if stems is None or stem in stems:
            by_stem.setdefault(stem, {})[suffix] = path
    sources = []
    for stem, files in sorted(by_stem.items()):
        markers = [files[s] for s in MARKER_SUFFIXES if s in files
                   and (s != ".csv" or _is_marker_csv(files[s]))]
        curves = [files[s] for s in CURVE_SUFFIXES if s in files]
        labels = [files[s] for s in LABEL_SUFFIXES if s in files]
        audio = files.get(".wav")
        livelink = files.get(".csv") if not markers and ".csv" in files else None
        if livelink is not None and not sniff_livelink(livelink):
            livelink = None
        videos = [files[s] for s in VIDEO_SUFFIXES if s in files]
        if markers:
            kind, layout, motion = "markers", layout_markers, markers[0]
            ignored = markers[1:] + curves
        elif livelink is not None:
            kind, layout, motion = "curves", "livelink", livelink
            ignored = curves
            # Live Link Face keeps a take's speech in its video.
            audio = audio or next((files[s] for s in MEDIA_SUFFIXES if s in files), None)
        elif curves and (audio is not None or ".channels.txt" in files):
            kind, layout, motion = "curves", "curves", curves[0]
            ignored = curves[1:] + videos
        elif videos:
            kind, layout, motion = "landmarks", "video", videos[0]
            ignored = videos[1:]
        else:
            if curves:
                logger.debug("%s: no %s.wav; not a clip", curves[0], stem)
            elif audio is not None:  # speech whose motion is missing: said, not skipped
                logger.warning("%s: no motion beside it (%s.c3d, .trc, .csv, .npy, "
                               ".curves.csv or a video); not a clip", audio.name, stem)
            continue
        if ignored:
            logger.warning("%s: using %s, ignoring %s", folder / stem, motion.name,
                           ", ".join(p.name for p in ignored))
        if len(labels) > 1:
            logger.warning("%s: using labels %s, ignoring %s", folder / stem, labels[0].name,
                           ", ".join(p.name for p in labels[1:]))
        role_files = {
            "motion": motion, "audio": audio, "labels": labels[0] if labels else None,
            "transcript": files.get(".txt"), "metadata": files.get(".json"),
            "words": files.get(".align"),
        }
        if kind == "markers":
            role_files["marker_table"] = marker_table
        elif kind == "curves" and layout != "livelink":
            role_files["channel_names"] = files.get(".channels.txt")
            role_files["settings"] = settings
        sources.append(ClipSource.make(corpus, stem, kind, layout, motion, role_files))
    return sources


def _is_facegood(folder: Path) -> bool:
    return (folder / "bs_value").is_dir() and (folder / "wav").is_dir()


def _facegood_clips(root: Path) -> list[ClipSource]:
    names = _first_existing(root / FACEGOOD_NAMES[0])
    listing = _first_existing(root / FACEGOOD_NAMES[1])
    settings = _first_existing(root / "curves.json")
    sources = []
    for motion in _files(root / "bs_value"):
        if not (motion.name.startswith("bs_value_") and motion.suffix.lower() == ".npy"):
            continue
        clip = motion.name[len("bs_value_"):-len(".npy")]
        audio = _first_existing(root / "wav" / f"{clip}.wav")
        sources.append(ClipSource.make(root.name, clip, "curves", "facegood", motion, {
            "motion": motion, "audio": audio, "channel_names": names,
            "channel_list": listing, "settings": settings,
        }))
    return sources


def _talkingface_clip(folder: Path) -> ClipSource:
    audio = _first_existing(*(folder / name for name in AUDIO_NAMES))
    name, parent = folder.name, folder.parent

    def side(*names: str) -> Path | None:  # in the clip folder, then beside it
        return _first_existing(*(folder / n for n in names),
                               *(parent / n for n in names if n.startswith(name)))

    labels = side("phones.csv", f"{name}.phones.csv", f"{name}.TextGrid", f"{name}.textgrid",
                  f"{name}.lab")
    return ClipSource.make(parent.name, name, "landmarks", "talkingface", folder, {
        "motion": folder / "landmarks.npy", "audio": audio,
        "metadata": _first_existing(folder / "meta.json"),
        "transcript": side("transcript.txt", f"{name}.txt"), "labels": labels,
        "words": side(f"{name}.align", "words.align"),
    })


def _scan(folder: Path, recursive: bool = True,
          stems: set[str] | None = None) -> Iterable[ClipSource]:
    """Clips in ``folder`` (and below, if ``recursive``); of per-stem clips only those of
    ``stems``, if given."""
    if folder.name == "clips" and _synthetic_root(folder.parent):
        folder = folder.parent
    stack = [folder]
    seen: set[Path] = set()
    while stack:
        here = stack.pop()
        real = here.resolve()
        if real in seen:  # a symbolic link back up the tree
            continue
        seen.add(real)
        skip: set[str] = set()
        if _synthetic_root(here):
            yield from _stem_clips(here / "clips", here.name, "synthetic",
                                   here / "markers.csv", None, stems)
            skip = {"clips"}
        elif _is_facegood(here):
            yield from _facegood_clips(here)
            skip = {"bs_value", "wav"}
        elif (here / "landmarks.npy").is_file():
            yield _talkingface_clip(here)
        else:
            yield from _stem_clips(
                here, here.name, "markers",
                _first_existing(here / "markers.csv", here.parent / "markers.csv"),
                _first_existing(here / "curves.json", here.parent / "curves.json"),
                stems,
            )
        if not recursive:
            break
        try:
            subfolders = sorted(p for p in here.iterdir() if p.is_dir()
                                and not p.name.startswith(".") and p.name not in skip)
        except OSError:
            subfolders = []
        stack.extend(reversed(subfolders))


def discover(paths: Sequence[str | os.PathLike[str]]) -> list[ClipSource]:
    """Find the clips in files and folders.

    Parameters
    ----------
    paths : sequence of path
        Folders (searched recursively) and files. A file stands for the clip it belongs
        to (its motion file or any of its side files).

    Returns
    -------
    list of ClipSource
        One per clip, sorted by (corpus, clip_id, kind, ...), without duplicates.

    Raises
    ------
    ParameterError
        If ``paths`` is not a sequence of paths or a path does not exist.
    """
    if isinstance(paths, str | bytes | os.PathLike) or not isinstance(paths, Sequence):
        raise ParameterError(f"paths: expected a sequence of paths, got {paths!r}")
    found: dict[tuple[str, Path], ClipSource] = {}
    for item in paths:
        path = Path(item)
        if not path.exists():
            raise ParameterError(f"paths: {path} does not exist")
        if path.is_dir():
            candidates = list(_scan(path))
        else:
            # The clip is described by the file's folder or, for FACEGOOD's wav/ and
            # bs_value/, by the folder above alone (read as a plain folder, wav/ said
            # of each FACEGOOD speech file it then ingested that it had no motion); of
            # the clips named by their files' stem, only this file's stem is read
            # (nothing is said of the others).
            wanted = path.resolve()
            stems = {split_name(path.name)[0]}
            above = path.parent.parent
            in_facegood = path.parent.name in ("wav", "bs_value") and _is_facegood(above)
            folders = [above] if in_facegood else [path.parent]
            nearby = [c for f in folders for c in _scan(f, False, stems)]
            candidates = [s for s in nearby if wanted in {p.resolve() for p in s.paths}]
            if not candidates:
                logger.warning("%s is not part of a clip this reader recognises", path)
        for source in candidates:
            found.setdefault((source.layout, source.source.resolve()), source)
    return sorted(found.values())
