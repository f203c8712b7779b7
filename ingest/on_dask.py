"""Ingest's per-clip work on a Dask cluster (``animegraph ingest --scheduler``).

The client (the one process that writes the database, under its writer lock) submits
one task a clip and gathers the prepared clips as they finish; the workers never touch
the database. Two things make this more than ``client.map``:

* **Resume.** Each prepared clip is kept in the client's cache folder as it arrives
  (:mod:`ingest.prepared_cache`, by the clip's bytes and the settings); a killed ingest
  run again takes those from the cache and submits only the others.
* **The bytes travel.** A clip whose files add up to at most :data:`SHIP_MAX_BYTES` is
  sent to its worker with its files' bytes, written there into a temporary folder laid
  out as on the client (so the readers find a clip's side files where they expect them)
  and removed after; a worker need not see the client's disks. A larger clip travels as
  its paths, which its worker must be able to read (a shared file system). On a local
  cluster (one this process started: its workers share this machine's disks) every clip
  travels as its paths.
"""

from __future__ import annotations

import contextlib
import logging
import os
import tempfile
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, fields, is_dataclass, replace
from pathlib import Path

from ingest.clip import checksum_bytes

logger = logging.getLogger(__name__)

#: Largest clip (the bytes of all its files) sent to a worker; larger clips are read from
#: their paths by the worker. A few minutes of video are tens of MB; Dask's messages
#: carry that comfortably.
SHIP_MAX_BYTES = 64 << 20
#: Clips submitted a worker thread at a time: enough that no worker waits for its next
#: clip, few enough that the clips' bytes in flight stay a handful per worker (all of a
#: 100-hour archive submitted at once would sit in the scheduler's memory).
IN_FLIGHT_PER_THREAD = 3


@dataclass(frozen=True)
class Shipped:
    """A clip's files as they travel to a worker.

    ``root``: the client's folder that holds them all; ``files``: (path relative to
    ``root``, bytes); ``source``: the clip's main path relative to ``root``; ``folder``:
    the main path is a folder (a landmark clip); ``checksum``: the clip's checksum, of
    these bytes (:func:`ingest.clip.checksum_bytes`: the client reads a clip once).
    """

    root: str
    files: tuple[tuple[str, bytes], ...]
    source: str
    folder: bool
    checksum: str


def ship(source, max_bytes: int = SHIP_MAX_BYTES) -> Shipped | None:
    """The files of ``source`` (a :class:`ingest.readers.ClipSource`) with their bytes,
    or None when they add up to more than ``max_bytes``, one cannot be read, or one is a
    symbolic link (its worker then reads the paths, and the reader says what is wrong
    with them: a link's bytes sent as a plain file would pass the readers' refusal of
    links that leave the clip's folder)."""
    paths = [Path(p) for p in source.paths]
    main = Path(source.source)
    try:
        if (not paths or any(p.is_symlink() for p in paths)
                or sum(p.stat().st_size for p in paths) > max_bytes):
            return None
        is_folder = main.is_dir()
        root = Path(os.path.commonpath([p.parent.absolute() for p in paths]
                                       + [main.absolute() if is_folder
                                          else main.parent.absolute()]))
        files = tuple((str(p.absolute().relative_to(root)), p.read_bytes()) for p in paths)
    except (OSError, ValueError):
        return None
    return Shipped(str(root), files, str(main.absolute().relative_to(root)), is_folder,
                   checksum_bytes(data for _, data in files))


def run_shipped(func: Callable, job, shipped: Shipped | None):
    """Worker: ``func(job)``, with the clip's files written from ``shipped`` into a
    temporary folder first (None: read where ``job.source`` says). The temporary folder
    is then named nowhere in what comes back: the client's paths are put in its place."""
    if shipped is None:
        return func(job)
    with tempfile.TemporaryDirectory(prefix="animegraph-clip-") as tmp:
        here = Path(tmp).resolve()
        for relative, data in shipped.files:
            path = _inside(here, relative)
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(data)
        main = _inside(here, shipped.source)
        if shipped.folder:
            main.mkdir(parents=True, exist_ok=True)
        roles = [role for role, _ in job.source.files]
        local = replace(job.source, source=main, files=tuple(
            (role, _inside(here, relative)) for role, (relative, _) in zip(roles, shipped.files,
                                                                          strict=True)))
        report, clip = func(replace(job, source=local))
        return (_renamed(report, str(here), shipped.root),
                _renamed(clip, str(here), shipped.root))


def _inside(folder: Path, relative: str) -> Path:
    """``folder / relative``, refused if ``relative`` leads out of ``folder``."""
    path = (folder / relative).resolve()
    if not path.is_relative_to(folder.resolve()):
        raise ValueError(f"a shipped file's path leaves its folder: {relative!r}")
    return path


def _renamed(record, old: str, new: str):
    """A report row or prepared clip with the temporary folder's name in its text fields
    (source, reason, note) and in the text of its dicts (a clip's ``extra``: what its
    reader and the phone alignment noted) replaced by the client's folder."""
    if record is None or not is_dataclass(record):
        return record
    changes = {}
    for f in fields(record):
        value = getattr(record, f.name)
        if isinstance(value, (str, dict)):
            swapped = _swapped(value, old, new)
            if swapped != value:
                changes[f.name] = swapped
    return replace(record, **changes) if changes else record


def _swapped(value, old: str, new: str):
    """``value`` (text, or a dict or list of them, nested) with ``old`` made ``new``."""
    if isinstance(value, str):
        return value.replace(old, new)
    if isinstance(value, dict):
        return {key: _swapped(item, old, new) for key, item in value.items()}
    if isinstance(value, list):
        return [_swapped(item, old, new) for item in value]
    return value


def map_clips(client, func: Callable, jobs: Sequence, *, settle: Callable,
              keep: Callable, failed: Callable,
              progress: Callable[[Iterator], Iterator] | None = None,
              max_bytes: int = SHIP_MAX_BYTES) -> list:
    """``[func(job) for job in jobs]`` on the Dask cluster of ``client``, resumable.

    Parameters
    ----------
    client : distributed.Client
    func : callable
        A module-level function of a job returning (report row, prepared clip or None).
    jobs : sequence
        One per clip (``job.source`` a ClipSource).
    settle : callable
        ``settle(job, checksum)``: the clip's outcome without a worker, (report row,
        clip or None, cache entry or None, True if taken from the cache), or None to
        prepare it. ``checksum`` is that of the bytes read to travel (None when they
        do not: ``settle`` reads the files). Called in order, a clip at a time, as the
        cluster has room: the client reads each clip's bytes once, and holds only those
        of the clips in flight.
    keep : callable
        ``keep(job, report, clip)``: keeps a prepared clip here (the workers may not
        share this cache folder) and returns its cache entry (None: not kept).
    failed : callable
        ``failed(job, reason)``: the row of a clip whose task failed (a bug, or its worker
        died); the other clips go on.
    progress : callable, optional
        Wraps the iterator of the clips as they are decided (items as those returned).
    max_bytes : int
        Largest clip that travels as bytes (:data:`SHIP_MAX_BYTES`).

    Returns
    -------
    list
        (report, clip or None, cache entry or None, taken from the cache), in the jobs'
        order.

    Notes
    -----
    At most :data:`IN_FLIGHT_PER_THREAD` clips a worker thread are submitted at a time, the
    next as one finishes. On any exception (a Ctrl-C above all) the tasks not finished are
    cancelled and the exception propagates; what was kept stays kept.
    """
    from distributed import as_completed

    results: list = [None] * len(jobs)
    futures: dict = {}
    completed = as_completed(loop=client.loop)
    room = IN_FLIGHT_PER_THREAD * _threads(client)
    travel = not _local(client)

    def finish(future) -> tuple:
        index = futures.pop(future)
        try:
            report, clip = future.result()
        except Exception as exc:  # a bug, or a worker that died on this clip
            logger.debug("clip %s failed on its worker", jobs[index].source, exc_info=True)
            report, clip = failed(jobs[index], f"worker error: {type(exc).__name__}: {exc}"), None
        future.release()
        results[index] = report, clip, keep(jobs[index], report, clip), False
        return results[index]

    def decided() -> Iterator[tuple]:
        compiled = False
        for index, job in enumerate(jobs):
            shipped = ship(job.source, max_bytes) if travel else None
            settled = settle(job, None if shipped is None else shipped.checksum)
            if settled is not None:
                results[index] = settled
                yield settled
                continue
            if not compiled:
                _compile_once_per_host(client)
                compiled = True
            if len(futures) >= room:
                yield finish(next(completed))
            future = client.submit(run_shipped, func, job, shipped, pure=False)
            futures[future] = index
            completed.add(future)
        for future in completed:
            yield finish(future)

    try:
        for _ in progress(decided()) if progress else decided():
            pass
    except BaseException:
        with contextlib.suppress(Exception):
            client.cancel(list(futures))
        raise
    return results


def _compile_once_per_host(client) -> None:
    """:func:`ingest.workers.compile_shared_kernels` on one worker of each host, before
    the clips: the workers of one machine share its numba cache, and compiling the same
    gufunc in several of them at once can leave a cache that crashes every later call
    (numba/numba#10128); after this they only read it."""
    from ingest.workers import compile_shared_kernels

    first: dict[str, str] = {}
    for address, worker in client.scheduler_info().get("workers", {}).items():
        first.setdefault(str(worker.get("host", address)), address)
    client.gather([client.submit(compile_shared_kernels, workers=[address], pure=False,
                                 allow_other_workers=False) for address in first.values()])


def _local(client) -> bool:
    """The client's cluster is one this process started here (a ``LocalCluster``): its
    workers read the clips where they are. Sending them each clip's bytes, written to a
    temporary folder and read back, cost a local cluster CPU the process pool does not
    spend (``docs/results/speed.md``, "Ingest on Dask")."""
    from distributed import LocalCluster

    return isinstance(getattr(client, "cluster", None), LocalCluster)


def _threads(client) -> int:
    """The threads of the cluster's workers (at least 1)."""
    workers = client.scheduler_info().get("workers", {})
    return max(1, sum(int(w.get("nthreads", 1)) for w in workers.values()))
