"""The per-clip half of an ingest (:mod:`ingest.pipeline`): each clip read, checked and
prepared (:func:`work`), in this process, in a process pool or on a Dask cluster
(:func:`run_clips`), resumable: each prepared clip is kept in the cache as it is made
(:mod:`ingest.prepared_cache`), and a killed ingest run again takes those and prepares
only the others.

In the pool, each worker keeps its clips itself (the workers share this machine's cache
folder) and looks for a kept one before it reads a clip; on Dask, the client does both
(:func:`ingest.on_dask.map_clips`: its workers may not share its disks).
"""

from __future__ import annotations

import contextlib
import functools
from dataclasses import asdict, dataclass, replace
from pathlib import Path

from threadpoolctl import threadpool_limits

from db.errors import AnimeGraphError, DataError
from ingest import prepared_cache
from ingest.clip import checksum_files
from ingest.motion import head_points
from ingest.plausible import Limits, check_clip
from ingest.prepare import PreparedClip, prepare_clip
from ingest.readers import ClipSource, load
from ingest.speech.ctc import kept_on_disk
from ingest.workers import map_in_processes


@dataclass(frozen=True)
class ClipReport:
    """What happened to one clip."""

    source: str
    clip_id: str
    status: str  # added | replaced | unchanged | rejected
    reason: str = ""
    n_animes: int = 0
    segmentation: str = ""
    duration_s: float = 0.0
    note: str = ""  # e.g. implausible samples filled as dropouts (ingest.plausible)
    lag_estimate_s: float | None = None  # lip-audio lag found (s, + = lips lead), ingest.lag
    lag_confidence: float | None = None  # correlation at its peak
    lag_margin: float | None = None  # ... minus the best side peak's
    lag_basis: str = ""  # pooled over N clips | own | not identifiable
    lag_applied_s: float | None = None  # the shift applied (0: none)


@dataclass(frozen=True)
class ClipJob:
    """One clip for a worker to read and prepare (:func:`work`).

    ``known``: the database's clips, (corpus, clip id) -> checksum (an unchanged one is
    not read); ``fps``: the frame rate to resample to (None: the clip's own);
    ``reference``: the head-pose reference; ``schema``: the channels a clip must have
    (the database's), None to take any; ``db``: the database's folder (a kept clip is
    taken by an ingest into the same one: the same ingest run again).
    """

    source: object
    known: dict
    fps: float | None
    reference: object
    engine: str | None
    limits: Limits | None
    posteriorgrams: bool
    schema: object = None
    db: str = ""  # the database it goes into: its prepared clip is kept for that one


def work(job: ClipJob):
    """Worker: read one clip and prepare it unless the database already has it (the phone
    model's outputs kept in the cache, as tracking is: :func:`ingest.speech.ctc.kept_on_disk`)."""
    with kept_on_disk():
        return _prepare_source(job)


def _prepare_source(job: ClipJob):
    source, known, fps, reference, engine, limits, posteriorgrams, schema = (
        job.source, job.known, job.fps, job.reference, job.engine, job.limits,
        job.posteriorgrams, job.schema)
    try:
        # Every reader's checksum is that of the clip's files in role order: an unchanged
        # clip is known before it is read (a video is not decoded, nor its audio aligned).
        key = (source.corpus, source.clip_id)
        if key in known and known[key] == _checksum(source):
            return ClipReport(str(source.path), source.clip_id, "unchanged"), None
        raw = load(source)
        if known.get((raw.corpus, raw.clip_id)) == raw.checksum:
            return ClipReport(str(source.path), raw.clip_id, "unchanged"), None
        # Before the checks and the phones (16 s of recognition for a 112 s FACEGOOD clip
        # that would then be rejected): a clip's channels must be the database's.
        if schema is not None and raw.schema != schema:
            raise DataError(raw.schema.difference(schema))
        raw, note = check_clip(raw, limits)
        clip = prepare_clip(raw, fps=fps,
                            head_reference=reference if has_head(raw.schema) else None,
                            phones_engine=engine, posteriorgrams=posteriorgrams)
        status = "replaced" if (raw.corpus, raw.clip_id) in known else "added"
        note = clip_note(note, clip)
        report = ClipReport(str(source.path), raw.clip_id, status, n_animes=len(clip.phones),
                            segmentation=clip.segmentation, duration_s=round(clip.duration, 3),
                            note=note)
        return report, clip
    except AnimeGraphError as exc:  # bad data or an unusable transcript: reject the clip
        return ClipReport(str(source.path), source.clip_id, "rejected", reason=str(exc)), None


def clip_note(checked: str, clip: PreparedClip) -> str:
    """The clip's line in the report: the plausibility check's note, then what the
    reader and the phone alignment had to make do with."""
    notes = [checked]
    gaps = clip.extra.get("frames_without_face", 0)
    if gaps:
        notes.append(f"no face in {gaps} frames (filled as gaps)")
    notes.append(clip.extra.get("transcript_fallback", ""))
    notes.append(clip.extra.get("transcript_doubt", ""))
    return "; ".join(n for n in notes if n)


def _checksum(source: ClipSource) -> str | None:
    try:
        return checksum_files(source.paths)
    except OSError:
        return None  # load() says what is wrong with the file


def run_clips(found, known, fps, config, workers, progress, reference, schema=None, *,
              client=None, cluster=None, keep: Path | None = None):
    """Prepare each clip of ``found`` (see :func:`_prepare_source`): in this process, in
    ``workers`` processes, or on the Dask cluster of ``client`` (or of ``cluster()``, a
    context manager yielding a client: left, and so a local cluster closed, once the
    clips are prepared). ``schema``: the channels a clip must have (the database's), None
    to take any. ``keep``: the database's folder, to be resumable: each prepared clip is
    kept in the cache (:mod:`ingest.prepared_cache`) and those an earlier ingest into it
    kept are taken from there.

    Returns (one (report, clip or None) a clip, the cache entries of the prepared clips,
    how many were taken from the cache)."""
    jobs = [ClipJob(s, {k: known[k] for k in [(s.corpus, s.clip_id)] if k in known}, fps,
                    reference, config.phones_engine, config.limits, config.posteriorgrams,
                    schema, str(Path(keep).resolve()) if keep else "") for s in found]
    wrap = progress(len(jobs)) if progress else None
    if keep is None and client is None and cluster is None:
        results = [(*done, None, False) for done in _map(work, jobs, workers, wrap)]
    else:
        bound = prepared_cache.Bound()

        def noted(done):  # in the writer, as each clip is decided: the folder bounded
            for row in done:
                if row[2] is not None:
                    bound.used(row[2])
                yield row

        def watched(done):
            return wrap(noted(done)) if wrap else noted(done)

        if client is None and cluster is None:
            results = _map(_work_kept, jobs, workers, watched)
        else:
            from ingest.on_dask import map_clips

            with contextlib.nullcontext(client) if client is not None else cluster() as on:
                results = map_clips(
                    on, work, jobs, settle=_settle, keep=_keep, progress=watched,
                    failed=lambda job, reason: ClipReport(str(job.source.path),
                                                          job.source.clip_id, "rejected",
                                                          reason=reason))
    return ([(report, clip) for report, clip, _, _ in results],
            [key for _, _, key, _ in results if key is not None],
            sum(resumed for *_, resumed in results))


def _map(func, jobs, workers, progress):
    if workers == 1 or len(jobs) == 1:
        # One native thread, as a pool worker has (ingest.workers): a clip's arrays are
        # small, and BLAS threads on every core spin more than they compute (the 800 GRID
        # clips cost 84 CPU-s here against 51 in a pool of 2, docs/results/speed.md,
        # "Ingest on Dask"). Only meanwhile: the writer's decomposition is one large
        # product that does use the cores.
        with threadpool_limits(limits=1):
            results = map(func, jobs)
            return list(progress(results) if progress else results)
    return map_in_processes(func, jobs, workers=workers, chunksize=4, progress=progress)


def _work_kept(job: ClipJob):
    """Worker: :func:`work`, resumable. Returns (report, clip or None, its cache entry or
    None, True if an earlier run had kept it)."""
    settled = _settle(job)
    if settled is not None:
        return settled
    report, clip = work(job)
    return report, clip, _keep(job, report, clip), False


def _settle(job: ClipJob, checksum: str | None = None):
    """A clip decided without preparing it, as :func:`_work_kept` returns it: unchanged
    in the database, or prepared by an earlier run and kept; None otherwise.
    ``checksum``: of its files, if read already."""
    source = job.source
    checksum = checksum or _checksum(source)
    if checksum is None:  # unreadable: its reader says why
        return None
    if job.known.get((source.corpus, source.clip_id)) == checksum:
        return ClipReport(str(source.path), source.clip_id, "unchanged"), None, None, False
    key = _entry(job, checksum)
    kept = prepared_cache.load(key)
    if kept is None:
        return None
    clip, row = kept  # its row says what the database held when it was kept
    row = replace(ClipReport(**row), status="replaced" if clip.key in job.known else "added")
    return row, clip, key, True


def _keep(job: ClipJob, report: ClipReport, clip: PreparedClip | None) -> str | None:
    """Keep a prepared clip in the cache, under the entry of the bytes it was read from;
    returns the entry (None: nothing kept)."""
    if clip is None:
        return None
    key = _entry(job, clip.checksum)
    prepared_cache.save(key, clip, asdict(report))
    return key


def _entry(job: ClipJob, checksum: str) -> str:
    """The cache entry of ``job``'s clip with these bytes: every setting its preparation
    depends on (:func:`ingest.prepared_cache.entry_key`), and the clip's own name and path
    (two clips of the same bytes, a copied folder, are two entries: each row says its own
    clip, and the copy is then rejected as one)."""
    source = job.source
    settings = {"version": package_version(), "db": job.db,
                "clip": [source.corpus, source.clip_id, str(source.path)], "fps": job.fps,
                "engine": job.engine, "limits": job.limits.to_entry() if job.limits else None,
                "posteriorgrams": job.posteriorgrams,
                "schema": None if job.schema is None else asdict(job.schema)}
    return prepared_cache.entry_key(checksum, settings, job.reference)


def has_head(schema) -> bool:
    """The clip's points have a head (at least 3 points) to take its pose from."""
    return schema.kind in ("markers", "landmarks") and head_points(schema.groups) >= 3


@functools.cache  # once a process: asked for every clip's cache entry
def package_version() -> str:
    """animegraph's version (a new one prepares clips anew)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("animegraph")
    except PackageNotFoundError:
        return "unknown"
