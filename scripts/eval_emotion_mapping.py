"""Emotion components and emotion mapping (Cao et al. 2005, §5.1.3 and §5.2).

Usage::

    python scripts/eval_emotion_mapping.py [--db DB --corpus CORPUS] [--out DIR]
        [--variants paper-exp,paper-gauss,offset-gauss] [--json OUT]

Without ``--db`` the default database (and corpus) in the cache folder are used, built
first if absent (``ANIMEGRAPH_CACHE``). Prints

1. the speech/emotion split of the independent components against the synthetic
   corpus' ground truth (which rig controls each component follows; needs ``--corpus``);
2. the paper's cross-validation of the mapping for every ordered pair of emotions and every
   held-out parallel sentence: unit-cube RMS of the mapped motion against the recorded one,
   and of the two baselines (no mapping; mean emotion offset), for each mapping variant
   (``paper-exp``: phi = exp(-x/d); ``paper-gauss``: exp(-x^2/d); ``offset-gauss``: the
   latter plus a constant term, not in the paper);
3. the paper's own case: neutral -> happy, the last parallel sentence held out.

Writes ``emotion_split.png``, ``emotion_mapping_fig7.png`` and ``emotion_mapping.json``
into ``--out`` (default ``out/emotion``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from animegraph.emotion.evaluate import (
    PAPER_RMS,
    EmotionData,
    component_truth,
    cross_validate,
    held_out,
    read_controls,
    summarize,
    unit_cube_rms,
)
from animegraph.emotion.plots import plot_mapping, plot_split
from db.store import Database
from ingest.corpus.face import EMOTION_CONTROLS, SPEECH_CONTROLS

VARIANTS = {
    "paper-exp": {"kernel": "exp", "offset": False},
    "paper-gauss": {"kernel": "gauss", "offset": False},
    "offset-gauss": {"kernel": "gauss", "offset": True},
}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--db", type=Path, default=None)
    ap.add_argument("--corpus", type=Path, default=None,
                    help="the synthetic corpus of --db (for the split's ground truth)")
    ap.add_argument("--out", type=Path, default=Path("out/emotion"))
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    if args.db is None:
        from animegraph.apps.demo import ensure_default_corpus, ensure_default_db

        args.corpus, _, _ = ensure_default_corpus()
        args.db, _ = ensure_default_db(args.corpus)
    args.out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    db = Database.open(args.db)
    data = EmotionData.load(db)
    split = data.model.split
    record: dict = {"db": str(args.db), "n_clips": len(data.clip_ids),
                    "parallel_sentences": data.model.parallel}

    print(f"# Speech / emotion components ({args.db})")
    truth = None
    if args.corpus is not None:
        controls, names = read_controls(args.corpus, data.clip_ids)
        truth = component_truth(data.sources, controls, names, SPEECH_CONTROLS,
                                EMOTION_CONTROLS)
    print("ic  label    speech  emotion  baseline  pair                 "
          + ("truth    R2_speech R2_emotion top control" if truth else ""))
    rows = []
    for k, lab in enumerate(split.labels):
        row = {"component": k, "label": lab, "speech_score": float(split.speech_score[k]),
               "emotion_score": float(split.emotion_score[k]),
               "emotion_baseline": float(split.emotion_baseline[k]),
               "emotion_pair": split.emotion_pair[k]}
        line = (f"{k:<3d} {lab:<8s} {row['speech_score']:6.3f} {row['emotion_score']:8.2f} "
                f"{row['emotion_baseline']:9.2f}  {row['emotion_pair']:<20s}")
        if truth:
            row.update(truth[k])
            line += (f" {truth[k]['truth']:<8s} {truth[k]['r2_speech']:9.2f} "
                     f"{truth[k]['r2_emotion']:10.2f} {truth[k]['top_control']} "
                     f"({truth[k]['top_r']:+.2f})")
        rows.append(row)
        print(line)
    record["components"] = rows
    if truth:
        correct = sum(r["label"] == r["truth"] for r in rows)
        record["split_accuracy"] = correct / len(rows)
        print(f"split agrees with the generator on {correct}/{len(rows)} components")
    plot_split(split, args.out / "emotion_split.png", truth=truth)

    record["cross_validation"] = {}
    for name in args.variants.split(","):
        params = VARIANTS[name]
        t1 = time.perf_counter()
        cv = cross_validate(data, **params)
        summary = summarize(cv)
        record["cross_validation"][name] = {"params": params, "rows": cv, "summary": summary}
        print(f"\n# Cross-validation, {name} ({params}); unit-cube RMS, mean (sd) over "
              f"held-out sentences x takes; {time.perf_counter() - t1:.0f} s")
        print("pair                     n   mapped           no mapping       mean offset      "
              "mapped best")
        for s in summary:
            print(f"{s['src'] + '->' + s['dst']:<24s} {s['n']:<3d} "
                  f"{s['mapped']:.4f} ({s['mapped_sd']:.4f})  {s['none']:.4f} "
                  f"({s['none_sd']:.4f})  {s['offset']:.4f} ({s['offset_sd']:.4f})  "
                  f"{100 * s['mapped_best']:5.1f} %")

    emotions = data.model.emotions
    if "neutral" in emotions and "happy" in emotions:
        parallel = data.parallel()
        sentences = parallel.sentences("neutral", "happy")
        case = {}
        for name in args.variants.split(","):
            h = held_out(data, "neutral", "happy", sentences[-1], parallel=parallel,
                         **VARIANTS[name])[0]
            rms = {"mapped": unit_cube_rms(h.mapped, h.recorded, data.names),
                   "none": unit_cube_rms(h.source, h.recorded, data.names),
                   "offset": unit_cube_rms(h.offset, h.recorded, data.names)}
            case[name] = {"sentence": sentences[-1], "clips": [h.clip_src, h.clip_dst], **rms}
            if name == "paper-gauss" or len(case) == 1:  # the default kernel
                plot_mapping(h, data.names, args.out / "emotion_mapping_fig7.png", rms=rms)
        record["paper_case"] = case
        print(f"\n# The paper's case: neutral -> happy, sentence {sentences[-1]} held out "
              f"(paper: {PAPER_RMS})")
        for name, c in case.items():
            print(f"{name:<14s} mapped {c['mapped']:.4f}  no mapping {c['none']:.4f}  "
                  f"mean offset {c['offset']:.4f}")
    record["seconds"] = time.perf_counter() - t0
    path = args.json or args.out / "emotion_mapping.json"
    path.write_text(json.dumps(record, indent=1, default=float))
    print(f"\nwrote {path}, {args.out / 'emotion_split.png'}, "
          f"{args.out / 'emotion_mapping_fig7.png'} in {record['seconds']:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
