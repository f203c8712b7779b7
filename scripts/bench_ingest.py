"""Time ``animegraph ingest`` on a synthetic corpus (default: the paper's size).

Usage::

    python scripts/bench_ingest.py [--scale paper|default] [--workers 2] [--corpus DIR]
                                   [--keep DB] [--json OUT]

Generates the corpus into a temporary folder (or uses ``--corpus``), ingests it, and
prints wall-clock time, clips and animes, frames, minutes of speech, database size on
disk and peak memory (this process and its workers); the CPU seconds of this process
(the serial part) and of its workers; the wall time of each corpus-wide step (from
ingest's ``say`` lines: the emotion step learns the emotion model and its classifier);
and the CPU seconds per clip of the emotion classifier's features
(:func:`ingest.emotion.model.classifier_features`) on the corpus' first ``--feature-clips``
labelled clips.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import sys
import tempfile
import time
from pathlib import Path

from db.store import Database
from ingest.corpus.synthetic import CorpusConfig, generate_corpus
from ingest.pipeline import ingest
from ingest.readers import discover, load


def _cpu(who) -> float:
    r = resource.getrusage(who)
    return r.ru_utime + r.ru_stime


def _feature_cpu_per_clip(corpus: Path, n: int) -> float | None:
    """CPU seconds per clip of the classifier's features (the first ``n`` labelled clips)."""
    try:
        from ingest.emotion.model import classifier_features
    except ImportError:  # an animegraph from before this was a function of its own
        return None
    clips = [c for c in (load(s) for s in discover([corpus])[:4 * n]) if c.emotion][:n]
    t = time.process_time()
    for c in clips:
        classifier_features(c.audio, c.sample_rate)
    return (time.process_time() - t) / max(len(clips), 1)


def _size_mb(path: Path) -> float:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file()) / 2**20


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scale", choices=["default", "paper"], default="paper")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--corpus", type=Path, help="ingest this corpus instead")
    parser.add_argument("--keep", type=Path, help="leave the database here")
    parser.add_argument("--json", type=Path, help="also write the results here")
    parser.add_argument("--feature-clips", type=int, default=20)
    args = parser.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        corpus = args.corpus
        if corpus is None:
            corpus = Path(tmp) / "corpus"
            t0 = time.perf_counter()
            generate_corpus(corpus, CorpusConfig(scale=args.scale), workers=args.workers)
            print(f"# generated the {args.scale} corpus in {time.perf_counter() - t0:.1f} s")
        db = Path(tmp) / "db"
        steps: list[tuple[float, str]] = []
        cpu0, child0 = _cpu(resource.RUSAGE_SELF), _cpu(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        report = ingest([corpus], db, workers=args.workers,
                        say=lambda line: steps.append((time.perf_counter(), line)))
        wall = time.perf_counter() - t0
        main_cpu = _cpu(resource.RUSAGE_SELF) - cpu0
        workers_cpu = _cpu(resource.RUSAGE_CHILDREN) - child0
        ends = [t for t, _ in steps[1:]] + [t0 + wall]
        step_s = {line.split("(")[0].replace("ingest: ", "").strip(" ."): round(end - t, 1)
                  for (t, line), end in zip(steps, ends, strict=True)}
        m = Database.open(db).manifest
        peak = max(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
                   resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss) / 1024
        row = {
            "scale": args.scale if args.corpus is None else str(args.corpus),
            "workers": args.workers, "wall_s": round(wall, 1), "clips": m["n_clips"],
            "rejected": report.count("rejected"), "animes": m["n_animes"],
            "frames": m["n_frames"], "speech_min": round(m["duration_s"] / 60, 1),
            "n_pcs": m["n_pcs"], "variance_kept": round(m["variance_kept"], 4),
            "db_mb": round(_size_mb(db), 1), "peak_rss_mb": round(peak),
            "cores": os.cpu_count(), "main_cpu_s": round(main_cpu, 1),
            "workers_cpu_s": round(workers_cpu, 1), "steps_s": step_s,
            "load_average": os.getloadavg()[0],
        }
        per_clip = _feature_cpu_per_clip(corpus, args.feature_clips)
        if per_clip is not None:
            row["emotion_feature_cpu_s_per_clip"] = round(per_clip, 4)
        for k, v in row.items():
            print(f"{k:14s} {v}")
        if args.keep:
            shutil.copytree(db, args.keep, dirs_exist_ok=False)
    if args.json:
        args.json.write_text(json.dumps(row, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
