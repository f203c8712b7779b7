"""The Anime Graph and its search (Cao et al. 2005, §4.1-4.2).

What the room holds, one module each:

* :mod:`.graph` -- the Anime Graph loaded from a database (anime nodes, their links);
* :mod:`.dtw` -- dynamic time warping of prosody curves (C_audio, Eq. 5) and warp paths;
* :mod:`.problem` -- the search request: weights (Eq. 2), candidates of each input phone
  with viseme back-off, the cost of a sequence, the flat arrays every solver uses;
* :mod:`.solve` -- :func:`search`, which runs one of the solvers
  :mod:`.exact` (default; its k-d tree in :mod:`.kdtree`), :mod:`.paper` (the paper's
  priority queue), :mod:`.window` (its bounded look-ahead) and :mod:`.dp` (the oracle);
* :mod:`.shortlist` -- k-best's candidates cut to each phone's first N by its ranking
  (beyond the paper), the audio cost computed where a lower bound cannot rule it out.

Imports: ``db`` and ``ingest`` only -- nothing else of ``animegraph``.
"""

from animegraph.search.graph import AnimeGraph
from animegraph.search.problem import (
    METHODS,
    Candidates,
    PathCost,
    SearchResult,
    SearchWeights,
    candidates,
    k_best,
    path_cost,
)
from animegraph.search.solve import search

__all__ = [
    "METHODS", "AnimeGraph", "Candidates", "PathCost", "SearchResult", "SearchWeights",
    "candidates", "k_best", "path_cost", "search",
]
