"""One writer at a time: an OS lock on a database and a batch output folder (issue #18)."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from test_sql_sandbox import _tiny_db

from db.errors import DataError
from db.lock import LOCK_NAME, writer_lock
from db.store import Database, current_version, write_version

_HOLD = textwrap.dedent("""
    import sys, time
    from db.lock import writer_lock
    with writer_lock(sys.argv[1]):
        print("locked", flush=True)
        time.sleep(120)
""")


def _hold(folder: Path) -> subprocess.Popen:
    """A real second process holding the writer lock of ``folder``."""
    proc = subprocess.Popen([sys.executable, "-c", _HOLD, str(folder)], stdout=subprocess.PIPE,
                            text=True)
    assert proc.stdout.readline().strip() == "locked"
    return proc


def test_a_second_writer_fails_with_one_line_and_the_lock_dies_with_its_holder(tmp_path):
    proc = _hold(tmp_path / "db")
    try:
        with pytest.raises(DataError, match=rf"being written by another process \(process "
                                            rf"{proc.pid}\) after waiting 0.3 s") as err:
            with writer_lock(tmp_path / "db", wait=0.3, what="database"):
                pass
        assert "\n" not in str(err.value)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    # kill -9 released it: the kernel drops a dead process's flock.
    with writer_lock(tmp_path / "db", wait=0):
        with writer_lock(tmp_path / "db", wait=0):  # re-entrant within a process
            pass


def test_the_version_switch_checks_current_did_not_move(tmp_path):
    db = _tiny_db(tmp_path / "db")
    tables = {name: db.table(name) for name in ("clips", "animes", "frames", "audio",
                                                "channels", "model_arrays", "components")}
    write_version(db.root, tables, {"fps": 30.0}, based_on="v000001")
    assert current_version(db.root) == "v000002"
    with pytest.raises(DataError, match="changed while this write was prepared"):
        write_version(db.root, tables, {"fps": 30.0}, based_on="v000001")
    with pytest.raises(DataError, match="changed while"):
        write_version(db.root, tables, {"fps": 30.0}, based_on=None)
    assert current_version(db.root) == "v000002"


def test_clean_up_spares_a_live_writers_staging_folder(tmp_path):
    db = _tiny_db(tmp_path / "db")
    proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(120)"])
    try:
        live = db.root / f".v000009.partial-{proc.pid}-abcd1234"
        dead = db.root / ".v000008.partial-999999999-abcd1234"
        legacy = db.root / ".v000007.partial-abcd1234"
        for folder in (live, dead, legacy):
            folder.mkdir()
        tables = {name: db.table(name) for name in ("clips", "animes", "frames", "audio",
                                                    "channels", "model_arrays", "components")}
        write_version(db.root, tables, {"fps": 30.0})
        assert live.is_dir() and not dead.exists() and not legacy.exists()
    finally:
        proc.kill()
        proc.wait()


def _subset(corpus: Path, stems: list[str], dest: Path) -> Path:
    (dest / "clips").mkdir(parents=True)
    for name in ("corpus.json", "markers.csv"):
        shutil.copy(corpus / name, dest / name)
    for stem in stems:
        for path in (corpus / "clips").glob(f"{stem}.*"):
            shutil.copy(path, dest / "clips" / path.name)
    return dest


def test_two_concurrent_ingests_lose_no_clip(tiny_corpus, tmp_path):
    stems = sorted(p.stem for p in (tiny_corpus / "clips").glob("*.c3d"))[:4]
    a = _subset(tiny_corpus, stems[:2], tmp_path / "a")
    b = _subset(tiny_corpus, stems[2:], tmp_path / "b")
    db = tmp_path / "shared.db"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    procs = [subprocess.Popen([sys.executable, "-m", "animegraph", "ingest", str(src), "--db",
                               str(db), "--quiet"], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True, env=env) for src in (a, b)]
    outs = [p.communicate(timeout=900) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], outs
    clips = Database.open(db).table("clips", columns=["clip_id"]).column("clip_id").to_pylist()
    assert sorted(clips) == stems  # both sets: none lost
    assert current_version(db) == "v000002"
    assert sorted(p.name for p in db.iterdir() if p.name.startswith(".")) == [LOCK_NAME]


def test_a_second_batch_into_one_folder_fails_with_one_line(tiny_db, tmp_path):
    db, _ = tiny_db
    script = tmp_path / "script.csv"
    script.write_text("id,text\nl1,hello there\n")
    out = tmp_path / "out"
    proc = _hold(out)
    try:
        run = subprocess.run([sys.executable, "-m", "animegraph", "batch", str(script), "--db",
                              str(db), "--out", str(out), "--render", "none", "--quiet"],
                             capture_output=True, text=True, timeout=300)
    finally:
        proc.kill()
        proc.wait()
    assert run.returncode != 0
    assert run.stderr.strip().count("\n") == 0
    assert "batch output folder" in run.stderr and "another process" in run.stderr


def test_a_lock_file_planted_as_a_link_or_a_fifo_is_refused_untouched(tmp_path):
    """A database folder from someone else: its lock file, linked to a file of the
    user's, would have been truncated and written with the writer's process id."""
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    for name, plant in (("link", lambda p: p.symlink_to(victim)), ("fifo", os.mkfifo)):
        root = tmp_path / name
        root.mkdir()
        plant(root / LOCK_NAME)
        with pytest.raises(DataError, match="cannot lock .*(symbolic link|not a regular file)"):
            with writer_lock(root, wait=0):
                pass
    assert victim.read_text() == "precious"


def test_a_database_folder_linked_elsewhere_takes_no_write(tiny_db, tmp_path, caplog):
    """reports/ or baselines/ planted as links: ingest's report and a fitted model were
    written where they pointed."""
    import logging

    from animegraph.baselines.stored import model_path
    from ingest.pipeline import _save_report

    good = tmp_path / "db"
    shutil.copytree(tiny_db[0], good, ignore=shutil.ignore_patterns("baselines", "reports"))
    victim = tmp_path / "victim"
    victim.mkdir()
    for name in ("reports", "baselines"):
        (good / name).symlink_to(victim)
    with pytest.raises(DataError, match="baselines is a symbolic link"):
        model_path(good, "hier-pca")
    from ingest.pipeline import IngestReport

    with caplog.at_level(logging.WARNING, logger="ingest.pipeline"):
        _save_report(good, IngestReport(db=good))
    assert "reports is a symbolic link" in caplog.text and not list(victim.iterdir())
