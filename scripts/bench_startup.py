"""Start-up of the command line: ``--help``, a one-shot ``synth`` and ``map-emotion``.

Usage::

    python scripts/bench_startup.py [--db PATH] [--runs 5] [--top 12]

Every figure is the median of ``--runs`` fresh ``python -m animegraph`` processes (warm:
one run first, unmeasured, so the OS file cache and numba's kernel cache are filled):

* ``animegraph --help`` wall time (target: <= 0.3 s);
* ``animegraph synth`` of a 4 s eSpeak NG sentence (phones from the ``.phones.csv``
  beside it, exact search) against the database (default: the demo's, ``--db`` or
  ``$ANIMEGRAPH_DB``): wall time, the work the command itself reports (loading the
  database + segment + audio cost + search + post), and the rest, the start-up overhead
  (interpreter, imports, writing; target: wall <= 3 s in all, overhead <= 2 s);
* ``animegraph map-emotion`` of that motion to sad: wall time and the reported work;
* the heaviest imports of ``synth`` by ``python -X importtime`` (cumulative).
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from animegraph.apps.cache import default_database
from db.store import is_database
from ingest.formats.phones_csv import write_phones_csv
from ingest.formats.wav import write_wav
from ingest.speech.espeak import Voice, speak

SENTENCE = "The quiet fisherman sold his boat and moved to the city by the sea."


def _run(args: list[str]) -> tuple[float, str]:
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-m", "animegraph", *args], capture_output=True,
                         text=True)
    wall = time.perf_counter() - t0
    if out.returncode != 0:
        sys.exit(f"bench_startup: 'animegraph {' '.join(args)}' failed: {out.stderr.strip()}")
    return wall, out.stderr


def _median(args: list[str], runs: int, parse=None) -> tuple[float, float | None]:
    _run(args)  # warm
    walls, works = [], []
    for _ in range(runs):
        wall, err = _run(args)
        walls.append(wall)
        if parse is not None:
            works.append(parse(err))
    return statistics.median(walls), (statistics.median(works) if works else None)


def _synth_work(err: str) -> float:
    load = float(re.search(r"loaded \d+ animes in ([\d.]+) s", err).group(1))
    total = float(re.search(r"; ([\d.]+) s = segment", err).group(1))
    return load + total


def _map_work(err: str) -> float:
    return float(re.search(r"frames from .* in ([\d.]+) s;", err).group(1))


def _imports(args: list[str], top: int) -> list[tuple[float, str]]:
    out = subprocess.run([sys.executable, "-X", "importtime", "-m", "animegraph", *args],
                         capture_output=True, text=True)
    rows = []
    for line in out.stderr.splitlines():
        m = re.match(r"import time:\s+\d+ \|\s+(\d+) \|( *)(\S+)", line)
        if m and len(m.group(2)) <= 3:  # the project's own imports and what they pull in
            rows.append((int(m.group(1)) / 1e6, m.group(3)))
    return sorted(rows, reverse=True)[:top]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--db", type=Path, default=None)
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--top", type=int, default=12)
    args = parser.parse_args()
    db = args.db or default_database()[0]
    if not is_database(db):
        sys.exit(f"bench_startup: no database at {db}: run 'animegraph demo' first")
    print(f"python {sys.version.split()[0]}, {os.cpu_count()} cores, load average "
          f"{os.getloadavg()[0]:.2f}; database {db}; median of {args.runs} warm runs")

    help_s, _ = _median(["--help"], args.runs)
    print(f"animegraph --help: {help_s:.2f} s wall (target <= 0.3 s)")

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        utt = speak(SENTENCE, Voice())
        write_wav(tmp / "speech.wav", utt.audio, utt.sample_rate)
        write_phones_csv(tmp / "speech.phones.csv", [(p.phone, p.start, p.end)
                                                     for p in utt.phones])
        synth = ["synth", str(tmp / "speech.wav"), "--db", str(db), "-o", str(tmp / "m.c3d")]
        wall, work = _median(synth, args.runs, _synth_work)
        print(f"animegraph synth ({utt.duration:.1f} s of speech): {wall:.2f} s wall = "
              f"{work:.2f} s work (load + segment + audio cost + search + post) + "
              f"{wall - work:.2f} s start-up and writing (targets: wall <= 3 s, "
              f"start-up <= 2 s)")
        mapping = ["map-emotion", str(tmp / "m.c3d"), "--db", str(db), "--to", "sad",
                   "--from", "neutral", "-o", str(tmp / "sad.c3d")]
        wall, work = _median(mapping, args.runs, _map_work)
        print(f"animegraph map-emotion: {wall:.2f} s wall = {work:.2f} s work + "
              f"{wall - work:.2f} s start-up and writing")
        print("heaviest imports of 'synth' (cumulative s):")
        for seconds, name in _imports(synth, args.top):
            print(f"  {seconds:6.3f}  {name}")


if __name__ == "__main__":
    main()
