"""Seeded fuzzing of what comes in: crafted databases, flipped bytes in clips (issue #18).

Every crafted database is either read correctly or refused with one line naming the
damage (a :class:`db.errors.AnimeGraphError`), never a traceback, never a crash; every
clip with a flipped byte is either rejected with one line or accepted with plausible
motion.
"""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from crafted import DATABASE_MUTATIONS, SQL_SEES, UNCHECKED_DAMAGE, crafted_database

from db.errors import AnimeGraphError, DataError

_READERS = ("open", "model", "info", "sql")


def _read_all(path) -> None:
    from animegraph.apps.info import database_info
    from animegraph.baselines.data import training_set
    from animegraph.synthesis.model import Model
    from db.sql import query
    from db.store import Database

    db = Database.open(path)
    database_info(db)
    query(db, "SELECT count(*) AS n, max(next_node) AS m FROM animes")
    model = Model.load(path)
    graph = model.graph
    assert ((graph.next_node >= -1) & (graph.next_node < graph.n_nodes)).all()
    # Every clip whole, as a baseline's first fit (the audio-only guide) and adding clips
    # read them.
    training_set(db)


@pytest.mark.parametrize("mutation", sorted(DATABASE_MUTATIONS))
def test_crafted_databases_are_read_or_refused_in_one_line(tiny_db, tmp_path, mutation):
    good, _ = tiny_db
    path = crafted_database(good, tmp_path / "db", mutation)
    try:
        _read_all(path)
    except AnimeGraphError as exc:
        assert "\n" not in str(exc).strip(), str(exc)
        if isinstance(exc, DataError):  # it names the damaged database
            assert str(path) in str(exc), str(exc)


@pytest.mark.parametrize("mutation", ["current_symlink", "current_fifo"])
def test_a_current_that_is_not_the_databases_own_file_is_damage_unechoed(tiny_db, tmp_path,
                                                                          mutation):
    # A CURRENT linked to another file had that file's first 60 bytes printed in every
    # command's error; a FIFO in its place kept every command waiting for a writer. The
    # wait is bounded so that a hang fails rather than holds the suite.
    import subprocess
    import sys

    from crafted import SECRET

    path = crafted_database(tiny_db[0], tmp_path / "db", mutation)
    for command in (["info"], ["sql", "SELECT 1"]):
        proc = subprocess.run([sys.executable, "-m", "animegraph", *command, "--db", str(path)],
                              capture_output=True, text=True, timeout=120)
        assert proc.returncode == 1, proc.stderr
        assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr
        assert "damaged" in proc.stderr and "CURRENT" in proc.stderr
        assert SECRET not in proc.stderr and "/bin/bash" not in proc.stderr
        assert "Traceback" not in proc.stderr


@pytest.mark.parametrize("mutation", ["phoneme_path", "phoneme_nul", "start_time_inf",
                                      "clip_fps_zero", "clip_fps_nan",
                                      "clip_phones_mismatch", "audio_odd_bytes"])
def test_export_of_a_crafted_database_stays_in_its_folder_or_is_one_line(tiny_db, tmp_path,
                                                                         mutation):
    """query --export puts a database's values in file names and divides by them: they
    were a traceback (a NUL, inf, a frame rate of 0, odd PCM bytes, phones and times of
    different counts) and a phoneme with '/' and '..' went into a path unsanitised."""
    import pyarrow.compute as pc
    import pyarrow.parquet as pq

    from animegraph.apps.query import QuerySpec, export_hits, run_query
    from db.store import Database

    path = crafted_database(tiny_db[0], tmp_path / "db", mutation)
    try:
        db = Database.open(path)
        run_query(db, QuerySpec(limit=None))
    except DataError as exc:  # refused before any export: its footers say the damage
        assert "\n" not in str(exc).strip() and str(path) in str(exc), str(exc)
        return
    live = path / (path / "CURRENT").read_text().strip()
    # the damaged rows: the first of the first part of animes, clips and audio
    first = {name: pq.read_table(sorted((live / name).rglob("*.parquet"))[0],
                                 partitioning=None).slice(0, 1).to_pylist()[0]
             for name in ("animes", "clips", "audio")}
    refused = []
    for k, (spec, column, value) in enumerate((
            (QuerySpec(limit=None), "node_id", first["animes"]["node_id"]),
            (QuerySpec(clips=True, limit=None), "clip_id", first["clips"]["clip_id"]),
            (QuerySpec(clips=True, limit=None), "clip_id", first["audio"]["clip_id"]))):
        hits = run_query(db, spec)
        hits = hits.filter(pc.equal(hits[column], value))
        assert hits.num_rows == 1
        out = tmp_path / f"export-{k}"
        try:
            export_hits(db, hits, out)
        except DataError as exc:
            assert "\n" not in str(exc).strip() and str(path) in str(exc), str(exc)
            assert not out.exists()
            refused.append(k)
            continue
        written = [p.resolve() for p in out.rglob("*")]
        assert written and all(p.is_relative_to(out.resolve()) for p in written)
    assert not (tmp_path.parent / "PWN").exists() and not list(tmp_path.rglob("PWN*"))
    if mutation in ("phoneme_unknown", "phoneme_path", "phoneme_nul"):
        # A phoneme that is no phone went into the index, a name and the preview's title
        # (a NUL: matplotlib's missing-glyph warning): it is damage.
        assert 0 in refused

def test_every_crafted_model_problem_is_refused(tiny_db, tmp_path):
    # Those that would crash a kernel or poison a synthesis must not load at all.
    from animegraph.synthesis.model import Model

    good, _ = tiny_db
    for mutation in ("next_node_huge", "next_node_negative", "prev_node_huge",
                     "next_node_wrong_clip", "n_frames_huge", "motion_short", "motion_nan",
                     "first_pcs_ragged", "arrays_shape_mismatch", "arrays_nan_mixing",
                     "arrays_wrong_size_mixing", "arrays_zero_cutoffs", "current_binary",
                     "manifest_deep", "manifest_channels_wrong", "frame_overflow"):
        path = crafted_database(good, tmp_path / mutation, mutation)
        with pytest.raises(DataError, match="damaged|not an animegraph"):
            Model.load(path)


def test_flipped_bytes_in_a_c3d_are_rejected_or_plausible(tiny_corpus, tmp_path):
    from ingest.plausible import Limits, check_clip
    from ingest.readers import discover, load

    stem = sorted(p.stem for p in (tiny_corpus / "clips").glob("*.c3d"))[0]
    folder = tmp_path / "clip"
    folder.mkdir()
    for suffix in (".c3d", ".wav", ".phones.csv", ".json"):
        shutil.copy(tiny_corpus / "clips" / f"{stem}{suffix}", folder / f"{stem}{suffix}")
    original = (folder / f"{stem}.c3d").read_bytes()
    rng = np.random.default_rng(18)
    limits = Limits()
    outcomes = {"rejected": 0, "accepted": 0}
    for _ in range(40):
        data = bytearray(original)
        data[int(rng.integers(len(data)))] ^= 1 << int(rng.integers(8))
        (folder / f"{stem}.c3d").write_bytes(bytes(data))
        [source] = discover([folder])
        try:
            clip, _ = check_clip(load(source), limits)
        except AnimeGraphError as exc:
            assert "\n" not in str(exc)
            outcomes["rejected"] += 1
            continue
        outcomes["accepted"] += 1
        pts = clip.motion.reshape(len(clip.motion), -1, 3)
        assert np.nanmax(np.abs(pts)) <= limits.max_coordinate_mm
        steps = np.linalg.norm(np.diff(pts, axis=0), axis=2) * clip.fps
        assert not (steps > limits.max_speed_mm_s).any()
    assert outcomes["accepted"] > 0  # most bytes are sample values: flips are absorbed


@pytest.mark.parametrize(("mutation", "what"), [("speaker_newline", "speaker"),
                                                ("sentence_id_path", "sentence id")])
def test_stored_labels_are_checked_as_new_ones_before_a_refit(tiny_db, tmp_path, mutation,
                                                             what):
    from db.store import Database
    from ingest.tables import prepared_from_database

    path = crafted_database(tiny_db[0], tmp_path / "db", mutation)
    with pytest.raises(DataError, match=f"is damaged: .*a stored clip's label: {what} "):
        prepared_from_database(Database.open(path))


@pytest.mark.parametrize("mutation", ["speaker_escape", "corpus_escape"])
def test_a_databases_terminal_escapes_are_printed_as_text(tiny_db, tmp_path, mutation,
                                                          capsys):
    """info, sql and query print what a (shared, untrusted) database holds: an escape
    sequence in a speaker or the manifest drove the terminal (retitled it, cleared it)."""
    from animegraph.apps.cli import main

    path = str(crafted_database(tiny_db[0], tmp_path / "db", mutation))
    shown = []
    for command in (["info"], ["sql", "SELECT speaker, speaker AS \"\x1b[2J\" FROM clips"],
                    ["sql", "EXPLAIN SELECT '\x1b[2J' FROM clips"], ["query", "--limit", "3"]):
        main(command + ["--db", path])
        shown.append(capsys.readouterr().out)
        assert not {"\x1b", "\x07", "\u202e"} & set(shown[-1]), (command, shown[-1])
    if mutation == "corpus_escape":  # a corpus name that is no plain name: refused at open
        assert shown == [""] * 4
        return
    assert "\\x1b]0;PWNED\\x07\\x1b[2J\\u202eevil" in shown[0]  # info: shown, as text


@pytest.mark.parametrize("mutation", UNCHECKED_DAMAGE)
def test_damage_is_refused_in_one_line(tiny_db, tmp_path, mutation):
    from db.sql import query
    from db.store import Database

    path = crafted_database(tiny_db[0], tmp_path / "db", mutation)
    with pytest.raises(DataError) as caught:
        _read_all(path)
    message = str(caught.value)
    assert "\n" not in message and str(path) in message and "damaged" in message, message
    if mutation in SQL_SEES:
        with pytest.raises(DataError, match="damaged"):
            query(Database.open(path), "SELECT * FROM frames, clips LIMIT 1")


def test_point_columns_are_complete_triples():
    """A channel ending in .x without its .y and .z (a renamed coordinate) is no point's:
    counted as one, the C3D writer's reshape into points was a traceback."""
    from animegraph.motion.files import point_columns, point_labels
    from db.validate import point_triples_problem

    names = ["lip_corner_r_x", "lip_corner_r.y", "lip_corner_r.z", "jaw.x", "jaw.y", "jaw.z",
             "head_yaw"]
    assert point_columns(names) == [3, 4, 5] and point_labels(names) == ("jaw",)
    assert "lip_corner_r.y" in point_triples_problem(names)
    assert point_triples_problem(names[3:]) == ""
