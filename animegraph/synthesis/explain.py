"""What a synthesis did, phone by phone: the ``--explain`` record.

Per input phone: the anime its motion came from (recording, position, emotion), its
audio cost (Eq. 5), whether a jump match led into it and the jump cost (Eq. 3-4), the
back-off used when the database lacks the phone, and with ``k_best`` the animes it
averages.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from animegraph.search.graph import AnimeGraph
from animegraph.synthesis.assemble import rank_weights
from animegraph.synthesis.result import Synthesis
from db.atomic import atomic_write
from ingest.speech.phones import PHONES


def blended_sources(graph: AnimeGraph, ranked: np.ndarray) -> list[dict]:
    """The animes one phone's k-best motion averages: where each came from, its weight."""
    return [{"node": int(a), "clip_id": graph.clip_ids[graph.node_clip[a]],
             "position": int(graph.position[a]), "weight": round(float(w), 4)}
            for a, w in zip(ranked, rank_weights(len(ranked)), strict=True)]


def explain_rows(model, phones, result, cands, audio_cost, target_cost=None) -> list[dict]:
    """One row per input phone: where its motion came from and what it cost (with
    ``target_cost``, the guide's too: :mod:`animegraph.synthesis.guide`)."""
    g = model.graph
    rows = []
    for i, (p, node) in enumerate(zip(phones, result.nodes, strict=True)):
        node = int(node)
        k = int(np.flatnonzero(cands.nodes[i] == node)[0])
        row = {
            "index": i, "phone": p.phone, "start": round(p.start, 4), "end": round(p.end, 4),
            "node": node, "clip_id": g.clip_ids[g.node_clip[node]],
            "anime_phone": phone_name(g, node), "position": int(g.position[node]),
            "emotion": g.emotions[g.node_emotion[node]],
            "audio_cost": float(audio_cost[i][k]),
            "backoff": cands.backoff[i],
        }
        if target_cost is not None:
            row["target_cost"] = float(target_cost[i][k])
        if i > 0:
            prev = int(result.nodes[i - 1])
            row["jump"] = bool(g.next_node[prev] != node)
            dist = np.linalg.norm(g.last_pcs[prev] - g.first_pcs[node]) / np.sqrt(g.n_channels)
            row["jump_cost"] = float(dist)
        else:
            row["jump"], row["jump_cost"] = False, 0.0
        rows.append(row)
    return rows


def phone_name(graph: AnimeGraph, node: int) -> str:
    return PHONES[int(graph.node_phone[node])]


def explain_record(synth: Synthesis) -> dict:
    """The ``--explain`` record of a synthesis: every phone's source and costs, the joins,
    the search result and the timings (what ``synth --explain-json`` and ``batch`` write)."""
    r = synth.result
    record = {"phones": synth.explain, "joins": synth.joins, "cost": r.cost,
              "n_jumps": r.n_jumps, "method": r.method, "segmentation": synth.segmentation,
              "timings": synth.timings}
    if synth.blended:
        record["k_best"] = list(synth.blended)
        record["k_best_ranking"] = "context" if synth.context_ranked else "audio cost"
        record["recentred"] = synth.recentred
        record["k_best_joins"] = "cross-faded" if synth.cross_faded else "cut"
    record["guide"] = "+".join(synth.guided) or None
    return record


def backoffs(synth: Synthesis) -> list[str]:
    """Phones the database lacks and the phone used instead, e.g. ``["ZH->SH"]``."""
    return sorted({f"{e['phone']}->{e['anime_phone']}" for e in synth.explain if e["backoff"]})


def write_explain(synth: Synthesis, path: Path, **extra) -> Path:
    """Write :func:`explain_record` (plus ``extra`` keys) as JSON, atomically."""
    record = {**extra, **explain_record(synth)}
    with atomic_write(path) as handle:
        handle.write(json.dumps(record, indent=1, default=_jsonable).encode())
    return path


def _jsonable(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, tuple):
        return list(value)
    return str(value)
