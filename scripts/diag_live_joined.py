"""Where the held-out GRID clips played as one stream lose against each its own stream.

Usage::

    python scripts/diag_live_joined.py --grid-db S1DB --grid-train-db DB640 [--take 0:16:2]
                                       [--lookahead 120] [--low-latency]

The clips of ``scripts/bench_live.py --quality grid`` (its split, database and scoring;
``--take`` a slice of its 20) are streamed each alone (a cold start) and back to back as
one stream (``bench_live.join_clips``: each clip on a frame of the stream). Each clip's
mouth R: cold, as one stream, as one stream with the cold stream's frames over its
leading silence (before the offline default's first phone), and as one stream whose
state is set back at each clip's first sample as a new stream's is (a diagnosis: the
stream cannot know where a clip starts): ppg-ridge's loud level (``loud``), the level
hama hears and pauses are judged by (``level``), the phones' kept choice of animes
(``memory``), and the three. The mean over the clips and the paired difference from
cold (± its standard error).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_live  # noqa: E402  (the bench's split, stream, joining and scoring)

RESETS = {"loud": ("loud",), "level": ("level",), "memory": ("memory",),
          "all three": ("loud", "level", "memory")}


def stream_reset(model, audio, sr, lookahead_ms, guide, starts, reset) -> np.ndarray:
    """The stream's frames, its state in ``reset`` set back at each sample of ``starts``."""
    from animegraph.live import Stream
    from animegraph.live.frontend import LoudLevel
    from animegraph.live.stream import SPEECH_OVER_NOISE_DB
    from animegraph.live.window import PhoneMemory

    stream = Stream(model, sample_rate=sr, lookahead_ms=lookahead_ms, guide=guide,
                    backlog_ms=None, **bench_live.WINDOW)
    cuts = sorted({0, len(audio), *starts,
                   *range(0, len(audio), int(bench_live.CHUNK_S * sr))})
    parts = []
    for a, b in zip(cuts[:-1], cuts[1:], strict=True):
        if a in starts and a > 0:
            if "loud" in reset:
                stream._loud = LoudLevel(SPEECH_OVER_NOISE_DB)
            if "level" in reset:
                stream._peak, stream._floor = 0.0, np.inf
            if "memory" in reset:
                stream._memory = PhoneMemory()
        parts.append(stream.push(audio[a:b]).motion)
    parts.append(stream.close().motion)
    return np.concatenate(parts)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--grid-db", type=Path, required=True)
    parser.add_argument("--grid-train-db", type=Path, required=True)
    parser.add_argument("--take", default="0:16:2", help="a slice of the 20 clips")
    parser.add_argument("--lookahead", type=float, default=120.0)
    parser.add_argument("--low-latency", action="store_true")
    args = parser.parse_args()

    from animegraph.live import stored_guide
    from animegraph.synthesis import Model, synthesize
    from animegraph.synthesis.path import AUDIO_ONLY_K_BEST

    if args.low_latency:
        bench_live.WINDOW.update(hop_ms=40.0, posterior_context_ms=300.0, settle_ms=40.0)
    bench_live.GRID_DB.append(args.grid_db)
    _, _, test, _ = bench_live.split("grid", Path("."), 0.0)[0]
    test = test[::max(1, -(-len(test) // 20))]
    test = test[slice(*[int(x) if x else None for x in args.take.split(":")])]
    model = Model.load(args.grid_train_db)
    guide, _ = stored_guide(args.grid_train_db)
    fps, la = model.graph.fps, args.lookahead
    audio, sr, firsts = bench_live.join_clips(test, fps)
    starts = {int(round(k / fps * sr)) for k in firsts}
    together = {"one stream": bench_live.live_motion(model, audio, sr, la, guide)[0],
                **{f"one stream, {name} reset": stream_reset(model, audio, sr, la, guide,
                                                             starts, reset)
                   for name, reset in RESETS.items()}}
    rows: dict[str, list[float]] = {}
    for clip, k in zip(test, firsts, strict=True):
        clip_audio = clip.audio.astype(np.float32) / 32768.0
        off = synthesize(model, clip_audio, sr, k_best=AUDIO_ONLY_K_BEST, guide=guide)
        lead = int(round(min(p.start for p in off.phones if p.phone != "SIL") * fps))
        cold, _ = bench_live.live_motion(model, clip_audio, sr, la, guide)
        n = len(cold)
        row = {"offline": bench_live.mouth_r(model, off.motion, clip),
               "cold": bench_live.mouth_r(model, cold, clip)}
        for name, motion in together.items():
            row[name] = bench_live.mouth_r(model, motion[k:k + n], clip)
        spliced = together["one stream"][k:k + n].copy()
        spliced[:lead] = cold[:lead]
        row["one stream, cold leading silence"] = bench_live.mouth_r(model, spliced, clip)
        print(f"{clip.clip_id}: " + ", ".join(f"{a} {b:.3f}" for a, b in row.items()),
              flush=True)
        for name, value in row.items():
            rows.setdefault(name, []).append(value)
    cold = np.asarray(rows["cold"])
    print(f"mean over {len(test)} clips (look-ahead {la:g} ms"
          f"{', --low-latency' if args.low_latency else ''}):")
    for name, values in rows.items():
        d = np.asarray(values) - cold
        print(f"  {name}: {np.mean(values):.4f} ({d.mean():+.4f} ± "
              f"{d.std(ddof=1) / np.sqrt(len(d)):.4f} against cold)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
