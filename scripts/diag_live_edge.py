"""Where a short look-ahead loses: each piece of a live window given the future it lacks.

A frame sent at a 40 ms look-ahead is estimated with 40 ms of audio after it; at 120 ms,
with 120 ms. This script plays the GRID split's held-out clips through a
:class:`animegraph.live.Stream` in which one piece of each window at a time is given
what it would have had with more audio heard (the *future*, ``--future`` s of the clip
past the window's end, which a live stream cannot have), and scores mouth R against the
recording (as ``bench_live.py --quality grid``):

* ``base``: the stream as it is;
* ``post``: hama's posteriors of every frame as they are once settled (the tentative
  rows of the newest ``settle`` ms replaced by their final values);
* ``post+seg``: and the window's phones recognised on the window and the future, cut
  at the window's end (the current phone's label and start known; its end not);
* ``post+ext``: and the whole window synthesized with the future, its frames up to the
  window's end kept (phones, time-warps, cross-fades, low-pass and the guide all see
  the future: about the longer look-ahead);
* ``post+extg``: the animes with the future, the guide without (the guide's share);
* ``post+gfut``: the guide with the future, the animes without;
* ``gonly`` / ``aonly``: the guide alone / the animes alone (no future given).

``python scripts/diag_live_edge.py --grid-db S1DB --grid-train-db DB640 --lookahead 40
[--low-latency] --variants base post post+seg post+ext post+extg post+gfut`` (the
databases as for ``bench_live.py --quality grid``); ``--take 0::2``: every other one of
the ``--max-clips`` clips ``bench_live.py`` scores. Prints each clip's mouth R per
variant and the mean. A diagnosis: the variants reach into the stream's private steps
and are not a way to run it.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from animegraph.live import Stream, stored_guide
from animegraph.live.frontend import FRAME_RATE
from animegraph.live.stream import LOW_LATENCY
from animegraph.live.window import window_motion
from animegraph.motion.measures import mouth_opening, pearson
from animegraph.synthesis import Model
from animegraph.synthesis.guide import guide_trajectory
from ingest.speech import ctc

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_live  # noqa: E402  (the bench's stream played and its settled posteriors)
from bench_live import play  # noqa: E402

VARIANTS = ("base", "post", "post+seg", "post+ext", "post+extg", "post+gfut", "gonly",
            "aonly")


def swapped(stream: Stream, flags: frozenset, future_s: float, full: np.ndarray,
            settled: np.ndarray | None) -> Stream:
    """``stream`` with its windows given the future in the ways ``flags`` name (``full``:
    the clip's whole audio; ``settled``: every frame's final posteriors)."""
    sr = stream.sample_rate

    def rows(first: int, n_samples: int) -> np.ndarray:
        count = int(np.ceil(n_samples / sr * FRAME_RATE - 1e-9))
        if "post" in flags:
            return settled[np.clip(np.arange(first, first + count), 0, len(settled) - 1)]
        return stream._track.posteriors(first, count)

    def guided(audio: np.ndarray, n: int) -> np.ndarray:
        end = SimpleNamespace(start=0.0, end=len(audio) / sr)
        g = guide_trajectory(stream.model, stream.guide, audio, sr, [end])
        return stream.model.to_channels(g)[:n]

    def motion(audio, segments, start_s, guide):
        return window_motion(stream.model, audio, sr, segments, start_s,
                             memory=stream._memory, k_best=stream.k_best, guide=guide)[0]

    def synthesize(audio, n, start_s, **_):
        first = int(round(start_s * FRAME_RATE))
        if "gonly" in flags:
            return guided(audio, n)
        ahead = bool(flags & {"seg", "ext", "extg", "gfut"})
        s0 = int(round(start_s * sr))
        longer = full[s0: s0 + len(audio) + int(round(future_s * sr))]
        heard = longer if ahead else audio
        ctc.remember(heard, sr, rows(first, len(heard)))
        segments = ctc.recognize(heard, sr)
        if all(s.phone == "SIL" for s in segments):
            return stream._pause(n)
        end_s = len(audio) / sr
        ctc.remember(audio, sr, rows(first, len(audio)))  # the window's own rows
        if "seg" in flags:
            cut = [s._replace(end=min(s.end, end_s)) for s in segments
                   if s.start < end_s - 1e-3]
            return motion(audio, cut, start_s, stream.guide)
        if "ext" in flags:
            ctc.remember(longer, sr, rows(first, len(longer)))
            return motion(longer, segments, start_s, stream.guide)[:n]
        if "extg" in flags:
            ctc.remember(longer, sr, rows(first, len(longer)))
            animes = motion(longer, segments, start_s, None)[:n]
            guide = guided(audio, n)
        elif "gfut" in flags:
            animes = motion(audio, ctc.recognize(audio, sr), start_s, None)
            guide = guided(longer, n)
        else:
            return motion(audio, segments, start_s, None if "aonly" in flags else stream.guide)
        k = min(len(animes), len(guide))
        return 0.5 * animes[:k] + 0.5 * guide[:k]  # as GUIDE_BLEND

    stream._synthesize = synthesize
    return stream


def settled_posteriors(model, guide, audio, sr, setting) -> np.ndarray:
    """Every frame's posteriors as the stream's track leaves them (settled)."""
    stream = Stream(model, sample_rate=sr, guide=guide, backlog_ms=None, **setting)
    return bench_live.settled_posteriors(stream, audio)


def mouth_r(model, pred, clip) -> float:
    truth = clip.motion.astype(np.float64)
    n = min(len(pred), len(truth))
    keep = ~np.asarray(clip.missing, dtype=bool)[:n].any(axis=1)
    return pearson(mouth_opening(model.to_local(pred[:n])[keep], model.names, model.kind),
                   mouth_opening(truth[:n][keep], model.names, model.kind))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--grid-db", type=Path, required=True)
    parser.add_argument("--grid-train-db", type=Path, required=True)
    parser.add_argument("--max-clips", type=int, default=20)
    parser.add_argument("--take", default="::1", help="a slice of those clips, e.g. 0::2")
    parser.add_argument("--lookahead", type=float, default=40.0, help="ms")
    parser.add_argument("--low-latency", action="store_true",
                        help="the --low-latency setting's hop and hama context")
    parser.add_argument("--future", type=float, default=0.08, help="s given ahead")
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=VARIANTS)
    args = parser.parse_args()
    from animegraph.apps.evaluate import grid_split
    from db.store import Database
    from ingest.tables import prepared_from_database

    _, test = grid_split(prepared_from_database(Database.open(args.grid_db)))
    test = test[::max(1, -(-len(test) // args.max_clips))]
    test = test[slice(*[int(p) if p else None for p in (args.take.split(":") + ["", ""])[:3]])]
    model = Model.load(args.grid_train_db)
    guide, _ = stored_guide(args.grid_train_db)
    setting = {**(LOW_LATENCY if args.low_latency else {}), "lookahead_ms": args.lookahead}
    print(f"# {len(test)} clips, {setting}, future {args.future} s, load {os.getloadavg()}",
          flush=True)
    scores: dict[str, list[float]] = {v: [] for v in args.variants}
    for clip in test:
        audio, sr = clip.audio.astype(np.float32) / 32768.0, clip.sample_rate
        settled = (settled_posteriors(model, guide, audio, sr, setting)
                   if any("post" in v for v in args.variants) else None)
        for v in args.variants:
            stream = swapped(Stream(model, sample_rate=sr, guide=guide, backlog_ms=None,
                                    **setting),
                             frozenset(v.split("+")) - {"base"}, args.future, audio, settled)
            scores[v].append(mouth_r(model, play(stream, audio), clip))
        print(clip.clip_id, " ".join(f"{v} {s[-1]:.3f}" for v, s in scores.items()),
              flush=True)
    print("mean", " ".join(f"{v} {np.mean(s):.3f}" for v, s in scores.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
