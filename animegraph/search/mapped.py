"""The Anime Graph of a large database kept converted on disk and memory-mapped.

Loading a graph converts the animes table's list columns (prosody curves, motion,
boundary frames) from Parquet into float32 arrays: 33.7 CPU-s and 4.3 GB resident at 4M
animes (docs/results/speed.md, "A database of 100 hours"), although a query reads only
part of it: the prosody and boundary frames of its phones' candidates, the motion of the
animes it chooses. Here the converted arrays of a database of at least
:data:`MIN_ANIMES` animes are written once, as ``.npy`` files in the user's cache folder
(:func:`ingest.cache.cache_dir`, ``graphs/``), and every later load maps them
(copy-on-write: the pages a query never reads are never read, and processes loading one
database share the pages they read). The per-recording mean motion that k-best
recentres on is computed then too (``clip_means``), so that a query need not read every
anime's motion to recentre.

A cache is used only for the files it was converted from: its index records the
:func:`db.memo.identity` (device, inode, size, modification and status-change times) of
the database's ``manifest.json`` and every animes file, and of each of its own files. A
database file rewritten, replaced or damaged by a write has a new identity, so the graph
is converted again from it, through every check of the Parquet read (a damaged file is
refused then); a cache file changed after it was written (a new identity) or whose
``.npy`` header does not give the recorded shape and dtype is not used. The values'
checks (finite, posteriors in (0, 1]) are made when they are converted, from the checked
Parquet; every load checks the structure the search kernels index with (links, offsets,
shapes: :meth:`AnimeGraph.check` with ``values=False``). As with :mod:`db.memo`, a
database file changed within :data:`db.memo.SETTLE_NS` of the conversion is not cached.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import re
import secrets
import shutil
from pathlib import Path

import numpy as np

from animegraph.search.graph import PHONE_INDEX, AnimeGraph, clip_motion_means
from db import memo
from db.atomic import replace_dir
from db.errors import DataError
from db.lock import pid_alive
from db.npyfile import check_npy
from db.store import Database
from ingest.cache import cache_dir

logger = logging.getLogger(__name__)

__all__ = ["MIN_ANIMES", "load_graph"]

#: Fewest animes (the manifest's ``n_animes``) of a database whose graph is cached: a
#: smaller one loads from Parquet in about a second (0.24 CPU-s at 15k animes).
MIN_ANIMES = 100_000
#: Version of the cache's layout; another is converted again.
FORMAT = 1
#: Largest index read (it lists every clip id: about 20 bytes each).
MAX_INDEX_BYTES = 256 << 20
#: The graph's arrays in the cache, and their dtypes.
ARRAYS = {
    "node_phone": "int16", "node_emotion": "int16", "node_clip": "int32",
    "position": "int32", "next_node": "int64", "prev_node": "int64",
    "start_frame": "int32", "end_frame": "int32", "start_time": "float32",
    "end_time": "float32", "prosody_offsets": "int64", "prosody_values": "float32",
    "motion_offsets": "int64", "motion_values": "float32", "first_pcs": "float32",
    "last_pcs": "float32", "posterior_offsets": "int64", "posterior_values": "float32",
    "clip_means": "float64",
}
#: Curves the loader allocates (:meth:`AnimeGraph.from_database`'s ``empty``) and the
#: graph's attribute each becomes.
_CURVES = {"prosody": "prosody_values", "motion": "motion_values",
           "posteriors": "posterior_values", "first_pcs": "first_pcs", "last_pcs": "last_pcs"}
_PARTIAL = re.compile(r"^\.(.+)\.partial-(\d+)-[0-9a-f]+$")


def load_graph(db: Database) -> AnimeGraph:
    """The Anime Graph of ``db``: mapped from its cache if there is one for these files,
    else loaded (:meth:`AnimeGraph.from_database`) and, for a database of at least
    :data:`MIN_ANIMES` animes, written to the cache as it is loaded.

    Raises
    ------
    DataError
        If the database's animes do not hold up (:meth:`AnimeGraph.from_database`).
    """
    n = db.manifest.get("n_animes")
    key = _key(db)
    if not isinstance(n, int) or n < MIN_ANIMES or key is None:
        return AnimeGraph.from_database(db)
    folder = cache_dir() / "graphs" / hashlib.sha256(
        os.fsencode(db.root.resolve())).hexdigest()[:24]
    graph = _open(folder, key)
    if graph is not None:
        return graph
    if not memo.settled(key[3]):  # file times cannot yet tell a later change
        return AnimeGraph.from_database(db)
    try:
        folder.parent.mkdir(parents=True, exist_ok=True)
        _remove_abandoned(folder.parent)
        staging = folder.parent / f".{folder.name}.partial-{os.getpid()}-{secrets.token_hex(4)}"
        staging.mkdir()
    except OSError as exc:
        logger.warning("cannot cache the anime graph in %s (%s): loaded from the "
                       "database", folder.parent, exc.strerror or exc)
        return AnimeGraph.from_database(db)
    try:
        _write(db, staging, key)
        replace_dir(staging, folder)
    except OSError as exc:
        logger.warning("cannot cache the anime graph in %s (%s): loaded from the "
                       "database", folder, exc.strerror or exc)
        return AnimeGraph.from_database(db)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    graph = _open(folder, key)
    return graph if graph is not None else AnimeGraph.from_database(db)


def _key(db: Database) -> tuple | None:
    """What the cache of ``db``'s graph is valid for: the layout, the database, its live
    version and the identities of its manifest and animes files (None if one is gone)."""
    files = [db.version_dir / "manifest.json", *db.files("animes")]
    ids = memo.identities(files)
    if ids is None:
        return None
    return (FORMAT, str(db.root.resolve()), db.version_dir.name,
            tuple(tuple(i) for i in ids))


def _file_id(path: Path) -> list:
    """A cache file's identity without its path (the folder is renamed into place)."""
    return list(memo.identity(path)[1:])


def _write(db: Database, staging: Path, key: tuple) -> None:
    """Load ``db``'s graph with its curves written into ``staging``, then its other arrays
    and the index (the files flushed to disk before the index names them)."""
    written = {}

    def empty(name: str, shape: tuple[int, ...]) -> np.ndarray:
        array = np.lib.format.open_memmap(staging / f"{_CURVES[name]}.npy", mode="w+",
                                          dtype=np.float32, shape=shape)
        written[_CURVES[name]] = array
        return array

    graph = AnimeGraph.from_database(db, empty)
    arrays = {"clip_means": clip_motion_means(graph)}
    for name in ARRAYS:
        if name not in written and name != "clip_means":
            value = getattr(graph, name)
            if value is not None:
                arrays[name] = value
    for array in written.values():
        array.flush()
    index = {"format": FORMAT, "key": key, "clip_ids": list(graph.clip_ids),
             "emotions": list(graph.emotions), "fps": graph.fps,
             "n_channels": graph.n_channels, "files": {}}
    del graph
    written.clear()  # the files are unmapped once nothing refers to them
    for name, array in arrays.items():
        np.save(staging / f"{name}.npy", np.ascontiguousarray(array, dtype=ARRAYS[name]),
                allow_pickle=False)
    for f in sorted(staging.glob("*.npy")):
        fd = os.open(f, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        index["files"][f.stem] = _file_id(f)
    (staging / "index.json").write_text(json.dumps(index))


def _open(folder: Path, key: tuple) -> AnimeGraph | None:
    """The graph mapped from the cache at ``folder`` if it was written for ``key`` and
    holds up, else None (the reason logged)."""
    try:
        raw = (folder / "index.json").read_bytes() if (
            folder / "index.json").stat().st_size <= MAX_INDEX_BYTES else b""
    except OSError:
        return None
    try:
        index = json.loads(raw)
        if index.get("format") != FORMAT or _lists(key) != index.get("key"):
            return None
        return _graph(folder, index)
    except (ValueError, TypeError, KeyError, AttributeError, OSError, DataError) as exc:
        logger.info("the anime graph's cache %s is not used: %s", folder, exc)
        return None


def _lists(value):
    """``value`` with its tuples as lists (as JSON gives them back)."""
    return [_lists(v) for v in value] if isinstance(value, tuple | list) else value


def _graph(folder: Path, index: dict) -> AnimeGraph:
    """The graph of the cache's files (ValueError, OSError or DataError if one does not
    hold up)."""
    arrays = {}
    for name, dtype in ARRAYS.items():
        path = folder / f"{name}.npy"
        recorded = index["files"].get(name)
        if recorded is None:
            if name.startswith("posterior"):
                arrays[name] = None
                continue
            raise ValueError(f"{name} is missing")
        if _file_id(path) != recorded:
            raise ValueError(f"{path} changed after it was written")
        check_npy(path)
        array = np.load(path, mmap_mode="c", allow_pickle=False)
        if array.dtype != np.dtype(dtype) or not array.flags.c_contiguous:
            raise ValueError(f"{path} holds {array.dtype}, not {dtype}")
        arrays[name] = array.view(np.ndarray)
    clip_ids, emotions = index["clip_ids"], index["emotions"]
    if not all(isinstance(c, str) for c in clip_ids + emotions):
        raise ValueError("clip ids and emotions must be text")
    node_phone = arrays["node_phone"]
    if ((node_phone < 0) | (node_phone >= len(PHONE_INDEX))).any():
        raise ValueError("node_phone outside the phones")
    if ((arrays["node_emotion"] < 0) | (arrays["node_emotion"] >= len(emotions))).any():
        raise ValueError("node_emotion outside the emotions")
    n = node_phone.shape[0]
    for name in ARRAYS:
        value = arrays[name]
        if value is not None and not name.endswith(("_values", "_pcs", "clip_means")) and (
                value.shape != ((n + 1,) if name.endswith("_offsets") else (n,))):
            raise ValueError(f"{name} has shape {value.shape}, not one value a node")
    for name in ("first_pcs", "last_pcs"):
        if arrays[name].ndim != 2:
            raise ValueError(f"{name} has shape {arrays[name].shape}")
    graph = AnimeGraph(
        **arrays, clip_ids=tuple(clip_ids), emotions=tuple(emotions),
        by_phone=tuple(np.flatnonzero(node_phone == p).astype(np.int64)
                       for p in range(len(PHONE_INDEX))),
        fps=float(index["fps"]), n_channels=int(index["n_channels"]))
    graph.check(values=False)
    return graph


def _remove_abandoned(graphs: Path) -> None:
    """Delete the staging folders of writers that are gone (killed while writing), and
    the caches of databases that are gone (their index names the database's folder)."""
    for child in graphs.iterdir():
        found = _PARTIAL.match(child.name)
        if found and not pid_alive(int(found.group(2))):
            shutil.rmtree(child, ignore_errors=True)
        elif not child.name.startswith("."):
            try:
                root = json.loads((child / "index.json").read_bytes())["key"][1]
            except (OSError, ValueError, TypeError, KeyError, IndexError):
                continue  # being written, or not ours: left alone
            if isinstance(root, str) and not Path(root).exists():
                shutil.rmtree(child, ignore_errors=True)
