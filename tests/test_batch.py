"""``animegraph batch``: dialogue scripts, a real two-worker Dask cluster, resume, bad input."""

from __future__ import annotations

import csv
import json
import os
import shutil

import numpy as np
import pytest

from animegraph.apps.batch import (
    EXAMPLE_SCRIPT,
    BatchInterrupted,
    BatchOptions,
    run_batch,
)
from animegraph.apps.batch_line import LineTask, run_line, voice_for
from animegraph.apps.batch_markers import (
    DONE,
    database_identity,
    finished,
    line_key,
    render_key,
    rendered,
)
from animegraph.apps.batch_report import read_report
from animegraph.apps.cli import main
from animegraph.apps.script import EmotionSpec, ScriptError, ScriptLine, parse_emotion, read_script
from db.errors import DataError, ParameterError
from db.store import Database
from ingest.corpus.emotions import STYLES
from ingest.formats.c3d import read_c3d
from ingest.formats.phones_csv import read_phones_csv
from ingest.formats.wav import read_wav
from ingest.speech.espeak import Voice, speak

#: A marker database's motion file in a batch (its default).
FILES = ("motion.c3d",)

# --------------------------------------------------------------------------- the script


def test_reads_csv_and_json_lines(tmp_path):
    (tmp_path / "rec").mkdir()
    csv_script = tmp_path / "lines.csv"
    csv_script.write_text(
        "ID, Text ,audio,emotion,speaker,voice,window,exact\n"
        'a1,"Hello, class.",,happy,tutor,en-us+f3,,\n'
        "\n"
        "b-2,Fine thanks,rec/b.wav,happy=3,student,,4,\n"
        "c.3,Again,,auto,,,,yes\n"
        'd_4,Mixed,,"sad=1,neutral=3",,,,\n'
    )
    lines = read_script(csv_script)
    assert [x.id for x in lines] == ["a1", "b-2", "c.3", "d_4"]
    assert [x.line_no for x in lines] == [2, 4, 5, 6]
    a, b, c, d = lines
    assert a.text == "Hello, class." and a.voice == "en-us+f3" and a.speaker == "tutor"
    assert a.emotion == EmotionSpec("given", (("happy", 1.0),)) and a.audio is None
    assert b.audio == (tmp_path / "rec" / "b.wav").absolute()
    assert b.emotion.source == "given" and b.window == 4 and b.method == "window"
    assert c.emotion.source == "auto" and c.method == "exact"
    # the phones of a line are known: k-best 20 unless a search is asked for (issue 14)
    assert [x.synthesis_path()[0] for x in lines] == [20, None, None, 20]
    assert "eSpeak NG phones: each phone the mean of its 20" in a.synthesis_path()[1]
    assert d.emotion.text == "sad=0.25,neutral=0.75" and d.emotion.argument == d.emotion.text

    jsonl = tmp_path / "lines.jsonl"
    jsonl.write_text('{"id": "a1", "text": "Hello, class.", "emotion": "happy"}\n\n'
                     '{"id": 7, "text": "Seven", "window": 3, "exact": false}\n')
    lines = read_script(jsonl)
    assert [(x.id, x.line_no, x.window) for x in lines] == [("a1", 1, None), ("7", 3, 3)]


@pytest.mark.parametrize("name, body, message", [
    ("s.csv", "id,text,mood\na,Hi,calm\n", "s.csv line 1: unknown column 'mood'"),
    ("s.csv", "id,text\na,Hello\nb,Hi,extra\n", "s.csv line 3: 3 fields"),
    ("s.csv", "id,text\na,Hello\n\nA,Again\n",
     "s.csv line 4: duplicate id 'A' (first on line 2)"),
    ("s.csv", "id,text,emotion\na,Hello,happy=x\n", "s.csv line 2: emotion mix"),
    ("s.csv", "id,text,emotion\na,Hello,happy sad\n", "s.csv line 2: emotion"),
    ("s.csv", "id,text,window,exact\na,Hello,3,true\n", "s.csv line 2: window and exact"),
    ("s.csv", "id,text,window\na,Hello,two\n", "s.csv line 2: window must be"),
    ("s.csv", "id,text\n../x,Hello\n", "s.csv line 2: id '../x'"),
    ("s.csv", "id,text\na,\n", "s.csv line 2: empty text"),
    ("s.csv", "id,speaker\na,tutor\n", "no 'text' column"),
    ("s.csv", "id,text\n", "has no lines"),
    ("s.jsonl", '{"id": "a", "text": "Hi"}\n{"id": "b", "text": \n', "s.jsonl line 2: not JSON"),
    ("s.jsonl", '{"id": "a", "text": "Hi", "colour": 1}\n', "s.jsonl line 1: unknown column"),
    ("s.jsonl", '["a", "Hi"]\n', "s.jsonl line 1: expected a JSON object"),
    ("s.jsonl", '{"id": "a", "text": "Hi", "x": ' + "[" * 100_000 + "]" * 100_000 + "}\n",
     "s.jsonl line 1: JSON nested too deeply"),
    ("s.txt", "id,text\na,Hi\n", "expected a .csv or .jsonl"),
])
def test_a_bad_script_is_refused_with_its_line(tmp_path, name, body, message):
    path = tmp_path / name
    path.write_text(body)
    with pytest.raises(ScriptError, match=message.replace(".", r"\.").replace("(", r"\(")
                       .replace(")", r"\)")):
        read_script(path)


def test_a_script_beyond_its_bounds_is_refused_at_once(tmp_path):
    """A script is read whole and parsed at ~50 times its size (64 MB of short lines took
    3.4 GB and 44 s, to fail on line 3), and a line's text went to eSpeak NG whatever its
    length."""
    from ingest.formats.text import MAX_SIDE_FILE_BYTES

    big = tmp_path / "big.csv"
    with open(big, "w") as handle:  # a hole after the header: no disk, no time
        handle.write("id,text\na,Hi\n")
        handle.truncate(MAX_SIDE_FILE_BYTES + 1)
    with pytest.raises(ScriptError, match=r"big\.csv is larger than 16,777,216 bytes"):
        read_script(big)
    long = tmp_path / "long.jsonl"
    long.write_text(json.dumps({"id": "a", "text": "word " * 2001}) + "\n")
    with pytest.raises(ScriptError, match=r"long\.jsonl line 1: text of 10,004 characters "
                                          r"\(at most 10,000"):
        read_script(long)


def test_the_shipped_example_is_a_valid_script():
    lines = read_script(EXAMPLE_SCRIPT)
    assert len(lines) >= 5 and {x.speaker for x in lines} == {"tutor", "student"}
    assert all(x.audio is None and x.emotion.source == "given" for x in lines)


def test_emotion_cells():
    assert parse_emotion("") == EmotionSpec("default") and parse_emotion(None).argument is None
    assert parse_emotion(" AUTO ").argument == "auto"
    assert parse_emotion(" Calm ").argument == "Calm"  # the database's spelling
    assert parse_emotion("happy=1, sad=0").source == "given"  # one weight left: a name
    mix = parse_emotion("happy=0.7,neutral=0.3")
    assert mix.source == "mix" and mix.weights == (("happy", 0.7), ("neutral", 0.3))
    for bad in ("happy=-1,sad=1", "happy=0,sad=0", "=1", "happy=nan,sad=1", "happy sad"):
        with pytest.raises(ValueError):
            parse_emotion(bad)


def test_a_line_is_spoken_with_its_emotions_prosody():
    def line(emotion, voice=None):
        return ScriptLine(id="x", text="Hi", line_no=2, emotion=parse_emotion(emotion),
                          voice=voice)

    assert voice_for(line("sad")) == voice_for(line("Sad")) == STYLES["sad"].voice
    assert voice_for(line("")) == voice_for(line("auto")) == STYLES["neutral"].voice
    mixed = voice_for(line("happy=0.5,sad=0.5"))
    assert mixed.rate == round((STYLES["happy"].voice.rate + STYLES["sad"].voice.rate) / 2)
    warnings: list[str] = []
    assert voice_for(line("bored", "en-us+m3"), warnings) == Voice(name="en-us+m3")
    assert "no eSpeak prosody preset for bored" in warnings[0]


def test_cli_refuses_a_bad_script_in_one_line(tmp_path, capsys):
    script = tmp_path / "s.csv"
    script.write_text("id,text\na,Hello\na,Again\n")
    code = main(["batch", str(script), "--db", str(tmp_path / "db"), "--out",
                 str(tmp_path / "out")])
    err = capsys.readouterr().err.strip()
    assert code == 1 and "\n" not in err and "line 3: duplicate id 'a'" in err
    assert not (tmp_path / "out").exists()


# --------------------------------------------------------------------------- markers


def test_summary_counts_in_the_singular_too(tmp_path):
    from animegraph.apps.batch import BatchResult

    row = {"id": "a", "status": "done", "duration_s": "1.5", "error": ""}
    result = BatchResult(rows=[row], report=tmp_path / "report.csv", n_workers=1,
                         elapsed_s=3.0)
    assert result.summary()[:2] == [
        "batch: 1 line: 1 made, 0 skipped (finished before), 0 failed",  # was "1 lines"
        "batch: 1.5 s of speech animated in 3.0 s on 1 worker (20.0 lines/min)"]
    result.rows = [row, {**row, "id": "b"}]
    assert result.summary()[0].startswith("batch: 2 lines: 2 made")
    # A line made otherwise than asked is said, not only in the report (a transcript
    # that did not fit its recording: '4 made, 0 failed' and nothing more).
    warned = [{**row, "id": f"w{i}", "warnings": "transcript alignment failed: ..."}
              for i in range(12)]
    result.rows = [row, *warned, {**warned[0], "id": "s", "status": "skipped"}]
    lines = result.summary()
    assert lines[2] == "batch: warning w0: transcript alignment failed: ..."
    assert lines[-2] == "batch: 2 more lines with warnings (the report's warnings column)"
    assert not any(" s:" in line for line in lines)  # said when it was made


def test_finished_needs_the_same_key_and_every_output(tmp_path):
    folder = tmp_path / "a"
    folder.mkdir()
    (folder / "speech.wav").write_bytes(b"x")
    marker = {"key": "k1", "outputs": ["speech.wav"], "row": {"id": "a", "status": "done"}}
    (folder / DONE).write_text(json.dumps(marker))
    assert finished(folder, "k1") == {"id": "a", "status": "done"}
    assert finished(folder, "k2") is None  # other inputs, database or options
    (folder / DONE).write_text(json.dumps(marker)[:-5])  # a truncated marker
    assert finished(folder, "k1") is None
    (folder / DONE).write_text(json.dumps({**marker, "outputs": ["speech.wav", "motion.c3d"]}))
    assert finished(folder, "k1") is None  # an output went missing


def _deep(p):
    p.write_text('{"key": ' + "[" * 100_000 + "]" * 100_000 + "}")


@pytest.mark.parametrize("make", [
    _deep,  # a RecursionError
    lambda p: p.write_bytes(b'{"key": "k1", "x": "' + b" " * (2 << 20) + b'"}'),  # 2 MB
    lambda p: os.mkfifo(p),  # the read blocked forever
    lambda p: p.symlink_to(p.parent.parent / "elsewhere.json"),  # read outside OUT
    lambda p: p.write_text(json.dumps(_MARKER | {"outputs": 5})),  # TypeError
    lambda p: p.write_text(json.dumps(_MARKER | {"outputs": [1]})),  # TypeError
    lambda p: p.write_text(json.dumps(_MARKER | {"outputs": "speech.wav"})),
    lambda p: p.write_text(json.dumps(_MARKER | {"outputs": ["../elsewhere.json"]})),
    lambda p: p.write_text(json.dumps(_MARKER | {"outputs": [str(p.parent.parent / "x")]})),
    lambda p: p.write_text(json.dumps(_MARKER | {"outputs": ["a\x00b"]})),
    lambda p: p.write_text(json.dumps(_MARKER | {"outputs": ["link.wav"]})),  # a link out
], ids=["deep", "huge", "fifo", "symlink", "outputs-int", "outputs-ints", "outputs-str",
        "outputs-up", "outputs-absolute", "outputs-nul", "outputs-symlink"])
def test_a_crafted_marker_is_not_a_finished_line(tmp_path, make):
    """An output folder from someone else: each marker was a traceback, a hang, or a
    read (or a look) outside the output folder; now the line is just not finished."""
    folder = tmp_path / "out" / "a"
    folder.mkdir(parents=True)
    (folder / "speech.wav").write_bytes(b"x")
    for name in ("elsewhere.json", "x"):  # finished markers and outputs outside the folder
        (tmp_path / "out" / name).write_text(json.dumps(_MARKER | {"outputs": []}))
    (folder / "link.wav").symlink_to(tmp_path / "out" / "x")
    make(folder / DONE)
    assert finished(folder, "k1") is None


_MARKER = {"key": "k1", "outputs": ["speech.wav"], "row": {"id": "a", "status": "done"}}


def test_a_line_folder_linking_out_of_the_output_folder_is_that_lines_error(tiny_db,
                                                                            tmp_path):
    # its files were written where the link points; a marker's row named another line
    outside = tmp_path / "outside"
    outside.mkdir()
    script = tmp_path / "lines.csv"
    script.write_text("id,text\na,Hi\nb,Hello\n")
    (tmp_path / "out" / "b").mkdir(parents=True)
    (tmp_path / "out" / "a").symlink_to(outside)
    # b finished, by its marker, but the marker's row names another line
    key = line_key(read_script(script)[1], database_identity(tiny_db[0])[1], FILES)
    (tmp_path / "out" / "b" / DONE).write_text(json.dumps(
        {"key": key, "outputs": [], "row": {"id": "a", "status": "done"}}))
    result = run_batch(script, BatchOptions(db=tiny_db[0], out=tmp_path / "out", workers=1))
    assert [(r["id"], r["status"]) for r in result.rows] == [("a", "failed"), ("b", "skipped")]
    assert "output folder" in result.rows[0]["error"] and "is a symbolic link" in \
        result.rows[0]["error"]
    assert not list(outside.iterdir())


def test_the_key_follows_inputs_recording_and_database(tmp_path):
    rec = tmp_path / "a.wav"
    rec.write_bytes(b"one")
    line = ScriptLine(id="a", text="Hi", line_no=2, audio=rec)
    key = line_key(line, "v000001:abc", FILES)
    assert key == line_key(line, "v000001:abc", FILES)
    assert key != line_key(line, "v000002:def", FILES)
    assert key != line_key(line, "v000001:abc", ("motion.c3d", "motion.npz"))
    assert key != line_key(ScriptLine(id="a", text="Hi!", line_no=2, audio=rec),
                           "v000001:abc", FILES)
    # the render is not the motion's: it has a key of its own, on the motion's
    assert render_key(key, "mp4") != render_key(key, "none")
    rec.write_bytes(b"two")
    assert key != line_key(line, "v000001:abc", FILES)
    assert render_key(line_key(line, "v000001:abc", FILES), "mp4") != render_key(key, "mp4")


def test_run_line_in_process(tiny_db, tmp_path):
    """A worker's job, without the cluster: a stale marker goes first, a bad emotion fails
    the line with its reason, and the model is loaded once for both lines."""
    from animegraph.apps import batch_line

    db = tiny_db[0]
    version, identity = database_identity(db)
    folder = tmp_path / "out" / "a"
    folder.mkdir(parents=True)
    (folder / DONE).write_text("{}")
    (folder / ".speech.wav.0123.tmp").write_bytes(b"half")

    def task(emotion):
        line = ScriptLine(id="a", text="Bob moved the vase.", line_no=2,
                          emotion=parse_emotion(emotion))
        return LineTask(line=line, db=str(db), db_version=version, folder=str(folder),
                        render="none", key=line_key(line, identity, FILES))

    bad = run_line(task("bored"))
    assert bad["status"] == "failed"
    assert "unknown emotion 'bored': it is not in the database" in bad["error"]
    assert not (folder / DONE).exists() and not list(folder.glob(".*.tmp"))
    good = run_line(task("angry"))
    assert good["status"] == "done" and good["emotion"] == "angry", good
    assert good["_loads"] == 1
    assert finished(folder, task("angry").key)["jumps"] == good["jumps"]
    with pytest.raises(DataError, match="changed during the batch"):
        batch_line._MODELS.clear()
        batch_line.worker_model(str(db), "v000999")


def test_run_line_reads_a_videos_sound_track(tiny_db, tiny_corpus, tmp_path):
    # A line's recording may be a video, as synth's may: it was read as a WAV and failed
    # with "corrupt or unreadable audio file ... Format not recognised".
    import subprocess

    import imageio_ffmpeg

    db = tiny_db[0]
    version, identity = database_identity(db)
    clip = sorted((tiny_corpus / "clips").glob("*_neutral_*.json"))[0]
    video = tmp_path / "take.mp4"
    subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-nostdin", "-v", "error", "-f",
                    "lavfi", "-i", "color=c=gray:s=64x48:r=25", "-i",
                    str(clip.with_suffix(".wav")), "-shortest", "-c:v", "libx264", "-c:a",
                    "aac", str(video)], check=True)
    folder = tmp_path / "out" / "v"
    line = ScriptLine(id="v", text=json.loads(clip.read_text())["text"], line_no=2,
                      audio=video)
    row = run_line(LineTask(line=line, db=str(db), db_version=version, folder=str(folder),
                            render="none", key=line_key(line, identity, FILES)))
    assert row["status"] == "done", row
    audio, rate = read_wav(folder / "speech.wav")
    wav, wav_rate = read_wav(clip.with_suffix(".wav"))
    assert rate == wav_rate and abs(len(audio) / rate - len(wav) / wav_rate) < 0.1


def test_emotions_are_checked_before_any_worker_starts(tiny_db, tmp_path):
    # An emotion the database lacks failed its line only on a worker, after the
    # cluster's start-up; a script of such lines started a cluster for nothing.
    script = tmp_path / "s.csv"
    script.write_text("id,emotion,voice,text\n"
                      "a,bored,,Hello there.\n"
                      "b,\"bored=0.5,happy=0.5\",,Hello there.\n"
                      "c,happy,en-xx,Hello there.\n")  # and a voice eSpeak NG lacks
    result = run_batch(script, BatchOptions(db=tiny_db[0], out=tmp_path / "out", workers=1))
    assert result.n_workers == 0  # no cluster
    assert [r["status"] for r in result.rows] == ["failed", "failed", "failed"]
    for row in result.rows[:2]:
        assert row["error"].startswith("unknown emotion 'bored': it is not in the database "
                                       "(it has angry, frustrated, happy, neutral, sad)")
    assert result.rows[2]["error"] == "voice name 'en-xx' is not an eSpeak NG voice"
    assert [r["status"] for r in read_report(result.report)] == ["failed"] * 3


def test_a_database_without_emotion_labels_fails_emotion_lines_at_once(unlabelled_db,
                                                                       tmp_path):
    # Each line failed on a worker after its start-up with "unknown emotion 'happy': it is
    # not in the database (it has unknown)".
    script = tmp_path / "s.csv"
    script.write_text("id,emotion,text\n"
                      "a,happy,Hello there.\n"
                      "b,auto,Hello there.\n"
                      "c,\"happy=0.7,neutral=0.3\",Hello there.\n")
    result = run_batch(script, BatchOptions(db=unlabelled_db, out=tmp_path / "out"))
    assert result.n_workers == 0
    errors = [r["error"] for r in result.rows]
    assert errors == [
        "unknown emotion 'happy': the database has no emotions (its clips carry no emotion "
        "labels): leave the emotion out",
        "the database has no emotion classifier (its clips carry no emotion labels): leave "
        "the emotion out instead of 'auto'",
        "unknown emotion 'happy': the database has no emotions (its clips carry no emotion "
        "labels): leave the emotion out"]


# --------------------------------------------------------------------------- the cluster


@pytest.fixture
def dialogue(tiny_corpus, tmp_path):
    """A script of five lines: spoken by eSpeak, recorded, mixed, and two that fail."""
    clip = sorted((tiny_corpus / "clips").glob("*_neutral_*.json"))[0]
    (tmp_path / "rec").mkdir()
    shutil.copy(clip.with_suffix(".wav"), tmp_path / "rec" / "take.wav")
    text = json.loads(clip.read_text())["text"]
    script = tmp_path / "dialogue.csv"
    with script.open("w", newline="") as handle:
        csv.writer(handle).writerows([
            ("id", "speaker", "emotion", "audio", "window", "text"),
            ("hello", "tutor", "happy", "", "3", "Bob moved the warm vase away."),
            ("recorded", "student", "neutral", "rec/take.wav", "", text),
            ("mixed", "tutor", "happy=0.7,neutral=0.3", "", "", "Pam sang a tune."),
            ("bored", "tutor", "bored", "", "", "This line has an emotion the database lacks."),
            ("lost", "student", "", "rec/missing.wav", "", "This recording is missing."),
            ("silent", "student", "", "", "", "..."),
        ])
    return script


def test_batch_on_a_two_worker_cluster(tiny_db, dialogue, tmp_path, capsys):
    db = tiny_db[0]
    out = tmp_path / "out"
    result = run_batch(dialogue, BatchOptions(db=db, out=out, workers=2))
    rows = {r["id"]: r for r in read_report(out / "report.csv")}
    assert list(rows) == ["hello", "recorded", "mixed", "bored", "lost", "silent"]
    assert result.n_workers == 2
    assert result.loads and set(result.loads.values()) == {1}  # one load per worker process
    assert not result.ok

    hello = rows["hello"]
    assert hello["status"] == "done" and hello["speech"] == "espeak", hello
    assert (hello["emotion"], hello["emotion_source"]) == ("happy", "given")
    assert float(hello["duration_s"]) > 1 and int(hello["jumps"]) >= 0
    folder = out / "hello"
    audio, sr = read_wav(folder / "speech.wav")
    motion = read_c3d(folder / "motion.c3d")
    assert abs(len(motion.points) / motion.rate - len(audio) / sr) < 0.05
    # The phone timing is eSpeak's own, not an alignment.
    truth = speak("Bob moved the warm vase away.", STYLES["happy"].voice).phones
    phones = read_phones_csv(folder / "phones.csv")
    assert [p.phone for p in phones] == [p.phone for p in truth]
    assert np.allclose([p.end for p in phones], [p.end for p in truth], atol=1e-5)
    record = json.loads((folder / "explain.json").read_text())
    assert record["method"] == "window" and record["segmentation"] == "labels"
    assert record["emotion"] == {"requested": "happy", "source": "given", "used": "happy"}
    assert len(record["phones"]) == len(phones)

    recorded = rows["recorded"]
    assert recorded["status"] == "done" and recorded["speech"] == "recording", recorded
    assert json.loads((out / "recorded" / "explain.json").read_text())["segmentation"] \
        == "aligned"

    mixed = rows["mixed"]
    assert mixed["emotion_source"] == "mix"
    assert mixed["status"] == "done" and mixed["emotion"] == "happy=0.70,neutral=0.30", mixed
    assert rows["bored"]["status"] == "failed"
    assert "unknown emotion 'bored': it is not in the database" in rows["bored"]["error"]
    assert rows["lost"]["status"] == "failed"
    assert rows["lost"]["error"].startswith("audio file not found")
    assert "eSpeak NG produced no speech" in rows["silent"]["error"]
    for name in ("bored", "lost", "silent"):
        assert not (out / name / DONE).exists()

    # Re-run: the finished lines are skipped (no cluster starts), the failed ones fail again.
    done_only = tmp_path / "done.csv"
    done_only.write_text("\n".join(dialogue.read_text().splitlines()[:3]) + "\n")
    before = (folder / DONE).stat().st_mtime_ns
    lost = tmp_path / "lost.jsonl"
    lost.write_text('{"id": "lost", "text": "Missing.", "audio": "rec/missing.wav"}\n')
    capsys.readouterr()
    assert main(["batch", str(done_only), "--db", str(db), "--out", str(out), "--quiet"]) == 0
    assert "0 made, 2 skipped" in capsys.readouterr().out
    assert main(["batch", str(lost), "--db", str(db), "--out", str(out), "--quiet"]) == 1
    assert "failed lost: audio file not found" in capsys.readouterr().out
    assert (folder / DONE).stat().st_mtime_ns == before

    # --force redoes a finished line (here on a one-worker cluster).
    said = []
    again = run_batch(done_only, BatchOptions(db=db, out=out, workers=1, force=True),
                      say=said.append)
    assert [r["status"] for r in again.rows] == ["done", "done"]
    # The kernels compiled by the first run are only loaded now (it said "compiling").
    assert "loading the search in this process before the workers start ..." in said
    assert not any("compiling" in line for line in said), said
    assert again.n_workers == 1 and (folder / DONE).stat().st_mtime_ns > before
    assert [str(r["jumps"]) for r in again.rows] == [rows["hello"]["jumps"],
                                                rows["recorded"]["jumps"]]


def test_an_unreachable_scheduler_is_one_line(tiny_db, tmp_path, capsys):
    script = tmp_path / "s.csv"
    script.write_text("id,text\na,Hello there.\n")
    code = main(["batch", str(script), "--db", str(tiny_db[0]), "--out",
                 str(tmp_path / "new" / "out"), "--scheduler", "tcp://127.0.0.1:9"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1 and len(err) == 1, err
    assert err[0].startswith("animegraph: error: cannot reach the Dask scheduler at "
                              "tcp://127.0.0.1:9")
    assert not (tmp_path / "new").exists()  # no folder, lock or report of "not run" lines
    # An output folder that was there keeps what it had: its report is not overwritten.
    out = tmp_path / "old"
    out.mkdir()
    (out / "report.csv").write_text("id,status\na,done\n")
    code = main(["batch", str(script), "--db", str(tiny_db[0]), "--out", str(out),
                 "--scheduler", "tcp://127.0.0.1:9"])
    assert code == 1 and len(capsys.readouterr().err.strip().splitlines()) == 1
    assert (out / "report.csv").read_text() == "id,status\na,done\n"


def test_a_malformed_scheduler_address_is_one_line_at_once(tiny_db, tmp_path):
    # The Client that failed to connect was left to the garbage collector: at exit it
    # waited 10 s and printed "Exception ignored in: Client.__del__" with a traceback.
    import os
    import subprocess
    import sys
    import time

    script = tmp_path / "s.csv"
    script.write_text("id,text\na,Hello there.\n")
    t0 = time.monotonic()
    done = subprocess.run([sys.executable, "-m", "animegraph", "batch", str(script), "--db",
                           str(tiny_db[0]), "--out", str(tmp_path / "out"), "--scheduler",
                           "nonsense"], capture_output=True, text=True, env=dict(os.environ),
                          timeout=120)
    err = done.stderr.strip().splitlines()
    assert done.returncode == 1 and len(err) == 1, done.stderr
    assert err[0].startswith("animegraph: error: cannot reach the Dask scheduler at "
                              "nonsense: missing port number")
    assert time.monotonic() - t0 < 9
    assert not (tmp_path / "out").exists()


def test_run_line_renders_an_mp4_preview(tiny_db, tmp_path):
    import imageio_ffmpeg

    db = tiny_db[0]
    version, identity = database_identity(db)
    folder = tmp_path / "out" / "a"
    folder.mkdir(parents=True)
    line = ScriptLine(id="a", text="Bob moved the vase.", line_no=2,
                      emotion=parse_emotion("happy"))
    row = run_line(LineTask(line=line, db=str(db), db_version=version, folder=str(folder),
                            render="mp4", key=line_key(line, identity, FILES)))
    assert row["status"] == "done", row
    preview = folder / "preview.mp4"
    assert rendered(folder, line_key(line, identity, FILES), "mp4")
    n_frames, seconds = imageio_ffmpeg.count_frames_and_secs(str(preview))
    assert n_frames > 10 and abs(seconds - row["duration_s"]) < 0.5
    assert not list(folder.glob(".*.tmp*"))


def test_changing_the_render_renders_the_stored_motion(tiny_db, tmp_path):
    """--render was part of each line's key: turning it on (or off) synthesized every line
    again. Now the motion's key leaves the render out, and the render has its own."""
    db = tiny_db[0]
    script = tmp_path / "s.csv"
    script.write_text("id,emotion,text\na,happy,Bob moved the vase.\nb,sad,Pam sang.\n")
    out = tmp_path / "out"
    first = run_batch(script, BatchOptions(db=db, out=out, workers=1))
    assert [r["status"] for r in first.rows] == ["done", "done"]
    made = {p: p.stat().st_mtime_ns for p in out.glob("[ab]/*") if p.name != DONE}
    assert len(made) == 8

    with_preview = run_batch(script, BatchOptions(db=db, out=out, workers=1, render="mp4"))
    assert [r["status"] for r in with_preview.rows] == ["rendered", "rendered"]
    assert with_preview.loads == {}  # no worker loaded the Anime Graph: nothing synthesized
    assert {p: p.stat().st_mtime_ns for p in made} == made
    assert [r["jumps"] for r in with_preview.rows] == [r["jumps"] for r in first.rows]
    assert "0 made, 2 rendered from stored motion" in with_preview.summary()[0]
    preview = out / "a" / "preview.mp4"
    rendered_at = preview.stat().st_mtime_ns

    # Off, and on again: nothing to do, no cluster; the preview stays, and what a render
    # cut short left goes.
    (out / "b" / ".preview.0123.tmp.mp4").write_bytes(b"half")
    for render in ("none", "mp4"):
        again = run_batch(script, BatchOptions(db=db, out=out, workers=1, render=render))
        assert [r["status"] for r in again.rows] == ["skipped", "skipped"], render
        assert again.n_workers == 0 and preview.stat().st_mtime_ns == rendered_at
        assert not list((out / "b").glob(".*"))

    # A Ctrl-C (here as the workers are up) leaves the report of what was done.
    with script.open("a") as handle:
        handle.write("c,,Pam sang a tune.\n")

    def interrupt(news: str) -> None:
        if "to make" in news:
            raise KeyboardInterrupt

    with pytest.raises(BatchInterrupted) as stop:
        run_batch(script, BatchOptions(db=db, out=out, workers=1, render="mp4"), say=interrupt)
    assert [r["status"] for r in stop.value.result.rows] == ["skipped", "skipped", "not run"]
    assert [r["status"] for r in read_report(out / "report.csv")] == [
        "skipped", "skipped", "not run"]
    assert "0 made, 2 skipped (finished before), 0 failed, 1 not run" in \
        stop.value.result.summary()[0]

    # A render interrupted after its old record was dropped: rendered again, alone.
    marker = json.loads((out / "a" / DONE).read_text())
    key = marker.pop("render") and marker["key"]
    (out / "a" / DONE).write_text(json.dumps(marker))
    assert finished(out / "a", key) is not None and not rendered(out / "a", key, "mp4")
    line = read_script(script)[0]
    row = run_line(LineTask(line=line, db=str(db), db_version=database_identity(db)[0],
                            folder=str(out / "a"), render="mp4", key=key,
                            motion_files=FILES, synthesize=False))
    assert row["status"] == "rendered" and "_loads" not in row, row
    assert rendered(out / "a", key, "mp4") and preview.stat().st_mtime_ns > rendered_at
    assert {p: p.stat().st_mtime_ns for p in made} == made


def test_a_line_made_again_keeps_no_file_of_the_earlier_run(tiny_db, tmp_path):
    # A preview (or another motion format) of the earlier motion stayed beside the new
    # motion, taken for this run's.
    db = tiny_db[0]
    version, identity = database_identity(db)
    folder = tmp_path / "out" / "a"
    folder.mkdir(parents=True)
    for name in ("preview.mp4", "motion.csv", "motion.npz"):
        (folder / name).write_bytes(b"old")
    line = ScriptLine(id="a", text="Bob moved the vase.", line_no=2)
    row = run_line(LineTask(line=line, db=str(db), db_version=version, folder=str(folder),
                            render="none", key=line_key(line, identity, FILES),
                            motion_files=FILES))
    assert row["status"] == "done", row
    assert sorted(p.name for p in folder.iterdir()) == [
        DONE, "explain.json", "motion.c3d", "phones.csv", "speech.wav"]


def test_a_failed_render_keeps_the_motion_for_the_next_run(tiny_db, tmp_path):
    # A line whose render failed lost its motion too: the next run synthesized it again.
    db = tiny_db[0]
    version, identity = database_identity(db)
    folder = tmp_path / "out" / "a"
    line = ScriptLine(id="a", text="Bob moved the vase.", line_no=2)
    key = line_key(line, identity, FILES)

    def task(synthesize: bool) -> LineTask:
        return LineTask(line=line, db=str(db), db_version=version, folder=str(folder),
                        render="mp4", key=key, motion_files=FILES, synthesize=synthesize)

    assert run_line(task(True))["status"] == "done"
    (folder / "preview.mp4").unlink()
    (folder / "preview.mp4").mkdir()  # the render cannot be put in its place
    row = run_line(task(False))
    assert row["status"] == "failed" and row["error"].startswith(
        "rendering preview.mp4 failed (the motion is made: the next run only renders): "), row
    assert finished(folder, key) is not None and not rendered(folder, key, "mp4")
    (folder / "preview.mp4").rmdir()
    assert run_line(task(False))["status"] == "rendered" and rendered(folder, key, "mp4")


def test_a_batch_writes_the_motion_formats_synth_writes(tiny_db, tmp_path):
    # A batch wrote one format per kind of database (C3D of markers, CSV of landmarks):
    # no C3D of a landmark database's points, no NPZ, where synth -o writes them.
    from animegraph.apps.batch_markers import motion_files
    from animegraph.motion.files import read_motion

    db = tiny_db[0]
    names = Database.open(db).table("channels").column("name").to_pylist()
    assert motion_files((), names, "markers") == FILES
    files = motion_files(("npz", "csv", "c3d", "npz"), names, "markers")
    assert files == ("motion.c3d", "motion.csv", "motion.npz")  # one order: one key
    points = [f"lm{i}.{a}" for i in range(3) for a in "xyz"]
    landmarks = points + ["pose.rx", "pose.ry", "pose.rz", "pose.tx", "pose.ty", "pose.tz",
                          "pose.scale"]
    assert motion_files((), landmarks, "landmarks") == ("motion.csv",)  # keeps the pose
    assert motion_files(("c3d",), landmarks, "landmarks") == ("motion.c3d",)
    with pytest.raises(ParameterError, match=r"^--motion-format c3d: C3D holds 3D points; "
                                             r"this database has curves"):
        motion_files(("c3d",), ["jaw_open", "mouth_oh"], "curves")

    version, identity = database_identity(db)
    folder = tmp_path / "out" / "a"
    line = ScriptLine(id="a", text="Bob moved the vase.", line_no=2)
    row = run_line(LineTask(line=line, db=str(db), db_version=version, folder=str(folder),
                            render="mp4", key=line_key(line, identity, files),
                            motion_files=files))
    assert row["status"] == "done", row
    motions = [read_motion(folder / name) for name in files]
    for motion in motions[1:]:
        assert motion.names == motions[0].names
        np.testing.assert_allclose(motion.values, motions[0].values, rtol=1e-4, atol=1e-3)
    assert rendered(folder, line_key(line, identity, files), "mp4")


def test_a_format_the_database_cannot_hold_is_one_line_before_any_work(tiny_db, tmp_path,
                                                                       capsys):
    script = tmp_path / "s.csv"
    script.write_text("id,text\na,Hello there.\n")
    for formats, message in (
            ("c3d,livelink", "--motion-format livelink: Live Link Face CSV needs a database "
                             "of ARKit blendshapes"),
            ("fbx", "motion format must be one of c3d, csv, npz, livelink, got 'fbx'")):
        code = main(["batch", str(script), "--db", str(tiny_db[0]), "-o",
                     str(tmp_path / "out"), "--motion-format", formats])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 1 and len(err) == 1 and message in err[0], err
        assert not (tmp_path / "out").exists()


def test_a_recording_whose_transcript_does_not_fit_goes_as_speech_alone(tiny_db, tiny_corpus,
                                                                      tmp_path):
    """As ``synth`` does: the speech alone, guided by the stored speech-alone guide (here
    mu-mlp; ppg-ridge is not fitted, and the row says so); the same motion as synthesizing
    the recording without a transcript."""
    from animegraph.baselines import make_estimator
    from animegraph.baselines.base import save_model
    from animegraph.baselines.stored import load_forward
    from animegraph.synthesis import Model, synthesize
    from animegraph.synthesis.path import AUDIO_ONLY_K_BEST
    from db.store import Database
    from ingest.tables import prepared_from_database

    db = tmp_path / "db"
    # Without the guides earlier tests may have fitted into the shared database on first use.
    shutil.copytree(tiny_db[0], db, ignore=shutil.ignore_patterns("baselines"))
    save_model(make_estimator("mu-mlp", n_mfcc=6, context=1, subset_hidden=(3, 4),
                              expression_hidden=4, frame_rate=60.0).fit(
        prepared_from_database(Database.open(db))), db)
    wav = sorted((tiny_corpus / "clips").glob("*_neutral_1.wav"))[0]
    version, identity = database_identity(db)
    folder = tmp_path / "out" / "r"
    line = ScriptLine(id="r", text="Nothing like what is said in it at all.", line_no=2,
                      audio=wav)
    row = run_line(LineTask(line=line, db=str(db), db_version=version, folder=str(folder),
                            render="none", key=line_key(line, identity, FILES)))
    assert row["status"] == "done", row
    assert row["warnings"].startswith("transcript alignment failed: "), row["warnings"]
    assert "without the speech-alone guide ppg-ridge (not fitted: animegraph fit --method " \
           "ppg-ridge" in row["warnings"]
    assert row["path"].startswith("audio only (the transcript does not fit the recording)")
    assert "mu-mlp's predicted motion" in row["path"]
    assert json.loads((folder / "explain.json").read_text())["guide"] == "mu-mlp"
    audio, sr = read_wav(wav)
    alone = synthesize(Model.load(db), audio, sr, k_best=AUDIO_ONLY_K_BEST,
                       guide=load_forward(db, "mu-mlp"))
    written = read_c3d(folder / "motion.c3d").points
    np.testing.assert_allclose(written.reshape(len(written), -1), alone.motion, atol=1e-3)

    # Finished, until the guide it lacked is fitted: then the line is made again.
    from animegraph.apps.batch_markers import guide_state

    def stored(parts):
        return guide_state(db, parts)

    assert finished(folder, line_key(line, identity, FILES), stored) is not None
    save_model(make_estimator("ppg-ridge").fit(prepared_from_database(Database.open(db))), db)
    assert finished(folder, line_key(line, identity, FILES), stored) is None
    # A line whose transcript fits records no guide: fitting one does not remake it.
    fits = ScriptLine(id="f", text=json.loads(wav.with_suffix(".json").read_text())["text"],
                      line_no=3, audio=wav)
    row = run_line(LineTask(line=fits, db=str(db), db_version=version,
                            folder=str(tmp_path / "out" / "f"), render="none",
                            key=line_key(fits, identity, FILES)))
    assert row["status"] == "done" and row["warnings"] == "", row
    assert "guides" not in json.loads((tmp_path / "out" / "f" / DONE).read_text())
    # Guide names from the output folder are only those of stored guides.
    marker = json.loads((folder / DONE).read_text())
    (folder / DONE).write_text(json.dumps({**marker, "guides": {"../../x": None}}))
    assert finished(folder, line_key(line, identity, FILES), stored) is None


def test_a_script_reads_no_recording_outside_its_folder(tmp_path):
    # A line's speech.wav is its recording: a script from others naming ../private.wav,
    # an absolute path or a symlink out would copy that file into the output folder
    private = tmp_path / "private.wav"
    private.write_bytes(b"RIFF")
    folder = tmp_path / "script"
    (folder / "rec").mkdir(parents=True)
    (folder / "rec" / "link.wav").symlink_to(private)
    script = folder / "lines.csv"
    for audio in ("../private.wav", str(private), "rec/../../private.wav", "rec/link.wav"):
        script.write_text(f"id,text,audio\na,Hi,{audio}\n")
        with pytest.raises(ScriptError, match=rf"lines\.csv line 2: audio '{audio}' is "
                                              r"outside the script's folder"):
            read_script(script)
    script.write_text("id,text,audio\na,Hi,rec/./b.wav\n")
    assert read_script(script)[0].audio == (folder / "rec" / "b.wav").absolute()


def test_a_recording_in_a_lines_output_folder_is_refused(tiny_db, tmp_path):
    # --out the script's folder and a line named like the recordings' folder: the line's
    # speech.wav would replace the recording rec/speech.wav (of this line or another)
    (tmp_path / "rec").mkdir()
    script = tmp_path / "lines.csv"
    script.write_text("id,text,audio\nrec,Hi,\nb,Hello,rec/speech.wav\n")
    with pytest.raises(ParameterError, match=r"lines\.csv line 3: its audio .*rec/speech\.wav "
                                             r"is in the output folder of line 'rec'"):
        run_batch(script, BatchOptions(db=tiny_db[0], out=tmp_path, workers=1))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lines.csv", "rec"]


def test_a_guide_that_could_not_be_fitted_says_why_in_a_batch(tiny_db, tmp_path):
    """A batch said 'not fitted: animegraph fit ...' of the guide synth had found cannot
    be fitted on the database (a fit that fails again): it says why, as synth does."""
    from animegraph.apps.batch_line import worker_guide
    from animegraph.baselines.stored import record_unfit

    db = tmp_path / "db"
    shutil.copytree(tiny_db[0], db, ignore=shutil.ignore_patterns("baselines"))
    record_unfit(db, "mu-mlp", "too little data for mu-mlp's speech-to-face network")
    version, _ = database_identity(db)
    guide, lacking, _ = worker_guide(str(db), version, "mu-mlp+ppg-ridge")
    assert guide is None and lacking == [
        "mu-mlp (could not be fitted: too little data for mu-mlp's speech-to-face network)",
        f"ppg-ridge (not fitted: animegraph fit --method ppg-ridge --db {db})"]


def test_emotion_auto_needs_the_lines_recording(tiny_db, tmp_path):
    # A line spoken by eSpeak NG was classified (its neutral voice came out "frustrated")
    # and synthesized with that emotion without a word
    script = tmp_path / "s.csv"
    script.write_text("id,emotion,text\na,auto,Hello there.\n")
    result = run_batch(script, BatchOptions(db=tiny_db[0], out=tmp_path / "out"))
    assert result.n_workers == 0
    assert [r["error"] for r in result.rows] == [
        "emotion auto is heard in the line's recording, and it has none (eSpeak NG speaks "
        "it): name the emotion, or give audio"]


def test_a_local_batch_leaves_port_8787_alone(tmp_path):
    # The local cluster's scheduler took 8787 (Dask's dashboard port) and, when another
    # cluster had it, warned "Port 8787 is already in use".
    import socket
    import warnings

    from animegraph.apps.batch_cluster import _client

    holder = socket.socket()
    try:
        holder.bind(("", 8787))
        holder.listen()
    except OSError:  # another cluster has it: as much the case to test
        pass
    with warnings.catch_warnings(record=True) as caught, holder:
        warnings.simplefilter("always")
        with _client(BatchOptions(db=tmp_path, out=tmp_path, workers=1), None) as client:
            port = client.cluster.scheduler.http_server.port
    assert not [w for w in caught if "8787" in str(w.message)], [str(w.message) for w in caught]
    assert port != 8787


def test_the_report_is_written_as_lines_finish(tiny_db, tmp_path, monkeypatch):
    # report.csv was written only when the batch ended: after a SIGKILL it was missing,
    # or the previous run's.
    import animegraph.apps.batch as batch

    monkeypatch.setattr(batch, "REPORT_EVERY_S", 0.0, raising=False)  # every line
    script = tmp_path / "lines.csv"
    script.write_text("id,text\na,Hi\nb,Hello\n")
    out = tmp_path / "out"
    seen = []

    def progress(total):
        def watch(finished_lines):
            for item in finished_lines:  # the report as it is when a line comes back
                seen.append(sorted(r["status"] for r in read_report(out / "report.csv")))
                yield item
        return watch

    run_batch(script, BatchOptions(db=tiny_db[0], out=out, workers=1), progress=progress)
    assert seen == [["not run", "not run"], ["done", "not run"]]
    assert [r["status"] for r in read_report(out / "report.csv")] == ["done", "done"]
