"""``animegraph batch``: a dialogue script in, a folder of animated lines out (issue #7).

Every line of the script (:mod:`animegraph.apps.script`) becomes a folder ``OUT/<id>/``:

- ``speech.wav``: the speech used (the recording, or eSpeak NG's speech);
- the motion, in each of ``motion_formats`` (``motion.c3d``, ``motion.csv``, ``motion.npz``,
  ``motion.livelink.csv``: what ``synth -o`` writes, by the same function), by default
  ``motion.c3d`` (marker databases), ``motion.livelink.csv`` (ARKit databases: Live Link
  Face CSV) or ``motion.csv`` (landmark databases, whose head pose C3D has no place for;
  other curves): :func:`animegraph.motion.files.motion_suffix`;
- ``phones.csv``: the phone timing the motion was made for;
- ``explain.json``: where every phone's motion came from and what it cost (the record of
  ``synth --explain-json``), with the line's inputs;
- ``preview.mp4`` with ``--render mp4``, rendered from the motion file;
- ``done.json``: the line's report row, the key of its inputs and the key of its render.

Lines without a recording are spoken by eSpeak NG with the emotion's prosody preset and
the phone timing comes straight from the synthesizer's events (no alignment); lines with
a recording are force-aligned to their text. The lines run in parallel on Dask
distributed: a local cluster of ``workers`` processes by default, or an existing cluster
at ``scheduler``. Each worker process loads the Anime Graph once (:func:`worker_model`).

A line is made in two steps, each with its own key in ``done.json``. Its motion (and
speech, phones, explanation) depends on the line's inputs, the recording's bytes, the
database version and the motion formats (:func:`line_key`); its preview on that motion and
the render options (:func:`render_key`). A line whose motion key matches is not
synthesized again unless ``force``: if its preview is missing or was rendered otherwise,
it is only rendered again from the stored motion (status ``rendered``), and turning
``render`` off keeps a preview there is. A recording that went as speech alone (its
transcript did not fit) is remade also when the stored guide it had (or lacked) has
changed since. Every file is written to a temporary name and renamed; ``done.json`` and
the files of the earlier run are removed before a line is synthesized again, and its
render key before it is rendered again, so an interrupted batch never leaves a line
whose files look finished but are not. A failing line records its reason in
``OUT/report.csv`` and the others go on; the report is rewritten as lines finish (every
:data:`REPORT_EVERY_S` at most), so that a batch killed outright leaves one that is
nearly current. One batch at a time writes into an output
folder (an OS lock, :func:`db.lock.writer_lock`); a second one fails with one line.
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import logging
import multiprocessing
import os
import stat
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path

from animegraph import __version__
from animegraph.apps.script import EmotionSpec, ScriptLine, read_script
from animegraph.motion.files import LIVELINK_SUFFIX, channels_left_out
from db.atomic import atomic_write
from db.errors import AnimeGraphError, DataError, ParameterError
from db.lock import lock_path, writer_lock
from db.store import Database, current_version
from ingest.readers.common import read_json_object
from ingest.workers import sigint_ignored_by_children

#: Longest wait for a local cluster's workers to start (a bound against a hang).
WORKER_START_TIMEOUT_S = 300.0

logger = logging.getLogger(__name__)

#: Version of the per-line layout and key; a change redoes every line.
FORMAT = 2
DONE = "done.json"
RENDER_MODES = ("none", "mp4")
PREVIEW = "preview.mp4"
#: ``motion_formats`` a batch writes, and the ending of their files (``synth -o``'s).
MOTION_FORMATS = {"c3d": ".c3d", "csv": ".csv", "npz": ".npz", "livelink": LIVELINK_SUFFIX}
#: Every file a line's folder holds from a run: removed before it is made again, so that
#: no file of an earlier run (another motion format, a preview) is taken for this one's.
LINE_FILES = ("speech.wav", "phones.csv", "explain.json", PREVIEW,
              *(f"motion{suffix}" for suffix in MOTION_FORMATS.values()))
#: Columns of ``OUT/report.csv``.
REPORT_COLUMNS = ("id", "status", "speaker", "speech", "path", "duration_s", "emotion",
                  "emotion_source", "motion_emotions", "jumps", "cost", "seconds",
                  "cpu_seconds", "warnings", "error")
#: Lines made with warnings that the summary names (the report has them all).
WARNINGS_SHOWN = 10
#: Seconds to wait for an existing scheduler (and for it to have a worker).
CONNECT_TIMEOUT_S = 5.0
#: Seconds between rewrites of ``report.csv`` while lines finish: a batch killed (SIGKILL,
#: a lost machine) leaves a report this old at most, and a long batch does not rewrite
#: its whole report at every line.
REPORT_EVERY_S = 2.0
#: The worked example shipped with the package: a tutor and a student, six lines.
EXAMPLE_SCRIPT = Path(__file__).resolve().parent / "examples" / "dialogue.csv"


class LineError(AnimeGraphError):
    """One line cannot be made; the batch goes on."""


class BatchInterrupted(KeyboardInterrupt):
    """A Ctrl-C stopped the batch: ``result`` is what it had done (its report written)."""

    def __init__(self, result: BatchResult):
        super().__init__()
        self.result = result


class NotStarted(DataError):
    """The cluster could not be had: no line ran, and the batch leaves nothing behind."""


@dataclass(frozen=True)
class BatchOptions:
    """How to run a batch (see ``animegraph batch --help``)."""

    db: Path
    out: Path
    workers: int = 2
    scheduler: str | None = None
    render: str = "none"
    force: bool = False
    connect_timeout: float = CONNECT_TIMEOUT_S
    #: Names in :data:`MOTION_FORMATS`; empty: the database's own (:func:`motion_files`).
    motion_formats: tuple[str, ...] = ()


@dataclass(frozen=True)
class LineTask:
    """What a worker needs to make one line (plain data: it travels to the worker)."""

    line: ScriptLine
    db: str
    db_version: str
    folder: str
    render: str
    key: str
    motion_files: tuple[str, ...] = ("motion.c3d",)  # the first is rendered
    synthesize: bool = True  # False: the motion is there (its key matches); render only


@dataclass
class BatchResult:
    """What a batch did: one report row per script line, in script order."""

    rows: list[dict]
    report: Path
    n_workers: int = 0
    elapsed_s: float = 0.0
    loads: dict = field(default_factory=dict)  # worker process id -> model loads

    def count(self, status: str) -> int:
        """Rows with this status (``done``, ``rendered``, ``skipped``, ``failed``,
        ``not run``)."""
        return sum(r["status"] == status for r in self.rows)

    @property
    def ok(self) -> bool:
        """True if no line failed or was left unrun."""
        return self.count("failed") == 0 and self.count("not run") == 0

    def summary(self) -> list[str]:
        """A few lines for the user."""
        done, skipped, failed = self.count("done"), self.count("skipped"), self.count("failed")
        rendered = self.count("rendered")
        speech = sum(float(r["duration_s"] or 0) for r in self.rows if r["status"] == "done")
        n = len(self.rows)
        lines = [f"batch: {n} line{'s' * (n != 1)}: {done} made, "
                 + (f"{rendered} rendered from stored motion, " if rendered else "")
                 + f"{skipped} skipped (finished before), {failed} failed"
                 + (f", {self.count('not run')} not run" if self.count("not run") else "")]
        on = f"on {self.n_workers} worker{'s' * (self.n_workers != 1)}"
        if done:
            rate = done / self.elapsed_s * 60 if self.elapsed_s > 0 else float("nan")
            lines.append(f"batch: {speech:.1f} s of speech animated in {self.elapsed_s:.1f} s "
                         f"{on} ({rate:.1f} lines/min)")
        elif rendered:
            lines.append(f"batch: {rendered} preview{'s' * (rendered != 1)} rendered in "
                         f"{self.elapsed_s:.1f} s {on}")
        for r in self.rows:
            if r["status"] == "failed":
                lines.append(f"batch: failed {r['id']}: {r['error']}")
        # A transcript that does not fit its recording is a line made otherwise than
        # asked: said here, not only in the report's warnings column.
        warned = [r for r in self.rows if r["status"] == "done" and r.get("warnings")]
        lines += [f"batch: warning {r['id']}: {r['warnings']}"
                  for r in warned[:WARNINGS_SHOWN]]
        if len(warned) > WARNINGS_SHOWN:
            more = len(warned) - WARNINGS_SHOWN
            lines.append(f"batch: {more} more line{'s' * (more != 1)} with warnings (the "
                         "report's warnings column)")
        lines.append(f"batch: report {self.report}")
        return lines


# --------------------------------------------------------------------------------------
# The batch (client side)
# --------------------------------------------------------------------------------------


def run_batch(
    script: Path, options: BatchOptions, *,
    progress: Callable[[int], Callable[[Iterable], Iterable]] | None = None,
    say: Callable[[str], object] | None = None,
) -> BatchResult:
    """Run every line of ``script``; write ``options.out/report.csv``.

    Parameters
    ----------
    script : Path
        CSV or JSON Lines dialogue script (:func:`animegraph.apps.script.read_script`).
    options : BatchOptions
    progress : callable, optional
        ``progress(total)`` returns a wrapper of the iterable of finished lines (a bar).
    say : callable, optional
        Receives a line of news before long steps.

    Raises
    ------
    BatchInterrupted
        A Ctrl-C (a KeyboardInterrupt) once the batch had its output folder: with the
        result so far, its report written (lines not reached are ``not run``).
    ScriptError
        The script is malformed (nothing runs).
    AnimeGraphError
        The database cannot be opened, rendering is unavailable, the scheduler cannot be
        reached, another batch is writing into ``options.out``: nothing runs. A cluster
        that cannot be had (:class:`NotStarted`) leaves nothing behind: no report, and no
        ``options.out`` if this batch made it.
    """
    say = say or (lambda _line: None)
    if options.render not in RENDER_MODES:
        raise ParameterError(f"render must be one of {', '.join(RENDER_MODES)}, got "
                             f"{options.render!r}")
    if options.scheduler is None and options.workers < 1:
        raise ParameterError(f"workers must be at least 1, got {options.workers}")
    lines = read_script(script)
    db = Path(options.db).absolute()
    from animegraph.synthesis.model import read_channels

    # a clear error now rather than one per line
    _, names, _, kind = read_channels(Database.open(db))
    files = motion_files(options.motion_formats, names, kind)
    if all(channels_left_out(name, names) for name in files):
        # e.g. a landmark database's head pose not in motion.c3d: said once, here
        logger.warning("%s", channels_left_out(files[0], names))
    version, identity = database_identity(db)
    out = Path(options.out).absolute()
    if out.exists() and not out.is_dir():
        raise ParameterError(f"--out {out} is a file, not a folder")
    # a line's files would replace a recording kept in a line's output folder
    written = {(out / line.id).resolve(): line.id for line in lines}
    for line in lines:
        if line.audio is not None and line.audio.resolve().parent in written:
            raise ParameterError(f"{Path(script).name} line {line.line_no}: its audio "
                                 f"{line.audio} is in the output folder of line "
                                 f"{written[line.audio.resolve().parent]!r}, which the "
                                 "batch writes into")
    made = [folder for folder in (out, *out.parents) if not folder.exists()]
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ParameterError(f"cannot create --out {out}: {exc.strerror or exc}") from None
    try:
        # One batch per output folder: a second one would delete the first's temporaries.
        with writer_lock(out, wait=0, what="batch output folder"):
            try:
                return _run_locked(lines, options, db, version, identity, files, out,
                                   progress, say)
            except NotStarted:
                if made:  # the folder is this batch's: its lock goes with it
                    lock_path(out).unlink(missing_ok=True)
                raise
    except NotStarted:
        for folder in made:  # innermost first; only if still empty
            try:
                folder.rmdir()
            except OSError:
                break
        raise


def _run_locked(lines, options: BatchOptions, db: Path, version, identity, files,
                out: Path, progress, say) -> BatchResult:
    rows: dict[str, dict] = {}
    tasks: list[LineTask] = []
    stored: dict[str, str | None] = {}

    def guides(parts: list[str]) -> dict:
        stored.update(guide_state(db, [p for p in parts if p not in stored]))
        return {p: stored[p] for p in parts}

    check_emotion = EmotionCheck(db)
    check_voice = VoiceCheck()
    for line in lines:
        folder = out / line.id
        try:
            if folder.is_symlink():  # from someone else: its files would go where it points
                raise LineError(f"its output folder {folder} is a symbolic link (a batch "
                                "writes only inside --out)")
            key = line_key(line, identity, files)
        except LineError as exc:
            rows[line.id] = _row(line, status="failed", error=str(exc))
            continue
        saved = None if options.force else finished(folder, key, guides)
        if saved is not None and rendered(folder, key, options.render):
            rows[line.id] = {**saved, "id": line.id, "status": "skipped"}
            _remove_temporaries(folder)  # of a render cut short, now turned off
            continue
        if saved is None:
            try:
                # here, not in each worker after its start-up
                check_emotion(line.emotion, recorded=line.audio is not None)
                check_voice(line)
            except LineError as exc:
                rows[line.id] = _row(line, status="failed", error=str(exc))
                continue
        tasks.append(LineTask(line=line, db=str(db), db_version=version, folder=str(folder),
                              render=options.render, key=key, motion_files=files,
                              synthesize=saved is None))

    report = out / "report.csv"
    result = BatchResult(rows=[], report=report)

    def so_far() -> list[dict]:
        return [rows.get(line.id) or _row(line, status="not run") for line in lines]
    t0 = time.perf_counter()
    written = True
    interrupted = False
    try:
        if tasks:
            making = [t for t in tasks if t.synthesize]

            def prepare() -> None:
                from animegraph.search.kernels import compile_notice

                if not making:  # renders only: no search runs
                    return
                # Compiling is the one-off minute; once cached, the kernels only load (a
                # batch said "compiling" every time).
                methods = {t.line.method for t in making}
                notice = next(filter(None, map(compile_notice, sorted(methods))), None)
                say(f"{notice.removesuffix(' ...')}, in this process before the workers "
                    "start ..."
                    if notice else "loading the search in this process before the workers "
                    "start ...")
                try:
                    warm_up(db, {(t.line.method, t.line.window) for t in making},
                            align=any(t.line.audio is not None for t in making))
                except AnimeGraphError as exc:  # the lines will meet it and say so
                    logger.warning("warming up the search kernels failed: %s", exc)

            entered = False
            try:
                with dask_client(options, prepare=prepare) as (client, n_workers):
                    entered = True
                    # the previous run's report goes now: lines still to make say "not run"
                    write_report(report, so_far())
                    last_written = time.monotonic()
                    result.n_workers = n_workers
                    say(f"{_plan(len(making), len(tasks) - len(making))} on {n_workers} "
                        f"Dask worker{'s' * (n_workers != 1)} ({len(lines) - len(tasks)} "
                        "skipped or failed before starting)")
                    for task, row in _run_tasks(client, tasks, progress):
                        pid, loads = row.pop("_pid", None), row.pop("_loads", None)
                        if pid is not None:
                            result.loads[pid] = loads
                        rows[task.line.id] = row
                        if time.monotonic() - last_written >= REPORT_EVERY_S:
                            write_report(report, so_far())
                            last_written = time.monotonic()
            except AnimeGraphError as exc:
                if entered:
                    raise
                written = False  # no cluster: no line ran, nothing to report
                raise NotStarted(str(exc)) from None
    except KeyboardInterrupt:
        interrupted = True  # the report says what was done
    finally:
        result.elapsed_s = time.perf_counter() - t0
        result.rows = so_far()
        if written:
            write_report(report, result.rows)
    if interrupted:
        raise BatchInterrupted(result) from None
    return result


def _plan(n_make: int, n_render: int) -> str:
    """``3 lines to make, 2 to render from stored motion``."""
    parts = [f"{n_make} line{'s' * (n_make != 1)} to make"] if n_make else []
    if n_render:
        parts.append(f"{n_render}{'' if n_make else ' line' + 's' * (n_render != 1)} to "
                     "render from stored motion")
    return ", ".join(parts)


def _run_tasks(client, tasks: list[LineTask], progress) -> Iterator[tuple[LineTask, dict]]:
    """Submit every line; yield (task, report row) as they finish."""
    from distributed import as_completed

    futures = {client.submit(run_line, task, pure=False): task for task in tasks}
    finished_lines: Iterable = as_completed(futures, loop=client.loop)
    if progress is not None:
        finished_lines = progress(len(futures))(finished_lines)
    for future in finished_lines:
        task = futures[future]
        try:
            row = future.result()
        except Exception as exc:  # a bug, or a worker that died on this line
            logger.debug("line %s failed on its worker", task.line.id, exc_info=True)
            row = _row(task.line, status="failed",
                       error=f"worker error: {type(exc).__name__}: {exc}")
        yield task, row
        future.release()


@contextmanager
def dask_client(options: BatchOptions, *, prepare: Callable[[], object] | None = None
                ) -> Iterator[tuple[object, int]]:
    """A Dask client: of a new local cluster of ``options.workers`` processes (one thread
    each, numba single-threaded), or of the cluster at ``options.scheduler``.

    ``prepare()`` runs once the scheduler is known to be reachable and before a local
    cluster's workers start. Yields (client, number of workers).

    Raises
    ------
    DataError
        The scheduler cannot be reached within ``options.connect_timeout`` seconds, or
        has no worker.
    """
    import distributed  # noqa: F401  (first: importing it sets its loggers' levels)

    quiet = logging.getLogger("distributed")
    level = quiet.level
    if not logger.isEnabledFor(logging.DEBUG):
        quiet.setLevel(logging.ERROR)  # Dask's news of its own start and stop
    try:
        with _client(options, prepare) as client:
            yield client, len(client.scheduler_info()["workers"])
    finally:
        quiet.setLevel(level)


@contextmanager
def _client(options: BatchOptions, prepare: Callable[[], object] | None):
    from distributed import Client, LocalCluster

    cluster = client = None
    try:
        if options.scheduler:
            address = options.scheduler
            # Made in two steps so that a Client that fails to connect can be closed here:
            # left to the garbage collector, it waits 10 s for its stopped event loop
            # and prints a traceback ("Exception ignored in: Client.__del__").
            client = Client.__new__(Client)
            try:
                client.__init__(address, timeout=options.connect_timeout,
                                set_as_default=False)
            except (OSError, TimeoutError, ValueError) as exc:
                _close_unconnected(client)
                client = None
                raise DataError(f"cannot reach the Dask scheduler at {address}: {exc}; give "
                                "the address of a running one, e.g. tcp://127.0.0.1:8786"
                                ) from None
            try:
                client.wait_for_workers(1, timeout=options.connect_timeout)
            except (OSError, TimeoutError) as exc:
                raise DataError(f"the Dask scheduler at {options.scheduler} has no workers "
                                f"({type(exc).__name__})") from None
            if prepare is not None:
                prepare()
        else:
            if prepare is not None:
                prepare()
            cluster = LocalCluster(
                n_workers=0, threads_per_worker=1, processes=True,
                # CRITICAL: a worker busy in a line when a Ctrl-C closes the scheduler
                # logs its failed heartbeat as an ERROR with a traceback; a line's own
                # errors come back through its future, not through the workers' logs.
                dashboard_address=None, silence_logs=logging.CRITICAL,
                # No dashboard, and the scheduler's own HTTP server (which it starts even
                # so, on 8787 by default) on a free local port: a second cluster said
                # "Port 8787 is already in use".
                scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"},
                # One core per worker: numba's own threads would compete with the others.
                env={"NUMBA_NUM_THREADS": "1"},
            )
            client = Client(cluster, set_as_default=False)
            # The worker processes are born ignoring SIGINT (a terminal's Ctrl-C reaches
            # the whole process group): a Ctrl-C ends the batch here, and the batch ends
            # the workers. Ignored only until they exist, so no Ctrl-C goes unseen for long.
            with sigint_ignored_by_children():
                started = set(multiprocessing.active_children())
                cluster.scale(options.workers)
                deadline = time.monotonic() + options.connect_timeout
                while (len(set(multiprocessing.active_children()) - started) < options.workers
                       and time.monotonic() < deadline):
                    time.sleep(0.01)
            try:
                client.wait_for_workers(options.workers, timeout=WORKER_START_TIMEOUT_S)
            except TimeoutError:
                raise DataError(f"the {options.workers} local Dask workers did not start "
                                f"within {WORKER_START_TIMEOUT_S:.0f} s") from None
        yield client
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()


def _close_unconnected(client) -> None:
    """Close a Client whose constructor failed, quietly."""
    try:
        client.close(timeout=1)
    except Exception:  # half made: whatever it lacks, it is no longer used
        logger.debug("closing an unconnected Dask client", exc_info=True)


def warm_up(db: Path, methods: set[tuple[str, int | None]], *, align: bool = False) -> None:
    """Compile (and cache) every numba kernel a line will run, in this process.

    Worker processes that compile and cache the same numba function at the same time can
    leave mismatched cache files and crash (numba issues #10128, #4807); after this they
    only load complete caches. One short eSpeak utterance is synthesized with each search
    method used, force-aligned if any line has a recording, and both the serial and
    the parallel audio-cost kernels are run.
    """
    import numpy as np

    from animegraph.search.dtw import audio_costs
    from animegraph.synthesis import Model, synthesize
    from ingest.formats.phones_csv import Segment
    from ingest.speech.espeak import Voice, speak

    model = Model.load(db)
    utt = speak("Good morning, class.", Voice())
    labels = [Segment(p.phone, p.start, p.end) for p in utt.phones]
    for method, window in sorted(methods, key=str):
        out = synthesize(model, utt.audio, utt.sample_rate, labels=labels, method=method,
                         window=window)
    if align:
        out = synthesize(model, utt.audio, utt.sample_rate, text=utt.text)
    g = model.graph
    query = out.phones[len(out.phones) // 2].prosody.astype(np.float32)
    for k in (2, min(g.n_nodes, 128)):
        audio_costs(query, g.prosody_values, g.prosody_offsets, np.arange(k))


# --------------------------------------------------------------------------------------
# Keys and markers
# --------------------------------------------------------------------------------------


class EmotionCheck:
    """``check(spec, recorded)``: a line's emotion checked against the database as
    synthesis will check it (names, a mix's mappings, a classifier for ``auto``), before
    any worker starts. Raises :class:`LineError` with synthesis' own message, or when
    ``auto`` has no recording to hear (eSpeak NG's voice carries no emotion, so the
    classifier's guess would be used silently). The database's emotion model is read on
    the first line that has an emotion."""

    def __init__(self, db: Path):
        self.db = db
        self._loaded: tuple | None = None

    def __call__(self, spec: EmotionSpec, recorded: bool = True) -> None:
        from animegraph.emotion.control import AUTO, no_classifier, resolve_emotion
        from ingest.emotion.model import EmotionModel, NoEmotionModel

        if spec.argument is None:
            return
        if self._loaded is None:
            database = Database.open(self.db)
            try:
                model = EmotionModel.from_database(database)
            except NoEmotionModel:  # an older database: names are still checked
                model = None
            # The Anime Graph's emotions (animegraph.search.graph.AnimeGraph.emotions).
            names = database.table("animes", columns=["emotion"]).column("emotion")
            self._loaded = (model, tuple(sorted(set(names.to_pylist()))))
        model, graph_emotions = self._loaded
        try:
            if spec.argument == AUTO:
                if model is None or model.classifier is None:
                    raise DataError(no_classifier(model))
                if not recorded:
                    raise DataError("emotion auto is heard in the line's recording, and it "
                                    "has none (eSpeak NG speaks it): name the emotion, or "
                                    "give audio")
            else:
                resolve_emotion(spec.argument, model, graph_emotions)
        except AnimeGraphError as exc:
            raise LineError(str(exc)) from None


class VoiceCheck:
    """``check(line)``: the eSpeak NG voice of a line without a recording is one eSpeak
    knows, before any worker starts (a misspelt voice failed its line on a worker, after
    the cluster's start-up). Raises :class:`LineError` with eSpeak's message; each voice
    is tried once, on a word."""

    def __init__(self):
        self._why: dict[str, str] = {}

    def __call__(self, line: ScriptLine) -> None:
        from ingest.speech.espeak import Voice, speak

        if line.audio is not None or not line.voice:
            return
        if line.voice not in self._why:
            try:
                speak("a", Voice(name=line.voice))
                self._why[line.voice] = ""
            except AnimeGraphError as exc:
                self._why[line.voice] = str(exc)
        if self._why[line.voice]:
            raise LineError(self._why[line.voice])


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
        audio = _file_digest(line.audio)
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


def _file_digest(path: Path) -> str:
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


def _write_marker(folder: Path, marker: dict) -> None:
    with atomic_write(folder / DONE) as handle:
        handle.write(json.dumps(marker, indent=1).encode())


# --------------------------------------------------------------------------------------
# One line (worker side)
# --------------------------------------------------------------------------------------

_MODELS: dict = {}
_LOADS: Counter = Counter()
_GUIDES: dict = {}
_MODEL_LOCK = threading.Lock()


def worker_model(db: str, version: str):
    """The Anime Graph of ``db`` at ``version``, loaded once per process and kept.

    Raises
    ------
    DataError
        The database's live version is no longer ``version`` (it was rebuilt during the
        batch).
    """
    from animegraph.synthesis import Model

    key = (str(Path(db).resolve()), version)
    with _MODEL_LOCK:
        model = _MODELS.get(key)
        if model is None:
            model = Model.load(db)
            live = model.db.version_dir.name
            if live != version:
                raise DataError(f"database {db} changed during the batch (live version {live}, "
                                f"the batch started with {version}); run the batch again")
            _MODELS.clear()  # one database at a time per process
            _MODELS[key] = model
            _LOADS[key] += 1
        return model


def guide_state(db: str | Path, parts: Iterable[str]) -> dict[str, str | None]:
    """What is stored of each guide part with ``db``'s live version: part -> the SHA-256
    of its model file, or None if there is none."""
    from animegraph.baselines.stored import model_path

    state = {}
    for part in parts:
        try:
            state[part] = _file_digest(model_path(db, part))
        except LineError:
            state[part] = None
    return state


def worker_guide(db: str, version: str, name: str) -> tuple[object, list[str], dict]:
    """The guide ``name`` (``a+b``: the mean of its parts) as stored with ``db``, loaded
    once per process and kept: (the guide, a tuple of its parts, or None; the parts not
    to be had, each with why; :func:`guide_state` of the parts as they were read). A
    worker does not fit a guide: that writes the database, and the batch only reads it."""
    from animegraph.baselines.stored import load_forward, unfit_reason

    key = (str(Path(db).resolve()), version, name)
    with _MODEL_LOCK:
        if key not in _GUIDES:
            state = guide_state(db, name.split("+"))  # before reading: never newer
            got, lacking = [], []
            for part in name.split("+"):
                try:
                    model = load_forward(db, part)
                except AnimeGraphError as exc:  # unreadable: the line goes on without it
                    model, why = None, str(exc)
                else:  # synth's first use may have found it cannot be fitted
                    reason = unfit_reason(db, part)
                    why = (f"could not be fitted: {reason}" if reason else
                           f"not fitted: animegraph fit --method {part} --db {db}")
                if model is None:
                    lacking.append(f"{part} ({why})")
                else:
                    got.append(model)
            guide = None if not got else got[0] if len(got) == 1 else tuple(got)
            _GUIDES.clear()  # one database at a time per process
            _GUIDES[key] = (guide, lacking, state)
        return _GUIDES[key]


def run_line(task: LineTask) -> dict:
    """Make one line's outputs; return its report row (status ``done`` or ``failed``).

    Errors a user can cause (an emotion the database lacks, text eSpeak cannot speak, an
    unreadable recording) become the row's ``error``; anything else propagates.
    """
    t0, cpu0 = time.perf_counter(), time.process_time()
    line = task.line
    folder = Path(task.folder)
    row = _row(line, status="failed")

    def timed(row: dict) -> dict:
        row["seconds"] = round(time.perf_counter() - t0, 3)
        row["cpu_seconds"] = round(time.process_time() - cpu0, 3)
        return row

    try:
        folder.mkdir(parents=True, exist_ok=True)
        if task.synthesize:
            # done.json first: the line is no longer finished; then every file of the
            # earlier run, so that none is taken for this run's
            for name in (DONE, *LINE_FILES):
                (folder / name).unlink(missing_ok=True)
        _remove_temporaries(folder)
        if task.synthesize:
            model = worker_model(task.db, task.db_version)
            made = _make_line(task, model, folder)
            outputs, guides = made.pop("_outputs"), made.pop("_guides")
            row.update(made, status="done")
            marker = {"format": FORMAT, "key": task.key, "outputs": outputs,
                      "row": timed(dict(row))}
            if guides:
                marker["guides"] = guides
            _write_marker(folder, marker)
        else:
            marker, saved = read_marker(folder), finished(folder, task.key)
            if marker is None or saved is None:  # not since the check
                raise LineError(f"{folder / DONE} changed during the batch; run it again")
            row.update(saved)
        if task.render != "none":
            _render_line(task, folder, marker)
        row["status"] = "done" if task.synthesize else "rendered"
        row["error"] = ""
    except AnimeGraphError as exc:
        row.update(status="failed", error=str(exc))
    except OSError as exc:
        where = f"{exc.filename}: " if exc.filename else ""
        row.update(status="failed", error=f"{where}{exc.strerror or exc}")
    timed(row)
    if task.synthesize:  # a render alone loads no model
        row["_pid"] = os.getpid()
        row["_loads"] = _LOADS[(str(Path(task.db).resolve()), task.db_version)]
    return row


def _render_line(task: LineTask, folder: Path, marker: dict) -> None:
    """Render the line's preview from its stored motion; record it in ``done.json``."""
    if marker.pop("render", None) is not None:
        _write_marker(folder, marker)  # first: the preview there is no longer of record
    try:
        _render(folder, task.motion_files[0])
    except (AnimeGraphError, OSError) as exc:
        raise LineError(f"rendering {PREVIEW} failed (the motion is made: the next run "
                        f"only renders): {exc}") from None
    marker["render"] = render_key(task.key, task.render)
    _write_marker(folder, marker)


def _make_line(task: LineTask, model, folder: Path) -> dict:
    from animegraph.synthesis import backoffs, synthesize, write_explain, write_motion
    from animegraph.synthesis.path import audio_only_guide
    from ingest.formats.media import read_audio
    from ingest.formats.phones_csv import write_phones_csv
    from ingest.formats.wav import write_wav

    line = task.line
    warnings: list[str] = []
    if line.audio is not None:
        audio, sample_rate = read_audio(line.audio)  # a WAV, or a video's sound track
        text, labels, speech = line.text, None, "recording"
    else:
        audio, sample_rate, labels = _speak(line, warnings)
        text, speech = None, "espeak"
    lacking: list[str] = []
    guides: dict[str, str | None] = {}

    def speech_alone_guide():
        """A recording whose transcript does not fit it is synthesized as speech alone
        is by ``synth``: with the audio-only path's guide."""
        name = audio_only_guide(known_phones=False, searched=line.searched)
        if name is None:
            return None
        guide, missing, state = worker_guide(task.db, task.db_version, name)
        lacking.extend(missing)
        guides.update(state)
        return guide

    synth = synthesize(model, audio, sample_rate, text=text, labels=labels,
                       emotion=line.emotion.argument, method=line.method, window=line.window,
                       k_best=line.synthesis_path()[0], recognized_guide=speech_alone_guide)
    warnings.extend(synth.warnings)  # a transcript not aligned and why; the speech's quality
    warnings.extend(synth.notes)  # e.g. emotion components that could not be mapped
    path = line.synthesis_path()[1]
    if line.audio is not None and synth.segmentation != "aligned":
        path = speech_alone_path(line, synth.guided)
    if lacking:
        warnings.append(f"without the speech-alone guide {', '.join(lacking)}")
    missing = backoffs(synth)
    if missing:
        warnings.append(f"phones missing from the database, backed off: {', '.join(missing)}")

    write_wav(folder / "speech.wav", audio, sample_rate)
    for name in task.motion_files:
        write_motion(synth, model, folder / name)
    write_phones_csv(folder / "phones.csv", synth.phones)
    used = emotion_used(synth, line.emotion)
    write_explain(synth, folder / "explain.json", id=line.id, text=line.text,
                  speaker=line.speaker, speech=speech,
                  emotion={"requested": line.emotion.text, "source": line.emotion.source,
                           "used": used})
    outputs = ["speech.wav", *task.motion_files, "phones.csv", "explain.json"]
    return {
        "speech": speech, "path": path,
        "duration_s": round(len(audio) / sample_rate, 3),
        "emotion": used, "motion_emotions": _motion_emotions(synth.explain),
        "jumps": synth.result.n_jumps, "cost": round(float(synth.result.cost), 4),
        "warnings": "; ".join(warnings), "error": "", "_outputs": outputs,
        "_guides": guides,
    }


def speech_alone_path(line: ScriptLine, guided: tuple[str, ...]) -> str:
    """The report's path for a recording whose transcript did not fit it: ``synth``'s
    for the speech alone."""
    from animegraph.synthesis.guide import GUIDE_BLEND
    from animegraph.synthesis.path import guide_line, synthesis_path

    _, path = synthesis_path("audio only (the transcript does not fit the recording)",
                             known_phones=False, searched=line.searched)
    name = "+".join(guided) or None
    return path + guide_line(name, GUIDE_BLEND, False, known_phones=False, asked=False)


def _speak(line: ScriptLine, warnings: list[str]):
    from ingest.formats.phones_csv import Segment
    from ingest.speech.espeak import speak

    utt = speak(line.text, voice_for(line, warnings))  # errors name the text or the voice
    labels = [Segment(p.phone, p.start, p.end) for p in utt.phones]
    return utt.audio, utt.sample_rate, labels


def voice_for(line: ScriptLine, warnings: list[str] | None = None):
    """The eSpeak NG voice of a line without a recording: its emotion's prosody preset
    (a mix blends the presets by weight; ``auto`` and no emotion speak neutrally), with
    the line's ``voice`` name if it has one."""
    from ingest.corpus.emotions import STYLES
    from ingest.speech.espeak import Voice

    spec = line.emotion
    weights = spec.weights if spec.source in ("given", "mix") else (("neutral", 1.0),)
    unknown = [name for name, _ in weights if name.lower() not in STYLES]
    if unknown and warnings is not None:
        warnings.append(f"no eSpeak prosody preset for {', '.join(unknown)}: spoken with the "
                        "neutral preset")
    presets = [(STYLES.get(name.lower(), STYLES["neutral"]).voice, w) for name, w in weights]
    fields = ("rate", "pitch", "pitch_range", "volume", "word_gap")
    blended = {f: int(round(sum(getattr(v, f) * w for v, w in presets))) for f in fields}
    voice = replace(Voice(), **blended)
    if line.voice:
        voice = replace(voice, name=line.voice)
    return voice


def emotion_used(synth, spec: EmotionSpec) -> str:
    """The emotion a line was made in: what synthesis resolved it to (``Synthesis.emotion``,
    e.g. the class ``auto`` detected, or a mix), else what was asked for; ``none`` for no
    preference."""
    resolved = synth.emotion  # animegraph.emotion.control.EmotionChoice
    if resolved is not None and resolved.target is not None:
        return resolved.describe()
    return spec.text or "none"


def _motion_emotions(explain: list[dict]) -> str:
    """Which emotions the chosen animes were recorded in, by share of speech time."""
    time_by: Counter = Counter()
    for e in explain:
        if e["phone"] != "SIL":
            time_by[e["emotion"]] += e["end"] - e["start"]
    total = sum(time_by.values())
    if total <= 0:
        return ""
    return ", ".join(f"{name} {share / total:.0%}" for name, share in time_by.most_common())


def _render(folder: Path, motion_name: str) -> None:
    """``preview.mp4``: the line's motion (its file ``motion_name``) on the face mesh
    (§7), its speech muxed in, its phones as captions: all read from the line's files."""
    import secrets

    from animegraph.face.render import deformer_for, render_motion
    from animegraph.motion.files import read_motion
    from ingest.formats.phones_csv import read_phones_csv

    motion = read_motion(folder / motion_name)
    track = [{"phone": p.phone, "start": p.start, "end": p.end}
             for p in read_phones_csv(folder / "phones.csv")]
    tmp = folder / f".preview.{secrets.token_hex(6)}.tmp.mp4"
    try:
        render_motion(motion, tmp, deformer=deformer_for(motion.names),
                      audio=folder / "speech.wav", phones=track)
        os.replace(tmp, folder / PREVIEW)
    finally:
        tmp.unlink(missing_ok=True)


def _remove_temporaries(folder: Path) -> None:
    """Temporary files a killed run left (hidden, so they never look finished)."""
    for path in folder.glob(".*.tmp*"):
        path.unlink(missing_ok=True)


# --------------------------------------------------------------------------------------
# The report
# --------------------------------------------------------------------------------------


def _row(line: ScriptLine, *, status: str, error: str = "") -> dict:
    row = dict.fromkeys(REPORT_COLUMNS, "")
    row.update(id=line.id, status=status, speaker=line.speaker,
               speech="recording" if line.audio is not None else "espeak",
               emotion=line.emotion.text or "none", emotion_source=line.emotion.source,
               error=error)
    return row


def write_report(path: Path, rows: list[dict]) -> Path:
    """``report.csv``: one row per script line, atomically."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=REPORT_COLUMNS, extrasaction="ignore",
                            lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    with atomic_write(path) as handle:
        handle.write(buffer.getvalue().encode())
    return path


def read_report(path: Path) -> list[dict]:
    """The rows of a ``report.csv``."""
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))
