"""A killed ``animegraph ingest --workers N`` redoes only the clips it had not finished
(the prepared clips kept in the cache: :mod:`ingest.prepared_cache`), and the kept clips
stay under their bound."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import psutil

from db.store import Database
from ingest import prepared_cache
from ingest.per_clip import ClipJob, work
from ingest.pipeline import ingest
from ingest.readers import discover

ROOT = Path(__file__).resolve().parents[1]


def _subset(corpus: Path, out: Path, sentences: tuple[str, ...]) -> Path:
    """A copy of the corpus with only some sentences' clips."""
    shutil.copytree(corpus, out, ignore=lambda folder, names: [
        n for n in names if Path(folder).name == "clips" and not n.startswith(sentences)])
    return out


def test_a_killed_pool_ingest_redoes_only_the_clips_it_had_not_finished(tiny_corpus,
                                                                       tmp_path,
                                                                       monkeypatch):
    corpus = _subset(tiny_corpus, tmp_path / "corpus", ("s0001", "s0002"))
    n_clips = len(discover([corpus]))
    cache, db = tmp_path / "cache", tmp_path / "db"
    kept = cache / "prepared"
    env = {**os.environ, "ANIMEGRAPH_CACHE": str(cache), "PYTHONPATH": str(ROOT)}
    command = [sys.executable, "-m", "animegraph", "ingest", str(corpus), "--db", str(db),
               "--workers", "2", "--quiet", "--no-prepare"]
    process = subprocess.Popen(command, env=env, stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
    try:
        while process.poll() is None and len(list(kept.glob("*.npz"))) < 3:
            time.sleep(0.02)
        workers = psutil.Process(process.pid).children(recursive=True)
        process.send_signal(signal.SIGKILL)  # no clean-up: as a machine that goes down
        process.wait()
        # The workers end with their parent (ingest.workers.die_with_parent); counted once
        # they have, so that no clip is kept after the count.
        _, alive = psutil.wait_procs(workers, timeout=30)
        assert not alive
    finally:
        if process.poll() is None:
            process.kill()
    finished = len(list(kept.glob("*.npz")))
    assert 3 <= finished < n_clips
    assert not (db / "manifest.json").exists()

    monkeypatch.setenv("ANIMEGRAPH_CACHE", str(cache))
    report = ingest([corpus], db, workers=2)
    # The clips kept before the kill are taken as they were; only the others are redone.
    assert report.resumed == finished and report.count("added") == n_clips
    assert f"{finished} clips prepared by an unfinished ingest" in "\n".join(report.lines())
    assert Database.open(db).manifest["n_clips"] == n_clips
    assert not list(kept.glob("*.npz"))  # in the database now: the entries are gone


def test_a_kept_clip_is_for_its_database_only(tiny_corpus, tmp_path, monkeypatch):
    # An ingest into another database prepares its clips itself: what is kept is one
    # ingest's, to be resumed (and removed) by that ingest alone.
    monkeypatch.setenv("ANIMEGRAPH_CACHE", str(tmp_path / "cache"))
    source = discover([tiny_corpus])[0]
    job = ClipJob(source, {}, None, None, None, None, False, db=str(tmp_path / "a"))
    from ingest.per_clip import _entry, _keep, _settle

    report, clip = work(job)
    key = _keep(job, report, clip)
    assert key == _entry(job, clip.checksum)
    settled = _settle(job)
    assert settled is not None and settled[2:] == (key, True)
    np.testing.assert_array_equal(settled[1].motion, clip.motion)
    other = ClipJob(source, {}, None, None, None, None, False, db=str(tmp_path / "b"))
    assert _settle(other) is None


def test_the_kept_clips_stay_under_their_bound_least_recently_used_out(tiny_corpus,
                                                                      tmp_path,
                                                                      monkeypatch):
    monkeypatch.setenv("ANIMEGRAPH_CACHE", str(tmp_path / "cache"))
    source = discover([tiny_corpus])[0]
    report, clip = work(ClipJob(source, {}, None, None, None, None, False))
    row = {"source": report.source}
    prepared_cache.save("old", clip, row)
    size = (prepared_cache.folder() / "old.npz").stat().st_size
    prepared_cache.save("older", clip, row)
    past = time.time() - 2 * prepared_cache.STALE_WRITE_S
    os.utime(prepared_cache.folder() / "older.npz", (past, past))
    os.utime(prepared_cache.folder() / "old.npz", (past + 60, past + 60))
    # What a worker ended as it wrote leaves (atomic_write's temporary file): removed once
    # old, left while it may be a write going on.
    stale, writing = (prepared_cache.folder() / f".{n}.npz.0a1b.tmp" for n in ("x", "y"))
    stale.write_bytes(b"half")
    os.utime(stale, (past, past))
    writing.write_bytes(b"half")

    bound = prepared_cache.Bound(max_bytes=2 * size)
    assert bound.total == 2 * size and list(bound.sizes) == ["older", "old"]
    assert not stale.exists() and writing.exists()
    writing.unlink()
    assert prepared_cache.load("older") is not None  # taken: the newest now
    bound.used("older")
    prepared_cache.save("new", clip, row)
    bound.used("new")  # three entries over a bound of two: the least recently used goes
    assert sorted(p.stem for p in prepared_cache.folder().glob("*.npz")) == ["new", "older"]
    assert bound.total == 2 * size and bound.evicted == 1
    # An entry larger than the bound alone is still kept (the one just written never goes).
    small = prepared_cache.Bound(max_bytes=size // 2)
    prepared_cache.save("newest", clip, row)
    small.used("newest")
    assert [p.stem for p in prepared_cache.folder().glob("*.npz")] == ["newest"]
