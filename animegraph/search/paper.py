"""``method="paper"``: Cao et al.'s Priority-Queue (branch and bound) algorithm, §4.2."""

from __future__ import annotations

import logging

import numpy as np

from animegraph.search.jit import kernel
from animegraph.search.problem import Problem, row_dist

log = logging.getLogger(__name__)



def paper(p: Problem, max_expansions: int,
           max_queue: int) -> tuple[np.ndarray, float, int, int, bool, bool]:
    """Cao et al.'s Priority-Queue algorithm (§4.2), as steps (1)–(4) describe it.

    (1) A queue node <seq, c, index> for every candidate of sn_1, c its Eq. (2) cost.
    (2) Remove the node q_min of least c; unless it is complete, create a queue node for
        every candidate of sn_{index+1}, with ``seq + (a,)`` and its cost, and queue them.
    (3) If q_min is complete (index = n): delete every queued node costlier than q_min.c;
        if q_min.c < mincost, it becomes the answer S_a and mincost.
    (4) Stop when the queue is empty, else go to (2).

    Representation (no change to the algorithm): ``seq`` is a parent pointer to the
    expanded node it extends. Once a complete sequence is known, a new node costlier than
    mincost is not queued: step (3) would delete it at the next complete sequence and,
    costs never decreasing along a sequence, it cannot lead to a cheaper one. Costs are
    >= 0 increments, so the first complete sequence removed is optimal; the search still
    runs to an empty queue as step (4) says.

    Capped: after ``max_expansions`` expansions, or when queueing the children would pass
    ``max_queue`` nodes, the search stops. The answer is then the best complete sequence
    if one was found (still optimal, by the argument above), else the deepest expanded
    partial sequence completed greedily (each step the cheapest transition plus unary
    cost): ``optimal=False``.
    """
    idx, cost, n_exp, n_dist, capped, found = _paper_kernel(
        p.cn, p.off, p.u, p.nxt, p.last, p.first, float(p.weights.w_jump), p.scale,
        max_expansions, max_queue)
    if capped:
        log.info("paper search stopped at its cap after %d expansions (%s)", n_exp,
                 "a complete sequence was found" if found else "none complete")
    return idx - p.off[:-1], float(cost), int(n_exp), int(n_dist), bool(capped), bool(found)


@kernel()
def _sift_down(hc, hr, hq, start, size):  # pragma: no cover
    i = start
    c, r, q = hc[i], hr[i], hq[i]
    while True:
        child = 2 * i + 1
        if child >= size:
            break
        if child + 1 < size and hc[child + 1] < hc[child]:
            child += 1
        if hc[child] < c:
            hc[i], hr[i], hq[i] = hc[child], hr[child], hq[child]
            i = child
        else:
            break
    hc[i], hr[i], hq[i] = c, r, q


@kernel()
def _push(hc, hr, hq, size, c, r, q):  # pragma: no cover
    i = size
    while i > 0:
        parent = (i - 1) // 2
        if hc[parent] <= c:
            break
        hc[i], hr[i], hq[i] = hc[parent], hr[parent], hq[parent]
        i = parent
    hc[i], hr[i], hq[i] = c, r, q


@kernel()
def _paper_kernel(cn, off, u, nxt, last, first, w1, scale, max_expansions,
                  max_queue):  # pragma: no cover
    n = len(off) - 1
    cap = max(min(max_queue, max(1024, 4 * (off[1] - off[0]))), off[1] - off[0])
    hc = np.empty(cap)  # queue: cost, expanded parent record (-1 for a root), flat candidate
    hr = np.empty(cap, dtype=np.int64)
    hq = np.empty(cap, dtype=np.int64)
    rcap = 1024
    rec_parent = np.empty(rcap, dtype=np.int64)  # expanded nodes: parent record, candidate
    rec_q = np.empty(rcap, dtype=np.int64)
    rec_layer = np.empty(rcap, dtype=np.int64)
    n_rec = 0
    size = 0
    n_dist = 0
    # (1) Initialisation.
    mincost = np.inf
    best_r = -2
    best_q = -1
    for q in range(off[0], off[1]):
        _push(hc, hr, hq, size, u[q], -1, q)
        size += 1
    capped = False
    deep_layer = -1
    deep_cost = np.inf
    deep_r = -1
    deep_q = -1
    while size > 0:  # (4)
        # (2) Remove q_min.
        c, r, q = hc[0], hr[0], hq[0]
        size -= 1
        if size > 0:
            hc[0], hr[0], hq[0] = hc[size], hr[size], hq[size]
            _sift_down(hc, hr, hq, 0, size)
        layer = 0 if r < 0 else rec_layer[r] + 1
        if layer == n - 1:
            # (3) Queue pruning: a complete matching sequence.
            k = 0
            for j in range(size):
                if hc[j] <= c:
                    hc[k], hr[k], hq[k] = hc[j], hr[j], hq[j]
                    k += 1
            size = k
            for j in range(size // 2 - 1, -1, -1):
                _sift_down(hc, hr, hq, j, size)
            if c < mincost:
                mincost = c
                best_r = r
                best_q = q
            continue
        if n_rec >= max_expansions or size + (off[layer + 2] - off[layer + 1]) > max_queue:
            capped = True
            if layer > deep_layer or (layer == deep_layer and c < deep_cost):
                deep_layer, deep_cost, deep_r, deep_q = layer, c, r, q
            break
        if layer > deep_layer or (layer == deep_layer and c < deep_cost):
            deep_layer, deep_cost, deep_r, deep_q = layer, c, r, q
        # (2) Expand q_min: one queue node per candidate of the next phone.
        if n_rec == rcap:
            rcap *= 2
            rec_parent = np.concatenate((rec_parent, np.empty(rcap - n_rec, dtype=np.int64)))
            rec_q = np.concatenate((rec_q, np.empty(rcap - n_rec, dtype=np.int64)))
            rec_layer = np.concatenate((rec_layer, np.empty(rcap - n_rec, dtype=np.int64)))
        rec_parent[n_rec] = r
        rec_q[n_rec] = q
        rec_layer[n_rec] = layer
        me = n_rec
        n_rec += 1
        a = cn[q]
        lo1, hi1 = off[layer + 1], off[layer + 2]
        if size + (hi1 - lo1) > cap:
            newcap = min(max_queue, max(2 * cap, size + (hi1 - lo1)))
            hc = np.concatenate((hc, np.empty(newcap - cap)))
            hr = np.concatenate((hr, np.empty(newcap - cap, dtype=np.int64)))
            hq = np.concatenate((hq, np.empty(newcap - cap, dtype=np.int64)))
            cap = newcap
        for q1 in range(lo1, hi1):
            b = cn[q1]
            t = scale * row_dist(last, a, first, b)
            n_dist += 1
            if nxt[a] != b:
                t += w1
            c1 = c + t + u[q1]
            if c1 > mincost:
                continue
            _push(hc, hr, hq, size, c1, me, q1)
            size += 1
    path = np.empty(n, dtype=np.int64)
    found = best_r > -2
    if found:
        cost = mincost
        path[n - 1] = best_q
        r = best_r
        i = n - 2
        while r >= 0:
            path[i] = rec_q[r]
            r = rec_parent[r]
            i -= 1
        return path, cost, n_rec, n_dist, capped, True
    # Capped before any complete sequence: complete the deepest one greedily.
    r = deep_r
    path[deep_layer] = deep_q
    i = deep_layer - 1
    while r >= 0:
        path[i] = rec_q[r]
        r = rec_parent[r]
        i -= 1
    cost = deep_cost
    for layer in range(deep_layer, n - 1):
        a = cn[path[layer]]
        best = np.inf
        qb = off[layer + 1]
        for q1 in range(off[layer + 1], off[layer + 2]):
            b = cn[q1]
            t = scale * row_dist(last, a, first, b)
            n_dist += 1
            if nxt[a] != b:
                t += w1
            if t + u[q1] < best:
                best = t + u[q1]
                qb = q1
        path[layer + 1] = qb
        cost += best
    return path, cost, n_rec, n_dist, capped, False
