"""The iPhone capture (Live Link Face CSV) in and out: what the reader finds, the round trip,
and a held-out synthesis scored against the capture.

Usage::

    python scripts/eval_livelink.py [--capture ../shared/data/livelink/neurosync_testset.csv]
                                    [--train-fraction 0.7 | --folds K]
                                    [--phones-engine ENGINE] [--json OUT]

Prints, for the real capture of ``../shared/data/livelink``:

1. what the clip reader reports: rows, frame rate from the timecode, dropped frames, the
   lip-audio lag (positive: lips lead) and its correlation;
2. the lag estimate on the capture's curves moved by known offsets (-0.3 .. +0.3 s);
3. the round trip read -> write (``.livelink.csv``) -> read: the largest value difference
   and whether every value cell is the capture's, character for character;
4. a held-out synthesis: a database from the first ``--train-fraction`` of the take
   (phones recognised as at ingest, by ``--phones-engine``: the default engine unless
   named), the rest synthesized from its audio
   and phones and scored against the capture (ARKit weights; :func:`animegraph.apps.evaluate
   .score_heldout`): the exact search, the paper's look-ahead windows, the naive random /
   first-anime baselines, and the k-best average (beyond the paper); before it, how well
   a vowel indicator of the recognised phones follows jawOpen. With ``--folds K``
   the take is cut into K equal blocks, each synthesized from a database of the others,
   and the table gives the means over the blocks (one cut scores a few seconds only).
   One 20 s take of one speaker: a smoke test of the workflow on real data, not a
   benchmark.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from grid_phone_engines import vowels_follow  # scripts/ is sys.path[0]

from animegraph.apps import evaluate
from animegraph.synthesis import Model
from ingest.formats.livelink import format_timecode, read_livelink, write_livelink
from ingest.pipeline import IngestConfig, build_database, prepare_sources
from ingest.prepare import slice_clip
from ingest.readers import discover, estimate_lag, load, shift_motion
from ingest.readers.livelink import frame_steps, mouth_activity
from ingest.readers.sync import audio_envelope
from ingest.speech.engines import ENGINES

CAPTURE = (Path(__file__).resolve().parents[1].parent / "shared" / "data" / "livelink"
           / "neurosync_testset.csv")
SHOWN = ("rmse_jaw_mouth", "r_jaw_mouth", "mouth_r", "rmse_all", "r_all", "jumps", "synth_s")


def reader_facts(capture: Path) -> dict:
    clip = load(discover([capture])[0])
    return {"rows": clip.n_frames, "fps": clip.fps, "seconds": round(clip.n_frames / clip.fps, 3),
            "audio_s": round(clip.duration, 3), **{k: clip.extra[k] for k in (
                "timecode_start", "dropped_frames", "gaps", "lip_audio_lag_s",
                "lag_confidence", "motion_audio_offset_s")}}


def lag_recovery(capture: Path, offsets=(-0.3, -0.2, -0.1, 0.1, 0.2, 0.3)) -> list[dict]:
    """The capture's curves moved by known offsets: the lag each estimate finds.

    A motion advanced by ``d`` seconds has its lips leading the audio by ``d`` more than
    the recording's own lag, so the estimate should move by ``d``.
    """
    clip = load(discover([capture])[0])
    loudness = audio_envelope(clip.audio, clip.sample_rate, clip.fps, clip.n_frames)
    base = clip.extra["lip_audio_lag_s"]
    rows = []
    for d in offsets:
        moved = shift_motion(clip.motion, -d, clip.fps)
        lag, r = estimate_lag(mouth_activity(moved, clip.schema.names), loudness, clip.fps)
        rows.append({"offset_s": d, "expected_s": round(base + d, 4),
                     "estimated_s": round(lag, 4), "error_ms": round(1000 * (lag - base - d), 1),
                     "r": round(r, 3)})
    return rows


def round_trip(capture: Path, folder: Path) -> dict:
    take = read_livelink(capture)
    fps, _ = frame_steps(take.frames, take.timecode_rate, capture)
    out = write_livelink(folder / "round_trip.livelink.csv", take.values, take.names, fps,
                         start=format_timecode(take.frames[0], take.timecode_rate))
    again = read_livelink(out)
    cells = [line.split(",", 2)[2] for line in capture.read_text().splitlines()[1:]]
    written = [line.split(",", 2)[2] for line in out.read_text().splitlines()[1:]]
    return {"max_value_diff": float(np.abs(again.values - take.values).max()),
            "cells_identical": cells == written,
            "max_timecode_diff_frames": round(float(np.abs(again.frames - take.frames).max()), 4)}


def heldout(capture: Path, fraction: float, folder: Path, engine: str | None = None,
            folds: int = 1) -> dict:
    """The held-out synthesis: with ``folds`` 1, the database from the first ``fraction`` of
    the take and the rest synthesized; with more, the take cut into ``folds`` equal
    blocks, each synthesized from a database of the others (contiguous blocks: the
    frames either side of a cut are the only ones a neighbour shares)."""
    t0 = time.perf_counter()
    (clip,), reference = prepare_sources(discover([capture]), IngestConfig(phones_engine=engine))
    vowels_r = vowels_follow(clip.phones, clip.motion[:, list(clip.schema.names).index(
        "jawOpen")], clip.fps)
    if folds == 1:
        cut = round(fraction * clip.duration, 2)
        blocks = [(0.0, cut), (cut, clip.duration)]
        tested = [1]
    else:
        edges = [round(clip.duration * k / folds, 2) for k in range(folds)] + [clip.duration]
        blocks = list(zip(edges[:-1], edges[1:], strict=True))
        tested = list(range(folds))
    runs = []
    for k in tested:
        train = [slice_clip(clip, a, b, suffix=f"_part{j}") for j, (a, b) in enumerate(blocks)
                 if j != k and (folds > 1 or j < k)]
        test = slice_clip(clip, *blocks[k], suffix="_test")
        db = folder / f"db{k}"
        build_database(db, train, reference=reference)
        model = Model.load(db)
        row = evaluate.score_heldout(model, test, rng=np.random.default_rng(0))
        runs.append({"test_from_s": blocks[k][0], "test_s": round(test.duration, 2),
                     "train_s": round(sum(c.duration for c in train), 2),
                     "animes": model.graph.n_nodes, "n_phones": row["n_phones"],
                     "methods": row["methods"]})
    methods = {m: {key: float(np.mean([r["methods"][m][key] for r in runs]))
                   if isinstance(v, int | float) and not isinstance(v, bool) else v
                   for key, v in scores.items()}
               for m, scores in runs[0]["methods"].items()}
    return {"folds": runs, "methods": methods, "vowels_jaw_r": round(vowels_r, 3),
            "seconds": round(time.perf_counter() - t0, 1)}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--capture", type=Path, default=CAPTURE)
    parser.add_argument("--train-fraction", type=float, default=0.7)
    parser.add_argument("--folds", type=int, default=1,
                        help="cut the take into this many blocks, each synthesized from a "
                        "database of the others (default 1: --train-fraction's one cut)")
    parser.add_argument("--phones-engine", choices=ENGINES, default=None,
                        help="phone engine of the held-out synthesis (default: ingest's)")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
    if args.folds < 1 or not 0 < args.train_fraction < 1:
        parser.error("--folds must be >= 1 and --train-fraction in (0, 1)")
    if not args.capture.is_file():
        print(f"eval_livelink: {args.capture} not found (the shared data)", file=sys.stderr)
        return 1
    out: dict = {"capture": str(args.capture)}
    out["reader"] = reader_facts(args.capture)
    print("reader:", json.dumps(out["reader"]))
    out["lag_recovery"] = lag_recovery(args.capture)
    for row in out["lag_recovery"]:
        print("lag recovery:", json.dumps(row))
    with tempfile.TemporaryDirectory() as tmp:
        out["round_trip"] = round_trip(args.capture, Path(tmp))
        print("round trip:", json.dumps(out["round_trip"]))
        out["heldout"] = heldout(args.capture, args.train_fraction, Path(tmp),
                                 args.phones_engine, args.folds)
    h = out["heldout"]
    print(f"phones: jawOpen against a vowel indicator of the recognised phones (50 ms "
          f"smoothing), r {h['vowels_jaw_r']:.3f}")
    for f in h["folds"]:
        print(f"held out: {f['test_s']} s from {f['test_from_s']} s ({f['n_phones']} phones), "
              f"database the other {f['train_s']} s ({f['animes']} animes)")
    if len(h["folds"]) > 1:
        print(f"means over the {len(h['folds'])} folds:")
    print("| method | " + " | ".join(SHOWN) + " |")
    print("|---" * (len(SHOWN) + 1) + "|")
    for method, scores in h["methods"].items():
        cells = [f"{scores[k]:.3f}" if isinstance(scores.get(k), float) else
                 str(scores.get(k, "")) for k in SHOWN]
        print(f"| {method} | " + " | ".join(cells) + " |")
    if args.json:
        args.json.write_text(json.dumps(out, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
