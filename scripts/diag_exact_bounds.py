"""How many states of the exact search any lower bound could prune (bench_search.py graphs).

Usage::

    python scripts/diag_exact_bounds.py --db DB [--size 1000000] [--input random4]

Builds the graph and the input of ``scripts/bench_search.py`` (same seed, same order of
draws, so the same problem as its row), runs the exact search's forward step without
pruning and the same step over the reversed layers, which give every state's least prefix
cost ``D`` and its exact cost to go ``H``, and prints the optimum, the greedy upper bound,
the gap of the relaxed bound ``h`` and, for several ε, the states whose best complete
sequence is within ε of the optimum: the states an exact lower bound with an upper bound
ε above the optimum would keep. Slow (two passes that prune nothing: about 80 s at 1M).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import bench_search as bs
import numpy as np

from animegraph.search import candidates, exact
from animegraph.search.graph import AnimeGraph
from animegraph.search.problem import Problem, SearchWeights
from ingest.speech.phones import PHONES


def unpruned(p: Problem, cn, off, u, nxt, prv, last, first) -> np.ndarray:
    """Least prefix cost of every state (u of the state included): the forward step of
    :func:`animegraph.search.exact.exact_layers` with no bound."""
    h0 = np.zeros(len(cn))
    pos = np.full(p.graph.n_nodes, -1, dtype=np.int64)
    D = np.full(len(cn), np.inf)
    pred = np.full(len(cn), -1, dtype=np.int64)
    D[:off[1]] = u[:off[1]]
    w1 = float(p.weights.w_jump)
    for i in range(len(off) - 2):
        layer = exact._prepare_layer(cn, off[i], off[i + 1], off[i + 1], off[i + 2], D, u, h0,
                                     last, w1, p.scale, np.inf, pos)
        exact._query_layer(cn, off[i + 1], off[i + 2], D, pred, u, h0, prv, last, first, w1,
                           p.scale, np.inf, pos, *layer[1:11])
        pos[cn[layer[0]]] = -1
    return D


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--db", type=Path, required=True)
    parser.add_argument("--size", type=int, default=1_000_000)
    parser.add_argument("--input", default="random4", help="held-out, random, random2, ...")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--length", type=int, default=30)
    args = parser.parse_args()
    from db.store import Database

    # The draws of bench_search.main, in its order.
    rng = np.random.default_rng(args.seed)
    base = AnimeGraph.from_database(Database.open(args.db))
    recs = bs.recordings(base)
    seqs = [tuple(base.node_phone[r]) for r in recs]
    long_enough = [i for i, r in enumerate(recs) if len(r) >= args.length]
    held = long_enough[int(rng.integers(len(long_enough)))]
    inputs = {"held-out": [PHONES[x] for x in seqs[held][:args.length]]}
    base = bs.subgraph(base, np.concatenate(
        [r for r, s in zip(recs, seqs, strict=True) if s != seqs[held]]))
    freq = np.bincount(base.node_phone, minlength=len(PHONES)).astype(float)
    inputs["random"] = list(rng.choice(PHONES, size=args.length, p=freq / freq.sum()))
    k = 2
    while args.input not in inputs:
        if k > 99:
            print(f"diag_exact_bounds: no input {args.input!r} (held-out, random, random2, ...)",
                  file=sys.stderr)
            return 2
        extra = np.random.default_rng([args.seed, k])
        inputs[f"random{k}"] = list(extra.choice(PHONES, size=args.length, p=freq / freq.sum()))
        k += 1
    g = bs.replicate(base, max(1, round(args.size / base.n_nodes)), rng)
    for label, phones in inputs.items():  # bench_search draws every input's audio in order
        cands = candidates(g, phones)
        audio = [rng.uniform(0.0, 20.0, size=len(c)) for c in cands.nodes]
        if label == args.input:
            break
    p = Problem.build(g, cands, audio, SearchWeights(), None)
    t = time.perf_counter()
    D = unpruned(p, p.cn, p.off, p.u, p.nxt, p.prv, p.last, p.first)
    n = len(p.off) - 1
    rev = [slice(p.off[i], p.off[i + 1]) for i in range(n - 1, -1, -1)]
    roff = np.concatenate(([0], np.cumsum(np.diff(p.off)[::-1])))
    rcn, ru = np.concatenate([p.cn[s] for s in rev]), np.concatenate([p.u[s] for s in rev])
    # Reversed, a transition's "last" frame is the first and "next" is "previous".
    Dr = unpruned(p, rcn, roff, ru, p.prv, p.nxt, p.first, p.last)
    to_go = np.concatenate([Dr[roff[n - 1 - i]:roff[n - i]] for i in range(n)]) - p.u
    total = D + to_go
    opt = float(D[p.off[n - 1]:].min())
    pos = np.full(g.n_nodes, -1, dtype=np.int64)
    w1 = float(p.weights.w_jump)
    h = exact._relaxed_backward(p.cn, p.off, p.u, p.nxt, p.last, p.first, w1, p.scale, pos)
    _, ub = exact._greedy(p.cn, p.off, p.u, h, p.nxt, p.last, p.first, w1, p.scale)
    lb = float(np.min(p.u[:p.off[1]] + h[:p.off[1]]))
    print(f"{g.n_nodes} nodes, input {args.input}: optimum {opt:.3f}, greedy upper bound "
          f"+{ub - opt:.2f}, relaxed lower bound -{opt - lb:.2f} ({time.perf_counter() - t:.0f} s)")
    print(f"states kept by the search's upper bound with an exact cost to go: "
          f"{np.count_nonzero(total <= ub)} of {np.count_nonzero(total < np.inf)}")
    for eps in (0.01, 0.1, 0.3, 1.0, 2.0):
        print(f"states within {eps:g} of the optimum: {np.count_nonzero(total <= opt + eps)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
