"""Throughput of ``animegraph batch``: lines per minute with 1 and 2 Dask workers.

Usage::

    python scripts/bench_batch.py [--db PATH] [--lines 200] [--workers 1 2]
                                  [--render none mp4] [--out DIR] [--json OUT]

The script is ``--lines`` held-out lines (the grammar's sentences after the default
corpus' 40, so none is in the database; every other line two sentences) whose neutral
eSpeak NG speech lasts 2-6 s, the five emotions in turn, no recordings: every line is
spoken by eSpeak, synthesized as ``batch`` does by default and written (WAV, C3D, phones,
explain JSON). Each
configuration runs into a fresh folder on a fresh local cluster (``threads_per_worker=1``,
numba single-threaded per worker).

Prints, per configuration: wall time from the start of ``run_batch`` to the report
(numba warm-up in the parent, cluster start and every line), lines per minute over that
wall time, the steady rate between the first and last finished line, the median wall and
CPU seconds a line took on its worker, and the scaling efficiency of 2 workers against 1
(rate(N) / (N x rate(1))). MP4 rendering is timed when this build has it; otherwise the
script says so and skips it.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

from animegraph.apps.batch import BatchOptions, run_batch
from ingest.corpus.emotions import EMOTIONS
from ingest.corpus.sentences import generate_sentences
from ingest.speech.espeak import Voice, speak

#: Sentences of the default corpus (``CorpusConfig().sentences``): the script starts after.
CORPUS_SENTENCES = 40


def make_script(path: Path, n_lines: int, *, min_s: float = 2.0, max_s: float = 6.0) -> dict:
    """Write a CSV script of ``n_lines`` held-out lines of ``min_s``-``max_s`` s of speech:
    one grammar sentence, or two for every other line (the grammar's sentences are short)."""
    rows: list[tuple[str, ...]] = []
    durations: list[float] = []
    sentences = iter(generate_sentences(CORPUS_SENTENCES + 20 * n_lines + 200)
                     [CORPUS_SENTENCES:])
    for first in sentences:
        text = first if len(rows) % 2 == 0 else f"{first} {next(sentences)}"
        seconds = speak(text, Voice()).duration
        if min_s <= seconds <= max_s:
            emotion = EMOTIONS[len(rows) % len(EMOTIONS)]
            rows.append((f"line{len(rows):04d}", "tutor", emotion, text))
            durations.append(seconds)
            if len(rows) == n_lines:
                break
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(("id", "speaker", "emotion", "text"))
        writer.writerows(rows)
    return {"lines": len(rows), "speech_s": round(sum(durations), 1),
            "mean_s": round(statistics.mean(durations), 2),
            "min_s": round(min(durations), 2), "max_s": round(max(durations), 2)}


def run(script: Path, db: Path, out: Path, workers: int, render: str) -> dict:
    """One configuration, on a fresh cluster into an empty folder."""
    stamps: list[float] = []

    def progress(total):
        def wrap(items):
            for item in items:
                stamps.append(time.perf_counter())
                yield item
        return wrap

    t0 = time.perf_counter()
    result = run_batch(script, BatchOptions(db=db, out=out, workers=workers, render=render,
                                            force=True), progress=progress)
    wall = time.perf_counter() - t0
    done = [r for r in result.rows if r["status"] == "done"]
    steady = (len(stamps) - 1) / (stamps[-1] - stamps[0]) * 60 if len(stamps) > 2 else None
    return {
        "workers": workers, "render": render, "lines": len(result.rows), "done": len(done),
        "failed": result.count("failed"), "wall_s": round(wall, 1),
        "first_line_s": round(stamps[0] - t0, 1) if stamps else None,
        "lines_per_min": round(len(done) / wall * 60, 1),
        "steady_lines_per_min": round(steady, 1) if steady else None,
        "median_line_s": round(statistics.median(float(r["seconds"]) for r in done), 2)
        if done else None,
        "median_line_cpu_s": round(statistics.median(float(r["cpu_seconds"]) for r in done), 2)
        if done else None,
        "model_loads": sorted(result.loads.values()),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--db", type=Path, default=None,
                        help="database (default: the default one in the cache, built if absent)")
    parser.add_argument("--lines", type=int, default=200, help="lines in the script (200)")
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--render", nargs="+", default=["none", "mp4"],
                        choices=("none", "mp4"))
    parser.add_argument("--out", type=Path, default=None, help="work folder (default: temp)")
    parser.add_argument("--json", type=Path, default=None, help="also write the figures here")
    args = parser.parse_args(argv)

    if args.db is None:
        from animegraph.apps.demo import ensure_default_corpus, ensure_default_db

        corpus, _, _ = ensure_default_corpus()
        args.db, _ = ensure_default_db(corpus)
    renders = list(args.render)
    work = args.out or Path(tempfile.mkdtemp(prefix="bench-batch-"))
    work.mkdir(parents=True, exist_ok=True)
    script = work / "script.csv"
    info = make_script(script, args.lines)
    print(f"script: {info['lines']} lines, {info['speech_s']} s of speech "
          f"({info['min_s']}-{info['max_s']} s, mean {info['mean_s']} s); db {args.db}")
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"load average before {os.getloadavg()[0]:.1f}")
    rows = []
    for render in renders:
        for workers in args.workers:
            row = run(script, args.db, work / f"out-{render}-{workers}", workers, render)
            rows.append(row)
            print(json.dumps(row), flush=True)
    print()
    print("| workers | render | lines | wall (s) | first line (s) | lines/min | steady lines/min "
          "| median s/line (CPU s) | scaling efficiency (wall / steady) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for row in rows:
        base = next((r for r in rows if r["render"] == row["render"] and r["workers"] == 1),
                    None)

        def efficiency(field, row=row, base=base):
            if not base or row["workers"] == 1 or not row[field] or not base[field]:
                return ""
            return f"{row[field] / (row['workers'] * base[field]):.0%}"

        eff = efficiency("lines_per_min")
        if eff:
            eff += f" / {efficiency('steady_lines_per_min')}"
        print(f"| {row['workers']} | {row['render']} | {row['done']}/{row['lines']} | "
              f"{row['wall_s']} | {row['first_line_s']} | {row['lines_per_min']} | "
              f"{row['steady_lines_per_min']} | {row['median_line_s']} "
              f"({row['median_line_cpu_s']}) | {eff} |")
    print(f"load average after: {os.getloadavg()[0]:.1f}")
    if args.json:
        args.json.write_text(json.dumps({"script": info, "runs": rows}, indent=1))
    return 0 if all(r["failed"] == 0 for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
