"""The search itself (§4.2): validate a request, build its :class:`Problem`, run a solver.

Solvers (:func:`search`, ``method=``), one module each:

``"exact"`` (default, :mod:`.exact`)
    The global optimum, fast: a forward dynamic program over the chain of candidate
    layers, pruned with an admissible backward bound and an upper bound from a feasible
    sequence, with a k-d tree (:mod:`.kdtree`) for the jump transitions; provably equal
    to the optimum of ``"dp"``.
``"paper"`` (:mod:`.paper`)
    The paper's Priority-Queue (branch and bound) algorithm, steps (1)–(4), with an
    expansion cap.
``"window"`` (:mod:`.window`)
    The paper's bounded look-ahead: optimise the current phone and ``window`` phones
    ahead, commit the current one, slide.
``"dp"`` (:mod:`.dp`)
    A plain Viterbi over all candidate pairs, O(Σ |C_i| |C_i+1|): the tests' oracle.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np

from animegraph.search.dp import dp
from animegraph.search.exact import exact, lower_bound
from animegraph.search.graph import AnimeGraph
from animegraph.search.paper import paper
from animegraph.search.problem import (
    METHODS,
    Candidates,
    Problem,
    SearchResult,
    SearchWeights,
)
from animegraph.search.window import window_search
from db.errors import ParameterError

log = logging.getLogger(__name__)

def search(graph: AnimeGraph, cands: Candidates, audio: Sequence[np.ndarray], *,
           weights: SearchWeights | None = None, emotion: str | None = None,
           method: str = "exact", window: int | None = None, tolerance: float = 0.0,
           max_expansions: int = 2_000_000, max_queue: int = 20_000_000) -> SearchResult:
    """Find the matching anime sequence of least cost (Eq. 2, §4.2).

    Parameters
    ----------
    graph : AnimeGraph
    cands : Candidates
        From :func:`candidates`, n >= 1 inputs.
    audio : sequence of np.ndarray
        ``audio[i]``, shape (len(cands.nodes[i]),), finite and >= 0: C_audio (Eq. 5) of
        input ``i`` against each of its candidates.
    weights : SearchWeights, optional
        Defaults to the paper's w1, w2, w3 = 100, 1, 0.01.
    emotion : str, optional
        The input's emotion E (soft preference); None uses ``cands.emotion``.
    method : {"exact", "paper", "window", "dp"}
        See the module docstring.
    window : int, optional
        ``method="window"`` only (required there): phones looked ahead of the current one
        (the paper: 3–6).
    tolerance : float, optional
        ``method="exact"`` only: accept a sequence whose cost is within this fraction of
        the optimum (0, the default: the optimum itself). The search then keeps only
        states that could beat the greedy upper bound by more than ``tolerance`` times
        a lower bound of the optimum, and returns the greedy sequence when none does; the
        result is certified: ``cost <= (1 + tolerance) * optimum``. Beyond the paper: on
        graphs of many near-identical recordings (near-ties the bounds cannot separate)
        it prunes most of the work.
    max_expansions : int
        ``method="paper"``: queue nodes expanded before the search stops (capped).
    max_queue : int
        ``method="paper"``: queue size (memory: 24 B a node) before the search stops.

    Returns
    -------
    SearchResult

    Raises
    ------
    ParameterError
        On an unknown method, a missing or invalid window, audio costs of the wrong shape
        or negative / non-finite, or a problem too large for ``method="dp"``.
    """
    weights = weights or SearchWeights()
    if method not in METHODS:
        raise ParameterError(f"method must be one of {METHODS}, got {method!r}")
    if method == "window":
        if window is None or isinstance(window, bool) or not isinstance(window, int | np.integer) \
                or window < 1:
            raise ParameterError(f"window must be an int >= 1 for method='window', got {window!r}")
    elif window is not None:
        raise ParameterError(f"window is only used by method='window', got window={window!r} "
                             f"with method={method!r}")
    if not isinstance(tolerance, int | float | np.floating) or not 0.0 <= tolerance < 1.0:
        raise ParameterError(f"tolerance must be a number in [0, 1), got {tolerance!r}")
    if tolerance and method != "exact":
        raise ParameterError(f"tolerance is only used by method='exact', got method={method!r}")
    for name, value in (("max_expansions", max_expansions), ("max_queue", max_queue)):
        if not isinstance(value, int | np.integer) or value < 1:
            raise ParameterError(f"{name} must be an int >= 1, got {value!r}")
    problem = Problem.build(graph, cands, audio, weights, emotion)
    capped = False
    if method == "exact":
        idx, cost, n_exp, n_dist = exact(problem, float(tolerance))
        optimal = tolerance == 0.0
    elif method == "dp":
        idx, cost, n_exp, n_dist = dp(problem)
        optimal = True
    elif method == "window":
        idx, cost, n_exp, n_dist = window_search(problem, int(window))
        optimal = window >= len(cands) - 1  # one window spans the input: the exact search
    else:
        idx, cost, n_exp, n_dist, capped, optimal = paper(problem, int(max_expansions),
                                                           int(max_queue))
        if capped and not optimal:
            _say_capped(problem, cost, n_exp)
    br = problem.breakdown(idx)
    log.debug("search %s: n=%d cost=%.6f jumps=%d expanded=%d distances=%d", method,
              len(cands), cost, br.n_jumps, n_exp, n_dist)
    return SearchResult(
        nodes=problem.nodes_of(idx), cost=float(cost), n_jumps=br.n_jumps,
        jump_cost=br.jump_cost, audio_cost=br.audio_cost, emotion_cost=br.emotion_cost,
        backoff_cost=br.backoff_cost, n_expanded=int(n_exp), method=method, optimal=optimal,
        n_distances=int(n_dist), capped=capped, backoff=cands.backoff,
    )


def _say_capped(problem: Problem, cost: float, n_expanded: int) -> None:
    """One warning, always (it was said with -v alone): the paper's search stopped at its
    cap before a complete sequence, so its answer is a partial one completed greedily,
    which was 87 % above the optimum on a real input. The gap is bounded from above by
    the exact search's lower bound of the optimum (O(N), no search)."""
    lower = lower_bound(problem)
    gap = (f"at most {100.0 * (cost - lower) / lower:.0f} % above the optimum"
           if lower > 0 and np.isfinite(lower) else "of unknown distance from the optimum")
    log.warning("the paper's search stopped at its cap (%d expansions) before a complete "
                "sequence: its answer, a partial sequence completed greedily, costs %.4g, "
                "%s; --search exact (or --exact) finds the optimum", n_expanded, cost, gap)
