"""``animegraph ingest`` on a Dask cluster (:mod:`ingest.on_dask`): the same database as
the process pool's, resumable after a kill, and clips whose bytes travel to the worker."""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from animegraph.apps.cli import main
from db.store import Database
from ingest import prepared_cache
from ingest.clip import checksum_files
from ingest.on_dask import _renamed, run_shipped, ship
from ingest.per_clip import ClipJob, work
from ingest.pipeline import IngestConfig, ingest
from ingest.readers import discover

distributed = pytest.importorskip("distributed")
ROOT = Path(__file__).resolve().parents[1]
#: The tables of the clips themselves: the same bytes whoever prepared them.
TABLES = ("clips", "animes", "frames", "audio", "channels")


def _threads_cluster():
    """A real Dask cluster in this process, of one worker thread."""
    cluster = distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                       dashboard_address=None)
    return cluster, distributed.Client(cluster, set_as_default=False)


def _same_database(a: Path, b: Path) -> None:
    one, other = Database.open(a), Database.open(b)
    for name in TABLES:
        assert one.table(name).equals(other.table(name)), name
    # The model comes from the same clips; the emotion classifier's features are summed
    # in whatever order the BLAS threads of the process that computes them take (a pool
    # worker's BLAS has one thread, this process' two): a 1e-6 relative spread, which its
    # calibration's fit carries to 1e-3.
    pd.testing.assert_frame_equal(one.table("components").to_pandas(),
                                  other.table("components").to_pandas(),
                                  check_exact=False, rtol=1e-3, atol=1e-2)
    arrays, others = one.arrays(), other.arrays()
    assert sorted(arrays) == sorted(others)
    for name, values in arrays.items():
        np.testing.assert_allclose(values, others[name], rtol=1e-3, atol=1e-2, err_msg=name)


def test_a_dask_ingest_writes_the_pools_database(tiny_db, tiny_corpus, tmp_path):
    path = tmp_path / "dask.db"
    # The worker's cache folder is shared by its tests: a killed ingest's kept clips stay.
    before = set(prepared_cache.folder().glob("*.npz"))
    cluster, client = _threads_cluster()
    try:
        report = ingest([tiny_corpus], path, IngestConfig(posteriorgrams=True),
                        client=client)
    finally:
        client.close()
        cluster.close()
    assert report.count("added") == tiny_db[1].count("added") and report.resumed == 0
    _same_database(path, tiny_db[0])
    # The clips are in: what this ingest kept is cleared.
    assert not set(prepared_cache.folder().glob("*.npz")) - before


def _subset(corpus: Path, out: Path, sentences: tuple[str, ...]) -> Path:
    """A copy of the corpus with only some sentences' clips."""
    shutil.copytree(corpus, out, ignore=lambda folder, names: [
        n for n in names if Path(folder).name == "clips"
        and not n.startswith(sentences)])
    return out


KILLED_INGEST = textwrap.dedent("""
    import sys
    from distributed import Client, LocalCluster
    from ingest.pipeline import ingest

    if __name__ == "__main__":
        with LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                          dashboard_address=None) as cluster, Client(cluster) as client:
            ingest([sys.argv[1]], sys.argv[2], client=client)
""")


def test_a_killed_dask_ingest_redoes_only_the_clips_it_had_not_finished(tiny_corpus,
                                                                        tmp_path,
                                                                        monkeypatch):
    corpus = _subset(tiny_corpus, tmp_path / "corpus", ("s0001", "s0002"))
    n_clips = len(discover([corpus]))
    cache = tmp_path / "cache"
    env = {**os.environ, "ANIMEGRAPH_CACHE": str(cache), "PYTHONPATH": str(ROOT)}
    kept = cache / "prepared"
    process = subprocess.Popen([sys.executable, "-c", KILLED_INGEST, str(corpus),
                                str(tmp_path / "db")], env=env, cwd=tmp_path,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        while process.poll() is None and len(list(kept.glob("*.npz"))) < 3:
            time.sleep(0.02)
        process.send_signal(signal.SIGKILL)
        process.wait()
    finally:
        if process.poll() is None:
            process.kill()
    finished = len(list(kept.glob("*.npz")))
    assert 3 <= finished < n_clips
    assert not (tmp_path / "db" / "manifest.json").exists()

    monkeypatch.setenv("ANIMEGRAPH_CACHE", str(cache))
    cluster, client = _threads_cluster()
    try:
        report = ingest([corpus], tmp_path / "db", client=client)
    finally:
        client.close()
        cluster.close()
    # The clips kept before the kill are taken as they were; only the others are redone.
    assert report.resumed == finished and report.count("added") == n_clips
    assert f"{finished} clips prepared by an unfinished ingest" in "\n".join(report.lines())
    assert not list(kept.glob("*.npz"))


def test_a_worker_without_the_files_gets_their_bytes(tiny_corpus, tmp_path):
    corpus = _subset(tiny_corpus, tmp_path / "corpus", ("s0001_angry_1",))
    source = discover([corpus])[0]
    job = ClipJob(source, {}, None, None, None, None, False)
    shipped = ship(source)
    assert shipped is not None and len(shipped.files) == len(source.paths)
    # The clip's checksum from the bytes that travel: the client reads a clip once.
    assert shipped.checksum == checksum_files(source.paths)
    expected_report, expected = work(job)
    shutil.rmtree(corpus)  # the worker has none of the clip's files now

    cluster, client = _threads_cluster()
    try:
        report, clip = client.submit(run_shipped, work, job, shipped, pure=False).result()
        missing, _ = client.submit(run_shipped, work, job, None, pure=False).result()
    finally:
        client.close()
        cluster.close()
    assert report == expected_report and report.status == "added"
    assert clip.source == expected.source == str(source.path)  # the client's path
    for name in ("motion", "missing", "audio", "prosody"):
        np.testing.assert_array_equal(getattr(clip, name), getattr(expected, name))
    assert clip.phones == expected.phones and clip.extra == expected.extra
    # The same job without its bytes: the worker looks for the files, and says so.
    assert missing.status == "rejected" and str(source.path.parent) in missing.reason


def test_the_workers_folder_is_named_nowhere_in_what_comes_back():
    @dataclass(frozen=True)
    class Row:
        source: str
        extra: dict
        n: int = 0

    tmp, home = "/tmp/animegraph-clip-x1", "/data/corpus"
    row = Row(f"{tmp}/a.mp4", {"transcript_doubt": f"read {tmp}/a.txt",
                               "files": [f"{tmp}/a.txt", {"side": f"{tmp}/a.json"}], "k": 3})
    back = _renamed(row, tmp, home)
    assert back.source == f"{home}/a.mp4" and back.n == 0
    assert back.extra == {"transcript_doubt": f"read {home}/a.txt",
                          "files": [f"{home}/a.txt", {"side": f"{home}/a.json"}], "k": 3}


def test_a_clip_with_a_link_travels_as_its_paths(tiny_corpus, tmp_path):
    corpus = _subset(tiny_corpus, tmp_path / "corpus", ("s0001_angry_1",))
    secret = tmp_path / "secret.txt"
    secret.write_text("not for the database")
    text = next((corpus / "clips").glob("*.phones.csv"))
    text.unlink()
    text.symlink_to(secret)
    # Its bytes would arrive as a plain file: the reader's refusal of the link would not
    # see it. Sent as paths, the worker's reader refuses it as on one machine.
    assert ship(discover([corpus])[0]) is None


def test_a_kept_clip_reads_back_as_it_was(tiny_corpus, tmp_path):
    source = discover([tiny_corpus])[0]
    report, clip = work(ClipJob(source, {}, None, None, None, None, False))
    key = prepared_cache.entry_key(clip.checksum, {"fps": None}, np.zeros((3, 3)))
    assert key != prepared_cache.entry_key(clip.checksum, {"fps": 30.0}, np.zeros((3, 3)))
    prepared_cache.save(key, clip, {"source": report.source})
    back, row = prepared_cache.load(key)
    assert row == {"source": report.source}
    for name in ("motion", "missing", "audio", "prosody"):
        np.testing.assert_array_equal(getattr(back, name), getattr(clip, name))
    np.testing.assert_array_equal(back.emotion_features.functionals,
                                  clip.emotion_features.functionals)
    assert replace(back, motion=None, missing=None, audio=None, prosody=None,
                   emotion_features=None).__dict__.keys() == clip.__dict__.keys()
    assert (back.phones, back.schema, back.extra) == (clip.phones, clip.schema, clip.extra)
    # A damaged entry is prepared again, not trusted.
    (prepared_cache.folder() / f"{key}.npz").write_bytes(b"not an npz")
    assert prepared_cache.load(key) is None
    prepared_cache.remove([key])


def test_cli_an_unreachable_scheduler_is_one_line(tiny_corpus, tmp_path, capsys):
    code = main(["ingest", str(tiny_corpus), "--db", str(tmp_path / "db"), "--quiet",
                 "--scheduler", "tcp://127.0.0.1:9", "--no-prepare"])
    err = capsys.readouterr().err.strip()
    assert code != 0 and len(err.splitlines()) == 1, err
    assert "cannot reach the Dask scheduler at tcp://127.0.0.1:9" in err
    assert not (tmp_path / "db").exists()


def test_cli_ctrl_c_on_a_scheduler_leaves_no_database_and_the_next_run_resumes(
        tiny_corpus, tmp_path):
    corpus = _subset(tiny_corpus, tmp_path / "corpus", ("s0001", "s0002"))
    n_clips = len(discover([corpus]))
    cache, db = tmp_path / "cache", tmp_path / "db"
    env = {**os.environ, "ANIMEGRAPH_CACHE": str(cache), "PYTHONPATH": str(ROOT)}
    command = [sys.executable, "-m", "animegraph", "ingest", str(corpus), "--db", str(db),
               "--quiet", "--no-prepare"]
    # A real scheduler on a TCP port, its worker a thread of this process.
    cluster = distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                       protocol="tcp", dashboard_address=None)
    try:
        command += ["--scheduler", cluster.scheduler_address]
        process = subprocess.Popen(command, env=env, stdout=subprocess.PIPE,
                                   stderr=subprocess.PIPE, text=True)
        try:
            while process.poll() is None and not list((cache / "prepared").glob("*.npz")):
                time.sleep(0.02)
            process.send_signal(signal.SIGINT)
            out, err = process.communicate(timeout=120)
        finally:
            if process.poll() is None:
                process.kill()
        assert process.returncode == 130, err
        assert err.strip().splitlines() == ["animegraph: interrupted"], err
        assert not db.exists()  # a first ingest interrupted leaves no folder
        kept = len(list((cache / "prepared").glob("*.npz")))
        assert 1 <= kept < n_clips

        again = subprocess.run(command, env=env, capture_output=True, text=True, timeout=600)
    finally:
        cluster.close()
    assert again.returncode == 0, again.stderr
    assert f"{n_clips} added" in again.stdout
    assert f"{kept} clip{'s' * (kept != 1)} prepared by an unfinished ingest" in again.stdout


def test_a_bad_clip_is_rejected_on_its_worker_and_the_others_go_in(tiny_corpus, tmp_path):
    corpus = _subset(tiny_corpus, tmp_path / "corpus", ("s0001",))
    victim = sorted((corpus / "clips").glob("*.wav"))[0]
    victim.write_bytes(victim.read_bytes()[:100])  # truncated
    cluster, client = _threads_cluster()
    try:
        report = ingest([corpus], tmp_path / "db", client=client)
    finally:
        client.close()
        cluster.close()
    rejected = [c for c in report.clips if c.status == "rejected"]
    assert len(rejected) == 1 and rejected[0].source.startswith(str(corpus))
    # The reason names the file where the user has it, not the worker's copy.
    assert str(victim) in rejected[0].reason and "animegraph-clip-" not in rejected[0].reason
    assert Database.open(tmp_path / "db").manifest["n_clips"] == report.count("added") > 0


def test_the_cluster_is_closed_before_the_database_is_written(tiny_corpus, tmp_path):
    corpus = _subset(tiny_corpus, tmp_path / "corpus", ("s0001",))
    events: list[str] = []
    clients: list = []

    @contextlib.contextmanager
    def cluster():
        made, client = _threads_cluster()
        clients.append(client)
        try:
            yield client
        finally:
            client.close()
            made.close()
            events.append("closed")

    report = ingest([corpus], tmp_path / "db", cluster=cluster,
                    say=lambda line: events.append(f"{line} (client {clients[0].status})"))
    assert report.count("added") == len(discover([corpus])) > 0
    # Once the clips were prepared the cluster went; the writer's steps came after.
    assert events[0] == "closed" and len(events) > 1, events
    assert all("(client closed)" in line for line in events[1:]), events


def test_a_local_cluster_runs_with_its_ticks_cut(tmp_path):
    from types import SimpleNamespace

    from animegraph.apps.batch_cluster import LOCAL_CLUSTER_CONFIG, dask_client

    def seen(dask_worker):  # on the worker: its settings and what it does periodically
        import os

        import dask

        return ({key: dask.config.get(key) for key in LOCAL_CLUSTER_CONFIG},
                sorted(dask_worker.periodic_callbacks),
                os.environ.get("MALLOC_TRIM_THRESHOLD_"), os.environ.get("OMP_NUM_THREADS"))

    options = SimpleNamespace(scheduler=None, workers=1, connect_timeout=30.0)
    with dask_client(options) as (client, n_workers):
        (config, callbacks, trim, omp), = client.run(seen).values()
        scheduler_ticks = client.run_on_scheduler(
            lambda dask_scheduler: dask_scheduler.periodic_callbacks["tick"].callback_time)
    assert n_workers == 1 and config == LOCAL_CLUSTER_CONFIG
    assert "profile" not in callbacks and "heartbeat" in callbacks
    # glibc's own trim threshold (Dask's 64 kB made a clip's arrays fault pages anew);
    # one native thread.
    assert trim == os.environ.get("MALLOC_TRIM_THRESHOLD_") and omp == "1"
    assert scheduler_ticks == 1000  # ms: Dask's default wakes it every 20
    # Left as they were for what runs after the cluster.
    import dask

    assert dask.config.get("distributed.worker.profile.enabled") is True


def test_a_local_cluster_reads_the_clips_where_they_are_a_scheduler_gets_their_bytes():
    from ingest.on_dask import _local

    cluster, client = _threads_cluster()
    try:
        assert _local(client)  # started here: its workers share this machine's disks
        with distributed.Client(cluster.scheduler_address, set_as_default=False) as remote:
            assert not _local(remote)  # known by its address only: the bytes travel
    finally:
        client.close()
        cluster.close()
