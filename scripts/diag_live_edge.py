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

VARIANTS = ("base", "post", "post+seg", "post+ext", "post+extg", "post+gfut", "gonly",
            "aonly")
#: The stream is pushed 20 ms at a time, as bench_live.py pushes it.
CHUNK_S = 0.02


class Swapped(Stream):
    """A stream whose windows are given the future in the ways ``flags`` name."""

    flags: frozenset = frozenset()
    future_s = 0.08
    full: np.ndarray  # the clip's whole audio
    settled: np.ndarray | None = None  # every frame's final posteriors

    def _rows(self, first: int, n_samples: int) -> np.ndarray:
        count = int(np.ceil(n_samples / self.sample_rate * FRAME_RATE - 1e-9))
        if "post" in self.flags:
            return self.settled[np.clip(np.arange(first, first + count), 0,
                                        len(self.settled) - 1)]
        return self._track.posteriors(first, count)

    def _guide(self, audio: np.ndarray, n: int) -> np.ndarray:
        end = SimpleNamespace(start=0.0, end=len(audio) / self.sample_rate)
        g = guide_trajectory(self.model, self.guide, audio, self.sample_rate, [end])
        return self.model.to_channels(g)[:n]

    def _motion(self, audio, segments, start_s, guide):
        return window_motion(self.model, audio, self.sample_rate, segments, start_s,
                             memory=self._memory, k_best=self.k_best, guide=guide)[0]

    def _synthesize(self, audio, n, start_s, **_):
        sr, fl = self.sample_rate, self.flags
        first = int(round(start_s * FRAME_RATE))
        if "gonly" in fl:
            return self._guide(audio, n)
        ahead = bool(fl & {"seg", "ext", "extg", "gfut"})
        s0 = int(round(start_s * sr))
        longer = self.full[s0: s0 + len(audio) + int(round(self.future_s * sr))]
        heard = longer if ahead else audio
        ctc.remember(heard, sr, self._rows(first, len(heard)))
        segments = ctc.recognize(heard, sr)
        if all(s.phone == "SIL" for s in segments):
            return self._pause(n)
        end_s = len(audio) / sr
        ctc.remember(audio, sr, self._rows(first, len(audio)))  # the window's own rows
        if "seg" in fl:
            cut = [s._replace(end=min(s.end, end_s)) for s in segments
                   if s.start < end_s - 1e-3]
            return self._motion(audio, cut, start_s, self.guide)
        if "ext" in fl:
            ctc.remember(longer, sr, self._rows(first, len(longer)))
            return self._motion(longer, segments, start_s, self.guide)[:n]
        if "extg" in fl:
            ctc.remember(longer, sr, self._rows(first, len(longer)))
            animes = self._motion(longer, segments, start_s, None)[:n]
            guide = self._guide(audio, n)
        elif "gfut" in fl:
            animes = self._motion(audio, ctc.recognize(audio, sr), start_s, None)
            guide = self._guide(longer, n)
        else:
            return self._motion(audio, segments, start_s,
                                None if "aonly" in fl else self.guide)
        k = min(len(animes), len(guide))
        return 0.5 * animes[:k] + 0.5 * guide[:k]  # as GUIDE_BLEND


def play(stream: Stream, audio: np.ndarray) -> np.ndarray:
    step = int(CHUNK_S * stream.sample_rate)
    parts = [stream.push(audio[k:k + step]).motion for k in range(0, len(audio), step)]
    parts.append(stream.close().motion)
    return np.concatenate(parts)


def settled_posteriors(model, guide, audio, sr, setting) -> np.ndarray:
    """Every frame's posteriors as the stream's track leaves them (settled)."""
    stream = Stream(model, sample_rate=sr, guide=guide, backlog_ms=None, **setting)
    rows: dict[int, np.ndarray] = {}
    track, update = stream._track, stream._track.update

    def keep(*a, **k):
        update(*a, **k)
        for f in range(track._first, track.frames):
            rows[f] = track._rows[f - track._first].copy()

    track.update = keep
    play(stream, audio)
    return np.stack([rows.get(f, rows[min(rows)]) for f in range(max(rows) + 1)])


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
            stream = Swapped(model, sample_rate=sr, guide=guide, backlog_ms=None, **setting)
            stream.flags = frozenset(v.split("+")) - {"base"}
            stream.future_s, stream.full, stream.settled = args.future, audio, settled
            scores[v].append(mouth_r(model, play(stream, audio), clip))
        print(clip.clip_id, " ".join(f"{v} {s[-1]:.3f}" for v, s in scores.items()),
              flush=True)
    print("mean", " ".join(f"{v} {np.mean(s):.3f}" for v, s in scores.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
