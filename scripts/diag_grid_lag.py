"""Is there a constant time offset between the synthesized and the tracked mouth on GRID?

Usage::

    python scripts/diag_grid_lag.py --grid-db DB [--methods kbest20-ctx exact]

The GRID split of ``scripts/eval_lipsync.py`` (every fifth clip in clip-id order held
out, the rest the database), phones aligned from the transcripts; for each held-out clip
and method, the Pearson R of the synthesized mouth opening shifted by -4..+4 frames
against the tracked one (+: the synthesis later). Prints the mean R per shift and how
many clips peak at each shift.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import eval_lipsync  # scripts/ is sys.path[0]
import numpy as np

from animegraph.apps import evaluate
from animegraph.motion.measures import mouth_opening, pearson
from db.store import Database
from ingest.tables import prepared_from_database

SHIFTS = range(-4, 5)


def shifted_r(pred: np.ndarray, truth: np.ndarray, shift: int) -> float:
    n = min(len(pred), len(truth))
    pred, truth = pred[:n], truth[:n]
    if shift >= 0:
        return pearson(pred[:n - shift], truth[shift:])
    return pearson(pred[-shift:], truth[:n + shift])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grid-db", type=Path, required=True)
    parser.add_argument("--methods", nargs="+", default=["kbest20-ctx", "exact"],
                        choices=evaluate.METHODS)
    args = parser.parse_args()
    eval_lipsync.SYSTEMS[:] = ["anime-graph"]
    db = Database.open(args.grid_db)
    train, test = evaluate.grid_split(prepared_from_database(db))
    fold = eval_lipsync.fit_fold(Path(tempfile.mkdtemp()), "grid", train,
                                 db.arrays().get("head_reference"))
    del train
    model = fold["model"]
    scores = {m: [] for m in args.methods}
    for clip in test:
        preds: dict = {}
        evaluate.score_heldout(model, clip, methods=args.methods, norm=fold["norm"],
                               rng=fold["rng"], predictions=preds)
        truth = mouth_opening(clip.motion.astype(np.float64), model.names, model.kind)
        for m in args.methods:
            pred = mouth_opening(preds[m], model.names, model.kind)
            scores[m].append([shifted_r(pred, truth, s) for s in SHIFTS])
    for m, rows in scores.items():
        a = np.array(rows)
        peaks = np.bincount(np.argmax(a, axis=1), minlength=len(SHIFTS))
        print(f"{m}: mean R by shift (frames, +: synthesis later): " + ", ".join(
            f"{s:+d} {r:.3f}" for s, r in zip(SHIFTS, a.mean(axis=0), strict=True)))
        print("  clips peaking at each shift: " + ", ".join(
            f"{s:+d} {c}" for s, c in zip(SHIFTS, peaks, strict=True)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
