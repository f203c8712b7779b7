"""``animegraph query``: SQL-expressible search of a real database, and export."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from animegraph.apps.cli import main
from animegraph.apps.query import (
    ClipData,
    QuerySpec,
    _write_snippet,
    build_sql,
    find_speaker,
    run_query,
)
from db.errors import ParameterError
from db.sql import query as run_sql
from db.store import Database
from ingest.formats.c3d import read_c3d
from ingest.formats.phones_csv import read_phones_csv
from ingest.formats.wav import read_wav


@pytest.fixture(scope="module")
def db(tiny_db):
    return Database.open(tiny_db[0])


def test_query_is_the_same_as_its_sql(db, tiny_db, capsys):
    spec = QuerySpec(phoneme="aa", emotion="angry", order_by="duration", descending=True,
                     limit=5)
    hits = run_query(db, spec)
    assert 0 < hits.num_rows <= 5
    rows = hits.to_pylist()
    assert all(r["phoneme"] == "AA" and r["emotion"] == "angry" for r in rows)
    durations = [r["duration"] for r in rows]
    assert durations == sorted(durations, reverse=True)
    # The same SQL through `animegraph sql` gives the same table.
    sql = build_sql(spec)
    assert run_sql(db, sql).equals(hits)
    assert main(["sql", "--db", str(tiny_db[0]), "--format", "csv", sql]) == 0
    via_sql = capsys.readouterr().out
    assert main(["query", "--db", str(tiny_db[0]), "--phoneme", "AA", "--emotion", "angry",
                 "--order-by", "duration", "--desc", "--limit", "5", "--format", "csv"]) == 0
    assert capsys.readouterr().out == via_sql
    assert main(["query", "--db", str(tiny_db[0]), "--phoneme", "AA", "--emotion", "angry",
                 "--order-by", "duration", "--desc", "--limit", "5", "--show-sql"]) == 0
    assert capsys.readouterr().out.strip() == sql


def test_shown_sql_finds_what_the_query_finds(db, tiny_db, capsys):
    # --show-sql printed the emotion and speaker as typed ('ANGRY', 'SYNTH'), which the
    # query matches in the database's spelling and the SQL did not match at all.
    argv = ["query", "--db", str(tiny_db[0]), "--emotion", "ANGRY", "--speaker", "SYNTH",
            "--phoneme", "aa", "--limit", "3"]
    assert main([*argv, "--show-sql"]) == 0
    sql = capsys.readouterr().out
    assert "emotion = 'angry'" in sql and "speaker = 'synth01'" in sql
    assert run_sql(db, sql).num_rows == 3


def test_every_filter(db):
    text_hits = run_query(db, QuerySpec(text="the young", limit=None)).to_pylist()
    assert text_hits and all("young" in r["text"].lower().split() for r in text_hits)
    # punctuation around a word is not part of it, as when a transcript is read ("boat,"
    # was refused)
    assert run_query(db, QuerySpec(text='"The, young!"', limit=None)).to_pylist() == text_hits
    long = run_query(db, QuerySpec(min_dur=0.15, limit=None)).to_pylist()
    assert long and all(r["duration"] >= 0.15 - 1e-4 for r in long)
    speaker = run_query(db, QuerySpec(speaker="synth01", limit=3))
    assert speaker.num_rows == 3
    # any case, or a part of the name: a label may carry a note ("Barack Obama (as named
    # in file)" in talkingface)
    assert run_query(db, QuerySpec(speaker="SYNTH", limit=3)).equals(speaker)
    clips = run_query(db, QuerySpec(clips=True, phoneme="ZH", min_dur=2.0, emotion="sad",
                                    order_by="duration", limit=None)).to_pylist()
    for row in clips:
        assert row["emotion"] == "sad" and row["duration"] >= 2.0
        phones = db.table("clips").filter(
            __import__("pyarrow.compute").compute.field("clip_id") == row["clip_id"]
        ).column("phones")[0].as_py().split()
        assert "ZH" in phones


@pytest.mark.parametrize("spec, needle", [
    (QuerySpec(phoneme="XX"), "ARPAbet"),
    (QuerySpec(order_by="loudness"), "--order-by"),
    (QuerySpec(limit=0), "--limit"),
    (QuerySpec(text="; --"), "--text '; --' holds no word"),
    (QuerySpec(min_dur=-1), "--min-dur"),
    (QuerySpec(emotion="bored"), "not in the database"),
    # an unknown speaker listed nothing, without a word
    (QuerySpec(speaker="synth02"), "unknown speaker 'synth02': the database has synth01"),
])
def test_bad_queries(db, spec, needle):
    with pytest.raises(ParameterError, match=needle):
        run_query(db, spec)


def test_quotes_cannot_escape_the_sql(db):
    assert run_sql(db, build_sql(QuerySpec(speaker="x' OR '1'='1"))).num_rows == 0


def test_a_speaker_is_found_by_a_part_of_its_name():
    known = ["Barack Obama (as named in file)", "US senator (not named)",
             "US congressman (not named)", None, "us"]
    assert find_speaker("obama", known) == "Barack Obama (as named in file)"
    assert find_speaker("US", known) == "us"  # its own name before a part of another's
    with pytest.raises(ParameterError, match="'senat' names 2 speakers") as err:
        find_speaker("senat", known[:3] + ["Senator Two"])
    assert "Senator Two; US senator (not named)" in str(err.value)
    with pytest.raises(ParameterError, match="clips name no speaker"):
        find_speaker("x", [None])


def test_export(db, tiny_db, tiny_corpus, tmp_path, capsys):
    out = tmp_path / "export"
    argv = ["query", "--db", str(tiny_db[0]), "--phoneme", "AA", "--emotion", "happy",
            "--limit", "2", "--context", "0.2", "--export", str(out)]
    assert main(argv) == 0
    capsys.readouterr()
    index = list(csv.DictReader((out / "index.csv").open()))
    assert len(index) == 2
    for row in index:
        assert (out / row["preview"]).read_bytes()[:4] == b"\x89PNG"
        motion = read_c3d(out / row["motion"])
        audio, rate = read_wav(out / row["audio"])
        start, end = float(row["snippet_start"]), float(row["snippet_end"])
        assert start <= float(row["start_time"]) - 0.2 + 1e-2
        assert end >= min(float(row["end_time"]) + 0.2 - 1e-2, end)
        assert motion.points.shape[0] == round((end - start) * motion.rate)
        assert abs(len(audio) / rate - (end - start)) < 2 / motion.rate
        phones = read_phones_csv(out / row["phones"])
        assert "AA" in [p.phone for p in phones]
        assert phones[0].start >= 0 and phones[-1].end <= end - start + 1e-3
        # The snippet is the recording itself (world coordinates), frame for frame.
        original = read_c3d(tiny_corpus / "clips" / f"{row['clip_id']}.c3d")
        f0 = round(start * original.rate)
        truth = original.points[f0:f0 + len(motion.points)]
        ok = np.isfinite(truth)
        assert np.abs(motion.points[ok] - truth[ok]).max() < 0.05
    # A snippet renders against its database; motion of other channels is refused.
    snippet = out / index[0]["motion"]
    assert main(["render", str(snippet), "--db", str(tiny_db[0]), "-o",
                 str(tmp_path / "snip.glb")]) == 0
    from animegraph.motion.files import write_channel_csv

    write_channel_csv(tmp_path / "other.csv", np.zeros((3, 3)), ["foo.x", "foo.y", "foo.z"],
                      30)
    capsys.readouterr()
    assert main(["render", str(tmp_path / "other.csv"), "--db", str(tiny_db[0]), "-o",
                 str(tmp_path / "other.glb")]) == 1
    assert "not the database's" in capsys.readouterr().err
    assert not (tmp_path / "other.glb").exists()
    # An existing folder is refused and left alone; --force replaces it.
    stamp = (out / "index.csv").stat().st_mtime_ns
    assert main(argv) == 1
    err = capsys.readouterr().err.strip()
    assert "--force" in err and len(err.splitlines()) == 1
    assert (out / "index.csv").stat().st_mtime_ns == stamp
    assert main([*argv[:-2], "--limit", "1", "--export", str(out), "--force"]) == 0
    assert len(list(csv.DictReader((out / "index.csv").open()))) == 1
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_export_of_clips_and_nothing_matched(tiny_db, tmp_path, capsys):
    out = tmp_path / "clips"
    assert main(["query", "--db", str(tiny_db[0]), "--clips", "--emotion", "sad", "--limit",
                 "1", "--export", str(out)]) == 0
    index = list(csv.DictReader((out / "index.csv").open()))
    assert len(index) == 1 and index[0]["snippet_start"] == "0.0"
    assert f"exported 1 hit to {out} (index.csv)" in capsys.readouterr().err  # not "1 hits"
    assert main(["query", "--db", str(tiny_db[0]), "--phoneme", "ZH", "--min-dur", "9",
                 "--export", str(tmp_path / "none")]) == 1
    assert "nothing matched" in capsys.readouterr().err
    assert not (tmp_path / "none").exists()


@pytest.mark.parametrize("extra, said, code", [
    (["--context", "-1"], "--context must be >= 0 seconds", 1),
    # a file is no folder to export into: refused as the option is read (the output check)
    (["--force"], "it is a file, not a folder", 2),
])
def test_an_export_that_cannot_be_written_is_refused_before_the_query(tiny_db, tmp_path,
                                                                     capsys, extra, said,
                                                                     code):
    # The table was printed first, then the error: as if the query had run and failed.
    (tmp_path / "afile").write_text("mine")
    out = tmp_path / ("afile" if "--force" in extra else "hits")
    assert main(["query", "--db", str(tiny_db[0]), "--phoneme", "AA", "--limit", "1",
                 "--export", str(out), *extra]) == code
    captured = capsys.readouterr()
    assert captured.out == "" and said in captured.err
    assert (tmp_path / "afile").read_text() == "mine" and not (tmp_path / "hits").exists()


def test_curve_snippets_are_csv(tmp_path):
    from animegraph.motion.files import read_motion

    clip = ClipData(motion=np.arange(20.0).reshape(10, 2), names=("jawOpen", "smile"),
                    groups=("lips", "lips"), kind="curves", fps=30.0,
                    audio=np.zeros(100, np.int16), sample_rate=16000, phones=[])
    name = _write_snippet(clip, 2, 6, tmp_path / "snip")
    assert name == "snip.csv"
    motion = read_motion(tmp_path / name)
    assert motion.names == ("jawOpen", "smile") and motion.fps == 30.0
    assert np.array_equal(motion.values, clip.motion[2:6])


def test_words_in_a_database_without_transcripts_are_an_error(tiny_db, tmp_path, capsys):
    # FACEGOOD, talkingface, an iPhone take: recognised phones, no words. `--text hello`
    # listed no hit and exit 0, as if the words were not said.
    from dataclasses import replace

    from ingest.pipeline import build_database
    from ingest.tables import prepared_from_database

    clips = [replace(c, text=None) for c in prepared_from_database(Database.open(tiny_db[0]))
             if c.sentence_id == "s0001"]
    build_database(tmp_path / "db", clips)
    assert main(["query", "--db", str(tmp_path / "db"), "--clips", "--text", "hello"]) == 1
    err = capsys.readouterr().err.strip()
    assert err.endswith("--text 'hello': the database's clips carry no transcript"), err
    assert main(["query", "--db", str(tmp_path / "db"), "--clips", "--limit", "1"]) == 0


def test_export_builds_the_face_once(tiny_db, tmp_path, monkeypatch, capsys):
    # Each hit's preview built the face's deformer anew (RBF systems per region): half of
    # a landmark database's export time (talkingface, 20 hits: 14.5 s, now 7.3 s).
    from animegraph.face import render

    calls = []
    real = render.deformer_for
    monkeypatch.setattr(render, "deformer_for", lambda names, **kw: calls.append(1)
                        or real(names, **kw))
    assert main(["query", "--db", str(tiny_db[0]), "--phoneme", "AA", "--limit", "3",
                 "--export", str(tmp_path / "hits")]) == 0
    assert len(calls) == 1
    assert len(list((tmp_path / "hits").glob("*.png"))) == 3


def test_export_quiet_has_no_progress_bar(tiny_db, tmp_path, capsys):
    # Every other command with a progress bar (ingest, render, batch, demo) takes --quiet;
    # query --export had none, and a script's log filled with bars.
    assert main(["query", "--db", str(tiny_db[0]), "--phoneme", "AA", "--limit", "2",
                 "--export", str(tmp_path / "hits"), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "exporting" not in err and "exported 2 hits" in err


def test_min_dur_keeps_what_the_table_shows_at_that_length(db):
    # A hit shown as 0.46 s was left out by --min-dur 0.46 when end - start came to
    # 0.45999999999 (FACEGOOD: 91.39 - 90.93); another shown as 0.46 was kept.
    rows = run_sql(db, "SELECT node_id, phoneme, end_time - start_time AS d FROM animes "
                       "WHERE round(end_time - start_time, 4) > end_time - start_time").to_pylist()
    assert rows, "no anime whose duration rounds up in the tiny database"
    hit = rows[0]
    shown = round(hit["d"], 4)
    hits = run_query(db, QuerySpec(phoneme=hit["phoneme"], min_dur=shown, limit=100000))
    assert hit["node_id"] in hits.column("node_id").to_pylist()
    assert min(hits.column("duration").to_pylist()) >= shown
