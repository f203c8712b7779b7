"""Mean and spread over codebook seeds of ``scripts/eval_emotion_boaw.py`` runs
(docs/results/emotion.md: what the codebook seed decides).

Usage::

    python scripts/summarize_emotion_seeds.py SEED0.json SEED1.json SEED2.json [--json OUT]

Each ``SEED*.json`` is ``eval_emotion_boaw.py --json`` of one ``--seed``. For every system
present in all of them and each protocol (nested 10-fold, LOSO, LOSO one utterance at a
time), prints the accuracy of each seed (the mean over folds, as the script prints it),
their mean, range (max - min) and standard deviation; and how often the seed changes what
is predicted: the share of the 535 utterances whose predicted emotion is not the same
under every seed (load-independent evidence of how much the seed decides). The McNemar
tests stored in the runs (``--mcnemar``) are listed per seed.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

PROTOCOLS = (("10fold", "acc", "10fold/pred"), ("loso", "acc", "loso/pred"),
             ("loso", "acc_single", "loso/pred_single"))
NAMES = {"10fold/pred": "10-fold", "loso/pred": "LOSO", "loso/pred_single": "LOSO, 1 utt."}


def summarize(runs: list[dict]) -> dict:
    """Per system and protocol: accuracies by seed, mean, range, sd, unstable share."""
    systems = [s for s in runs[0] if isinstance(runs[0][s], dict) and "loso" in runs[0][s]
               and all(s in r for r in runs)]
    out = {}
    for system in systems:
        out[system] = {}
        for kind, metric, key in PROTOCOLS:
            if any(kind not in r[system] for r in runs):
                continue
            acc = np.array([r[system][kind][metric] for r in runs])
            preds = np.array([r[system]["per_utterance"][key] for r in runs])
            unstable = float(np.mean(np.any(preds != preds[0], axis=0)))
            out[system][NAMES[key]] = {"by_seed": acc.tolist(), "mean": float(acc.mean()),
                                       "range": float(np.ptp(acc)), "sd": float(acc.std()),
                                       "unstable": unstable}
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    try:
        runs = [json.loads(p.read_text()) for p in args.runs]
    except (OSError, ValueError) as exc:
        print(f"summarize_emotion_seeds: error: {exc}", file=sys.stderr)
        return 1
    out = summarize(runs)
    print(f"{len(runs)} seeds ({', '.join(p.stem for p in args.runs)}); accuracy %")
    for system, rows in out.items():
        for name, r in rows.items():
            seeds = " / ".join(f"{100 * a:.1f}" for a in r["by_seed"])
            print(f"  {system:<10}{name:<14}{seeds:<22} mean {100 * r['mean']:.1f}  range "
                  f"{100 * r['range']:.1f}  sd {100 * r['sd']:.2f}  utterances whose "
                  f"prediction changes with the seed {100 * r['unstable']:.1f} %")
    for p, r in zip(args.runs, runs, strict=True):
        for key, m in r.get("mcnemar", {}).items():
            print(f"  McNemar {p.stem} {key}: {100 * m['first']:.1f} vs "
                  f"{100 * m['second']:.1f}; only first right {m['only_first_right']}, "
                  f"only second right {m['only_second_right']}; exact p = {m['p']:.3f}")
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
