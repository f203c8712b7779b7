"""``method="window"``: the paper's bounded look-ahead (§4.2, 3–6 phones ahead)."""

from __future__ import annotations

import numpy as np

from animegraph.search.exact import exact_layers
from animegraph.search.problem import Problem


def window_search(p: Problem, window: int) -> tuple[np.ndarray, float, int, int]:
    """Receding horizon (§4.2: "consider only 3–6 phonemes ahead of the current phoneme").

    At input t, with a_0 .. a_t-1 committed, the sub-sequence t .. t+window (the current
    phone and ``window`` phones ahead) is optimised exactly, its first transition being
    the one from a_t-1; a_t is committed from that optimum and the window slides by one.
    The last window (reaching input n-1) is committed whole. The cost of each window is
    Eq. (2) restricted to it, so its optimum is the one the paper's Priority-Queue
    algorithm would return on it (both are exact; ties aside). The result is a local
    optimum made of optimal short sequences: never better than the global one.
    """
    n = p.n
    idx = np.empty(n, dtype=np.int64)
    cost = 0.0
    n_exp = n_dist = 0
    prev = -1
    for t in range(n):
        stop = min(t + window + 1, n)
        cn, off, u = p.sub(t, stop, prev)
        sub_idx, sub_cost, e, d = exact_layers(p, cn, off, u)
        n_exp += e
        n_dist += d + (off[1] if prev >= 0 else 0)
        if stop == n:
            idx[t:] = sub_idx
            cost += sub_cost
            break
        idx[t] = sub_idx[0]
        cost += float(u[sub_idx[0]])  # u of the first layer includes the transition in
        prev = int(cn[sub_idx[0]])
    return idx, cost, n_exp, n_dist
