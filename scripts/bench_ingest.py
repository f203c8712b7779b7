"""Time ``animegraph ingest`` on a synthetic corpus (default: the paper's size) or any folder.

Usage::

    python scripts/bench_ingest.py [--scale paper|default] [--workers 2] [--corpus DIR]
                                   [--keep DB] [--json OUT]
    python scripts/bench_ingest.py --corpus DIR --per-clip-every K
    python scripts/bench_ingest.py --read-back DB
    python scripts/bench_ingest.py --corpus DIR --subset N --fresh-cache [--dask | --scheduler A]
    python scripts/bench_ingest.py --dask --workers W --idle SECONDS

Generates the corpus into a temporary folder (or uses ``--corpus``), ingests it, and
prints each corpus-wide step with the wall and CPU time so far (this process, and its
finished workers), then wall-clock time, clips and animes, frames, minutes of speech,
database size on disk, CPU time of all processes, the load average, and peak memory
(this process and its workers).

``--per-clip-every K``: no database; the per-clip work of an ingest
(``ingest.per_clip.work``: read, check, align, features) on every K-th clip of the
corpus, in this process, once the one-off loads (CMUdict, the aligner) are done: its
wall and CPU time a clip, and the CPU of child processes (ffmpeg) a clip; then the cost
a clip of keeping the prepared clips in the cache (what makes an ingest resumable) and of
taking them back, and their size.

``--dask``: the per-clip work on a new local Dask cluster of ``--workers`` processes
(``animegraph ingest --scheduler``'s path, :mod:`ingest.on_dask`; its start-up counted);
``--scheduler ADDRESS``: on an existing one. ``--subset N``: copies of the corpus' first
N clips (by name) are ingested; ``--fresh-cache``: in an empty cache folder, so that face
tracking and the phone model run again (the cold cost of a clip). The wall time at which
the clips were all prepared is printed as ``clips_s``, the rest (decomposition, emotion
model, writing: the one writer's serial part) as ``writer_s``.

``--dask --idle SECONDS``: no ingest; the CPU of a local Dask cluster of ``--workers``
processes (as ``ingest`` starts it) while it starts and then while it waits for work
``SECONDS`` seconds, summed over every process of the tree: its heartbeats and event
loops cost CPU whether or not it has clips, for as long as it is up.

``--read-back DB``: no ingest; the time and peak memory of reading every clip of the
database back (``ingest.tables.prepared_from_database``, as an ingest into an existing
database and ``eval_lipsync --grid-db`` do).

After an ingest it also prints the CPU seconds per clip of the emotion classifier's
features (:func:`ingest.emotion.model.classifier_features`) on the corpus' first
``--feature-clips`` labelled clips.
"""

from __future__ import annotations

import argparse
import contextlib
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
    from ingest.per_clip import ClipJob, work
    from ingest.pipeline import IngestConfig, _head_reference
    from ingest.readers import discover
    from ingest.speech.g2p import pronounce
    from ingest.speech.sphinx import _engine

    config = IngestConfig()
    found = discover([corpus])[::every]
    reference = _head_reference(found, config.limits)
    pronounce("bin")
    _engine("align")  # one-off loads left out
    t0, (c0, k0) = time.perf_counter(), _cpu()
    results = [work(ClipJob(s, {}, None, reference, config.phones_engine, config.limits,
                             config.posteriorgrams)) for s in found]
    wall, (c1, k1) = time.perf_counter() - t0, _cpu()
    n = len(found)
    print(f"{n} clips ({sum(r.status != 'rejected' for r, _ in results)} prepared): "
          f"{1000 * wall / n:.0f} ms wall, {1000 * (c1 - c0) / n:.0f} ms CPU a clip, "
          f"+ {1000 * (k1 - k0) / n:.0f} ms CPU of child processes (ffmpeg); load "
          f"{os.getloadavg()[0]:.1f}")
    _kept_cost([(r, c) for r, c in results if c is not None])
    return 0


def _kept_cost(prepared: list) -> None:
    """Wall and CPU a clip of keeping the prepared clips in the cache (what makes an ingest
    resumable: :func:`ingest.prepared_cache.save`) and of taking them back, and their size."""
    from dataclasses import asdict

    from ingest import prepared_cache

    if not prepared:
        return
    keys = [f"bench-{k}" for k in range(len(prepared))]
    t0, c0 = time.perf_counter(), time.process_time()
    for key, (report, clip) in zip(keys, prepared, strict=True):
        prepared_cache.save(key, clip, asdict(report))
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    size = sum((prepared_cache.folder() / f"{key}.npz").stat().st_size for key in keys)
    t0, c0 = time.perf_counter(), time.process_time()
    for key in keys:
        prepared_cache.load(key)
    back_wall, back_cpu = time.perf_counter() - t0, time.process_time() - c0
    prepared_cache.remove(keys)
    n = len(prepared)
    print(f"kept in the cache: {1000 * wall / n:.1f} ms wall, {1000 * cpu / n:.1f} ms CPU, "
          f"{size / n / 2**20:.2f} MB a clip; taken back: {1000 * back_wall / n:.1f} ms wall, "
          f"{1000 * back_cpu / n:.1f} ms CPU a clip")


def read_back(db: Path) -> int:
    from ingest.tables import prepared_from_database

    t0, (c0, _) = time.perf_counter(), _cpu()
    clips = prepared_from_database(Database.open(db))
    print(f"{len(clips)} clips read back in {time.perf_counter() - t0:.1f} s wall, "
          f"{_cpu()[0] - c0:.1f} s CPU, peak RSS {_peak_mb():.0f} MB; load "
          f"{os.getloadavg()[0]:.1f}")
    return 0


def idle_cluster(workers: int, seconds: float) -> int:
    import psutil

    def tree_cpu() -> float:
        me = psutil.Process()
        total = sum(me.cpu_times()[:2])
        for child in me.children(recursive=True):
            try:
                times = child.cpu_times()
            except psutil.Error:  # ended meanwhile
                continue
            total += times.user + times.system
        return total

    t0, c0 = time.perf_counter(), tree_cpu()
    with _cluster(argparse.Namespace(dask=True, scheduler=None, workers=workers)) as (_, n):
        t1, c1 = time.perf_counter(), tree_cpu()
        time.sleep(seconds)
        t2, c2 = time.perf_counter(), tree_cpu()
    print(f"local Dask cluster of {n} workers: started in {t1 - t0:.1f} s wall, "
          f"{c1 - c0:.1f} CPU-s; idle {t2 - t1:.0f} s: {c2 - c1:.2f} CPU-s "
          f"({(c2 - c1) / (t2 - t1):.3f} CPU-s a second); load {os.getloadavg()[0]:.1f}")
    return 0


def _subset(corpus: Path, n: int, out: Path) -> Path:
    """Copies of the files of ``corpus``' first ``n`` clips (in name order), under ``out``
    (copies, not links: ingest refuses links that leave a clip's folder)."""
    found = sorted(discover([corpus]), key=lambda s: s.clip_id)[:n]
    for source in found:
        for path in source.paths:
            target = out / Path(path).relative_to(corpus)
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(path, target)
    return out


def _cluster(args):
    """A Dask client (``--dask``, ``--scheduler``) as ``ingest`` uses it, or None."""
    from types import SimpleNamespace

    if not (args.dask or args.scheduler):
        return contextlib.nullcontext((None, args.workers))
    from animegraph.apps.batch_cluster import CONNECT_TIMEOUT_S, dask_client

    return dask_client(SimpleNamespace(scheduler=args.scheduler, workers=args.workers,
                                       connect_timeout=CONNECT_TIMEOUT_S))


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
    parser.add_argument("--dask", action="store_true",
                        help="on a local Dask cluster of --workers processes")
    parser.add_argument("--scheduler", metavar="ADDRESS", help="on this Dask cluster")
    parser.add_argument("--idle", type=float, metavar="SECONDS",
                        help="with --dask: the CPU of an idle local cluster, no ingest")
    parser.add_argument("--subset", type=int, metavar="N", help="the first N clips only")
    parser.add_argument("--fresh-cache", action="store_true",
                        help="in an empty cache folder (tracking, phones computed again)")
    args = parser.parse_args()
    if args.read_back:
        return read_back(args.read_back)
    if args.idle is not None:
        if not args.dask:
            parser.error("--idle needs --dask")
        return idle_cluster(args.workers, args.idle)
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
        if args.subset:
            corpus = _subset(corpus, args.subset, Path(tmp) / "subset")
        if args.fresh_cache:
            os.environ["ANIMEGRAPH_CACHE"] = str(Path(tmp) / "cache")
        db = Path(tmp) / "db"
        t0, (c0, k0) = time.perf_counter(), _cpu()
        load = os.getloadavg()[0]
        steps: list[float] = []

        def say(line: str) -> None:
            me, kids = _cpu()
            steps.append(time.perf_counter() - t0)
            print(f"# {time.perf_counter() - t0:7.1f} s wall, CPU {me - c0:.1f} s here + "
                  f"{kids - k0:.1f} s workers, load {os.getloadavg()[0]:.1f}: {line}",
                  flush=True)

        on_dask = bool(args.dask or args.scheduler)
        cluster_up: dict = {"start_s": 0.0, "workers": args.workers}

        @contextlib.contextmanager
        def cluster():  # as ingest enters it: for the clips only
            t = time.perf_counter()
            with _cluster(args) as (client, n):
                cluster_up.update(start_s=time.perf_counter() - t, workers=n)
                yield client

        report = ingest([corpus], db, workers=args.workers, say=say,
                        cluster=cluster if on_dask else None)
        wall = time.perf_counter() - t0
        started, n_workers = cluster_up["start_s"], cluster_up["workers"]
        me, kids = _cpu()
        m = Database.open(db).manifest
        row = {
            "scale": args.scale if args.corpus is None else str(args.corpus),
            "workers": n_workers, "on": "dask" if on_dask else (
                "pool" if args.workers > 1 else "this process"),
            "wall_s": round(wall, 1), "start_s": round(started, 1),
            "clips_s": round(steps[0], 1) if steps else None,
            "writer_s": round(wall - steps[0], 1) if steps else None,
            "clips": m["n_clips"],
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
