"""Time the Anime Graph search (§4.2) at the paper's graph size and at 10x and 100x.

Usage::

    python scripts/bench_search.py [--db PATH] [--sizes 10000 100000 1000000]
                                   [--repeats 5] [--methods exact window paper] [--json OUT]
                                   [--n-random K] [--tolerances 0.01]

The base graph is a database (``--db``) or synthetic recordings with English-like phone
frequencies and sentences repeated over takes (as in the corpus). Larger graphs are
replicas of the base: each replica's recordings are new clips, and every boundary frame
(shared by a node's last frame and its successor's first) is perturbed by Gaussian noise
of 0.1 x the per-component spread, so consecutive nodes still join and no two replicas
coincide. Inputs: the first 30 phones of a held-out recording whose phone sequence is
removed from the graph with every recording that repeats it (a novel sentence), and 30
random phones drawn with the graph's phone frequencies (the hard case: many jumps).
Audio costs are random (their DTW is timed elsewhere).

Prints, per size, input and method: median latency, the median CPU time of the process
(every thread's; less sensitive to other processes' load than the latency), states
expanded, frame distances, jumps, cost, and for ``paper`` whether it hit its cap; and the
graph's memory.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

from animegraph.search import candidates, search
from animegraph.search.graph import AnimeGraph
from ingest.speech.phones import PHONES

#: Approximate relative frequencies of the phones in English speech (per 1,000).
PHONE_FREQ = {
    "AA": 9, "AE": 14, "AH": 38, "AO": 8, "AW": 2, "AY": 6, "EH": 12, "ER": 9, "EY": 7,
    "IH": 26, "IY": 14, "OW": 6, "OY": 1, "UH": 2, "UW": 7, "B": 10, "CH": 4, "D": 26,
    "DH": 17, "F": 10, "G": 5, "HH": 9, "JH": 3, "K": 18, "L": 25, "M": 17, "N": 42,
    "NG": 5, "P": 11, "R": 25, "S": 29, "SH": 4, "T": 43, "TH": 3, "V": 11, "W": 11,
    "Y": 4, "Z": 16, "ZH": 1, "SIL": 30,
}


def synthetic_base(n_target: int, rng: np.random.Generator, n_pcs: int = 8,
                   n_channels: int = 216) -> AnimeGraph:
    """Sentences of 25-60 phones, each recorded in 3 takes x 2 emotions, ~n_target nodes."""
    p = np.array([PHONE_FREQ[x] for x in PHONES], dtype=float)
    p /= p.sum()
    means = rng.normal(0.0, 10.0, size=(len(PHONES), n_pcs)) * np.linspace(2, 0.5, n_pcs)
    recs: list[np.ndarray] = []
    emo: list[int] = []
    while sum(len(r) for r in recs) < n_target:
        sentence = rng.choice(len(PHONES), size=int(rng.integers(25, 61)), p=p)
        for e in rng.choice(5, size=2, replace=False):
            for _ in range(3):
                recs.append(sentence)
                emo.append(int(e))
    node_phone = np.concatenate(recs).astype(np.int16)
    lengths = np.array([len(r) for r in recs])
    n = len(node_phone)
    starts = np.concatenate(([0], np.cumsum(lengths)[:-1]))
    first = np.empty((n, n_pcs), dtype=np.float32)
    last = np.empty((n, n_pcs), dtype=np.float32)
    for s, length in zip(starts, lengths, strict=True):
        ph = node_phone[s:s + length]
        # Boundary frames: between two phones, the mean of their shapes plus take noise.
        shapes = means[ph]
        bounds = np.empty((length + 1, n_pcs))
        bounds[0] = shapes[0]
        bounds[-1] = shapes[-1]
        bounds[1:-1] = 0.5 * (shapes[:-1] + shapes[1:])
        bounds += rng.normal(0.0, 3.0, size=bounds.shape)
        first[s:s + length] = bounds[:-1]
        last[s:s + length] = bounds[1:]
    return _graph(node_phone, np.repeat(emo, lengths).astype(np.int16),
                  np.repeat(np.arange(len(recs)), lengths).astype(np.int32), lengths,
                  first, last, n_channels, ("angry", "frustrated", "happy", "neutral", "sad"))


def _graph(node_phone, node_emotion, node_clip, lengths, first, last, n_channels, emotions,
           fps=120.0) -> AnimeGraph:
    n = len(node_phone)
    starts = np.concatenate(([0], np.cumsum(lengths)[:-1]))
    position = np.arange(n) - np.repeat(starts, lengths)
    next_node = np.arange(1, n + 1, dtype=np.int64)
    next_node[np.cumsum(lengths) - 1] = -1
    prev_node = np.arange(-1, n - 1, dtype=np.int64)
    prev_node[starts] = -1
    frames = np.full(n, 12, dtype=np.int32)
    return AnimeGraph(
        node_phone=node_phone, node_emotion=node_emotion, node_clip=node_clip,
        position=position.astype(np.int32), next_node=next_node, prev_node=prev_node,
        start_frame=(position * 12).astype(np.int32),
        end_frame=(position * 12 + 12).astype(np.int32),
        start_time=(position * 0.1).astype(np.float32),
        end_time=(position * 0.1 + 0.1).astype(np.float32),
        prosody_offsets=np.arange(n + 1, dtype=np.int64) * 10,
        prosody_values=np.zeros((n * 10, 9), dtype=np.float32),
        motion_offsets=np.concatenate(([0], np.cumsum(frames))).astype(np.int64),
        motion_values=np.zeros((int(frames.sum()), first.shape[1]), dtype=np.float32),
        first_pcs=first, last_pcs=last,
        by_phone=tuple(np.flatnonzero(node_phone == p).astype(np.int64)
                       for p in range(len(PHONES))),
        clip_ids=tuple(f"clip{c:07d}" for c in range(int(node_clip.max()) + 1)),
        emotions=tuple(emotions), fps=fps, n_channels=n_channels,
    )


def recordings(g: AnimeGraph) -> list[np.ndarray]:
    """Node ids of each recording, in order."""
    heads = np.flatnonzero(g.prev_node < 0)
    out = []
    for h in heads:
        seq = [h]
        while g.next_node[seq[-1]] >= 0:
            seq.append(int(g.next_node[seq[-1]]))
        out.append(np.array(seq, dtype=np.int64))
    return out


def subgraph(g: AnimeGraph, keep: np.ndarray) -> AnimeGraph:
    """The graph of the recordings in ``keep`` (node ids, whole recordings), renumbered."""
    keep = np.sort(keep)
    remap = np.full(g.n_nodes, -1, dtype=np.int64)
    remap[keep] = np.arange(len(keep))

    def links(a):
        return np.where(a[keep] >= 0, remap[np.maximum(a[keep], 0)], -1)

    def ragged(offsets, values):
        counts = (offsets[1:] - offsets[:-1])[keep]
        idx = np.concatenate([np.arange(offsets[k], offsets[k + 1]) for k in keep])
        return np.concatenate(([0], np.cumsum(counts))).astype(np.int64), values[idx]

    po, pv = ragged(g.prosody_offsets, g.prosody_values)
    mo, mv = ragged(g.motion_offsets, g.motion_values)
    phone = g.node_phone[keep]
    return AnimeGraph(
        node_phone=phone, node_emotion=g.node_emotion[keep], node_clip=g.node_clip[keep],
        position=g.position[keep], next_node=links(g.next_node), prev_node=links(g.prev_node),
        start_frame=g.start_frame[keep], end_frame=g.end_frame[keep],
        start_time=g.start_time[keep], end_time=g.end_time[keep],
        prosody_offsets=po, prosody_values=pv, motion_offsets=mo, motion_values=mv,
        first_pcs=g.first_pcs[keep], last_pcs=g.last_pcs[keep],
        by_phone=tuple(np.flatnonzero(phone == p).astype(np.int64) for p in range(len(PHONES))),
        clip_ids=g.clip_ids, emotions=g.emotions, fps=g.fps, n_channels=g.n_channels,
    )


def replicate(g: AnimeGraph, copies: int, rng: np.random.Generator) -> AnimeGraph:
    """``copies`` replicas of ``g`` (the first unperturbed), as distinct clips."""
    if copies == 1:
        return g
    n = g.n_nodes
    shift = np.repeat(np.arange(copies, dtype=np.int64) * n, n)
    n_clips = int(g.node_clip.max()) + 1

    def links(a):
        t = np.tile(a, copies)
        return np.where(t >= 0, t + shift, -1)

    def ragged(offsets, values):
        step = offsets[-1]
        o = np.concatenate([offsets[:-1] + r * step for r in range(copies)] + [[copies * step]])
        return o.astype(np.int64), np.tile(values, (copies, 1))

    sigma = 0.1 * np.concatenate([g.first_pcs, g.last_pcs]).std(axis=0)
    first = np.tile(g.first_pcs, (copies, 1))
    last = np.tile(g.last_pcs, (copies, 1))
    nxt = links(g.next_node)
    # One noise vector per boundary frame: a node's last frame and its successor's first.
    noise_last = (rng.standard_normal(last.shape) * sigma).astype(np.float32)
    noise_last[:n] = 0
    noise_first = (rng.standard_normal(first.shape) * sigma).astype(np.float32)
    noise_first[:n] = 0
    has_next = nxt >= 0
    noise_first[nxt[has_next]] = noise_last[has_next]
    first += noise_first
    last += noise_last
    po, pv = ragged(g.prosody_offsets, g.prosody_values)
    mo, mv = ragged(g.motion_offsets, g.motion_values)
    phone = np.tile(g.node_phone, copies)
    clip = (np.tile(g.node_clip, copies).astype(np.int64)
            + np.repeat(np.arange(copies) * n_clips, n)).astype(np.int32)
    return AnimeGraph(
        node_phone=phone, node_emotion=np.tile(g.node_emotion, copies), node_clip=clip,
        position=np.tile(g.position, copies), next_node=nxt, prev_node=links(g.prev_node),
        start_frame=np.tile(g.start_frame, copies), end_frame=np.tile(g.end_frame, copies),
        start_time=np.tile(g.start_time, copies), end_time=np.tile(g.end_time, copies),
        prosody_offsets=po, prosody_values=pv, motion_offsets=mo, motion_values=mv,
        first_pcs=first, last_pcs=last,
        by_phone=tuple(np.flatnonzero(phone == p).astype(np.int64) for p in range(len(PHONES))),
        clip_ids=tuple(f"{c}#r{r}" for r in range(copies) for c in g.clip_ids),
        emotions=g.emotions, fps=g.fps, n_channels=g.n_channels,
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--db", type=Path, help="base graph from this database")
    parser.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000, 1_000_000])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--length", type=int, default=30, help="input phones")
    parser.add_argument("--windows", type=int, nargs="+", default=[3, 6])
    parser.add_argument("--paper-cap", type=int, default=2_000_000,
                        help="max_expansions of method='paper'")
    parser.add_argument("--paper-queue", type=int, default=20_000_000,
                        help="max_queue of method='paper'")
    parser.add_argument("--methods", nargs="+", default=["exact", "window", "paper"],
                        choices=["exact", "window", "paper", "dp"])
    parser.add_argument("--tolerances", type=float, nargs="*", default=[0.01],
                        help="also run the exact search with these certified tolerances "
                             "(cost <= (1 + t) * optimum)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--n-random", type=int, default=1,
                        help="random inputs (their difficulty varies much; the extra ones "
                             "are drawn from their own generators, so the first is unchanged)")
    parser.add_argument("--json", type=Path, help="also write the results here")
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)

    if args.db:
        from db.store import Database

        base = AnimeGraph.from_database(Database.open(args.db))
        source = f"database {args.db}"
    else:
        base = synthetic_base(10_500, rng)
        source = "synthetic recordings"
    # Hold out a recording and every recording with the same phone sequence.
    recs = recordings(base)
    seqs = [tuple(base.node_phone[r]) for r in recs]
    long_enough = [i for i, r in enumerate(recs) if len(r) >= args.length]
    held = long_enough[int(rng.integers(len(long_enough)))]
    held_phones = [PHONES[p] for p in seqs[held][:args.length]]
    keep = np.concatenate([r for r, s in zip(recs, seqs, strict=True) if s != seqs[held]])
    removed = len(recs) - sum(1 for s in seqs if s != seqs[held])
    base = subgraph(base, keep)
    freq = np.bincount(base.node_phone, minlength=len(PHONES)).astype(float)
    random_phones = list(rng.choice(PHONES, size=args.length, p=freq / freq.sum()))
    inputs = {"held-out": held_phones, "random": random_phones}
    for k in range(2, args.n_random + 1):
        extra = np.random.default_rng([args.seed, k])
        inputs[f"random{k}"] = list(extra.choice(PHONES, size=args.length, p=freq / freq.sum()))

    print(f"# {platform.processor() or platform.machine()}, {os.cpu_count()} cores; base: "
          f"{source}, {base.n_nodes} nodes after holding out {removed} recording(s) of one "
          f"phone sequence; input length {args.length}")
    print(f"{'nodes':>9s} {'MB':>7s} {'input':9s} {'method':10s} {'median_ms':>10s} "
          f"{'cpu_ms':>8s} "
          f"{'expanded':>10s} {'distances':>11s} {'jumps':>5s} {'cost':>10s} note")
    rows = []
    for size in args.sizes:
        copies = max(1, round(size / base.n_nodes))
        t0 = time.perf_counter()
        g = replicate(base, copies, rng)
        build_s = time.perf_counter() - t0
        mb = g.nbytes() / 1e6
        for label, phones in inputs.items():
            cands = candidates(g, phones)
            audio = [rng.uniform(0.0, 20.0, size=len(c)) for c in cands.nodes]
            runs = [("exact", {}, args.repeats)]
            runs += [(f"exact@{t:g}", {"tolerance": t}, args.repeats) for t in args.tolerances]
            if "dp" in args.methods:
                runs.append(("dp", {}, args.repeats))
            if "window" in args.methods:
                runs += [(f"window{k}", {"window": k}, args.repeats) for k in args.windows]
            if "paper" in args.methods:
                runs.append(("paper", {"max_expansions": args.paper_cap,
                                       "max_queue": args.paper_queue}, 1))
            exact_cost = None
            for name, kw, reps in runs:
                method = "window" if name.startswith("window") else name.split("@")[0]
                search(g, cands, audio, method=method, **kw) if reps > 1 else None  # warm
                times, cpus = [], []
                for _ in range(reps):
                    t, c = time.perf_counter(), time.process_time()
                    res = search(g, cands, audio, method=method, **kw)
                    times.append(time.perf_counter() - t)
                    cpus.append(time.process_time() - c)
                med = float(np.median(times)) * 1e3
                cpu = float(np.median(cpus)) * 1e3
                if name == "exact":
                    exact_cost = res.cost
                note = []
                if res.capped:
                    note.append("hit cap")
                if exact_cost is not None and name != "exact":
                    note.append(f"+{max(0.0, res.cost - exact_cost):.2f} over optimum")
                row = {"nodes": g.n_nodes, "copies": copies, "graph_mb": mb,
                       "build_s": build_s, "input": label, "method": name,
                       "median_ms": med, "cpu_ms": cpu, "runs": reps,
                       "n_expanded": res.n_expanded,
                       "n_distances": res.n_distances, "n_jumps": res.n_jumps,
                       "cost": res.cost, "optimal": res.optimal, "capped": res.capped,
                       "candidates": int(cands.sizes.sum())}
                rows.append(row)
                print(f"{g.n_nodes:9d} {mb:7.0f} {label:9s} {name:10s} {med:10.1f} {cpu:8.1f} "
                      f"{res.n_expanded:10d} {res.n_distances:11d} {res.n_jumps:5d} "
                      f"{res.cost:10.2f} {'; '.join(note)}")
                sys.stdout.flush()
        del g
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
