"""The audio cost C_audio of Eq. 5 over the paper's prosody curves or, beyond the paper,
over phone posteriorgrams.

* ``"plp"`` (the paper, §4.2): DTW of RASTA-PLP curves, Euclidean local distance.
* ``"posteriorgram"``: DTW of phone posteriorgrams (:mod:`ingest.speech.posteriorgram`)
  with the local distance ``-log(p . q)`` (Hazen, Shen & White 2009; Zhang & Glass
  2009), the standard speaker- and language-robust matcher of query-by-example spoken
  term detection. Needs a database ingested with hama installed.
* ``"plp+posteriorgram"``: the mean of the two, each divided by its median over the
  phone's candidates first, so that neither scale dominates (the two costs are in
  different units: Euclidean PLP distance and nats).
"""

from __future__ import annotations

import numpy as np

from animegraph.search.dtw import audio_costs_many
from db.errors import DataError, ParameterError

#: The audio costs :func:`candidate_costs` computes; the first is the paper's.
AUDIO_COSTS = ("plp", "posteriorgram", "plp+posteriorgram")
#: Where candidates come from: the recognised phone's animes (the paper's a_i.P = sn_i.P,
#: §4.2), or those and the animes of the phones its posteriorgram makes likely.
CANDIDATE_SOURCES = ("label", "likely")
#: ``"likely"``: the phones of the :data:`LIKELY_PHONES` largest mean posteriors over
#: the input phone's frames join its own.
LIKELY_PHONES = 3


def check_audio_cost(name: object) -> str:
    """``name`` if it is one of :data:`AUDIO_COSTS`, else ParameterError."""
    if not isinstance(name, str) or name not in AUDIO_COSTS:
        raise ParameterError(f"audio cost must be one of {', '.join(AUDIO_COSTS)}, got {name!r}")
    return name


def needs_posteriorgram(name: str) -> bool:
    """True if the audio cost ``name`` reads posteriorgrams."""
    return "posteriorgram" in check_audio_cost(name)


def require_posteriorgrams(graph, root) -> None:
    """DataError (one line) unless the graph holds per-anime posteriorgrams."""
    if graph.posterior_values is None:
        raise DataError(f"database {root} has no phone posteriorgrams (it was ingested without "
                        "them, the default, or without hama): re-ingest it with "
                        "'animegraph ingest --posteriorgrams', or use the paper's audio cost "
                        "(--audio-cost plp)")


def candidate_costs(graph, phones, nodes, audio_cost: str = "plp") -> list[np.ndarray]:
    """C_audio of every input phone against its candidate nodes.

    Parameters
    ----------
    graph : animegraph.search.AnimeGraph
    phones : sequence of animegraph.synthesis.Phone
        With ``posteriors`` set when ``audio_cost`` reads posteriorgrams.
    nodes : sequence of np.ndarray of int
        ``nodes[i]``: the candidates of phone ``i``.
    audio_cost : str
        One of :data:`AUDIO_COSTS`.

    Returns
    -------
    list of np.ndarray of float64, shapes (len(nodes[i]),)
    """
    check_audio_cost(audio_cost)
    out = {}
    if audio_cost in ("plp", "plp+posteriorgram"):
        out["plp"] = audio_costs_many([p.prosody.astype(np.float32) for p in phones],
                                      graph.prosody_values, graph.prosody_offsets, nodes)
    if needs_posteriorgram(audio_cost):
        if graph.posterior_values is None:
            raise DataError("the database has no phone posteriorgrams")
        if any(p.posteriors is None for p in phones):
            raise ParameterError("the input phones have no posteriorgrams")
        out["post"] = audio_costs_many([p.posteriors for p in phones], graph.posterior_values,
                                       graph.posterior_offsets, nodes, metric="neglog-dot")
    if len(out) == 1:
        return next(iter(out.values()))
    return [0.5 * (_by_median(a) + _by_median(b)) for a, b in zip(out["plp"], out["post"],
                                                                     strict=True)]


def likely_candidates(graph, phones, cands, top: int = LIKELY_PHONES):
    """Candidates widened to the phones each input's posteriorgram makes likely.

    Recognised phones are often wrong (phone error rate 0.4-0.6 on real speech,
    docs/results/segmentation.md, "Recognition from the audio alone"), and the paper's matching
    constraint a_i.P = sn_i.P then offers only
    animes of the wrong phone. As spoken term detection searches a recogniser's N-best
    hypotheses rather than its single best (e.g. the phone lattices of Can & Saraclar
    2011, "Lattice indexing for spoken term detection", IEEE TASLP), each input phone
    here also takes the animes of the ``top`` phones of largest mean posterior over its
    frames; the posteriorgram cost then ranks them all. Silence keeps its own.

    Parameters
    ----------
    graph : animegraph.search.AnimeGraph
    phones : sequence of animegraph.synthesis.Phone
        With ``posteriors``.
    cands : animegraph.search.Candidates
        The label candidates (:func:`animegraph.search.candidates`).
    top : int

    Returns
    -------
    animegraph.search.Candidates
        ``nodes[i]`` the union, ascending; everything else as ``cands``.
    """
    from dataclasses import replace

    from ingest.speech.phones import PHONES
    from ingest.speech.posteriorgram import PHONE_COLUMNS

    nodes = []
    for phone, own in zip(phones, cands.nodes, strict=True):
        if phone.phone == "SIL" or phone.posteriors is None:
            nodes.append(own)
            continue
        mean = np.asarray(phone.posteriors, dtype=np.float64).mean(axis=0)
        likely = [PHONES.index(PHONE_COLUMNS[k]) for k in np.argsort(-mean)[:top]]
        nodes.append(np.unique(np.concatenate([own, *(graph.by_phone[p] for p in likely)])))
    return replace(cands, nodes=tuple(nodes))


def _by_median(costs: np.ndarray) -> np.ndarray:
    scale = float(np.median(costs)) if len(costs) else 1.0
    return costs / scale if scale > 0 else costs
