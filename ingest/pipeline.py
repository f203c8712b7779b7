"""``animegraph ingest``: source folders in, a new version of the motion database out.

1. Find the clips under the sources (:func:`ingest.readers.discover`).
2. Per clip, in worker processes: read it, skip it if the database already has it with
   the same checksum, else check that it is plausible (labels, phones, motion:
   :mod:`ingest.plausible`; implausible samples become dropouts or the clip is rejected)
   and prepare it (:func:`ingest.prepare.prepare_clip`). A clip that fails is rejected
   with its reason; the others go on.
3. If anything was added or changed: the clips already in the database and the new ones
   are decomposed together (PCA keeping 95 % of the variance, then FastICA over the
   whole corpus, Cao et al. §4.1 and §5.1.2), the per-component low-pass cutoffs are
   learned (§4.3), the emotion model is learned (speech/emotion components, emotion
   mappings and the speech emotion classifier, §5-6, :mod:`ingest.emotion.model`), the
   anime nodes are built, and a new database version is written atomically
   (:func:`db.store.write_version`).
   A database written before emotion models existed is rebuilt from its own clips even
   when nothing changed, so that it gets one.
4. A report (one row per clip: added, replaced, unchanged or rejected, with the reason)
   is returned, and saved beside the database.
"""

from __future__ import annotations

import csv
import io
import logging
import os
import time
from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from db.atomic import atomic_write
from db.errors import DataError, ParameterError
from db.lock import LOCK_NAME, writer_lock
from db.store import (
    ANY_VERSION,
    WRITE_WAIT_S,
    Database,
    is_database,
    is_staging,
    own_folder,
    write_version,
)
from ingest import prepared_cache
from ingest.clip import checksum_files, stored_schema
from ingest.decompose import (
    ENERGY_KEPT,
    VARIANCE_KEPT,
    MotionDecomposer,
    cutoff_frequencies,
    pcs_of_clips,
)
from ingest.emotion.model import fit_emotion_model, stored_model_current
from ingest.lag import decide_lags
from ingest.motion import fill_gaps
from ingest.per_clip import ClipReport, has_head, package_version, run_clips
from ingest.plausible import Limits, check_clip
from ingest.prepare import MIN_LAG_CORRECTED_S, PreparedClip
from ingest.readers import ClipSource, discover, load
from ingest.readers.sync import MIN_EVIDENCE_S, MIN_PEAK_MARGIN
from ingest.tables import build_tables, prepared_from_database, stored_limits

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class IngestConfig:
    """Settings of an ingest; the defaults are the paper's."""

    variance: float = VARIANCE_KEPT  # PCA variance kept (§4.1: 95 %)
    energy: float = ENERGY_KEPT  # energy below each component's cutoff (§4.3: 99 %)
    fps: float | None = None  # database frame rate (default: the existing database's, else
    #                           the highest among the new clips)
    # Shift landmark / Live Link motion by its lip-audio lag where identifiable.
    correct_lag: bool = True
    pool_lag: bool = True  # lag per speaker/session, pooled (ingest.lag); False: per clip
    random_state: int = 0  # FastICA seed
    phones_engine: str | None = None  # ingest.speech.engines.ENGINES (None: the default)
    # Store each clip's phone posteriorgram (hama installed; beyond the paper, for synth
    # --audio-cost posteriorgram): about 0.08 CPU-s per second of speech when hama has not
    # recognised the phones already. Off by default: the posteriorgram cost did not measure
    # better than the paper's (docs/results/lipsync.md, "Choices inside the default"); on when the
    # database has them.
    # Clips whose phones hama recognised keep theirs in any case (prepare_clip): it costs
    # nothing, and ppg-ridge's fit then need not hear them again.
    posteriorgrams: bool = False
    # Plausibility limits of the new clips (ingest.plausible; --max-speed). None: the
    # database's, those its clips were added with (ingest.tables.stored_limits), else the
    # defaults. A database keeps the loosest its clips were added with.
    limits: Limits | None = None


@dataclass
class IngestReport:
    """What an ingest did."""

    db: Path
    clips: list[ClipReport] = field(default_factory=list)
    written: bool = False
    version: str | None = None
    seconds: float = 0.0
    summary: dict = field(default_factory=dict)
    resumed: int = 0  # prepared clips an unfinished distributed ingest had kept (resume)

    def count(self, status: str) -> int:
        return sum(1 for c in self.clips if c.status == status)

    def lines(self) -> list[str]:
        """A short human summary, rejected clips with their reasons."""
        head = (f"{self.count('added')} added, {self.count('replaced')} replaced, "
                f"{self.count('unchanged')} unchanged, {self.count('rejected')} rejected "
                f"in {self.seconds:.1f} s")
        out = [head]
        if self.resumed:
            out.append(f"  {_clips(self.resumed)} prepared by an unfinished ingest, taken "
                       "from the cache")
        for c in self.clips:
            if c.status == "rejected":
                out.append(f"  rejected {c.source}: {c.reason}")
            elif c.note:
                out.append(f"  {c.status} {c.source}: {c.note}")
        out += self._lag_lines()
        if self.written:
            s = self.summary
            out.append(f"database {self.db} is now {self.version}: {_clips(s['n_clips'])}, "
                       f"{s['n_animes']} animes, {s['duration_s'] / 60:.1f} min, "
                       f"{s['n_pcs']} principal / independent components "
                       f"({100 * s['variance_kept']:.1f} % of the variance)")
            e = s.get("emotion")
            if e:
                clf = e["classifier"]
                ids = " ".join(map(str, e["emotion_components"]))
                which = f"emotion components {ids}" if ids else "no emotion components"
                out.append(f"emotion: {which}, "
                           f"{len(e['mappings'])} emotion mappings, "
                           + (f"classifier over {len(clf['classes'])} emotions" if clf
                              else "no classifier"))
        else:
            out.append(f"database {self.db} unchanged")
        return out

    def _lag_lines(self) -> list[str]:
        """One line per lip-audio lag decision shared by clips (ingest.lag)."""
        groups: dict[tuple, list[ClipReport]] = {}
        for c in self.clips:
            if c.lag_basis:
                groups.setdefault((c.lag_basis, bool(c.lag_applied_s)), []).append(c)
        out = []
        for (basis, applied), rows in groups.items():
            lags = sorted(r.lag_estimate_s for r in rows)
            found = (f"{lags[0]:+.3f} s" if lags[0] == lags[-1]
                     else f"{lags[0]:+.3f} to {lags[-1]:+.3f} s")
            first = rows[0]
            detail = (f", r {first.lag_confidence:.2f}, margin {first.lag_margin:.2f}"
                      if len(rows) == 1 or lags[0] == lags[-1] else "")
            out.append(f"lip-audio lag {found} ({basis}{detail}): "
                       + (f"applied to {_clips(len(rows))}" if applied else
                          f"not applied to {_clips(len(rows))} ({_not_applied(basis, rows)})"))
        return out

    def to_csv(self) -> str:
        buffer = io.StringIO()
        names = list(ClipReport.__dataclass_fields__)
        writer = csv.DictWriter(buffer, fieldnames=names)
        writer.writeheader()
        for c in self.clips:
            writer.writerow(asdict(c))
        return buffer.getvalue()


def ingest(
    sources: Sequence[str | os.PathLike],
    db_path: str | os.PathLike,
    config: IngestConfig | None = None,
    *,
    workers: int = 1,
    progress: Callable[[int], Callable] | None = None,
    say: Callable[[str], object] | None = None,
    wait: float = WRITE_WAIT_S,
    client=None,
    cluster: Callable[[], AbstractContextManager] | None = None,
) -> IngestReport:
    """Ingest clips found under ``sources`` into the database at ``db_path``.

    Parameters
    ----------
    sources : sequence of path
        Files or folders holding clips of any supported kind.
    db_path : path
        Database folder; created if absent.
    config : IngestConfig, optional
    workers : int
        Processes preparing clips in parallel.
    progress : callable, optional
        ``progress(total)`` returns a wrapper for an iterable of finished clips.
    say : callable, optional
        Receives a line naming each corpus-wide step after the clips are read
        (decomposition, emotion model, writing), which take most of a large ingest.
    wait : float
        Seconds to wait for another writer of the database to finish. The database's
        writer lock is held for the whole ingest, so that two ingests into one
        database run one after the other and neither loses the other's clips.
    client : distributed.Client, optional
        Prepare the clips on this Dask cluster instead (``workers`` is then unused):
        resumable, and the clips' bytes travel to the workers (:mod:`ingest.on_dask`).
        This process alone writes the database.
    cluster : callable, optional
        Instead of ``client``: ``cluster()`` is a context manager that yields a
        ``distributed.Client``; entered once the clips to prepare are known and left
        (a local cluster closed) as soon as they are prepared, before the writer's part
        (decomposition, emotion model, writing), which runs in this process alone: a
        cluster left up meanwhile spends CPU on its heartbeats for nothing.

    Raises
    ------
    ParameterError
        If a source does not exist, nothing ingestable is found, ``db_path`` is
        something else than a database, or every clip is rejected.
    DataError
        If another process is still writing the database after ``wait`` seconds.
    """
    config = config or IngestConfig()
    started = time.perf_counter()
    db_path = Path(db_path)
    for s in sources:
        if not Path(s).exists():
            raise ParameterError(f"source {s} does not exist")
    if workers < 1:
        raise ParameterError(f"workers must be >= 1, got {workers}")
    # Checked before the lock is taken (not to leave a lock file in a folder of something
    # else), and again under it; a folder holding our lock file is a database being made.
    if db_path.exists() and not is_database(db_path) and (
            not db_path.is_dir() or not (db_path / LOCK_NAME).exists() and _foreign(db_path)):
        raise ParameterError(f"--db {db_path} exists and is not an animegraph database")
    # What the sources hold is checked before the database is touched (or made).
    found = discover([Path(s) for s in sources])
    if not found:
        raise ParameterError("no clips found under " + ", ".join(str(s) for s in sources))
    _check_tracker(found)
    made = not db_path.exists()
    try:
        with writer_lock(db_path, wait=wait, what="database"):
            return _ingest_locked(found, db_path, config, workers, progress, started, say,
                                  client, cluster)
    except BaseException:  # an interrupt too: a first ingest that fails leaves no folder
        if made:
            _remove_unmade(db_path)
        raise


def _remove_unmade(folder: Path) -> None:
    """Remove the folder a first ingest made if it holds nothing but the lock file.

    Another ingest into the same new folder, started meanwhile and waiting for the lock
    (``wait`` > 0), then fails to write and says so: nothing is lost.
    """
    try:
        if [p.name for p in folder.iterdir()] == [LOCK_NAME]:
            (folder / LOCK_NAME).unlink()
            folder.rmdir()
    except OSError:
        pass


def _ingest_locked(found: list[ClipSource], db_path: Path, config: IngestConfig, workers: int,
                   progress, started: float, say: Callable[[str], object] | None,
                   client=None, cluster=None) -> IngestReport:
    existing: Database | None = None
    if is_database(db_path):
        existing = Database.open(db_path)
    elif _foreign(db_path):
        raise ParameterError(f"--db {db_path} exists and is not an animegraph database")
    based_on = existing.version_dir.name if existing is not None else None

    known: dict[tuple[str, str], str] = {}
    fps = config.fps
    reference = None
    # A database written before it kept its limits: its clips went in with --max-speed
    # as given again, else the defaults.
    stored = stored_limits(existing, config.limits) if existing is not None else Limits()
    config = replace(config, limits=config.limits or stored)
    # What the next version keeps: limits its stored clips and the new ones all pass.
    written = replace(config, limits=config.limits.loosest(stored))
    if existing is not None:
        reference = existing.arrays().get("head_reference")
        clips = existing.table("clips", columns=["corpus", "clip_id", "checksum"]).to_pylist()
        known = {(c["corpus"], c["clip_id"]): c["checksum"] for c in clips}
        fps = existing.manifest["fps"]
        if "posteriors" in existing.columns("animes") and not config.posteriorgrams:
            # A database that stores posteriorgrams keeps them for the clips added to it.
            # (The animes table has them only then; the clips table always has the column.)
            config = replace(config, posteriorgrams=True)
        if config.fps is not None and config.fps != fps:
            raise ParameterError(f"--fps {config.fps} differs from the database's {fps} fps")

    if reference is None:
        reference = _head_reference(found, config.limits)
    report = IngestReport(db=db_path)
    schema = stored_schema(existing) if existing is not None else None
    results, kept_keys, report.resumed = run_clips(found, known, fps, config, workers, progress,
                                              reference, schema, client=client, cluster=cluster,
                                              keep=db_path)
    new: list[PreparedClip] = []
    for clip_report, clip in results:
        report.clips.append(clip_report)
        if clip is not None:
            new.append(clip)
    new = _drop_copies(new, known, report)

    if new:
        kept = []
        if existing is not None:
            replaced = {c.key for c in new}
            kept = [c for c in prepared_from_database(existing, stored)
                    if c.key not in replaced]
        new = decide_lags(new, kept, correct=config.correct_lag, pooled=config.pool_lag)
        _report_lags(report, new)
        target_fps = fps or max(c.fps for c in new)
        new = [_at_fps(c, target_fps) for c in new]
        everything = _consistent(kept, new, report)
        if everything:
            _write(db_path, everything, written, target_fps, report, reference, based_on,
                   say)
    elif existing is not None and not stored_model_current(existing.manifest):
        # Written before emotion models existed, or before this version's classifier:
        # learn it now from the stored clips.
        _write(db_path, prepared_from_database(existing, stored), written, fps, report,
               reference, based_on, say)
    report.seconds = time.perf_counter() - started
    _save_report(db_path, report)
    # Every clip is decided now (in the database, or rejected): what was kept is not needed.
    prepared_cache.remove(kept_keys)
    if not report.written and report.count("rejected") == len(report.clips):
        raise ParameterError(f"every clip was rejected ({len(report.clips)}); first: "
                             f"{report.clips[0].source}: {report.clips[0].reason}")
    return report


def _foreign(folder: Path) -> bool:
    """True if ``folder`` holds anything but a writer's lock and staging folders."""
    return any(p.name != LOCK_NAME and not is_staging(p.name) for p in folder.iterdir())


def _check_tracker(found: Sequence[ClipSource]) -> None:
    """One line, not one rejection a clip, when videos need the tracker and it is absent."""
    from ingest.readers.video import TRACKER_HINT, cache_path, tracker_available

    videos = [s for s in found if s.layout == "video"]
    # Importing the tracker takes seconds: only when a video is not tracked yet.
    if any(not cache_path(checksum_files([s.source])).is_file() for s in videos) and \
            not tracker_available():
        raise ParameterError(TRACKER_HINT)


def prepare_sources(
    found: Sequence[ClipSource], config: IngestConfig | None = None, *, workers: int = 1,
) -> tuple[list[PreparedClip], np.ndarray | None]:
    """Prepare clips without a database: (the usable clips at one frame rate, head reference).

    Rejected clips are logged and left out; a clip's note (what it made do with, as on
    its line in ingest's report) is logged too.
    """
    config = config or IngestConfig()
    _check_tracker(found)
    reference = _head_reference(list(found), config.limits)
    results, _, _ = run_clips(list(found), {}, config.fps, config, workers, None, reference)
    clips = decide_lags([c for r, c in results if c is not None], correct=config.correct_lag,
                        pooled=config.pool_lag)
    for r, _ in results:  # what ingest's report would say of each clip
        if r.status == "rejected":
            logger.warning("rejected %s: %s", r.source, r.reason)
        elif r.note:
            logger.warning("%s: %s", r.source, r.note)
    if not clips:
        raise ParameterError("no usable clips")
    fps = config.fps or max(c.fps for c in clips)
    return [_at_fps(c, fps) for c in clips], reference


def _drop_copies(new: list[PreparedClip], known: dict[tuple[str, str], str],
                 report: IngestReport) -> list[PreparedClip]:
    """``new`` without the clips whose files are byte for byte another clip's, in the
    database or earlier in ``new`` (a copied folder ingested again): each is rejected on
    its report row. A recording in twice would be two of k-best's candidates, and its
    animes two votes, for one take."""
    replaced = {c.key for c in new}
    owner = {checksum: key for key, checksum in known.items() if key not in replaced}
    rows = {(r.source, r.clip_id): k for k, r in enumerate(report.clips)}
    kept = []
    for clip in new:
        first = owner.setdefault(clip.checksum, clip.key) if clip.checksum else clip.key
        if first == clip.key:
            kept.append(clip)
            continue
        k = rows[(clip.source, clip.clip_id)]
        report.clips[k] = ClipReport(clip.source, clip.clip_id, "rejected",
                                     reason=f"the same recording as {'/'.join(first)} "
                                            "(identical files)")
    return kept


def _report_lags(report: IngestReport, clips: list[PreparedClip]) -> None:
    """Copy each clip's lag decision (:func:`ingest.lag.decide_lags`) into its report row."""
    decided = {(c.source, c.clip_id): c.extra for c in clips if "lag_basis" in c.extra}
    for k, row in enumerate(report.clips):
        extra = decided.get((row.source, row.clip_id))
        if extra is not None:
            report.clips[k] = replace(
                row, lag_estimate_s=extra["lag_estimate_s"],
                lag_confidence=extra["lag_estimate_confidence"],
                lag_margin=extra["lag_estimate_margin"], lag_basis=extra["lag_basis"],
                lag_applied_s=extra["lag_corrected_s"])


def _head_reference(found: list[ClipSource], limits: Limits | None) -> np.ndarray | None:
    """The head frame of a new database: its first plausible clip's mean head pose.

    Rest positions from the corpus' ``markers.csv`` would do as well; the mean pose of
    one clip needs nothing but the clip.
    """
    for source in found:
        if source.kind == "curves":  # no points, no head frame: not worth reading
            return None
        try:
            raw, _ = check_clip(load(source), limits)
        except DataError:
            continue
        if not has_head(raw.schema):
            return None
        filled, _ = fill_gaps(raw.motion, raw.schema.names)
        pts = filled.reshape(len(filled), -1, 3)
        return pts[:, np.asarray(raw.schema.groups[::3]) == "head"].mean(axis=0)
    return None


def _at_fps(clip: PreparedClip, fps: float) -> PreparedClip:
    """Clips prepared before the database's rate was known are brought to it here."""
    if clip.fps == fps:
        return clip
    from ingest.motion import resample_motion

    motion = resample_motion(clip.motion, clip.fps, fps).astype(np.float32)
    missing = resample_motion(clip.missing.astype(np.float64), clip.fps, fps) > 0.5
    return replace(clip, motion=motion, missing=missing, fps=fps)


def _consistent(kept: list[PreparedClip], new: list[PreparedClip],
                report: IngestReport) -> list[PreparedClip]:
    """Drop new clips whose channels differ from the database's (or the first clip's)."""
    reference = kept[0].schema if kept else new[0].schema
    out = list(kept)
    by_id = {(r.clip_id, r.source): r for r in report.clips}
    for clip in new:
        if clip.schema == reference:
            out.append(clip)
            continue
        reason = clip.schema.difference(reference)
        old = by_id[(clip.clip_id, clip.source)]
        report.clips[report.clips.index(old)] = ClipReport(old.source, old.clip_id,
                                                           "rejected", reason=reason)
    return out if len(out) > len(kept) else []


def _write(db_path: Path, clips: list[PreparedClip], config: IngestConfig, fps: float,
           report: IngestReport, reference: np.ndarray | None, based_on: str | None,
           say: Callable[[str], object] | None = None) -> None:
    summary, version_dir = build_database(db_path, clips, config, fps=fps, reference=reference,
                                          based_on=based_on, say=say)
    report.written = True
    report.version = version_dir.name
    report.summary = summary


def build_database(
    db_path: str | os.PathLike, clips: Sequence[PreparedClip], config: IngestConfig | None = None,
    *, fps: float | None = None, reference: np.ndarray | None = None,
    say: Callable[[str], object] | None = None,
    based_on: str | None | object = ANY_VERSION,
) -> tuple[dict, Path]:
    """Decompose prepared clips together and write them as a new database version.

    The corpus-wide half of an ingest (PCA keeping ``config.variance`` then FastICA over
    all clips, §4.1/§5.1.2; per-component cutoffs, §4.3; anime nodes), usable on its own
    to build databases from clips prepared once (e.g. the folds of an evaluation).
    ``based_on`` is passed to :func:`db.store.write_version`.

    Returns
    -------
    (summary, version folder)
    """
    config = config or IngestConfig()
    clips = list(clips)
    if not clips:
        raise ParameterError("no clips to build a database from")
    fps = fps or clips[0].fps
    say = say or (lambda _line: None)
    say(f"ingest: decomposing the motion of {_clips(len(clips))} (PCA, then FastICA) ...")
    motion = np.concatenate([c.motion for c in clips]).astype(np.float64)
    model = MotionDecomposer(variance=config.variance, random_state=config.random_state)
    model.fit(motion)
    del motion
    pcs = pcs_of_clips(model, [c.motion for c in clips])
    sources = [model.sources_from_pcs(p) for p in pcs]
    cutoffs = cutoff_frequencies(sources, fps, energy=config.energy)
    extra_arrays = {} if reference is None else {"head_reference": reference}
    say("ingest: learning the emotion model (components, mappings, classifier) ...")
    emotion = fit_emotion_model(
        sources, [c.motion for c in clips], [c.emotion for c in clips],
        [c.sentence_id for c in clips], [(c.audio, c.sample_rate) for c in clips],
        model.mixing_.T @ model.components_, clips[0].schema.groups, fps,
        random_state=config.random_state, speakers=[c.speaker for c in clips],
        classifier_rows=[c.emotion_features for c in clips])
    emotion_arrays, emotion_entry, emotion_columns = emotion.to_database()
    say("ingest: building the anime nodes and writing the database ...")
    tables = build_tables(clips, model, cutoffs, arrays={**extra_arrays, **emotion_arrays},
                          component_columns=emotion_columns, pcs=pcs)
    emotions: dict[str, int] = {}
    for c in clips:
        emotions[c.emotion] = emotions.get(c.emotion, 0) + 1
    summary = {
        "animegraph_version": package_version(), "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "kind": clips[0].schema.kind, "fps": fps, "n_channels": clips[0].schema.n_channels,
        "n_clips": len(clips), "n_animes": tables["animes"].num_rows,
        "n_frames": tables["frames"].num_rows,
        "duration_s": round(sum(c.duration for c in clips), 3),
        "clips_per_emotion": dict(sorted(emotions.items())),
        "corpora": sorted({c.corpus for c in clips}),
        "n_pcs": model.n_pcs_, "variance_kept": float(model.explained_variance_ratio_.sum()),
        "variance_target": config.variance, "energy_target": config.energy,
        "ica_converged": bool(model.ica_converged_),
        "emotion": emotion_entry,
        "limits": (config.limits or Limits()).to_entry(),
    }
    return summary, write_version(db_path, tables, summary, based_on=based_on)


def _save_report(db_path: Path, report: IngestReport) -> None:
    if not is_database(db_path):  # nothing written into a new folder: leave it empty
        return
    try:
        folder = own_folder(db_path, "reports")
    except DataError as exc:  # the clips are in: only the report is not kept
        logger.warning("%s: the ingest report is not saved", exc)
        return
    folder.mkdir(exist_ok=True)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    with atomic_write(folder / f"ingest-{stamp}-{os.getpid()}.csv") as handle:
        handle.write(report.to_csv().encode())


def _not_applied(basis: str, rows: list[ClipReport]) -> str:
    """Why a lag was not applied to ``rows`` (ingest.lag.decide_lags' rules)."""
    if basis == "not identifiable":
        if min(r.lag_margin for r in rows) >= MIN_PEAK_MARGIN:
            return (f"less than {MIN_EVIDENCE_S:g} s of audio to tell its peak from the side "
                    "peaks a syllable away")
        return f"its peak beats the side peaks by less than {MIN_PEAK_MARGIN:g}"
    if all(abs(r.lag_estimate_s) < MIN_LAG_CORRECTED_S for r in rows):
        return f"under the {1000 * MIN_LAG_CORRECTED_S:.0f} ms worth correcting"
    return "lag correction is off"


def _clips(n: int) -> str:
    return f"{n} clip" if n == 1 else f"{n} clips"

