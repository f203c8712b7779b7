"""Time the synthetic corpus generator at the default and the paper's size.

Usage::

    python scripts/bench_corpus.py [--scale default paper] [--workers 2] [--json OUT]

Prints, per scale: clips, sentences, minutes of speech, wall-clock seconds, and
seconds of speech generated per second. The corpora are written to a temporary
folder and deleted.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

from ingest.corpus.synthetic import CorpusConfig, generate_corpus


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scale", nargs="+", default=["default", "paper"],
                        choices=["default", "paper"])
    parser.add_argument("--workers", type=int, default=os.cpu_count())
    parser.add_argument("--json", type=Path, help="also write the results here")
    args = parser.parse_args()

    rows = []
    print(f"# {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"workers={args.workers}")
    print(f"{'scale':8s} {'clips':>6s} {'sentences':>9s} {'speech_min':>10s} "
          f"{'wall_s':>7s} {'speech_s_per_s':>14s}")
    for scale in args.scale:
        with tempfile.TemporaryDirectory() as tmp:
            start = time.perf_counter()
            summary = generate_corpus(Path(tmp) / "corpus", CorpusConfig(scale=scale),
                                      workers=args.workers)
            wall = time.perf_counter() - start
        row = {"scale": scale, "clips": summary.n_clips, "sentences": summary.n_sentences,
               "speech_min": summary.duration_s / 60, "wall_s": wall,
               "speech_s_per_s": summary.duration_s / wall, "workers": args.workers}
        rows.append(row)
        print(f"{scale:8s} {row['clips']:6d} {row['sentences']:9d} {row['speech_min']:10.1f} "
              f"{wall:7.1f} {row['speech_s_per_s']:14.1f}")
        sys.stdout.flush()
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
