"""A k-d tree for the additively weighted nearest neighbour of the exact search.

The jump part of the exact search's recursion (:func:`animegraph.search.exact.exact_layers`)
asks, for each state ``b`` of a layer, for ``min_a w1 + D(a) + s ||x_a - y_b||`` over the
kept states ``a`` of the previous layer, below a threshold: a nearest neighbour in which
every point carries its own additive weight ``D(a)``.

Why it is written here rather than taken from :class:`scipy.spatial.cKDTree`: cKDTree
answers unweighted k-nearest and ball queries only. The weighted query would need
either ever larger k-nearest queries until the k-th distance plus the least weight
passes the best value (no bound on the work), or one query per distinct weight. This
tree keeps, per node, its bounding box *and the least weight below it*, so a subtree is
skipped as soon as ``w1 + min D + s * box distance`` reaches the best value or the
keep threshold; leaves are scanned in ascending weight with an early exit. Its kernels
are numba ``nogil`` functions, so a layer's queries run on several threads, which
cKDTree's per-call GIL release does not give for millions of tiny queries.
"""

from __future__ import annotations

import numpy as np

from animegraph.search.jit import kernel

#: Points per leaf of the k-d tree over the kept states of a layer.
LEAF = 16


@kernel()
def _select(perm, x, dim, s, e, kth):  # pragma: no cover
    """Reorder ``perm[s:e]`` so that ``perm[kth]`` holds the point of rank ``kth - s`` along
    ``dim``, smaller ones before it and larger ones after (quickselect)."""
    lo, hi = s, e - 1
    while hi > lo:
        mid = (lo + hi) // 2
        # Median of three as the pivot, moved to hi.
        a, b, c = x[perm[lo], dim], x[perm[mid], dim], x[perm[hi], dim]
        if (a <= b <= c) or (c <= b <= a):
            piv = mid
        elif (b <= a <= c) or (c <= a <= b):
            piv = lo
        else:
            piv = hi
        perm[piv], perm[hi] = perm[hi], perm[piv]
        pv = x[perm[hi], dim]
        store = lo
        for t in range(lo, hi):
            if x[perm[t], dim] < pv:
                perm[store], perm[t] = perm[t], perm[store]
                store += 1
        perm[store], perm[hi] = perm[hi], perm[store]
        if store == kth:
            return
        if store < kth:
            lo = store + 1
        else:
            hi = store - 1


@kernel()
def _sort_by(perm, key, s, e):  # pragma: no cover
    """Sort ``perm[s:e]`` by ``key[perm]`` ascending (insertion sort for a leaf, else heap
    sort; numba compiles these far faster than ``np.argsort``)."""
    n = e - s
    if n <= 32:
        for i in range(s + 1, e):
            p = perm[i]
            k = key[p]
            j = i - 1
            while j >= s and key[perm[j]] > k:
                perm[j + 1] = perm[j]
                j -= 1
            perm[j + 1] = p
        return
    for root in range(n // 2 - 1, -1, -1):
        _sift(perm, key, s, root, n)
    for end in range(n - 1, 0, -1):
        perm[s], perm[s + end] = perm[s + end], perm[s]
        _sift(perm, key, s, 0, end)


@kernel()
def _sift(perm, key, s, root, n):  # pragma: no cover
    while True:
        child = 2 * root + 1
        if child >= n:
            return
        if child + 1 < n and key[perm[s + child + 1]] > key[perm[s + child]]:
            child += 1
        if key[perm[s + child]] > key[perm[s + root]]:
            perm[s + root], perm[s + child] = perm[s + child], perm[s + root]
            root = child
        else:
            return


@kernel()
def build_tree(x, d, leaf):  # pragma: no cover
    """k-d tree over points ``x`` (m, k) weighted by ``d`` (m,); leaves sorted by ``d``.

    Returns the permutation of the points, and per tree node: [start, end) into the
    permuted points, children (-1 at a leaf), bounding box and least weight. With
    ``leaf >= m`` the tree is a single leaf: every point in ascending weight.
    """
    m, k = x.shape
    size = 4 * (m // leaf + 1) + 1
    perm = np.arange(m)
    start = np.empty(size, dtype=np.int64)
    end = np.empty(size, dtype=np.int64)
    left = np.full(size, -1, dtype=np.int64)
    right = np.full(size, -1, dtype=np.int64)
    lo = np.empty((size, k))
    hi = np.empty((size, k))
    mind = np.empty(size)
    stack = np.empty(size, dtype=np.int64)
    start[0], end[0] = 0, m
    nn = 1
    stack[0] = 0
    sp = 1
    while sp > 0:
        sp -= 1
        node = stack[sp]
        s, e = start[node], end[node]
        for j in range(k):
            lo[node, j] = np.inf
            hi[node, j] = -np.inf
        md = np.inf
        for t in range(s, e):
            i = perm[t]
            if d[i] < md:
                md = d[i]
            for j in range(k):
                v = x[i, j]
                if v < lo[node, j]:
                    lo[node, j] = v
                if v > hi[node, j]:
                    hi[node, j] = v
        mind[node] = md
        if e - s > leaf:
            dim = 0
            spread = -1.0
            for j in range(k):
                if hi[node, j] - lo[node, j] > spread:
                    spread = hi[node, j] - lo[node, j]
                    dim = j
            if spread > 0.0:
                mid = (s + e) // 2
                _select(perm, x, dim, s, e, mid)
                left[node], right[node] = nn, nn + 1
                start[nn], end[nn] = s, mid
                start[nn + 1], end[nn + 1] = mid, e
                stack[sp], stack[sp + 1] = nn, nn + 1
                sp += 2
                nn += 2
                continue
        _sort_by(perm, d, s, e)  # a leaf: by ascending weight
    return perm, start[:nn], end[:nn], left[:nn], right[:nn], lo[:nn], hi[:nn], mind[:nn]


@kernel()
def _box_dist(lo, hi, node, y):  # pragma: no cover
    s = 0.0
    for j in range(y.shape[0]):
        t = max(lo[node, j] - y[j], 0.0) + max(y[j] - hi[node, j], 0.0)  # branch-free
        s += t * t
    return np.sqrt(s)


@kernel()
def query(xs, ds, start, end, left, right, lo, hi, mind, y, w1, scale, best, thr,
           stack, bounds):  # pragma: no cover
    """Least ``w1 + ds[r] + scale * ||xs[r] - y||`` below ``min(best, thr)``, branch and
    bound over the tree: (value, row or -1, distances evaluated)."""
    arg = -1
    n_dist = 0
    b0 = w1 + mind[0] + scale * _box_dist(lo, hi, 0, y)
    if b0 >= best or b0 > thr:
        return best, arg, n_dist
    stack[0] = 0
    bounds[0] = b0
    sp = 1
    npc = y.shape[0]
    while sp > 0:
        sp -= 1
        node = stack[sp]
        if bounds[sp] >= best or bounds[sp] > thr:
            continue
        if left[node] < 0:
            for r in range(start[node], end[node]):
                base = w1 + ds[r]
                if base >= best or base > thr:
                    break
                lim = best if best < thr else thr
                if scale > 0.0:
                    room = (lim - base) / scale
                    room2 = room * room
                    s = 0.0
                    for j in range(npc):
                        t = xs[r, j] - y[j]
                        s += t * t
                    n_dist += 1
                    if s > room2:
                        continue
                    v = base + scale * np.sqrt(s)
                else:
                    v = base
                if v < best:
                    best = v
                    arg = r
            continue
        l, rr = left[node], right[node]
        bl = w1 + mind[l] + scale * _box_dist(lo, hi, l, y)
        br = w1 + mind[rr] + scale * _box_dist(lo, hi, rr, y)
        if bl <= br:  # push the worse child first: the better one is explored first
            first_n, first_b, second_n, second_b = rr, br, l, bl
        else:
            first_n, first_b, second_n, second_b = l, bl, rr, br
        if first_b < best and first_b <= thr:
            stack[sp] = first_n
            bounds[sp] = first_b
            sp += 1
        if second_b < best and second_b <= thr:
            stack[sp] = second_n
            bounds[sp] = second_b
            sp += 1
    return best, arg, n_dist
