"""Face tracking speed on videos, filling the tracking cache (issue #14).

Usage::

    python scripts/bench_tracking.py [VIDEO_OR_FOLDER ...] [--limit N]

Default: the GRID s1 videos of ``../shared/data/grid/s1``. Each video is tracked with
:func:`ingest.readers.video.cached_tracking` (videos already in the cache are read from
it and counted apart). Prints per-video and total frames, seconds and ms per frame of
the tracking proper (decoding included), and how many frames had no face or two.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from tqdm import tqdm

from ingest.readers.discovery import VIDEO_SUFFIXES
from ingest.readers.video import cached_tracking, tracker_available

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("paths", nargs="*", type=Path, default=[SHARED / "grid" / "s1"])
    parser.add_argument("--limit", type=int, default=0, help="first N videos only")
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
    tracked = cached = frames = no_face = two = 0
    seconds = 0.0
    started = time.perf_counter()
    for video in tqdm(videos, unit="video"):
        result = cached_tracking(video, progress=False)
        if result.seconds:
            tracked += 1
            frames += len(result.landmarks)
            seconds += result.seconds
        else:
            cached += 1
        no_face += int((result.n_faces == 0).sum())
        two += int((result.n_faces > 1).sum())
    wall = time.perf_counter() - started
    print(f"{len(videos)} videos: {tracked} tracked, {cached} from the cache, "
          f"{wall:.1f} s wall")
    if tracked:
        print(f"tracking: {frames} frames in {seconds:.1f} s = {1000 * seconds / frames:.2f} ms "
              f"a frame ({frames / seconds:.1f} frames/s)")
    print(f"frames without a face: {no_face}; with two faces: {two}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
