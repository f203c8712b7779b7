"""``method="dp"``: plain Viterbi over every candidate pair, the tests' oracle."""

from __future__ import annotations

import numpy as np

from animegraph.search.problem import Problem
from db.errors import ParameterError

#: The ``"dp"`` oracle refuses layers with more candidate pairs than this (memory ~8 B each).
DP_MAX_PAIRS = 4_000_000


def dp(p: Problem) -> tuple[np.ndarray, float, int, int]:
    """Viterbi over every pair of consecutive candidates: D(b) = u(b) + min_a D(a) + T(a, b)."""
    from scipy.spatial.distance import cdist  # deferred: the default search does not use it

    sizes = np.diff(p.off)
    pairs = sizes[:-1] * sizes[1:]
    if len(pairs) and pairs.max() > DP_MAX_PAIRS:
        i = int(pairs.argmax())
        raise ParameterError(f"method='dp' handles at most {DP_MAX_PAIRS} candidate pairs "
                             f"between two inputs, got {int(pairs[i])} (inputs {i}, {i + 1})")
    w1 = p.weights.w_jump
    layer = [p.cn[p.off[i]:p.off[i + 1]] for i in range(p.n)]
    unary = [p.u[p.off[i]:p.off[i + 1]] for i in range(p.n)]
    D = unary[0].copy()
    back = []
    for i in range(p.n - 1):
        a, b = layer[i], layer[i + 1]
        dist = cdist(p.last[a].astype(np.float64), p.first[b].astype(np.float64))
        total = D[:, None] + (w1 * (p.nxt[a][:, None] != b[None, :]) + p.scale * dist)
        arg = total.argmin(axis=0)
        D = total[arg, np.arange(len(b))] + unary[i + 1]
        back.append(arg)
    idx = np.empty(p.n, dtype=np.int64)
    idx[-1] = int(D.argmin())
    cost = float(D[idx[-1]])
    for i in range(p.n - 2, -1, -1):
        idx[i] = back[i][idx[i + 1]]
    return idx, cost, int(sizes.sum()), int(pairs.sum())
