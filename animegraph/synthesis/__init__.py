"""Speech in, facial motion out: the synthesis pipeline (Cao et al. 2005, §4.2-4.3, §5.2).

* :mod:`.model` -- :class:`Model`, what synthesis needs from a database, loaded once;
* :mod:`.pipeline` -- :func:`synthesize`: phones and prosody of the input speech, the
  search, the motion, its emotion;
* :mod:`.assemble` -- from an anime sequence to continuous motion: time-warping,
  blending at jumps, smoothing, and k-best blending (beyond the paper);
* :mod:`.result` -- :class:`Synthesis`, what :func:`synthesize` returns;
* :mod:`.explain` -- the ``--explain`` record: where each phone's motion came from;
* :mod:`.output` -- a synthesis written to a motion file, a motion file read in a
  database's channels.

Imports: ``db``, ``ingest``, and of ``animegraph`` only :mod:`animegraph.search`,
:mod:`animegraph.emotion` and :mod:`animegraph.motion`.
"""

from animegraph.synthesis.assemble import (
    HELPER_MODES,
    Phone,
    PostOptions,
    blend_k_best,
    rank_weights,
    warp_positions,
)
from animegraph.synthesis.explain import backoffs, explain_record, write_explain
from animegraph.synthesis.model import Model, to_world
from animegraph.synthesis.output import read_database_motion, write_motion
from animegraph.synthesis.pipeline import (
    check_not_silent,
    map_emotion,
    query_phones,
    recentres,
    render_k_best,
    render_nodes,
    score_candidates,
    synthesize,
)
from animegraph.synthesis.result import Synthesis

__all__ = [
    "HELPER_MODES", "Model", "Phone", "PostOptions", "Synthesis", "backoffs", "blend_k_best",
    "check_not_silent", "explain_record", "map_emotion", "query_phones", "rank_weights",
    "read_database_motion", "recentres", "render_k_best", "render_nodes", "score_candidates",
    "synthesize", "to_world", "warp_positions", "write_explain", "write_motion",
]
