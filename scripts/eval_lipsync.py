"""Lip-sync evaluation on held-out synthetic sentences (Cao et al. §4, measured).

Usage::

    python scripts/eval_lipsync.py [--corpus DIR] [--holdout-parallel 2] [--holdout-single 6]
                                   [--json OUT] [--plot OUT.png]

Whole sentences are held out of the database (two of those spoken in all five emotions
and six single-emotion ones by default): the database is built from the rest, then each
held-out clip is synthesized from its audio and its phone labels, in its emotion, and
compared with its recorded (ground-truth) motion in the database's head-stabilised
space. Methods: exact search, the paper's windowed search (K = 3 and 6), and two naive
baselines (a random anime of the right phoneme per phone; always the first anime of the
phoneme, ignoring every cost). Printed: RMSE over the face (mm), RMSE over the lips,
lip vertex error (mm), Pearson R of mouth opening, jumps, search time.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from animegraph import evaluate
from animegraph.search import search
from animegraph.synth import Model, query_phones, render_nodes, score_candidates
from ingest.corpus.synthetic import CorpusConfig, generate_corpus
from ingest.formats.c3d import read_c3d
from ingest.formats.phones_csv import read_phones_csv
from ingest.formats.wav import read_wav
from ingest.motion import fill_gaps, stabilize_points
from ingest.pipeline import ingest

METHODS = ("exact", "window3", "window6", "random", "first")


def split(corpus: Path, n_parallel: int, n_single: int) -> tuple[set[str], list[Path]]:
    """Held-out sentence ids and their clip stems."""
    meta = json.loads((corpus / "corpus.json").read_text())
    parallel = meta["parallel_sentences"]
    clips = sorted((corpus / "clips").glob("*.json"))
    sentences = sorted({json.loads(p.read_text())["sentence_id"] for p in clips})
    singles = [s for s in sentences if s not in parallel]
    held = set(parallel[-n_parallel:] if n_parallel else []) | set(singles[-n_single:])
    stems = [p.with_suffix("") for p in clips if json.loads(p.read_text())["sentence_id"] in held]
    return held, stems


def training_corpus(corpus: Path, held: set[str], out: Path) -> Path:
    """A corpus folder of hard links to every clip not held out."""
    target = out / corpus.name
    (target / "clips").mkdir(parents=True)
    for name in ("corpus.json", "markers.csv"):
        os.link(corpus / name, target / name)
    for meta in (corpus / "clips").glob("*.json"):
        if json.loads(meta.read_text())["sentence_id"] in held:
            continue
        stem = meta.name[: -len(".json")]
        for f in (corpus / "clips").glob(f"{stem}.*"):
            os.link(f, target / "clips" / f.name)
    return target


def evaluate_clip(model: Model, stem: Path, rng: np.random.Generator) -> dict:
    audio, sr = read_wav(stem.with_suffix(".wav"))
    labels = read_phones_csv(Path(f"{stem}.phones.csv"))
    emotion = json.loads(Path(f"{stem}.json").read_text())["emotion"]
    phones, _ = query_phones(audio, sr, labels=labels)
    cands, audio_cost = score_candidates(model, phones, emotion=emotion)
    truth_raw = read_c3d(stem.with_suffix(".c3d")).points.reshape(-1, len(model.names))
    truth, missing = fill_gaps(truth_raw, model.names)
    truth = stabilize_points(truth, model.groups, model.head_reference)
    truth[missing] = np.nan
    face = np.array([i for i, g in enumerate(model.groups) if g != "head"])
    lips = evaluate.lip_channels(model.names, model.groups)
    mouth_truth = evaluate.mouth_opening(truth, model.names, model.kind)
    rows = {}
    for method in METHODS:
        t0 = time.perf_counter()
        if method in ("random", "first"):
            nodes = evaluate.baseline_nodes(cands.nodes, method, rng)
            jumps = int(np.sum(model.graph.next_node[nodes[:-1]] != nodes[1:]))
        else:
            window = int(method[-1]) if method.startswith("window") else None
            result = search(model.graph, cands, audio_cost, emotion=emotion,
                            method="window" if window else "exact", window=window)
            nodes, jumps = result.nodes, result.n_jumps
        search_s = time.perf_counter() - t0
        ics, _ = render_nodes(model, phones, nodes, emotion=emotion)
        pred = model.decomposer.inverse_transform(ics)  # head-stabilised, like ``truth``
        rows[method] = {
            "rmse_face_mm": evaluate.rmse(pred, truth, face),
            "rmse_lips_mm": evaluate.rmse(pred, truth, lips),
            "lve_mm": evaluate.lip_vertex_error(pred, truth, model.names, model.groups),
            "mouth_r": evaluate.pearson(
                evaluate.mouth_opening(pred, model.names, model.kind), mouth_truth),
            "jumps": jumps, "search_s": search_s,
        }
    return {"clip": stem.name, "emotion": emotion, "n_phones": len(phones), "methods": rows}


def plot(model: Model, stem: Path, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    audio, sr = read_wav(stem.with_suffix(".wav"))
    labels = read_phones_csv(Path(f"{stem}.phones.csv"))
    emotion = json.loads(Path(f"{stem}.json").read_text())["emotion"]
    phones, _ = query_phones(audio, sr, labels=labels)
    cands, audio_cost = score_candidates(model, phones, emotion=emotion)
    truth = read_c3d(stem.with_suffix(".c3d")).points.reshape(-1, len(model.names))
    fig, ax = plt.subplots(figsize=(11, 3.5))
    t = np.arange(len(truth)) / model.graph.fps
    ax.plot(t, evaluate.mouth_opening(truth, model.names, model.kind), "k", lw=2,
            label="recorded")
    for method, style in (("exact", "C0"), ("window3", "C1"), ("random", "C3:")):
        if method == "random":
            nodes = evaluate.baseline_nodes(cands.nodes, "random", np.random.default_rng(0))
        else:
            window = 3 if method == "window3" else None
            nodes = search(model.graph, cands, audio_cost, emotion=emotion,
                           method="window" if window else "exact", window=window).nodes
        ics, joins = render_nodes(model, phones, nodes, emotion=emotion)
        pred = model.to_channels(ics)
        tt = np.arange(len(pred)) / model.graph.fps
        ax.plot(tt, evaluate.mouth_opening(pred, model.names, model.kind), style, lw=1,
                label=method)
        if method == "exact":
            for j in joins:
                ax.axvline(phones[j["index"] + 1].start, color="C0", lw=0.5, alpha=0.4)
    for p in phones:
        if p.phone != "SIL":
            ax.text((p.start + p.end) / 2, 0.02, p.phone, fontsize=6, ha="center",
                    transform=ax.get_xaxis_transform())
    ax.set_xlabel("time (s)")
    ax.set_ylabel("mouth opening (mm)")
    ax.set_title(f"held-out {stem.name}: recorded vs synthesized (thin lines: jump matches)")
    ax.legend(fontsize=7, ncol=4)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--corpus", type=Path, help="synthetic corpus (default: generate one)")
    parser.add_argument("--holdout-parallel", type=int, default=2)
    parser.add_argument("--holdout-single", type=int, default=6)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--json", type=Path)
    parser.add_argument("--plot", type=Path)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        corpus = args.corpus
        if corpus is None:
            corpus = tmp / "corpus"
            generate_corpus(corpus, CorpusConfig(), workers=args.workers)
        held, stems = split(corpus, args.holdout_parallel, args.holdout_single)
        train = training_corpus(corpus, held, tmp / "train")
        ingest([train], tmp / "db", workers=args.workers)
        model = Model.load(tmp / "db")
        print(f"# database: {model.graph.n_nodes} animes from "
              f"{model.db.manifest['n_clips']} clips; held out {len(held)} sentences, "
              f"{len(stems)} clips")
        rng = np.random.default_rng(0)
        results = [evaluate_clip(model, s, rng) for s in stems]
        if args.plot:
            plot(model, stems[0], args.plot)
    keys = ("rmse_face_mm", "rmse_lips_mm", "lve_mm", "mouth_r", "jumps", "search_s")
    print(f"{'method':8s} " + " ".join(f"{k:>13s}" for k in keys))
    summary = {}
    for method in METHODS:
        vals = {k: float(np.nanmean([r["methods"][method][k] for r in results])) for k in keys}
        summary[method] = vals
        print(f"{method:8s} " + " ".join(f"{vals[k]:13.3f}" for k in keys))
    if args.json:
        args.json.write_text(json.dumps({"summary": summary, "clips": results}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
