"""Lip-audio lag on real data: each clip's own estimate against the pooled one
(docs/results/capture.md, "Lip-audio lag").

Usage::

    python scripts/eval_lag.py [--datasets talkingface facegood grid] [--grid-clips N]

For every clip: its own lag estimate (peak of the lip-activity / loudness correlation,
+ = lips lead the audio), the margin of that peak over its best side peak, and whether
it is identifiable (:meth:`ingest.readers.sync.LagEstimate.identifiable`); then per
speaker (the pooling of :mod:`ingest.lag`) the pooled estimate and its margin. Also how
many clips the earlier per-clip rule (own estimate applied when >= 80 ms) would have
shifted. Clips without a speaker are one speaker per corpus folder, as at ingest.

* talkingface: landmark clips, as the reader reads them (its ``lag_evidence``);
* facegood: animation curves; lip activity is the summed |d/dt| of the curves of the
  ``lips`` group (jaw, mouth), smoothed over 3 frames;
* grid: the GRID s1 videos, tracked (``pip install -e ".[video]"``; cached per clip).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from db.errors import DataError
from ingest.prepare import MIN_LAG_CORRECTED_S
from ingest.readers import discover, load
from ingest.readers.sync import audio_envelope, lag_evidence, lag_from_evidence

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def curve_activity(motion: np.ndarray, groups) -> np.ndarray:
    """Summed |d/dt| of the lips-group curves, smoothed over 3 frames; (n_frames,)."""
    lips = np.asarray(groups) == "lips"
    activity = np.abs(np.gradient(motion[:, lips], axis=0)).sum(axis=1)
    padded = np.pad(activity, 1, mode="edge")
    return np.convolve(padded, np.ones(3) / 3.0, mode="valid")


def evidence_of(clip) -> np.ndarray:
    if "lag_evidence" in clip.extra:
        return np.asarray(clip.extra["lag_evidence"])
    loudness = audio_envelope(clip.audio, clip.sample_rate, clip.fps, clip.n_frames)
    return lag_evidence(curve_activity(clip.motion, clip.schema.groups), loudness, clip.fps)


def report(name: str, sources) -> None:
    rows = []
    for source in sources:
        try:
            clip = load(source)
        except DataError as exc:
            print(f"# rejected: {exc}")
            continue
        evidence = evidence_of(clip)
        own = lag_from_evidence([evidence], clip.duration)
        rows.append((clip.speaker or clip.corpus, clip.clip_id, clip.duration, evidence, own))
    print(f"\n## {name}: {len(rows)} clips")
    print(f"{'clip':32s} {'s':>6s} {'own lag':>8s} {'r':>6s} {'margin':>7s} identifiable")
    for _, clip_id, seconds, _, own in rows[:40]:
        print(f"{clip_id:32s} {seconds:6.1f} {own.lag_s:+8.3f} {own.confidence:6.3f} "
              f"{own.margin:7.3f} {'yes' if own.identifiable() else 'no'}")
    if len(rows) > 40:
        print(f"... ({len(rows) - 40} more)")
    old = sum(abs(r[4].lag_s) >= MIN_LAG_CORRECTED_S for r in rows)
    own_ok = sum(r[4].identifiable() for r in rows)
    lags = np.array([r[4].lag_s for r in rows])
    print(f"per-clip estimates: median {np.median(lags):+.3f} s, "
          f"|lag| >= {MIN_LAG_CORRECTED_S} s in {old} clips (the earlier rule shifted them), "
          f"identifiable on their own: {own_ok}")
    speakers = sorted({r[0] for r in rows})
    print(f"{'speaker':40s} {'clips':>5s} {'min':>6s} {'pooled':>8s} {'r':>6s} {'margin':>7s} "
          "identifiable")
    for speaker in speakers:
        mine = [r for r in rows if r[0] == speaker]
        pooled = lag_from_evidence([r[3] for r in mine], sum(r[2] for r in mine))
        print(f"{speaker[:40]:40s} {len(mine):5d} {pooled.seconds / 60:6.1f} "
              f"{pooled.lag_s:+8.3f} {pooled.confidence:6.3f} {pooled.margin:7.3f} "
              f"{'yes' if pooled.identifiable() else 'no'}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--datasets", nargs="+", default=["talkingface", "facegood", "grid"])
    parser.add_argument("--grid-clips", type=int, default=0,
                        help="first N GRID clips only (default: all)")
    args = parser.parse_args()
    for name in args.datasets:
        root = SHARED / name
        if not root.exists():
            print(f"# {name}: skipped, {root} is absent")
            continue
        sources = discover([root])
        if name == "grid" and args.grid_clips:
            sources = sources[:args.grid_clips]
        report(name, sources)
    return 0


if __name__ == "__main__":
    sys.exit(main())
