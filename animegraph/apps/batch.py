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
at ``scheduler``. Each worker process loads the Anime Graph once
(:func:`animegraph.apps.batch_line.worker_model`).

A line is made in two steps, each with its own key in ``done.json``. Its motion (and
speech, phones, explanation) depends on the line's inputs, the recording's bytes, the
database version and the motion formats
(:func:`animegraph.apps.batch_markers.line_key`); its preview on that motion and the render
options (:func:`animegraph.apps.batch_markers.render_key`). A line whose motion key
matches is not synthesized again unless ``force``: if its preview is missing or was
rendered otherwise, it is only rendered again from the stored motion (status
``rendered``), and turning
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

import logging
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from animegraph.apps.batch_cluster import CONNECT_TIMEOUT_S, dask_client
from animegraph.apps.batch_line import LineTask, run_line
from animegraph.apps.batch_markers import (
    LineError,
    database_identity,
    finished,
    guide_state,
    line_key,
    motion_files,
    remove_temporaries,
    rendered,
)
from animegraph.apps.batch_report import line_row, write_report
from animegraph.apps.script import EmotionSpec, ScriptLine, read_script
from animegraph.motion.files import channels_left_out
from db.errors import AnimeGraphError, DataError, ParameterError
from db.lock import lock_path, writer_lock
from db.store import Database

logger = logging.getLogger(__name__)

RENDER_MODES = ("none", "mp4")
#: Lines made with warnings that the summary names (the report has them all).
WARNINGS_SHOWN = 10
#: Seconds between rewrites of ``report.csv`` while lines finish: a batch killed (SIGKILL,
#: a lost machine) leaves a report this old at most, and a long batch does not rewrite
#: its whole report at every line.
REPORT_EVERY_S = 2.0
#: The worked example shipped with the package: a tutor and a student, six lines.
EXAMPLE_SCRIPT = Path(__file__).resolve().parent / "examples" / "dialogue.csv"


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
    #: Names in :data:`animegraph.apps.batch_markers.MOTION_FORMATS`; empty: the database's
    #: own (:func:`animegraph.apps.batch_markers.motion_files`).
    motion_formats: tuple[str, ...] = ()


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
            rows[line.id] = line_row(line, status="failed", error=str(exc))
            continue
        saved = None if options.force else finished(folder, key, guides)
        if saved is not None and rendered(folder, key, options.render):
            rows[line.id] = {**saved, "id": line.id, "status": "skipped"}
            remove_temporaries(folder)  # of a render cut short, now turned off
            continue
        if saved is None:
            try:
                # here, not in each worker after its start-up
                check_emotion(line.emotion, recorded=line.audio is not None)
                check_voice(line)
            except LineError as exc:
                rows[line.id] = line_row(line, status="failed", error=str(exc))
                continue
        tasks.append(LineTask(line=line, db=str(db), db_version=version, folder=str(folder),
                              render=options.render, key=key, motion_files=files,
                              synthesize=saved is None))

    report = out / "report.csv"
    result = BatchResult(rows=[], report=report)

    def so_far() -> list[dict]:
        return [rows.get(line.id) or line_row(line, status="not run") for line in lines]
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
                if notice:  # a line of its own: what follows reads the same either way
                    say(notice)
                say("loading the search in this process before the workers start ...")
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
            row = line_row(task.line, status="failed",
                           error=f"worker error: {type(exc).__name__}: {exc}")
        yield task, row
        future.release()


def warm_up(db: Path, methods: set[tuple[str, int | None]], *, align: bool = False) -> None:
    """Compile (and cache) every numba kernel a line will run, in this process.

    Worker processes that compile and cache the same numba function at the same time can
    leave mismatched cache files and crash (numba issues #10128, #4807); after this they
    only load complete caches. One short eSpeak utterance is synthesized with each search
    method used, force-aligned if any line has a recording
    (:func:`animegraph.apps.prepare.warm_kernels`).
    """
    from animegraph.apps.prepare import warm_kernels

    warm_kernels(db, methods, align=align)


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
