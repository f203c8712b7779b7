"""Evaluate phone segmentation (ingest.speech.segment) against a synthetic corpus's true timing.

Generates a synthetic corpus (eSpeak NG speech whose phone timing is known exactly, in the
five emotions), then for every clip:

* forced alignment of its transcript (``align``): absolute error of the phone onsets
  matched to the reference by an edit-distance alignment of the two phone sequences
  (eSpeak's and CMUdict's pronunciations differ for some words);
* phone recognition without transcript (``recognize``): phone error rate, and the onset
  error of the phones it got right.

Prints a table per emotion and overall (median and p90 errors in ms, boundaries compared,
speed as seconds of computation per second of audio); ``--json OUT`` saves it.

    python scripts/eval_segmentation.py --sentences 40 --json seg.json
    python scripts/eval_segmentation.py --corpus /path/to/corpus   # an existing corpus
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

from ingest.corpus.synthetic import CorpusConfig, generate_corpus
from ingest.formats.phones_csv import read_phones_csv
from ingest.formats.wav import read_wav
from ingest.speech.segment import align, boundary_errors, phone_error_rate, recognize


def _clips(folder: Path, limit: int | None) -> list[Path]:
    clips = sorted((folder / "clips").glob("*.json"))
    if not clips:
        sys.exit(f"no clips in {folder / 'clips'}")
    return clips[:limit] if limit else clips


def _evaluate(clip: Path, do_recognize: bool, refine: bool) -> dict:
    meta = json.loads(clip.read_text())
    stem = clip.name[: -len(".json")]
    audio, rate = read_wav(clip.with_name(stem + ".wav"))
    reference = read_phones_csv(clip.with_name(stem + ".phones.csv"))
    n_ref = sum(1 for s in reference if s.start > 0)
    out = {"clip": stem, "emotion": meta.get("emotion", "?"), "seconds": len(audio) / rate,
           "reference_boundaries": n_ref}
    start = time.perf_counter()
    aligned = align(audio, rate, meta["text"], refine=refine)
    out["align_time"] = time.perf_counter() - start
    out["align_errors"] = boundary_errors(reference, aligned).tolist()
    out["align_signed"] = boundary_errors(reference, aligned, signed=True).tolist()
    out["align_per"] = phone_error_rate(reference, aligned)
    if do_recognize:
        start = time.perf_counter()
        recognized = recognize(audio, rate, refine=refine)
        out["recognize_time"] = time.perf_counter() - start
        out["recognize_errors"] = boundary_errors(reference, recognized).tolist()
        out["recognize_per"] = phone_error_rate(reference, recognized)
    return out


def _summary(rows: list[dict], do_recognize: bool) -> dict:
    errors = np.concatenate([np.asarray(r["align_errors"]) for r in rows]) * 1000
    signed = np.concatenate([np.asarray(r["align_signed"]) for r in rows]) * 1000
    seconds = sum(r["seconds"] for r in rows)
    summary = {
        "clips": len(rows),
        "audio_s": round(seconds, 2),
        "boundaries_compared": int(errors.size),
        "reference_boundaries": int(sum(r["reference_boundaries"] for r in rows)),
        "align_median_ms": float(np.median(errors)) if errors.size else float("nan"),
        "align_p90_ms": float(np.percentile(errors, 90)) if errors.size else float("nan"),
        "align_within_20ms": float(np.mean(errors <= 20)) if errors.size else float("nan"),
        "align_bias_ms": float(np.median(signed)) if signed.size else float("nan"),
        "align_per": float(np.mean([r["align_per"] for r in rows])),
        "align_time_per_s": sum(r["align_time"] for r in rows) / seconds,
    }
    if do_recognize:
        rerr = np.concatenate([np.asarray(r["recognize_errors"]) for r in rows]) * 1000
        summary.update({
            "recognize_per": float(np.mean([r["recognize_per"] for r in rows])),
            "recognize_boundaries": int(rerr.size),
            "recognize_median_ms": float(np.median(rerr)) if rerr.size else float("nan"),
            "recognize_p90_ms": float(np.percentile(rerr, 90)) if rerr.size else float("nan"),
            "recognize_time_per_s": sum(r["recognize_time"] for r in rows) / seconds,
        })
    return summary


def _table(groups: dict[str, dict], do_recognize: bool) -> str:
    head = (f"{'group':<11} {'clips':>5} {'bnd':>9} {'med ms':>7} {'p90 ms':>7} {'<=20ms':>7} "
            f"{'bias':>6} {'aPER':>6} {'a s/s':>6}")
    if do_recognize:
        head += f" | {'rPER':>6} {'r bnd':>6} {'r med':>6} {'r p90':>6} {'r s/s':>6}"
    lines = [head, "-" * len(head)]
    for name, s in groups.items():
        line = (f"{name:<11} {s['clips']:>5} "
                f"{s['boundaries_compared']:>4}/{s['reference_boundaries']:<4} "
                f"{s['align_median_ms']:>7.1f} {s['align_p90_ms']:>7.1f} "
                f"{100 * s['align_within_20ms']:>6.1f}% {s['align_bias_ms']:>6.1f} "
                f"{s['align_per']:>6.3f} {s['align_time_per_s']:>6.3f}")
        if do_recognize:
            line += (f" | {s['recognize_per']:>6.3f} {s['recognize_boundaries']:>6} "
                     f"{s['recognize_median_ms']:>6.1f} {s['recognize_p90_ms']:>6.1f} "
                     f"{s['recognize_time_per_s']:>6.3f}")
        lines.append(line)
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--corpus", type=Path, help="evaluate an existing corpus folder")
    parser.add_argument("--sentences", type=int, default=40, help="sentences to generate")
    parser.add_argument("--parallel", type=int, default=10,
                        help="of which spoken in all five emotions")
    parser.add_argument("--variations", type=int, default=1, help="takes per pair")
    parser.add_argument("--seed", type=int, default=0, help="corpus seed")
    parser.add_argument("--workers", type=int, default=2, help="corpus generation workers")
    parser.add_argument("--limit", type=int, help="evaluate only the first N clips")
    parser.add_argument("--no-recognize", action="store_true", help="skip phone recognition")
    parser.add_argument("--no-refine", action="store_true",
                        help="keep PocketSphinx's 10 ms boundaries (no spectral refinement)")
    parser.add_argument("--json", type=Path, help="write the summary and per-clip rows here")
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug messages")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    do_recognize = not args.no_recognize

    with tempfile.TemporaryDirectory(prefix="evalseg-") as tmp:
        folder = args.corpus
        if folder is None:
            folder = Path(tmp) / "corpus"
            config = CorpusConfig(sentences=args.sentences, parallel=args.parallel,
                                  variations=args.variations, seed=args.seed)
            start = time.perf_counter()
            generate_corpus(folder, config, workers=args.workers)
            print(f"generated corpus in {time.perf_counter() - start:.1f} s", file=sys.stderr)
        rows = [_evaluate(clip, do_recognize, not args.no_refine)
                for clip in _clips(folder, args.limit)]

    by_emotion: dict[str, list[dict]] = defaultdict(list)
    for row in rows:
        by_emotion[row["emotion"]].append(row)
    groups = {e: _summary(r, do_recognize) for e, r in sorted(by_emotion.items())}
    groups["overall"] = _summary(rows, do_recognize)
    print(_table(groups, do_recognize))
    print("bnd: phone onsets compared / reference onsets; bias: median signed error (ms); "
          "aPER/rPER: phone error rate of alignment/recognition; s/s: compute seconds per "
          "audio second")
    if args.json:
        args.json.write_text(json.dumps({"summary": groups, "clips": rows}, indent=1))
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
