"""Time ``animegraph ingest`` on a synthetic corpus (default: the paper's size).

Usage::

    python scripts/bench_ingest.py [--scale paper|default] [--workers 2] [--corpus DIR]
                                   [--keep DB] [--json OUT]

Generates the corpus into a temporary folder (or uses ``--corpus``), ingests it, and
prints wall-clock time, clips and animes, frames, minutes of speech, database size on
disk and peak memory (this process and its workers).
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


def _size_mb(path: Path) -> float:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file()) / 2**20


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scale", choices=["default", "paper"], default="paper")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--corpus", type=Path, help="ingest this corpus instead")
    parser.add_argument("--keep", type=Path, help="leave the database here")
    parser.add_argument("--json", type=Path, help="also write the results here")
    args = parser.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        corpus = args.corpus
        if corpus is None:
            corpus = Path(tmp) / "corpus"
            t0 = time.perf_counter()
            generate_corpus(corpus, CorpusConfig(scale=args.scale), workers=args.workers)
            print(f"# generated the {args.scale} corpus in {time.perf_counter() - t0:.1f} s")
        db = Path(tmp) / "db"
        t0 = time.perf_counter()
        report = ingest([corpus], db, workers=args.workers)
        wall = time.perf_counter() - t0
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
            "cores": os.cpu_count(),
        }
        for k, v in row.items():
            print(f"{k:14s} {v}")
        if args.keep:
            shutil.copytree(db, args.keep, dirs_exist_ok=False)
    if args.json:
        args.json.write_text(json.dumps(row, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
