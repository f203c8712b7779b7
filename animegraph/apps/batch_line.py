"""One line of ``animegraph batch`` (:mod:`animegraph.apps.batch`), made on a Dask worker:
its speech, motion, phones and explanation (:func:`run_line`), its preview, and the
models a worker process loads once and keeps (:func:`worker_model`, :func:`worker_guide`)."""

from __future__ import annotations

import os
import threading
import time
from collections import Counter
from dataclasses import dataclass, replace
from pathlib import Path

from animegraph.apps.batch_markers import (
    DONE,
    FORMAT,
    LINE_FILES,
    PREVIEW,
    LineError,
    finished,
    guide_state,
    read_marker,
    remove_temporaries,
    render_key,
    write_marker,
)
from animegraph.apps.batch_report import line_row
from animegraph.apps.script import EmotionSpec, ScriptLine
from db.errors import AnimeGraphError, DataError


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
    row = line_row(line, status="failed")

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
        remove_temporaries(folder)
        if task.synthesize:
            model = worker_model(task.db, task.db_version)
            made = _make_line(task, model, folder)
            outputs, guides = made.pop("_outputs"), made.pop("_guides")
            row.update(made, status="done")
            marker = {"format": FORMAT, "key": task.key, "outputs": outputs,
                      "row": timed(dict(row))}
            if guides:
                marker["guides"] = guides
            write_marker(folder, marker)
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
        write_marker(folder, marker)  # first: the preview there is no longer of record
    try:
        _render(folder, task.motion_files[0])
    except (AnimeGraphError, OSError) as exc:
        raise LineError(f"rendering {PREVIEW} failed (the motion is made: the next run "
                        f"only renders): {exc}") from None
    marker["render"] = render_key(task.key, task.render)
    write_marker(folder, marker)


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
