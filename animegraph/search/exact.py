"""``method="exact"``: the global optimum of Eq. (2) by pruned forward dynamic programming.

Beyond the paper (which searched a window of 3–6 phones): see :func:`exact_layers` for
the algorithm and its proof of exactness. The jump transitions are answered by the k-d
tree of :mod:`animegraph.search.kdtree`; kernels are compiled by numba (cached on disk
after the first call) and a large layer's queries run on several threads.
"""

from __future__ import annotations

import logging

import numpy as np

from animegraph.search.jit import kernel
from animegraph.search.kdtree import LEAF, build_tree, query
from animegraph.search.problem import Problem, row_dist
from animegraph.search.threads import thread_pool
from db.system import usable_cpus

log = logging.getLogger(__name__)

#: Dominated jump sources are looked for among at most this many neighbours.
_DOMINANCE_RANGE = 64
#: Rebuild the tree when dominance leaves fewer than this fraction of the states.
_REBUILD = 0.7
#: Queries of a layer below which one thread does them all.
_PARALLEL_MIN = 2048


def exact(p: Problem, tolerance: float = 0.0) -> tuple[np.ndarray, float, int, int]:
    return exact_layers(p, p.cn, p.off, p.u, tolerance)


def exact_layers(p: Problem, cn: np.ndarray, off: np.ndarray, u: np.ndarray,
                  tolerance: float = 0.0) -> tuple[np.ndarray, float, int, int]:
    """Global optimum of the chain ``cn``/``off``/``u``: (indices, cost, states, distances).

    The problem is a shortest path through layers of candidates, with the transition
    ``T(a, b) = w1 [b != next(a)] + s ||last(a) - first(b)||`` (s = w2 / sqrt(n_channels))
    and the unary cost ``u(b)``. The plain Viterbi recursion
    ``D(b) = u(b) + min_a D(a) + T(a, b)`` costs |C_i| |C_i+1| distances a layer. Three
    steps avoid almost all of them without changing the result:

    1. **Lower bound** ``h(a)`` on the cost to go from ``a`` (a backward DP on a
       relaxation): ``h(a) = min(T(a, next a) + u(next a) + h(next a),
       w1 + min_b u(b) + h(b))``, the first term only when ``next a`` is a candidate of
       the next layer. It drops the distance of jump transitions only (>= 0), so by
       induction ``h <= H``, the true cost to go (admissible). O(N).
    2. **Upper bound** ``UB``: the cost of one feasible sequence, built greedily forward,
       each step taking the successor that minimises ``T + u + h`` with true distances.
       O(N) distances.
    3. **Pruned forward DP.** A state ``b`` is kept only if ``D(b) + h(b) <= UB``. For a
       kept ``b``, the consecutive predecessor ``prev b`` costs O(1). The jump part,
       ``w1 + min_a D(a) + s ||last(a) - first(b)||``, is an additively weighted
       nearest-neighbour query over the kept states ``a`` of the previous layer, answered
       by branch and bound in a k-d tree over their last frames whose nodes carry their
       bounding box and least ``D`` (lower bound of a subtree: ``w1 + min D + s *
       box distance``; leaves are scanned in ascending ``D``). A subtree or point is
       skipped only when its lower bound reaches the best value found or exceeds
       ``UB - h(b) - u(b)`` (it could neither improve ``b`` nor keep it); a point's
       distance is computed whole, without an early exit on its partial sum, so that
       the loop over the few components vectorises (~10-15 % less CPU time at 1M nodes
       than the early exit; the skip test is the same). With few queries the tree is a
       single leaf (a scan in ascending ``D``). Before the queries, states that can never
       be the best source are dropped: ``a`` is dominated by ``a'`` when
       ``D(a') + s ||x_a' - x_a|| < D(a)`` (by a 1e-9 relative margin), for then, by
       the triangle inequality, ``a'`` beats ``a`` for every target; dominance is
       checked among neighbours in the tree (subtrees of <= ``_DOMINANCE_RANGE``
       states), and the tree is rebuilt when many states go. Queries of a large layer
       run on several threads (numba releases the GIL).

    Exactness: let π be an optimal sequence, cost OPT <= UB. For each of its states,
    (prefix cost of π) + h <= (prefix cost) + H <= OPT <= UB. By induction over layers,
    each state of π is kept with ``D <= its prefix cost``: its predecessor on π is kept
    (or dominated by a kept state that does at least as well, following the chain of
    dominations to a state that stays), and the search skips only sources whose lower
    bound is not below the best value found or is above the keep threshold, which π's
    predecessor is not. Every computed ``D`` is the cost of a real prefix, so ``min D``
    over the last layer is both <= OPT and >= OPT: it equals the optimum of the full
    Viterbi recursion (the ``"dp"`` oracle), up to floating-point rounding (1e-12).
    Comparisons with UB carry a relative slack of 1e-9 so that rounding never prunes π.
    Cost: O(N) for the bounds plus, per kept state, one tree query; in the worst case
    (bounds that prune nothing) this is the Viterbi recursion with a spatial index.

    With ``tolerance`` t > 0 the keep threshold is ``UB - t * LB`` instead of UB, with
    ``LB = min(u + h)`` over the first layer (<= OPT). If ``OPT <= UB - t * LB``, the
    argument above keeps π and the result is optimal; otherwise the greedy sequence,
    returned when nothing is kept, costs ``UB < OPT + t * LB <= (1 + t) OPT``.
    """
    n = len(off) - 1
    pos = np.full(p.graph.n_nodes, -1, dtype=np.int64)
    w1 = float(p.weights.w_jump)
    h = _relaxed_backward(cn, off, u, p.nxt, p.last, p.first, w1, p.scale, pos)
    gpath, ub = _greedy(cn, off, u, h, p.nxt, p.last, p.first, w1, p.scale)
    if n == 1:
        return gpath - off[:-1], float(ub), len(cn), 0
    ub_eff = ub + 1e-9 * (1.0 + abs(ub))
    if tolerance > 0.0:
        ub_eff = ub - tolerance * float(np.min(u[:off[1]] + h[:off[1]]))
    path, cost, kept, n_dist = _forward(cn, off, u, h, p.nxt, p.prv, p.last, p.first, w1,
                                        p.scale, ub_eff, pos)
    if path[0] < 0:
        # With a tolerance: nothing beats the greedy sequence by more than it (see
        # above). Without one this cannot happen (the greedy sequence is kept).
        if tolerance == 0.0:
            log.warning("exact search kept no complete sequence; returning the greedy one")
        return gpath - off[:-1], float(ub), kept, n_dist
    return path - off[:-1], float(cost), kept, n_dist + len(cn)



def lower_bound(p: Problem) -> float:
    """A lower bound of the optimal cost of ``p`` (<= OPT): the relaxed backward costs'
    least over the first layer, ``LB`` of :func:`exact_layers`. O(N), no search."""
    pos = np.full(p.graph.n_nodes, -1, dtype=np.int64)
    h = _relaxed_backward(p.cn, p.off, p.u, p.nxt, p.last, p.first, float(p.weights.w_jump),
                          p.scale, pos)
    return float(np.min(p.u[:p.off[1]] + h[:p.off[1]]))


@kernel()
def _relaxed_backward(cn, off, u, nxt, last, first, w1, scale, pos):  # pragma: no cover
    n = len(off) - 1
    h = np.zeros(len(cn))
    for i in range(n - 2, -1, -1):
        lo1, hi1 = off[i + 1], off[i + 2]
        m = np.inf
        for q in range(lo1, hi1):
            v = u[q] + h[q]
            if v < m:
                m = v
            pos[cn[q]] = q
        for p in range(off[i], off[i + 1]):
            best = w1 + m
            j = nxt[cn[p]]
            if j >= 0:
                q = pos[j]
                if q >= 0:
                    v = scale * row_dist(last, cn[p], first, j) + u[q] + h[q]
                    if v < best:
                        best = v
            h[p] = best
        for q in range(lo1, hi1):
            pos[cn[q]] = -1
    return h


@kernel()
def _greedy(cn, off, u, h, nxt, last, first, w1, scale):  # pragma: no cover
    n = len(off) - 1
    path = np.empty(n, dtype=np.int64)
    best = np.inf
    qb = off[0]
    for q in range(off[0], off[1]):
        v = u[q] + h[q]
        if v < best:
            best = v
            qb = q
    path[0] = qb
    cost = u[qb]
    for i in range(n - 1):
        a = cn[path[i]]
        best = np.inf
        tb = 0.0
        qb = off[i + 1]
        # The consecutive successor first: its value then spares the distances of the
        # jumps that cannot beat it (w1 + u + h >= best); the value chosen is the same.
        for q in range(off[i + 1], off[i + 2]):
            if cn[q] == nxt[a]:
                tb = scale * row_dist(last, a, first, cn[q])
                best = tb + u[q] + h[q]
                qb = q
                break
        for q in range(off[i + 1], off[i + 2]):
            b = cn[q]
            if nxt[a] == b or w1 + u[q] + h[q] >= best:
                continue
            t = scale * row_dist(last, a, first, b) + w1
            v = t + u[q] + h[q]
            if v < best:
                best = v
                qb = q
                tb = t
        path[i + 1] = qb
        cost += tb + u[qb]
    return path, cost



@kernel()
def _prepare_layer(cn, lo, hi, lo1, hi1, D, u, h, last, w1, scale, ub,
                   pos):  # pragma: no cover
    """The kept states of layer [lo, hi) as a k-d tree over their last frames, weighted
    by D; ``pos[node]`` set to each kept state (for the consecutive test)."""
    npc = last.shape[1]
    m = 0
    for q in range(lo, hi):
        if D[q] < np.inf:
            m += 1
    alive = np.empty(m, dtype=np.int64)
    xa = np.empty((m, npc))
    da = np.empty(m)
    k = 0
    dmin = np.inf
    for q in range(lo, hi):
        if D[q] < np.inf:
            alive[k] = q
            pos[cn[q]] = q
            da[k] = D[q]
            if D[q] < dmin:
                dmin = D[q]
            for j in range(npc):
                xa[k, j] = last[cn[q], j]
            k += 1
    n_query = 0
    for q in range(lo1, hi1):
        if w1 + dmin <= ub - h[q] - u[q]:
            n_query += 1
    # A k-d tree pays off when many states query it; else one leaf in ascending D.
    leaf = LEAF if n_query > 8 * np.log2(m + 1) else max(m, 1)
    perm, start, end, left, right, tlo, thi, mind = build_tree(xa, da, leaf)
    xs, ds, ids = xa[perm], da[perm], alive[perm]
    if leaf == LEAF:
        n_kept = _drop_dominated(xs, ds, ids, start, end, left, right, tlo, thi, mind, scale)
        if n_kept < _REBUILD * m:  # a smaller tree over the states that remain
            sel = np.empty(n_kept, dtype=np.int64)
            k = 0
            for node in range(len(start)):
                if left[node] < 0:
                    for r in range(start[node], end[node]):
                        sel[k] = r
                        k += 1
            xs, ds, ids = xs[sel], ds[sel], ids[sel]
            perm, start, end, left, right, tlo, thi, mind = build_tree(xs, ds, leaf)
            xs, ds, ids = xs[perm], ds[perm], ids[perm]
    return (alive, xs, ds, ids, start, end, left, right, tlo, thi, mind, n_query)


@kernel()
def _drop_dominated(xs, ds, ids, start, end, left, right, lo, hi, mind,
                    scale):  # pragma: no cover
    """Remove from the tree's leaves the states that cannot be the best jump source.

    State r is dominated by a if ``D(a) + s ||x_a - x_r|| < D(r)`` (by a margin): by the
    triangle inequality ``D(a) + s ||x_a - y|| < D(r) + s ||x_r - y||`` for every y, so
    the least jump cost into any state is the same without r (a chain of dominations
    ends at a state that is kept). Checked among near neighbours only (subtrees of at
    most ``_DOMINANCE_RANGE`` points); leaves are compacted and bounds recomputed.
    """
    n_nodes = len(start)
    npc = xs.shape[1]
    keep = np.ones(len(ds), dtype=np.bool_)
    stack = np.empty(n_nodes + 1, dtype=np.int64)
    stack[0] = 0
    sp = 1
    while sp > 0:
        sp -= 1
        node = stack[sp]
        s, e = start[node], end[node]
        if e - s > _DOMINANCE_RANGE:
            if left[node] >= 0:
                stack[sp] = left[node]
                stack[sp + 1] = right[node]
                sp += 2
            continue
        for r in range(s, e):
            margin = 1e-9 * (1.0 + abs(ds[r]))
            for a in range(s, e):
                if a == r or not keep[a] or ds[a] >= ds[r] - margin:
                    continue
                room = (ds[r] - margin - ds[a]) / scale if scale > 0.0 else np.inf
                d2 = 0.0
                for j in range(npc):
                    t = xs[a, j] - xs[r, j]
                    d2 += t * t
                if d2 < room * room:
                    keep[r] = False
                    break
    for node in range(n_nodes - 1, -1, -1):
        if left[node] < 0:
            k = start[node]
            for r in range(start[node], end[node]):
                if keep[r]:
                    if k != r:
                        ds[k] = ds[r]
                        ids[k] = ids[r]
                        for j in range(npc):
                            xs[k, j] = xs[r, j]
                        keep[k] = True
                    k += 1
            end[node] = k
            for j in range(npc):
                lo[node, j] = np.inf
                hi[node, j] = -np.inf
            mind[node] = np.inf
            for r in range(start[node], end[node]):
                if ds[r] < mind[node]:
                    mind[node] = ds[r]
                for j in range(npc):
                    lo[node, j] = min(lo[node, j], xs[r, j])
                    hi[node, j] = max(hi[node, j], xs[r, j])
        else:
            l, rr = left[node], right[node]
            mind[node] = min(mind[l], mind[rr])
            for j in range(npc):
                lo[node, j] = min(lo[l, j], lo[rr, j])
                hi[node, j] = max(hi[l, j], hi[rr, j])
    n_kept = 0
    for node in range(n_nodes):
        if left[node] < 0:
            n_kept += end[node] - start[node]
    return n_kept


@kernel()
def _query_layer(cn, q_from, q_to, D, pred, u, h, prv, last, first, w1, scale, ub, pos,
                 xs, ds, ids, start, end, left, right, tlo, thi, mind):  # pragma: no cover
    """D and pred of the states [q_from, q_to) of the next layer; returns distances."""
    npc = last.shape[1]
    y = np.empty(npc)
    stack = np.empty(256, dtype=np.int64)
    bounds = np.empty(256)
    n_dist = 0
    has_tree = len(ds) > 0
    for q in range(q_from, q_to):
        b = cn[q]
        thr = ub - h[q] - u[q]
        best = np.inf
        arg = -1
        pb = prv[b]
        if pb >= 0:
            qa = pos[pb]
            if qa >= 0:
                best = D[qa] + scale * row_dist(last, pb, first, b)
                arg = qa
                n_dist += 1
        if has_tree and w1 + mind[0] < best and w1 + mind[0] <= thr:
            for j in range(npc):
                y[j] = first[b, j]
            v, r, nd = query(xs, ds, start, end, left, right, tlo, thi, mind, y, w1, scale,
                              best, thr, stack, bounds)
            n_dist += nd
            if r >= 0:
                best = v
                arg = ids[r]
        if best <= thr:
            D[q] = best + u[q]
            pred[q] = arg
    return n_dist


def _forward(cn, off, u, h, nxt, prv, last, first, w1, scale, ub, pos):
    """Pruned forward DP (see :func:`exact_layers`): (flat path, cost, kept, distances)."""
    n = len(off) - 1
    D = np.full(len(cn), np.inf)
    pred = np.full(len(cn), -1, dtype=np.int64)
    keep0 = u[:off[1]] + h[:off[1]] <= ub
    D[:off[1]][keep0] = u[:off[1]][keep0]
    kept = int(keep0.sum())
    n_dist = 0
    for i in range(n - 1):
        lo, hi, lo1, hi1 = off[i], off[i + 1], off[i + 1], off[i + 2]
        (alive, xs, ds, ids, start, end, left, right, tlo, thi, mind,
         n_query) = _prepare_layer(cn, lo, hi, lo1, hi1, D, u, h, last, w1, scale, ub,
                                    pos)
        if len(alive) == 0:
            break
        args = (D, pred, u, h, prv, last, first, w1, scale, ub, pos, xs, ds, ids, start, end,
                left, right, tlo, thi, mind)
        n_dist += _run_queries(cn, lo1, hi1, n_query, args)
        pos[cn[alive]] = -1
        kept += int(np.count_nonzero(D[lo1:hi1] < np.inf))
    last_layer = D[off[n - 1]:off[n]]
    q = int(np.argmin(last_layer))
    if not np.isfinite(last_layer[q]):
        return np.full(n, -1, dtype=np.int64), np.inf, kept, n_dist
    path = np.empty(n, dtype=np.int64)
    qb = off[n - 1] + q
    for i in range(n - 1, -1, -1):
        path[i] = qb
        qb = pred[qb]
    return path, float(last_layer[q]), kept, n_dist


def _run_queries(cn, lo1, hi1, n_query, args) -> int:
    """The queries of one layer, split over threads when there are many (numba releases
    the GIL)."""
    threads = usable_cpus(8)  # the CPUs this process may use, at most 8
    if threads == 1 or n_query < _PARALLEL_MIN:
        return _query_layer(cn, lo1, hi1, *args)
    cuts = np.linspace(lo1, hi1, threads + 1).astype(np.int64)
    futures = [thread_pool(threads).submit(_query_layer, cn, int(a), int(b), *args)
               for a, b in zip(cuts[:-1], cuts[1:], strict=True)]
    return sum(f.result() for f in futures)
