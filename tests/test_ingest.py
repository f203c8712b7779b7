"""``animegraph ingest`` end to end on the synthetic corpus, and the database it writes."""

from __future__ import annotations

import json
import logging
import re
import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest

from animegraph.apps.cli import main
from db.errors import DataError, ParameterError
from db.sql import query
from db.store import Database, current_version
from ingest.decompose import MotionDecomposer
from ingest.formats.phones_csv import read_phones_csv
from ingest.pipeline import ingest, prepare_sources
from ingest.readers import discover
from ingest.tables import prepared_from_database


def test_every_clip_goes_in(tiny_db, tiny_corpus):
    path, report = tiny_db
    n = len(list((tiny_corpus / "clips").glob("*.c3d")))
    assert report.count("added") == n and report.written
    db = Database.open(path)
    assert db.manifest["n_clips"] == n and db.manifest["fps"] == 120.0
    assert db.manifest["kind"] == "markers" and db.manifest["n_channels"] == 216
    assert len(list((path / "reports").glob("ingest-*.csv"))) == 1


def test_animes_are_the_ground_truth_phones_linked_in_order(tiny_db, tiny_corpus):
    db = Database.open(tiny_db[0])
    animes = db.table("animes").sort_by("node_id").to_pylist()
    by_clip = {}
    for a in animes:
        by_clip.setdefault(a["clip_id"], []).append(a)
    for clip_id, nodes in by_clip.items():
        truth = read_phones_csv(tiny_corpus / "clips" / f"{clip_id}.phones.csv")
        assert [a["phoneme"] for a in nodes] == [s.phone for s in truth]
        assert [a["position"] for a in nodes] == list(range(len(nodes)))
        assert nodes[0]["prev_node"] is None and nodes[-1]["next_node"] is None
        for a, b in zip(nodes, nodes[1:], strict=False):
            assert a["next_node"] == b["node_id"] and b["prev_node"] == a["node_id"]
            assert a["end_frame"] >= b["start_frame"] >= a["start_frame"]
    clips = {c["clip_id"]: c for c in db.table("clips").to_pylist()}
    assert {c["segmentation"] for c in clips.values()} == {"labels"}
    meta = json.loads((tiny_corpus / "clips" / f"{animes[0]['clip_id']}.json").read_text())
    assert clips[animes[0]["clip_id"]]["emotion"] == meta["emotion"]


def test_prosody_curves_are_nine_rasta_plp_coefficients(tiny_db):
    db = Database.open(tiny_db[0])
    animes = db.table("animes", columns=["prosody", "prosody_frames", "end_time",
                                         "start_time"]).to_pylist()
    for a in animes[:200]:
        assert len(a["prosody"]) == 9 * a["prosody_frames"] >= 9
        assert np.isfinite(a["prosody"]).all()
        assert a["prosody_frames"] <= round((a["end_time"] - a["start_time"]) / 0.01) + 2


def test_model_keeps_95_percent_and_reconstructs_the_frames(tiny_db):
    db = Database.open(tiny_db[0])
    model = MotionDecomposer.from_arrays(db.arrays())
    assert db.manifest["variance_kept"] >= 0.95
    names = db.table("channels").column("name").to_pylist()
    clip_id = db.table("clips").column("clip_id")[0].as_py()
    frames = db.table("frames").filter(
        pc.field("clip_id") == clip_id).sort_by("frame")
    motion = np.stack([frames.column(n).to_numpy() for n in names], axis=1)
    animes = db.table("animes").filter(
        pc.field("clip_id") == clip_id).sort_by("node_id")
    first = animes.to_pylist()[1]
    ics = np.asarray(first["motion"]).reshape(first["n_frames"], -1)
    recon = model.inverse_transform(ics)
    orig = motion[first["start_frame"]:first["end_frame"]]
    # What PCA leaves out is small next to the motion itself.
    assert np.sqrt(np.mean((recon - orig) ** 2)) < 0.5 * np.sqrt(np.mean(
        (orig - motion.mean(axis=0)) ** 2))
    cut = db.table("components").column("cutoff_hz").to_numpy()
    assert ((cut > 0) & (cut <= 60.0)).all()


def test_dropouts_are_filled_and_remembered(tiny_db):
    db = Database.open(tiny_db[0])
    out = query(db, "SELECT count(*) AS n FROM frames WHERE len(missing) > 0")
    assert out.column("n")[0].as_py() > 0
    out = query(db, "SELECT count(*) AS n FROM frames WHERE isnan(\"lip_corner_r.x\")")
    assert out.column("n")[0].as_py() == 0


def test_reingesting_the_same_clips_changes_nothing(tiny_db, tiny_corpus):
    path, _ = tiny_db
    version = current_version(path)
    report = ingest([tiny_corpus], path)
    assert report.count("unchanged") == report.count("added") + report.count("unchanged")
    assert not report.written and current_version(path) == version


def test_clips_that_name_no_speaker_keep_a_text_column(tiny_db, tmp_path):
    """SQL users see speaker as VARCHAR (all null), not a column of type NULL."""
    from dataclasses import replace

    from ingest.pipeline import build_database
    from ingest.tables import prepared_from_database

    clips = [replace(c, speaker=None)
             for c in prepared_from_database(Database.open(tiny_db[0]))[:6]]
    build_database(tmp_path / "db", clips)
    db = Database.open(tmp_path / "db")
    for table in ("animes", "clips"):
        rows = query(db, f"SELECT column_name, column_type FROM (DESCRIBE {table})").to_pylist()
        types = {r["column_name"]: r["column_type"] for r in rows}
        assert types["speaker"] == "VARCHAR", (table, types["speaker"])


def test_a_bad_clip_is_rejected_and_the_others_go_in(tiny_corpus, tmp_path):
    src = tmp_path / "corpus"
    shutil.copytree(tiny_corpus, src)
    victim = sorted((src / "clips").glob("*.wav"))[0]
    victim.write_bytes(victim.read_bytes()[:100])  # truncated
    report = ingest([src], tmp_path / "db")
    rejected = [c for c in report.clips if c.status == "rejected"]
    assert len(rejected) == 1 and victim.stem in rejected[0].source
    assert rejected[0].reason and "\n" not in rejected[0].reason
    assert Database.open(tmp_path / "db").manifest["n_clips"] == report.count("added")


def test_a_copied_folder_is_not_ingested_twice(tiny_corpus, tmp_path):
    """The same files under another folder name are another corpus's clip ids, but the
    same recordings: rejected with the clip they copy, in one ingest or a later one."""
    src = tmp_path / "a" / tiny_corpus.name
    shutil.copytree(tiny_corpus, src)
    for extra in sorted((src / "clips").iterdir()):
        if not extra.name.startswith(("s0001_", "s0002_")):
            extra.unlink()
    copy = tmp_path / "copy"
    shutil.copytree(src, copy)
    report = ingest([src, copy], tmp_path / "db")
    added = [c for c in report.clips if c.status == "added"]
    copies = [c for c in report.clips if c.status == "rejected"]
    assert added and sorted(c.clip_id for c in copies) == sorted(c.clip_id for c in added)
    for row in copies:  # the first found of the two goes in
        other = "copy" if str(src) in row.source else tiny_corpus.name
        assert row.reason == f"the same recording as {other}/{row.clip_id} (identical files)"
    assert Database.open(tmp_path / "db").manifest["n_clips"] == len(added)
    for folder in (src, copy):  # later: whichever is in the database stands
        with pytest.raises(ParameterError, match="every clip was rejected"):
            ingest([folder.rename(tmp_path / "again")], tmp_path / "db")
        (tmp_path / "again").rename(folder)


def test_a_transcript_that_does_not_fit_is_said_in_the_report(tiny_corpus, tmp_path, capsys,
                                                              caplog):
    """A clip whose transcript is another utterance's goes in with its phones recognised,
    and the report and the clips table say so; its neighbours are aligned as before."""
    src = tmp_path / tiny_corpus.name
    shutil.copytree(tiny_corpus, src)
    clips = sorted((src / "clips").glob("*.json"))[:3]
    for clip in clips[:2]:
        clip.with_suffix(".phones.csv").unlink()  # no labels: the transcript is aligned
    meta = json.loads(clips[0].read_text())
    meta["text"] = "Nothing like what is said in it at all."
    clips[0].write_text(json.dumps(meta))
    for extra in sorted((src / "clips").iterdir()):
        if extra.name.split(".")[0] not in {c.stem for c in clips}:
            extra.unlink()
    db = tmp_path / "db"
    assert main(["ingest", str(src), "--db", str(db), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert f"added {clips[0].with_suffix('.c3d')}: transcript alignment failed: " in out, out
    assert "fell back to phone recognition" in out
    assert str(clips[1].with_suffix(".c3d")) not in out  # its own transcript: aligned
    rows = {r["clip_id"]: r for r in Database.open(db).table(
        "clips", columns=["clip_id", "segmentation", "extra"]).to_pylist()}
    wrong, right = rows[clips[0].stem], rows[clips[1].stem]
    assert wrong["segmentation"] == "recognized" and right["segmentation"] == "aligned"
    assert json.loads(wrong["extra"])["transcript_fallback"].startswith(
        "transcript alignment failed: ")
    assert "transcript_fallback" not in json.loads(right["extra"])
    caplog.clear()  # the evaluations prepare clips without a report: the log says it
    with caplog.at_level(logging.WARNING, logger="ingest.pipeline"):
        prepare_sources(discover([src]))
    said = [r.getMessage() for r in caplog.records if r.name == "ingest.pipeline"]
    assert any(m.startswith(f"{clips[0].with_suffix('.c3d')}: transcript alignment failed")
               for m in said), said
    assert not any(str(clips[1].with_suffix(".c3d")) in m for m in said)


def test_a_clips_report_line_says_what_it_made_do_with():
    from types import SimpleNamespace

    from ingest.per_clip import clip_note

    clip = SimpleNamespace(extra={"frames_without_face": 9, "transcript_fallback":
                                  "transcript alignment failed: x; fell back to recognition"})
    assert clip_note("2 samples filled", clip) == (
        "2 samples filled; no face in 9 frames (filled as gaps); transcript alignment "
        "failed: x; fell back to recognition")
    assert clip_note("", SimpleNamespace(extra={"frames_without_face": 0})) == ""


def test_adding_clips_refits_the_model_over_everything(tiny_corpus, tmp_path):
    first = tmp_path / "part" / tiny_corpus.name  # same corpus name: the same clips
    (first / "clips").mkdir(parents=True)
    shutil.copy(tiny_corpus / "corpus.json", first)
    shutil.copy(tiny_corpus / "markers.csv", first)
    clips = sorted({p.name.split(".")[0] for p in (tiny_corpus / "clips").iterdir()})
    for stem in clips[:4]:
        for f in (tiny_corpus / "clips").glob(f"{stem}.*"):
            shutil.copy(f, first / "clips")
    db = tmp_path / "db"
    ingest([first], db)
    assert Database.open(db).manifest["n_clips"] == 4
    report = ingest([tiny_corpus], db)
    assert report.count("unchanged") == 4 and report.count("added") == len(clips) - 4
    assert Database.open(db).manifest["n_clips"] == len(clips)
    assert current_version(db) == "v000002"
    # Labelled clips, no --posteriorgrams: the clips added later get none either (the
    # clips table always has the column; only a database storing them keeps them on).
    frames = Database.open(db).table("clips", columns=["posterior_frames"])
    assert frames.column("posterior_frames").null_count == len(clips)


def test_errors(tmp_path):
    with pytest.raises(ParameterError, match="does not exist"):
        ingest([tmp_path / "nope"], tmp_path / "db")
    (tmp_path / "empty").mkdir()
    with pytest.raises(ParameterError, match="no clips found"):
        ingest([tmp_path / "empty"], tmp_path / "db")
    (tmp_path / "notdb").mkdir()
    (tmp_path / "notdb" / "x.txt").write_text("mine")
    with pytest.raises(ParameterError, match="not an animegraph database"):
        ingest([tmp_path / "empty"], tmp_path / "notdb")


# --- the command line --------------------------------------------------------------


def test_cli_sql_info_and_formats(tiny_db, capsys, tmp_path):
    path, _ = tiny_db
    assert main(["info", "--db", str(path)]) == 0
    out = capsys.readouterr().out
    assert "markers, 216 channels at 120 fps" in out and "principal components" in out
    sql = "SELECT phoneme, count(*) AS n FROM animes GROUP BY 1 ORDER BY n DESC LIMIT 3"
    assert main(["sql", "--db", str(path), sql]) == 0
    assert "phoneme" in capsys.readouterr().out
    assert main(["sql", "--db", str(path), sql, "--format", "csv"]) == 0
    assert capsys.readouterr().out.splitlines()[0] == '"phoneme","n"'
    assert main(["sql", "--db", str(path), sql, "--format", "jsonl"]) == 0
    assert len(capsys.readouterr().out.splitlines()) == 3
    assert main(["sql", "--db", str(path), sql, "--format", "json"]) == 0
    assert len(json.loads(capsys.readouterr().out)) == 3  # one document
    out = tmp_path / "top.parquet"
    assert main(["sql", "--db", str(path), sql, "--format", "parquet", "-o", str(out)]) == 0
    assert pq.read_table(out).num_rows == 3


def test_sql_help_lists_every_table_and_real_columns(tiny_db):
    # `sql --help` named the tables, no column: a data person had to guess them.
    from animegraph.apps.cli_parser import SQL_TABLES_HELP
    from db.store import TABLES

    listed = dict(re.findall(r"(\w+): [^;(]*\(([^)]*)\)", SQL_TABLES_HELP))
    assert set(listed) == set(TABLES)
    for table, columns in listed.items():
        names = [c for c in columns.split(", ") if re.fullmatch(r"\w+", c)]
        have = query(Database.open(tiny_db[0]), f"SELECT * FROM {table} LIMIT 0").column_names
        assert names and set(names) <= set(have), (table, set(names) - set(have))


def test_cli_sql_writes_the_format_its_output_is_named(tiny_db, tmp_path):
    # `-o phones.csv` wrote the aligned text table (cut at 50 rows) under a CSV's name.
    path, _ = tiny_db
    sql = "SELECT phoneme, count(*) AS n FROM animes GROUP BY 1 ORDER BY 1"
    for name in ("phones.csv", "phones.parquet", "phones.jsonl", "phones.txt"):
        assert main(["sql", "--db", str(path), sql, "--max-rows", "2",
                     "-o", str(tmp_path / name)]) == 0
    csv_lines = (tmp_path / "phones.csv").read_text().splitlines()
    assert csv_lines[0] == '"phoneme","n"' and len(csv_lines) > 3
    assert pq.read_table(tmp_path / "phones.parquet").num_rows == len(csv_lines) - 1
    assert json.loads((tmp_path / "phones.jsonl").read_text().splitlines()[0])["n"] > 0
    assert "more rows" in (tmp_path / "phones.txt").read_text()  # no format named: a table
    # --format still wins over the name
    assert main(["sql", "--db", str(path), sql, "--format", "jsonl",
                 "-o", str(tmp_path / "as.csv")]) == 0
    assert (tmp_path / "as.csv").read_text().startswith("{")


def test_cli_sql_json_is_a_document_strict_readers_open(tiny_db, tmp_path, capsys):
    # `-o x.json` wrote JSON Lines (json.load and pandas.read_json refused the file), and a
    # NaN (a database without emotions has NaN emotion scores) as the bare word NaN.
    path, _ = tiny_db
    sql = ("SELECT phoneme, count(*) AS n, 'nan'::DOUBLE AS x, [1.0, 'inf'::DOUBLE] AS l "
           "FROM animes GROUP BY 1 ORDER BY 1 LIMIT 3")
    assert main(["sql", "--db", str(path), sql, "-o", str(tmp_path / "p.json")]) == 0

    def strict(word):
        raise ValueError(f"not JSON: {word}")

    rows = json.loads((tmp_path / "p.json").read_text(), parse_constant=strict)
    assert len(rows) == 3 and rows[0]["x"] is None and rows[0]["l"] == [1.0, None]
    import pandas as pd

    assert pd.read_json(tmp_path / "p.json").shape == (3, 4)
    capsys.readouterr()
    assert main(["query", "--db", str(path), "--limit", "2", "--format", "json"]) == 0
    assert len(json.loads(capsys.readouterr().out)) == 2


@pytest.mark.parametrize("argv, needle", [
    (["sql", "--db", "{db}", "DELETE FROM animes"], "only SELECT"),
    (["sql", "--db", "{db}", "SELECT nope FROM animes"], "query failed"),
    (["sql", "--db", "{tmp}", "SELECT 1"], "not an animegraph database"),
    (["info", "--db", "{tmp}/missing"], "does not exist"),
    (["sql", "--db", "{db}", "SELECT 1", "--limit", "0"], "--limit must be at least 1"),
    (["sql", "--db", "{db}", "SELECT 1", "--timeout", "-1"], "--timeout must be more than 0"),
])
def test_cli_errors_are_one_line(tiny_db, tmp_path, capsys, argv, needle):
    argv = [a.format(db=tiny_db[0], tmp=tmp_path) for a in argv]
    assert main(argv) == (2 if needle.startswith("--") else 1)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0]


def test_readme_queries_run(tiny_db):
    db = Database.open(tiny_db[0])
    per_emotion = query(db, "SELECT emotion, count(DISTINCT phoneme) AS phonemes, count(*) "
                            "AS animes FROM animes GROUP BY emotion ORDER BY emotion")
    assert per_emotion.num_rows == 5
    longest = query(db, "SELECT clip_id, start_time, end_time - start_time AS dur FROM animes "
                        "WHERE phoneme = 'AA' AND emotion = 'angry' ORDER BY dur DESC LIMIT 5")
    assert longest.num_rows >= 1
    prosody = query(db, "SELECT emotion, avg(list_avg(prosody)) AS mean_prosody, "
                        "avg(prosody[1]) AS mean_c0 FROM animes GROUP BY emotion")
    assert prosody.num_rows == 5


def test_cli_ingest_reports_rejections_with_exit_status_1(tiny_corpus, tmp_path, capsys):
    # One sentence's clips (10 of the 34; one of them damaged) are enough to show a clip
    # rejected beside clips that go in: the whole corpus made this the slowest ingest test.
    src = tmp_path / tiny_corpus.name
    shutil.copytree(tiny_corpus, src, ignore=lambda folder, names: [
        n for n in names if Path(folder).name == "clips" and not n.startswith("s0001_")])
    victim = sorted((src / "clips").glob("*.c3d"))[0]
    victim.write_bytes(victim.read_bytes()[: victim.stat().st_size // 2])  # truncated C3D
    db = tmp_path / "db"
    # --no-prepare: the guides' fit and the kernels after a write are test_prepare.py's
    assert main(["ingest", str(src), "--db", str(db), "--quiet", "--no-prepare"]) == 1
    out = capsys.readouterr().out
    assert f"rejected {victim}" in out and "truncated" in out
    assert "is now v000001" in out
    # still rejected
    assert main(["ingest", str(src), "--db", str(db), "--quiet", "--no-prepare"]) == 1
    assert "database" in capsys.readouterr().out
    assert current_version(db) == "v000001"


def test_a_first_ingest_that_rejects_every_clip_leaves_no_folder(tiny_corpus, tmp_path):
    src = tmp_path / tiny_corpus.name
    shutil.copytree(tiny_corpus, src)
    for victim in (src / "clips").glob("*.c3d"):
        victim.write_bytes(victim.read_bytes()[: victim.stat().st_size // 2])  # truncated
    db = tmp_path / "db"
    with pytest.raises(ParameterError):
        ingest([src], db)
    assert not db.exists()  # not even the folder with the lock file it was made under


def _damage_stored_frames(db, how: str) -> str:
    """Damage one stored clip's frames in place (10 samples of one marker's y at 500 m,
    or NaN); returns the clip's "corpus/clip id"."""
    part = sorted((db / current_version(db) / "frames").rglob("*.parquet"))[0]
    table = pq.read_table(part, partitioning=None)
    corpus, clip_id = table.column("corpus")[0].as_py(), table.column("clip_id")[0].as_py()
    rows = np.flatnonzero(np.asarray(pc.equal(table.column("clip_id"), clip_id)))[50:60]
    name = [c for c in table.column_names if c.endswith(".y")][5]
    values = table.column(name).to_numpy().copy()
    values[rows] = 5e5 if how == "spike" else np.nan
    i = table.column_names.index(name)
    pq.write_table(table.set_column(i, name, pa.array(values, table.schema.field(name).type)),
                   part)
    return f"{corpus}/{clip_id}"


@pytest.mark.parametrize("how, reason", [("spike", "implausible in 10 frame(s)"),
                                         # NaN: refused as the frames are read (db.validate)
                                         ("nan", "nan (must be finite)")])
def test_damaged_stored_frames_refuse_the_database_before_a_refit(tiny_db, tiny_corpus,
                                                                  tmp_path, capsys, how,
                                                                  reason):
    # Someone else's database whose stored frames were damaged: adding a clip refits the
    # model over every stored clip, so they are checked as a new clip is (issue #18).
    db = tmp_path / "db"
    shutil.copytree(tiny_db[0], db)
    damaged = _damage_stored_frames(db, how)
    src = tmp_path / "new" / tiny_corpus.name
    (src / "clips").mkdir(parents=True)
    for name in ("corpus.json", "markers.csv"):
        shutil.copy(tiny_corpus / name, src)
    stem = sorted(p.name.split(".")[0] for p in (tiny_corpus / "clips").glob("*.c3d"))[0]
    for f in (tiny_corpus / "clips").glob(f"{stem}.*"):
        shutil.copy(f, src / "clips" / f.name.replace(stem, "zz_new"))
    meta = src / "clips" / "zz_new.json"  # not byte for byte the stored clip's files
    meta.write_text(json.dumps({**json.loads(meta.read_text()), "take": "new"}))
    before = sorted(p.name for p in db.iterdir())

    assert main(["ingest", str(src), "--db", str(db), "--quiet"]) != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert f"database {db} is damaged" in err and f"clip {damaged}: " in err, err
    assert reason in err and "Traceback" not in err, err
    assert current_version(db) == "v000001" and sorted(p.name for p in db.iterdir()) == before
    with pytest.raises(DataError, match=re.escape(f"clip {damaged}: ") + ".*" + re.escape(reason)):
        prepared_from_database(Database.open(db))
