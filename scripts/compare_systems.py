"""Paired comparison of two systems on the same held-out clips of an ``eval_lipsync`` run.

Usage::

    python scripts/compare_systems.py RUN.json --dataset grid [--part aligned]
                                      [--system kbest20] [--against exact mu-mlp ...]
                                      [--measures mouth_r lve] [--seed 0] [--per-clip]
                                      [--other-run RUN2.json] [--clips REGEX]

Reads the per-clip scores of ``scripts/eval_lipsync.py --json RUN.json`` and prints, per
measure, the mean per-clip difference (system minus the other), its 95 % bootstrap
confidence interval (2,000 resamples of the clips, percentile method; Efron & Tibshirani,
An Introduction to the Bootstrap, 1993, ch. 13) and the share of clips on which the system
is better (higher mouth R, lower errors). ``--per-clip`` also lists every clip's values
(e.g. the folds of a leave-one-clip-out run). ``--other-run`` takes the ``--against``
systems from a second run of the same deterministic split (clips paired by id), so that
two settings of one row (e.g. two guides) are compared; ``--clips`` keeps the clips whose
id matches a regular expression (e.g. talkingface's within-speaker ``_last30`` clips).
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

import numpy as np

#: Measures where higher is better; every other one is an error.
HIGHER_BETTER = ("mouth_r", "hong_r", "acc")
N_RESAMPLES = 2000


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("--dataset", default="grid")
    parser.add_argument("--part", default=None, help="e.g. aligned or recognized (grid)")
    parser.add_argument("--system", default="kbest20")
    parser.add_argument("--against", nargs="+", default=None, help="default: every other")
    parser.add_argument("--measures", nargs="+", default=["mouth_r", "lve"])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--per-clip", action="store_true",
                        help="also print each clip's values of every system and measure")
    parser.add_argument("--other-run", type=Path,
                        help="take the --against systems from this run (same split)")
    parser.add_argument("--clips", default=None, help="only clips whose id matches this regex")
    args = parser.parse_args()
    try:
        rows = _rows(args.run, args.dataset, args.part)
        others = _rows(args.other_run, args.dataset, args.part) if args.other_run else None
    except (OSError, ValueError, KeyError, TypeError) as exc:
        print(f"compare_systems: cannot read {args.dataset} {args.part or ''}: {exc}",
              file=sys.stderr)
        return 1
    if args.clips:
        rows = [r for r in rows if re.search(args.clips, r["clip"])]
    if others is not None:
        if not args.against:
            print("compare_systems: --other-run needs --against", file=sys.stderr)
            return 1
        other = {r["clip"]: r["methods"] for r in others}
        rows = [{**r, "methods": {args.system: r["methods"].get(args.system, {}),
                                  **{f"{s} (other run)": other.get(r["clip"], {}).get(s, {})
                                     for s in args.against}}}
                for r in rows if r["clip"] in other]
        args.against = [f"{s} (other run)" for s in args.against]
    systems = list(dict.fromkeys(m for r in rows for m in r["methods"]))
    if args.system not in systems:
        print(f"compare_systems: no {args.system!r} in the run ({', '.join(systems)})",
              file=sys.stderr)
        return 1
    if args.per_clip:
        shown = [args.system, *(args.against or [s for s in systems if s != args.system])]
        for measure in args.measures:
            print(f"{measure} per clip: " + "  ".join(shown))
            for r in rows:
                vals = [r["methods"].get(s, {}).get(measure) for s in shown]
                print(f"  {r['clip']:28s} " + "  ".join(
                    "-" if v is None else f"{v:.4f}" for v in vals))
    rng = np.random.default_rng(args.seed)
    print(f"{args.dataset} {args.part or ''}: {len(rows)} clips; {args.system} minus ...")
    for other in args.against or [s for s in systems if s != args.system]:
        for measure in args.measures:
            pairs = [(r["methods"][args.system].get(measure), r["methods"][other].get(measure))
                     for r in rows if args.system in r["methods"] and other in r["methods"]]
            diff = np.array([a - b for a, b in pairs if a is not None and b is not None
                             and np.isfinite(a) and np.isfinite(b)])
            if not diff.size:
                continue
            means = rng.choice(diff, (N_RESAMPLES, diff.size)).mean(axis=1)
            lo, hi = np.percentile(means, [2.5, 97.5])
            better = (diff > 0) if measure in HIGHER_BETTER else (diff < 0)
            print(f"  {other:28s} {measure:8s} {diff.mean():+.3f}  95 % CI [{lo:+.3f}, "
                  f"{hi:+.3f}]  better on {100 * better.mean():.0f} % of {diff.size} clips")
    return 0


def _rows(run: Path, dataset: str, part: str | None) -> list[dict]:
    """Per-clip rows of ``dataset`` (and ``part``) in an eval_lipsync JSON run."""
    data = json.loads(run.read_text())[dataset]
    if part:
        data = data[part]
    return data["clips"] if isinstance(data, dict) else data


if __name__ == "__main__":
    sys.exit(main())
