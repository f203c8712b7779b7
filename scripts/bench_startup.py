"""Start-up of the command line: ``--help``, a one-shot ``synth`` and ``map-emotion``.

Usage::

    python scripts/bench_startup.py [--db PATH] [--runs 5] [--top 12]

Every figure is the median of ``--runs`` fresh ``python -m animegraph`` processes (warm:
one run first, unmeasured, so the OS file cache and numba's kernel cache are filled),
wall time and CPU time (user + system of the process: less dependent on the machine's
load than wall time, which on a loaded machine is several times a quiet one's):

* ``animegraph --help`` wall time (target: <= 0.3 s);
* ``animegraph synth`` of a 4 s eSpeak NG sentence (phones from the ``.phones.csv``
  beside it, exact search) against the database (default: the demo's, ``--db`` or
  ``$ANIMEGRAPH_DB``): wall time, the work the command itself reports (loading the
  database + segment + audio cost + search + post), and the rest, the start-up overhead
  (interpreter, imports, writing; target: wall <= 3 s in all, overhead <= 2 s);
* ``animegraph map-emotion`` of that motion to sad: wall time and the reported work;
* the heaviest imports of ``synth`` by ``python -X importtime`` (cumulative), their sum,
  and which of the libraries a one-shot ``synth`` should not import it imported.

With ``--kernels`` it measures the search's numba kernels instead
(:mod:`animegraph.apps.prepare`, :mod:`animegraph.search.kernels`):

* a fresh cache (``NUMBA_CACHE_DIR`` a new folder, a new process): what
  ``animegraph warmup`` (and so ``ingest``) spends compiling them, in all and per kernel
  (numba's compile events; a kernel's time includes the kernels it calls that were
  compiled for it), wall and CPU time;
* the same work in a new process on that now warm cache (the kernels loaded from disk);
* the hot kernel against NumPy: Eq. 5's DTW as a vectorised NumPy row recurrence (each
  row's horizontal steps a running minimum) against the compiled ``audio_costs`` on the
  same curves (the NumPy version only accumulates, a lower bound of its cost).

With ``--heard`` it measures phones heard once (:mod:`ingest.speech.heard`): an
audio-only ``synth`` of that sentence (or of the recording ``--audio`` names; no phone
labels beside it) in a fresh cache folder, then the same recording again with another
option (``--k-best 5``), each a new process: wall, CPU, the reported segmentation time and
work (segment + audio cost + search + post; the rest of the wall is the process's start,
imports, loading the database and guides, and writing) of both, and the second's share of
the first
(target: <= 20 %). The database's default guides are used if it has them stored, else
``--guide none`` for both (a first fit would be timed, not the phones). A third process
runs the second command again with its parts timed in CPU seconds (every thread's, by
wrapping the functions each part runs): the interpreter's libraries, numba's import and
its first cached kernel (numba sets up its CPU target then, importing ``scipy.linalg``
for its BLAS check), loading the graph and the guides, the phones from the cache and the
input's features, the audio cost, the guides' predictions, the search, the k-best
assembly, writing: what a new process cannot skip, and what a cache could.

To compare with another checkout, run this script with ``PYTHONPATH=THAT_CHECKOUT``.
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from animegraph.apps.cache import default_database
from db.store import is_database
from ingest.formats.phones_csv import write_phones_csv
from ingest.formats.wav import write_wav
from ingest.speech.espeak import Voice, speak

SENTENCE = "The quiet fisherman sold his boat and moved to the city by the sea."


#: The processes' environment: a user's Python caches bytecode (``__pycache__``); some
#: environments (this machine's among them) set PYTHONDONTWRITEBYTECODE, which would
#: compile every module of
#: the project at each start (``--no-bytecode`` keeps it).
_ENV = dict(os.environ)

#: Libraries a one-shot synth does not need (used by other commands).
HEAVY = ("sklearn", "scipy.signal", "scipy.stats", "scipy.interpolate", "scipy.spatial",
         "scipy.fft", "pandas", "pyarrow.dataset", "librosa", "duckdb")


def _run(args: list[str], env: dict | None = None) -> tuple[float, float, str]:
    """(wall s, CPU s, stderr) of one ``python -m animegraph ARGS``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-m", "animegraph", *args], capture_output=True,
                         text=True, env={**_ENV, **(env or {})})
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if out.returncode != 0:
        sys.exit(f"bench_startup: 'animegraph {' '.join(args)}' failed: {out.stderr.strip()}")
    return wall, cpu, out.stderr


def _median(args: list[str], runs: int, parse=None, envs=({},)) -> list[tuple[float, ...]]:
    """Per environment of ``envs``: median (wall, CPU, work) over ``runs`` runs, the
    environments' runs alternating."""
    for env in envs:
        _run(args, env)  # warm
    rows = [[] for _ in envs]
    for _ in range(runs):
        for k, env in enumerate(envs):
            wall, cpu, err = _run(args, env)
            rows[k].append((wall, cpu, parse(err) if parse else 0.0))
    return [tuple(statistics.median(r[i] for r in runs_) for i in range(3)) for runs_ in rows]


def _synth_work(err: str) -> float:
    load = float(re.search(r"loaded \d+ animes in ([\d.]+) s", err).group(1))
    total = float(re.search(r"; ([\d.]+) s = segment", err).group(1))
    return load + total


def _map_work(err: str) -> float:
    return float(re.search(r"frames from .* in ([\d.]+) s;", err).group(1))


def _imports(args: list[str], top: int):
    """The heaviest imports (cumulative s), all imports' total, the HEAVY ones made, and
    the names of all modules imported."""
    out = subprocess.run([sys.executable, "-X", "importtime", "-m", "animegraph", *args],
                         capture_output=True, text=True, env=_ENV)
    rows, total, names = [], 0.0, set()
    for line in out.stderr.splitlines():
        m = re.match(r"import time:\s+\d+ \|\s+(\d+) \|( *)(\S+)", line)
        if not m:
            continue
        names.add(m.group(3))
        if len(m.group(2)) == 1:
            total += int(m.group(1)) / 1e6  # top level: each import counted once
        if len(m.group(2)) <= 3:  # the project's own imports and what they pull in
            rows.append((int(m.group(1)) / 1e6, m.group(3)))
    return sorted(rows, reverse=True)[:top], total, [h for h in HEAVY if h in names], names


_KERNEL_CHILD = """
import json, sys, time
from pathlib import Path
from numba.core import event

class Recorder(event.Listener):
    def __init__(self):
        self.stack, self.rows = [], []
    def on_start(self, ev):
        self.stack.append((time.perf_counter(), time.process_time()))
    def on_end(self, ev):
        w0, c0 = self.stack.pop()
        f = ev.data["dispatcher"].py_func
        self.rows.append([f"{f.__module__.rsplit('.', 1)[-1]}.{f.__name__}", len(self.stack),
                          time.perf_counter() - w0, time.process_time() - c0])

rec = Recorder()
event.register("numba:compile", rec)
w0, c0 = time.perf_counter(), time.process_time()
from animegraph.apps.prepare import compile_kernels
import animegraph.search.kernels as kernels
kernels.uncompiled_kernels = lambda method="exact": ["all"]  # run the work on a warm cache too
compile_kernels(Path(sys.argv[1]))
print(json.dumps({"wall": time.perf_counter() - w0, "cpu": time.process_time() - c0,
                  "rows": rec.rows}))
"""


def _kernel_run(db: Path, cache: Path) -> dict:
    import json

    out = subprocess.run([sys.executable, "-c", _KERNEL_CHILD, str(db)], capture_output=True,
                         text=True, env={**_ENV, "NUMBA_CACHE_DIR": str(cache)})
    if out.returncode != 0:
        sys.exit(f"bench_startup: the kernel run failed: {out.stderr.strip()[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def _numpy_dtw_cost(x: np.ndarray, y: np.ndarray) -> float:
    """Eq. 5's accumulated DTW cost (Euclidean frames, steps (1,0), (0,1), (1,1)) in NumPy:
    each row's horizontal steps are a running minimum of ``b[k] - C[k]`` plus ``C[j]``."""
    c = np.sqrt(((x[:, None, :] - y[None, :, :]) ** 2).sum(axis=2))  # (n, m)
    prev = np.cumsum(c[0])
    for i in range(1, len(x)):
        best_above = np.minimum(prev, np.concatenate(([np.inf], prev[:-1])))
        b = c[i] + best_above
        run = np.cumsum(c[i])
        prev = run + np.minimum.accumulate(b - run)
    return float(prev[-1])


_PARTS_CHILD = """
import json, sys, time
t0 = time.process_time()
parts = {}

inner = [0.0]  # CPU of the timed calls inside the running one: each part is its own time

def timed(owner, attr, label):
    fn = getattr(owner, attr)
    def wrapped(*args, **kwargs):
        c, outer = time.process_time(), inner[0]
        inner[0] = 0.0
        try:
            return fn(*args, **kwargs)
        finally:
            spent = time.process_time() - c
            parts[label] = parts.get(label, 0.0) + spent - inner[0]
            inner[0] = outer + spent
    setattr(owner, attr, wrapped)

import numpy, pyarrow, pyarrow.parquet
parts["numpy, pyarrow"] = time.process_time() - t0
c = time.process_time()
import numba
parts["numba's import"] = time.process_time() - c
import animegraph.apps.commands.synth as command
import animegraph.baselines.predicting as predicting
import animegraph.search.dtw as dtw
import animegraph.synthesis as synthesis
import animegraph.synthesis.pipeline as pipeline
from animegraph.synthesis.model import Model
timed(dtw, "_check_nodes", "numba's first cached kernel (its CPU target, scipy.linalg)")
timed(Model, "load", "loading the graph")
timed(command, "load_guide", "loading the guides")
timed(pipeline, "query_phones", "phones (from the cache) and the input's features")
timed(pipeline, "score_candidates", "audio cost (DTW)")
timed(pipeline, "guide_trajectory", "the guides' predictions")
timed(pipeline, "search", "search")
timed(pipeline, "render_k_best", "k-best assembly")
timed(synthesis, "write_motion", "writing")
from animegraph.apps.cli import main
code = main(sys.argv[1:])
parts["the whole process"] = time.process_time()
print(json.dumps(parts))
sys.exit(code)
"""


def _parts_run(args: list[str], env: dict) -> dict:
    """CPU seconds by part of one ``synth`` (:data:`_PARTS_CHILD`)."""
    import json

    out = subprocess.run([sys.executable, "-c", _PARTS_CHILD, *args], capture_output=True,
                         text=True, env={**_ENV, **env})
    if out.returncode != 0:
        sys.exit(f"bench_startup: the timed run failed: {out.stderr.strip()[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def kernel_report(db: Path, repeats: int) -> None:
    from animegraph.search.dtw import audio_costs

    with tempfile.TemporaryDirectory() as tmp:
        fresh = _kernel_run(db, Path(tmp))
        warm = _kernel_run(db, Path(tmp))
    print(f"kernels, fresh cache: {fresh['wall']:.1f} s wall, {fresh['cpu']:.1f} s CPU for "
          f"the warm-up's synthesis (compiling {len(fresh['rows'])} kernel signatures)")
    print(f"kernels, warm cache: {warm['wall']:.1f} s wall, {warm['cpu']:.1f} s CPU for the "
          f"same work ({len(warm['rows'])} compiled)")
    print("compile time per kernel (top level first; s wall / s CPU, including callees):")
    for name, depth, wall, cpu in sorted(fresh["rows"], key=lambda r: (r[1], -r[3])):
        print(f"  {'  ' * depth}{name:32s} {wall:7.2f} {cpu:7.2f}")
    rng = np.random.default_rng(0)
    x = rng.standard_normal((20, 9))
    ys = [rng.standard_normal((int(m), 9)).astype(np.float32)
          for m in rng.integers(10, 30, 200)]
    offsets = np.concatenate([[0], np.cumsum([len(y) for y in ys])]).astype(np.int64)
    values = np.concatenate(ys)
    nodes = np.arange(len(ys))
    audio_costs(x, values, offsets, nodes)  # compiled (cache) before timing
    c0 = time.process_time()
    for _ in range(repeats):
        audio_costs(x, values, offsets, nodes)
    compiled = (time.process_time() - c0) / repeats / len(ys)
    c0 = time.process_time()
    for y in ys:
        _numpy_dtw_cost(x, y.astype(np.float64))
    numpy_s = (time.process_time() - c0) / len(ys)
    print(f"Eq. 5 DTW of a 20-frame phone against 10-30-frame animes: compiled "
          f"{1e6 * compiled:.1f} us CPU a pair (audio_costs, {len(ys)} pairs a call), NumPy "
          f"{1e6 * numpy_s:.1f} us a pair ({numpy_s / compiled:.0f} x): numba kept")


def heard_report(db: Path, audio: Path | None = None) -> None:
    import shutil

    import soundfile

    from animegraph.apps.prepare import unfitted_note

    guide = [] if unfitted_note(db) is None else ["--guide", "none"]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        if audio is None:
            utt = speak(SENTENCE, Voice())
            write_wav(tmp / "speech.wav", utt.audio, utt.sample_rate)
            duration = utt.duration
        else:  # a copy: no phone labels beside it
            shutil.copy(audio, tmp / "speech.wav")
            duration = soundfile.info(str(audio)).duration
        env = {"ANIMEGRAPH_CACHE": str(tmp / "cache")}
        base = ["synth", str(tmp / "speech.wav"), "--db", str(db), *guide]
        rows = []
        for extra in ([], ["--k-best", "5"]):
            wall, cpu, err = _run([*base, *extra, "-o", str(tmp / "m.npz")], env)
            found = re.search(r"([\d.]+) s = segment ([\d.]+)", err)
            rows.append((wall, cpu, float(found.group(2)), float(found.group(1)),
                         "phones heard before" in err))
        parts = _parts_run([*base, "--k-best", "5", "-o", str(tmp / "m.npz")], env)
    what = f"{duration:.1f} s" + (", " + " ".join(guide) if guide else "")
    for (wall, cpu, segment, work, hit), label in zip(rows, ("first", "again, --k-best 5"),
                                                      strict=True):
        print(f"synth from speech alone ({what}), {label}: {wall:.2f} s wall, "
              f"{cpu:.2f} s CPU, segment {segment:.2f} s"
              f"{' (from the cache)' if hit else ''} of {work:.2f} s work, "
              f"{wall - work:.2f} s the rest (start-up, loading, writing)")
    print(f"the second run's share of the first: {rows[1][0] / rows[0][0]:.0%} wall, "
          f"{rows[1][1] / rows[0][1]:.0%} CPU (target <= 20 %)")
    whole = parts.pop("the whole process")
    print(f"the second run again, CPU s by part ({whole:.2f} s from the interpreter's start, "
          f"{rows[0][1]:.2f} s the first run's whole process):")
    for label, seconds in parts.items():
        print(f"  {seconds:6.3f}  {seconds / rows[0][1]:4.0%} of the first  {label}")
    print(f"  {whole - sum(parts.values()):6.3f}  the rest (the project's imports, the "
          "interpreter, the command's own checks)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--db", type=Path, default=None)
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--top", type=int, default=12)
    parser.add_argument("--kernels", action="store_true",
                        help="measure the numba kernels (fresh and warm cache, NumPy) instead")
    parser.add_argument("--heard", action="store_true",
                        help="measure a second synth of one recording (phones cached) instead")
    parser.add_argument("--audio", type=Path, default=None,
                        help="with --heard: this recording instead of the eSpeak NG sentence")
    parser.add_argument("--no-bytecode", action="store_true",
                        help="keep PYTHONDONTWRITEBYTECODE if set (default: drop it)")
    args = parser.parse_args()
    if not args.no_bytecode:
        _ENV.pop("PYTHONDONTWRITEBYTECODE", None)
    db = args.db or default_database()[0]
    if not is_database(db):
        sys.exit(f"bench_startup: no database at {db}: run 'animegraph demo' first")
    print(f"python {sys.version.split()[0]}, {os.cpu_count()} cores, load average "
          f"{os.getloadavg()[0]:.2f}; database {db}; median of {args.runs} warm runs; "
          f"bytecode {'not ' if _ENV.get('PYTHONDONTWRITEBYTECODE') else ''}cached")
    if args.heard:
        heard_report(db, args.audio)
        return
    if args.kernels:
        kernel_report(db, args.runs)
        print(f"load average at the end: {os.getloadavg()[0]:.2f}")
        return

    (help_s, help_cpu, _), = _median(["--help"], args.runs)
    print(f"animegraph --help: {help_s:.2f} s wall, {help_cpu:.2f} s CPU (target <= 0.3 s)")

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        utt = speak(SENTENCE, Voice())
        write_wav(tmp / "speech.wav", utt.audio, utt.sample_rate)
        write_phones_csv(tmp / "speech.phones.csv", [(p.phone, p.start, p.end)
                                                     for p in utt.phones])
        synth = ["synth", str(tmp / "speech.wav"), "--db", str(db), "-o", str(tmp / "m.c3d")]
        (wall, cpu, work), = _median(synth, args.runs, _synth_work)
        print(f"animegraph synth ({utt.duration:.1f} s of speech): {wall:.2f} s wall, "
              f"{cpu:.2f} s CPU = {work:.2f} s work (load + segment + audio cost + search + "
              f"post) + {wall - work:.2f} s start-up and writing (targets: wall <= 3 s, "
              f"start-up <= 2 s)")
        mapping = ["map-emotion", str(tmp / "m.c3d"), "--db", str(db), "--to", "sad",
                   "--from", "neutral", "-o", str(tmp / "sad.c3d")]
        (wall, cpu, work), = _median(mapping, args.runs, _map_work)
        print(f"animegraph map-emotion: {wall:.2f} s wall, {cpu:.2f} s CPU = {work:.2f} s "
              f"work + {wall - work:.2f} s start-up and writing")
        rows, total, heavy, names = _imports(synth, args.top)
        print(f"imports of 'synth': {len(names)} modules, {total:.2f} s in all (one run); of "
              f"the libraries it does not need ({', '.join(HEAVY)}): "
              f"{', '.join(heavy) or 'none'}")
        print("heaviest imports of 'synth' (cumulative s):")
        for seconds, name in rows:
            print(f"  {seconds:6.3f}  {name}")
    print(f"load average at the end: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
