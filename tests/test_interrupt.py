"""Ctrl-C and a dying parent, with real signals sent to a real ``animegraph`` process.

Each test starts the command in its own session (as a terminal's foreground job), waits
until its worker processes exist, sends SIGINT to the whole group (what Ctrl-C does) or
SIGKILL to the parent, and then polls, with a bounded wait, for every process to end.
No test asserts on speed; the bounds only keep a broken build from hanging the suite.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import psutil
import pytest

#: Longest wait for a process to appear or to end (a bound, not a measurement).
BOUND_S = 120.0


def _start(args: list[str], tmp_path: Path, **env_vars: str) -> tuple[subprocess.Popen, Path]:
    err = tmp_path / "stderr.txt"
    env = {**os.environ, "PYTHONUNBUFFERED": "1", **env_vars}
    proc = subprocess.Popen([sys.executable, "-m", "animegraph", *args], cwd=tmp_path,
                            stdout=subprocess.DEVNULL, stderr=err.open("w"), env=env,
                            start_new_session=True)
    return proc, err


def _wait_for(condition, what: str, bound: float = BOUND_S) -> None:
    deadline = time.monotonic() + bound
    while not condition():
        if time.monotonic() > deadline:
            pytest.fail(f"gave up waiting for {what}")
        time.sleep(0.1)


def _workers(proc: subprocess.Popen) -> list[psutil.Process]:
    try:
        return psutil.Process(proc.pid).children(recursive=True)
    except psutil.NoSuchProcess:
        return []


def _gone(processes: list[psutil.Process]) -> bool:
    return not [p for p in processes if p.is_running() and p.status() != psutil.STATUS_ZOMBIE]


def _interrupt(proc: subprocess.Popen, times: int) -> None:
    for _ in range(times):
        os.killpg(proc.pid, signal.SIGINT)
        time.sleep(0.3)


def _ended(proc: subprocess.Popen, workers: list[psutil.Process]) -> int:
    try:
        code = proc.wait(BOUND_S)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        pytest.fail("the command did not end after Ctrl-C")
    _wait_for(lambda: _gone(workers), "the worker processes to end")
    return code


def _clean_exit(code: int, err: Path) -> None:
    text = err.read_text()
    assert code == 130, text
    assert "Traceback" not in text and "InvalidStateError" not in text, text
    assert text.rstrip().endswith("animegraph: interrupted"), text


@pytest.mark.parametrize("presses", [1, 2, 3])
def test_ctrl_c_ends_a_parallel_ingest(tiny_corpus, tmp_path, presses):
    db = tmp_path / "db"
    proc, err = _start(["ingest", str(tiny_corpus), "--db", str(db), "--workers", "2"],
                       tmp_path)
    _wait_for(lambda: len(_workers(proc)) >= 2 or proc.poll() is not None, "the workers")
    assert proc.poll() is None, err.read_text()
    time.sleep(1.0)  # let them take work
    workers = _workers(proc)
    _interrupt(proc, presses)
    _clean_exit(_ended(proc, workers), err)
    assert not db.exists()  # nothing half-written, not even the folder with its lock file


def test_ctrl_c_ends_a_corpus_being_generated(tmp_path):
    out = tmp_path / "corpus"
    proc, err = _start(["corpus", "synth", "--out", str(out), "--sentences", "6",
                        "--parallel", "2", "--workers", "2"], tmp_path)
    _wait_for(lambda: len(_workers(proc)) >= 2 or proc.poll() is not None, "the workers")
    time.sleep(1.0)
    workers = _workers(proc)
    _interrupt(proc, 2)
    _clean_exit(_ended(proc, workers), err)
    assert not out.exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".corpus")]  # no staging


def test_workers_end_when_the_parent_is_killed(tiny_corpus, tmp_path):
    proc, err = _start(["ingest", str(tiny_corpus), "--db", str(tmp_path / "db"),
                        "--workers", "2"], tmp_path)
    _wait_for(lambda: len(_workers(proc)) >= 2 or proc.poll() is not None, "the workers")
    workers = _workers(proc)
    assert workers, err.read_text()
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(BOUND_S)
    _wait_for(lambda: _gone(workers), "the orphaned workers to end")


def test_ctrl_c_ends_a_batch(tiny_db, tmp_path):
    script = tmp_path / "script.csv"
    script.write_text("id,text\n" + "".join(
        f"l{i},This is line number {i} of a long dialogue.\n" for i in range(12)))
    out = tmp_path / "out"
    proc, err = _start(["batch", str(script), "--db", str(tiny_db[0]), "--out", str(out),
                        "--workers", "2"], tmp_path)
    # Two Dask workers (each a nanny and its worker process) once the cluster is up.
    _wait_for(lambda: len(_workers(proc)) >= 2 or proc.poll() is not None, "the workers")
    assert proc.poll() is None, err.read_text()
    time.sleep(2.0)
    workers = _workers(proc)
    _interrupt(proc, 2)
    _clean_exit(_ended(proc, workers), err)
    for folder in out.iterdir() if out.exists() else []:
        done = folder / "done.json"
        if done.exists():  # a line that says it is finished is complete
            json.loads(done.read_text())


def _at_work(proc: subprocess.Popen, err: Path, marker: str | None = None,
             cpu_s: float = 3.0, bound: float = BOUND_S) -> None:
    """Wait until the command is inside its work: ``marker`` on its stderr, or (without
    one) ``cpu_s`` seconds of CPU spent, past the imports. Fails if it ended before."""
    def busy() -> bool:
        if proc.poll() is not None:
            return True
        if marker is not None:
            return marker in err.read_text()
        try:
            times = psutil.Process(proc.pid).cpu_times()
        except psutil.NoSuchProcess:
            return True
        return times.user + times.system >= cpu_s

    _wait_for(busy, f"the command at work ({marker or f'{cpu_s} s of CPU'}): "
              f"{err.read_text()[-400:]}", bound)
    assert proc.poll() is None, f"it ended before the Ctrl-C: {err.read_text()}"


def _long_speech(tiny_corpus: Path, tmp_path: Path, repeats: int = 6) -> Path:
    """The corpus' speech end to end, several times: work of many seconds."""
    from ingest.formats.wav import read_wav, write_wav

    parts, rate = [], None
    for wav in sorted((tiny_corpus / "clips").glob("*.wav")):
        samples, rate = read_wav(wav)
        parts.append(samples)
    path = tmp_path / "long.wav"
    write_wav(path, np.concatenate(parts * repeats), rate)
    return path


def test_ctrl_c_ends_a_sql_query(tiny_db, tmp_path):
    # DuckDB ran on, deaf to the KeyboardInterrupt, until the query ended or its time
    # limit passed (--timeout 120: 119 s), then a RuntimeError traceback and exit 1.
    proc, err = _start(["sql", "--db", str(tiny_db[0]), "--timeout", "600",
                        "SELECT count(*) FROM range(1000000000000)"], tmp_path)
    _at_work(proc, err)
    _interrupt(proc, 1)
    _clean_exit(_ended(proc, []), err)


def test_ctrl_c_ends_a_synth(tiny_db, tiny_corpus, tmp_path):
    speech = _long_speech(tiny_corpus, tmp_path)
    out = tmp_path / "out.c3d"
    proc, err = _start(["-v", "synth", str(speech), "--db", str(tiny_db[0]), "-o", str(out)],
                       tmp_path)
    _at_work(proc, err, "synthesizing")
    _interrupt(proc, 1)
    _clean_exit(_ended(proc, _workers(proc)), err)
    assert not out.exists()


def test_ctrl_c_ends_a_synth_while_pocketsphinx_places_the_phones(tiny_db, tiny_corpus,
                                                                   tmp_path):
    # PocketSphinx's decoder keeps Python's lock for a whole utterance: the Ctrl-C used
    # to wait for it (seconds on a long recording). A fresh cache, or the phones heard in
    # another test are read from it and PocketSphinx never runs.
    from animegraph.apps.cache import CACHE_ENV

    speech = _long_speech(tiny_corpus, tmp_path, repeats=2)  # about 5 min of speech
    out = tmp_path / "out.c3d"
    proc, err = _start(["-vv", "synth", str(speech), "--db", str(tiny_db[0]), "-o", str(out)],
                       tmp_path, **{CACHE_ENV: str(tmp_path / "cache")})
    # hama hears the speech first: a minute or more on a loaded machine
    _at_work(proc, err, "PocketSphinx places", bound=5 * BOUND_S)
    time.sleep(0.3)  # inside the decoding
    decoders = _workers(proc)  # the decoding's child process, at least
    assert decoders, "PocketSphinx decodes in the synth's own process: a Ctrl-C waits for it"
    _interrupt(proc, 1)
    _clean_exit(_ended(proc, decoders), err)
    assert not out.exists()


def test_ctrl_c_ends_a_render(tiny_corpus, tmp_path):
    from ingest.formats.c3d import MarkerData, read_c3d, write_c3d

    clip = read_c3d(sorted((tiny_corpus / "clips").glob("*.c3d"))[0])
    motion = tmp_path / "long.c3d"
    write_c3d(motion, MarkerData(np.concatenate([clip.points] * 8), clip.labels, clip.rate))
    out = tmp_path / "out.mp4"
    proc, err = _start(["render", str(motion), "-o", str(out)], tmp_path)
    _at_work(proc, err, "rendering")
    _interrupt(proc, 1)
    _clean_exit(_ended(proc, _workers(proc)), err)
    assert not out.exists()


def test_ctrl_c_ends_a_fit(tiny_db, tmp_path):
    import shutil

    db = tmp_path / "db"
    shutil.copytree(tiny_db[0], db)
    proc, err = _start(["fit", "--db", str(db), "--method", "hier-pca"], tmp_path)
    _at_work(proc, err, cpu_s=1.5)  # its imports take about 1 s of CPU, the fit seconds
    _interrupt(proc, 1)
    _clean_exit(_ended(proc, _workers(proc)), err)
