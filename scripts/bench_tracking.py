"""Face tracking speed on videos, filling the tracking cache
(docs/results/speed.md, "Face tracking").

Usage::

    python scripts/bench_tracking.py [VIDEO_OR_FOLDER ...] [--limit N] [--workers 2]
                                     [--fresh]

Default: the GRID s1 videos of ``../shared/data/grid/s1``. Each video is tracked with
:func:`ingest.readers.video.cached_tracking` (videos already in the cache are read from
it and counted apart), or with ``--fresh`` tracked again without touching the cache, in
``--workers`` processes (one video a process at a time, as ``animegraph ingest
--workers`` tracks). Prints frames, the wall time of the whole run and its rate (frames
per second over all processes), and per frame the wall and the CPU time (the tracking
process's ``time.process_time`` plus its ffmpeg's: load-independent) of the tracking
proper (decoding included), the load average before and after, and how many frames had
no face or two.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from tqdm import tqdm

from ingest.readers.discovery import VIDEO_SUFFIXES
from ingest.readers.video import cached_tracking, track_video, tracker_available
from ingest.workers import map_in_processes

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def _track(job: tuple[Path, bool]) -> tuple[int, float, float, int, int, bool]:
    """(frames, wall s, CPU s, frames without a face, with two, read from the cache)."""
    video, fresh = job
    result = track_video(video, progress=False) if fresh else cached_tracking(video,
                                                                              progress=False)
    return (len(result.landmarks), result.seconds, result.cpu_seconds,
            int((result.n_faces == 0).sum()), int((result.n_faces > 1).sum()),
            result.seconds == 0.0)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("paths", nargs="*", type=Path, default=[SHARED / "grid" / "s1"])
    parser.add_argument("--limit", type=int, default=0, help="first N videos only")
    parser.add_argument("--workers", type=int, default=2, help="tracking processes")
    parser.add_argument("--fresh", action="store_true",
                        help="track again, neither reading nor writing the cache")
    args = parser.parse_args()
    if not tracker_available():
        print('the face tracker is not installed: pip install -e ".[video]"', file=sys.stderr)
        return 2
    videos = []
    for path in args.paths:
        videos += sorted(p for p in path.iterdir() if p.suffix.lower() in VIDEO_SUFFIXES) \
            if path.is_dir() else [path]
    if args.limit:
        videos = videos[:args.limit]
    load_before = os.getloadavg()
    started = time.perf_counter()
    jobs = [(v, args.fresh) for v in videos]
    bar = lambda results: tqdm(results, total=len(jobs), unit="video")  # noqa: E731
    if args.workers > 1 and len(jobs) > 1:
        results = map_in_processes(_track, jobs, workers=args.workers, progress=bar)
    else:
        results = [_track(j) for j in bar(jobs)]
    wall = time.perf_counter() - started
    tracked = [r for r in results if not r[5]]
    frames = sum(r[0] for r in tracked)
    seconds, cpu = sum(r[1] for r in tracked), sum(r[2] for r in tracked)
    print(f"{len(videos)} videos: {len(tracked)} tracked, {len(videos) - len(tracked)} from "
          f"the cache, {args.workers} process(es), {wall:.1f} s wall; load average "
          f"{load_before[0]:.1f} before, {os.getloadavg()[0]:.1f} after, {os.cpu_count()} "
          f"cores")
    if tracked:
        print(f"tracking: {frames} frames, {frames / wall:.1f} frames/s over the run; per "
              f"frame {1000 * seconds / frames:.2f} ms wall, {1000 * cpu / frames:.2f} ms CPU "
              f"(one process: {frames / cpu:.1f} frames/s of CPU)")
    print(f"frames without a face: {sum(r[3] for r in results)}; with two faces: "
          f"{sum(r[4] for r in results)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
