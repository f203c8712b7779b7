"""Time ``animegraph ingest`` on a synthetic corpus (default: the paper's size) or any folder.

Usage::

    python scripts/bench_ingest.py [--scale paper|default] [--workers 2] [--corpus DIR]
                                   [--keep DB] [--json OUT]
    python scripts/bench_ingest.py --corpus DIR --per-clip-every K
    python scripts/bench_ingest.py --read-back DB

Generates the corpus into a temporary folder (or uses ``--corpus``), ingests it, and
prints each corpus-wide step with the wall and CPU time so far (this process, and its
finished workers), then wall-clock time, clips and animes, frames, minutes of speech,
database size on disk, CPU time of all processes, the load average, and peak memory
(this process and its workers).

``--per-clip-every K``: no database; the per-clip work of an ingest
(``ingest.pipeline._work``: read, check, align, features) on every K-th clip of the
corpus, in this process, once the one-off loads (CMUdict, the aligner) are done: its
wall and CPU time a clip, and the CPU of child processes (ffmpeg) a clip.

``--read-back DB``: no ingest; the time and peak memory of reading every clip of the
database back (``ingest.tables.prepared_from_database``, as an ingest into an existing
database and ``eval_lipsync --grid-db`` do).

After an ingest it also prints the CPU seconds per clip of the emotion classifier's
features (:func:`ingest.emotion.model.classifier_features`) on the corpus' first
``--feature-clips`` labelled clips.
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


def _cpu() -> tuple[float, float]:
    """CPU seconds (user + system) of this process and of its finished children."""
    me = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime, kids.ru_utime + kids.ru_stime


def _peak_mb() -> float:
    return max(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
               resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss) / 1024


def per_clip(corpus: Path, every: int) -> int:
    from ingest.pipeline import ClipJob, IngestConfig, _head_reference, _work
    from ingest.readers import discover
    from ingest.speech.g2p import pronounce
    from ingest.speech.sphinx import _engine

    config = IngestConfig()
    found = discover([corpus])[::every]
    reference = _head_reference(found, config.limits)
    pronounce("bin")
    _engine("align")  # one-off loads left out
    t0, (c0, k0) = time.perf_counter(), _cpu()
    results = [_work(ClipJob(s, {}, None, reference, config.phones_engine, config.limits,
                             config.posteriorgrams)) for s in found]
    wall, (c1, k1) = time.perf_counter() - t0, _cpu()
    n = len(found)
    print(f"{n} clips ({sum(r.status != 'rejected' for r, _ in results)} prepared): "
          f"{1000 * wall / n:.0f} ms wall, {1000 * (c1 - c0) / n:.0f} ms CPU a clip, "
          f"+ {1000 * (k1 - k0) / n:.0f} ms CPU of child processes (ffmpeg); load "
          f"{os.getloadavg()[0]:.1f}")
    return 0


def read_back(db: Path) -> int:
    from ingest.tables import prepared_from_database

    t0, (c0, _) = time.perf_counter(), _cpu()
    clips = prepared_from_database(Database.open(db))
    print(f"{len(clips)} clips read back in {time.perf_counter() - t0:.1f} s wall, "
          f"{_cpu()[0] - c0:.1f} s CPU, peak RSS {_peak_mb():.0f} MB; load "
          f"{os.getloadavg()[0]:.1f}")
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scale", choices=["default", "paper"], default="paper")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--corpus", type=Path, help="ingest this corpus instead")
    parser.add_argument("--keep", type=Path, help="leave the database here")
    parser.add_argument("--json", type=Path, help="also write the results here")
    parser.add_argument("--per-clip-every", type=int, metavar="K",
                        help="time the per-clip work on every K-th clip of --corpus")
    parser.add_argument("--read-back", type=Path, metavar="DB",
                        help="time reading every clip of DB back")
    parser.add_argument("--feature-clips", type=int, default=20,
                        help="clips timed for the emotion features (default 20)")
    args = parser.parse_args()
    if args.read_back:
        return read_back(args.read_back)
    if args.per_clip_every:
        if args.corpus is None:
            parser.error("--per-clip-every needs --corpus")
        return per_clip(args.corpus, args.per_clip_every)

    with tempfile.TemporaryDirectory() as tmp:
        corpus = args.corpus
        if corpus is None:
            corpus = Path(tmp) / "corpus"
            t0 = time.perf_counter()
            generate_corpus(corpus, CorpusConfig(scale=args.scale), workers=args.workers)
            print(f"# generated the {args.scale} corpus in {time.perf_counter() - t0:.1f} s")
        db = Path(tmp) / "db"
        t0, (c0, k0) = time.perf_counter(), _cpu()
        load = os.getloadavg()[0]

        def say(line: str) -> None:
            me, kids = _cpu()
            print(f"# {time.perf_counter() - t0:7.1f} s wall, CPU {me - c0:.1f} s here + "
                  f"{kids - k0:.1f} s workers, load {os.getloadavg()[0]:.1f}: {line}",
                  flush=True)

        report = ingest([corpus], db, workers=args.workers, say=say)
        wall = time.perf_counter() - t0
        me, kids = _cpu()
        m = Database.open(db).manifest
        row = {
            "scale": args.scale if args.corpus is None else str(args.corpus),
            "workers": args.workers, "wall_s": round(wall, 1), "clips": m["n_clips"],
            "rejected": report.count("rejected"), "animes": m["n_animes"],
            "frames": m["n_frames"], "speech_min": round(m["duration_s"] / 60, 1),
            "n_pcs": m["n_pcs"], "variance_kept": round(m["variance_kept"], 4),
            "db_mb": round(_size_mb(db), 1), "cpu_s": round(me - c0 + kids - k0, 1),
            "cpu_parent_s": round(me - c0, 1), "cpu_workers_s": round(kids - k0, 1),
            "load_before": round(load, 1), "load_after": round(os.getloadavg()[0], 1),
            "peak_rss_mb": round(_peak_mb()), "cores": os.cpu_count(),
        }
        feature_cpu = _feature_cpu_per_clip(corpus, args.feature_clips)
        if feature_cpu is not None:
            row["emotion_feature_cpu_s_per_clip"] = round(feature_cpu, 4)
        for k, v in row.items():
            print(f"{k:14s} {v}")
        if args.keep:
            shutil.copytree(db, args.keep, dirs_exist_ok=False)
    if args.json:
        args.json.write_text(json.dumps(row, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
