"""Where live synthesis loses to the offline default in a clip's first second.

Usage::

    python scripts/diag_live_start.py --grid-db S1DB --grid-train-db DB640 [--max-clips 20]
                                      [--lookahead 120]

For the held-out GRID clips of ``scripts/bench_live.py --quality grid`` (the same split and
database), the live stream's output at one look-ahead is scored (mouth R, the bench's
``mouth_r``) as it is and with the offline default's frames put in its place over one
stretch of the clip at a time: the leading silence (before hama's first phone, offline),
the first word (from there to 1 s), and the rest (after 1 s). The stretch whose
replacement recovers the gap is where it is lost.

Then hama's start-of-input effect: the posteriors of each clip's first 200 ms of leading
noise heard alone (at the start of the model's input) and with 600 ms of silence before
it (what :class:`animegraph.live.frontend.PosteriorTrack` gives it at a stream's start),
against the whole clip's: frames whose likeliest phone is not silence.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_live  # noqa: E402  (the bench's split, stream and scoring)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--grid-db", type=Path, required=True)
    parser.add_argument("--grid-train-db", type=Path, required=True)
    parser.add_argument("--max-clips", type=int, default=20)
    parser.add_argument("--lookahead", type=float, default=120.0)
    args = parser.parse_args()

    from animegraph.live import stored_guide
    from animegraph.live.frontend import MODEL_RATE, to_model_rate
    from animegraph.synthesis import Model, synthesize
    from animegraph.synthesis.path import AUDIO_ONLY_K_BEST
    from ingest.speech import ctc
    from ingest.speech.phones import PHONES

    bench_live.GRID_DB.append(args.grid_db)
    _, test, _ = bench_live.split("grid", Path("."), 0.0)
    test = test[::max(1, -(-len(test) // args.max_clips))]
    model = Model.load(args.grid_train_db)
    guide, _ = stored_guide(args.grid_train_db)
    fps = model.graph.fps
    silence = PHONES.index("SIL")
    rows: dict[str, list[float]] = {}
    for clip in test:
        audio = clip.audio.astype(np.float32) / 32768.0
        sr = clip.sample_rate
        off = synthesize(model, audio, sr, k_best=AUDIO_ONLY_K_BEST, guide=guide)
        hama = synthesize(model, audio, sr, k_best=AUDIO_ONLY_K_BEST, guide=guide,
                          phones_engine="hama")
        first_phone = min(p.start for p in hama.phones if p.phone != "SIL")
        live, _ = bench_live.live_motion(model, audio, sr, args.lookahead, guide)
        k0, k1 = int(round(first_phone * fps)), int(round(fps))
        row = {"offline": bench_live.mouth_r(model, off.motion, clip),
               "live": bench_live.mouth_r(model, live, clip)}
        for name, (a, b) in {"leading silence": (0, k0), "first word": (k0, max(k0, k1)),
                             "after 1 s": (k1, len(live))}.items():
            spliced = live.copy()
            b = min(b, len(spliced), len(off.motion))
            spliced[a:b] = off.motion[a:b]
            row[f"live, offline's {name}"] = bench_live.mouth_r(model, spliced, clip)
        x = to_model_rate(audio, sr)
        x = (x * (0.9 / np.abs(x).max())).astype(np.float32)
        noise = x[: int(0.2 * MODEL_RATE)] if first_phone > 0.25 else None
        if noise is not None:
            pad = np.zeros(int(0.6 * MODEL_RATE), dtype=np.float32)
            for name, probs in (("whole clip", ctc.phone_probs(x)[:10]),
                                ("noise alone", ctc.phone_probs(noise)[:10]),
                                ("silence + noise",
                                 ctc.phone_probs(np.concatenate([pad, noise]))[30:40])):
                row[f"phone frames of 10, {name}"] = float((probs.argmax(1) != silence).sum())
        print(f"{clip.clip_id}: leading silence {first_phone:.2f} s, "
              + ", ".join(f"{k} {v:.3f}" for k, v in row.items()), flush=True)
        for k, v in row.items():
            rows.setdefault(k, []).append(v)
    print(f"mean over {len(test)} clips (look-ahead {args.lookahead:g} ms): "
          + ", ".join(f"{k} {np.mean(v):.3f}" for k, v in rows.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
