"""Lip-sync evaluation on held-out data: the Anime Graph against naive and published baselines.

Usage::

    python scripts/eval_lipsync.py [--datasets synthetic facegood talkingface grid]
                                   [--systems anime-graph mu-mlp hier-pca av-hmm]
                                   [--corpus DIR] [--json OUT] [--plots DIR]
                                   [--param av-hmm:n_states=8 ...]

Systems: ``anime-graph`` (exact and windowed search, and the naive random /
first-anime baselines), ``mu-mlp`` (Hong et al. 2002), ``hier-pca`` (Cosker et al.) and
``av-hmm`` (Terissi et al. 2013). Every fold fits each baseline on the same training clips
the fold's database is built from and scores all systems on the same held-out clips,
with the same measures plus Hong's R and MSE (Eq. 6, 8) and Terissi's AMSE and ACC
(Eq. 11-12), the training time (database build for the Anime Graph, ``fit`` for a
baseline) and the synthesis real-time factor. A baseline that cannot be fitted on a
fold (too little data) is reported and left out of that fold. ``--param
METHOD:NAME=VALUE`` sets a baseline's hyper-parameter (default: the paper's); its rows
are then labelled with it, e.g. ``av-hmm(n_mix=2,n_states=8)``.

* synthetic: whole sentences held out of the database (two of those spoken in all five
  emotions and six single-emotion ones), each held-out clip synthesized from its audio
  and its phone labels, in its emotion;
* facegood (real, animation curves, Mandarin): leave one clip out of five;
* talkingface (real, English, landmarks from video): within-speaker splits of the two
  long clips (first 70 % as the database, last 30 % synthesized) and leave one clip out
  across the other eleven (``--talkingface-splits`` picks either);
* grid (real, English, one speaker on video, with transcripts and word alignments):
  the 800 GRID s1 utterances, faces tracked (``pip install -e ".[video]"``; cached),
  split within the speaker: in clip-id order every fifth clip is held out (160), the
  other 640 are the database. The database's phones are aligned inside GRID's word
  alignments (as ingest does); the held-out clips are synthesized (a) from those phones
  and (b) from phones recognised in their audio alone (the phone engine, as for the other
  real data; ``--grid-engines hama pocketsphinx`` scores each engine's phones in the same
  run, as parts ``recognized-<engine>``, with how they agree with the aligned ones:
  ``scripts/grid_phone_engines.py``'s measures per clip, ``phones_vs_aligned``). ``--grid-db``
  reads the clips prepared by an ``animegraph ingest`` of ``grid/s1`` instead of preparing
  them again.

Every table has two reference rows (:mod:`animegraph.baselines.reference`):
``loudness``, the speech's smoothed RMS envelope mapped to every channel by least squares
on the fold's training clips, and ``mean-pose``, the training motion's mean. A method
that does not beat loudness is not lip-sync.

Talkingface and FACEGOOD clips have no transcripts: phones come from phone recognition by
the default phone engine (``ingest.speech.engines``), as at ingest; ``--phones-engine``
picks another. Held-out clips are scored one at a time and only their scores kept
(``peak_rss_mb`` in the JSON says what the process held at most). Each clip is prepared
once; every fold's database is built from prepared clips (PCA/ICA refitted without the
held-out data). Synthesized motion is compared with the
recording in the database's space (head-stabilised markers, normalised landmarks).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import resource
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
from grid_phone_engines import agreement as phone_agreement  # scripts/ is sys.path[0]

from animegraph.apps import evaluate
from animegraph.apps.plots import plot_heldout, plot_systems
from animegraph.baselines import BASELINES, METHODS, make_estimator
from animegraph.baselines.peers import PEERS
from animegraph.baselines.reference import Loudness, MeanPose
from animegraph.motion import measures
from animegraph.synthesis import Model
from animegraph.synthesis.guide import GUIDES
from db.errors import AnimeGraphError
from ingest.corpus.synthetic import CorpusConfig, generate_corpus
from ingest.pipeline import IngestConfig, build_database, prepare_sources
from ingest.prepare import slice_clip
from ingest.readers import discover
from ingest.speech.engines import ENGINES
from ingest.speech.segment import segment
from ingest.tables import prepared_from_database

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"


PLOTS: dict[str, Path] = {}
SYSTEMS: list[str] = list(METHODS)
PARAMS: dict[str, dict] = {}
#: The Anime Graph's rows (``animegraph.apps.evaluate.METHODS``; ``--graph-methods``).
GRAPH_METHODS: list[str] = list(evaluate.DEFAULT_METHODS)
#: Peer rows (``animegraph.baselines.peers``; ``--peers``).
PEER_ROWS: list[str] = []
#: The baseline guiding the ``-guided`` / ``-blend`` rows (``--guide``), if any.
GUIDE: list[str] = []
#: IngestConfig settings of every prepared clip (the phone engine).
INGEST: dict[str, object] = {}
#: The talkingface splits scored (``--talkingface-splits``).
TALKINGFACE_SPLITS: list[str] = ["within-speaker", "leave-one-clip-out"]
#: The systems plot shows the first seconds of its clip (real clips run 20-110 s).
PLOT_SECONDS = 12.0


def label(method: str) -> str:
    """A system's row label: the method, with any non-default hyper-parameters."""
    params = PARAMS.get(method)
    return method + (f"({','.join(f'{k}={v}' for k, v in sorted(params.items()))})"
                     if params else "")


def parse_param(text: str) -> tuple[str, str, object]:
    """``METHOD:NAME=VALUE`` (VALUE a JSON number, or else a string)."""
    try:
        method, rest = text.split(":", 1)
        name, value = rest.split("=", 1)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected METHOD:NAME=VALUE, got {text!r}") from None
    if method not in BASELINES:
        raise argparse.ArgumentTypeError(f"{method!r} is not a baseline ({', '.join(BASELINES)})")
    known = make_estimator(method).get_params()
    if name not in known:
        raise argparse.ArgumentTypeError(f"{method} has no parameter {name!r} "
                                         f"({', '.join(sorted(known))})")
    try:
        parsed = json.loads(value)
    except ValueError:
        parsed = value
    return method, name, parsed


def run_fold(tmp: Path, name: str, train, test, reference=None) -> list[dict]:
    return score_fold(fit_fold(tmp, name, train, reference), name, test)


def fit_fold(tmp: Path, name: str, train, reference=None) -> dict:
    """Build the fold's database from ``train`` and fit every baseline on it."""
    db = tmp / f"db-{name}"
    t0 = time.perf_counter()
    build_database(db, train, reference=reference)
    train_s = {m: time.perf_counter() - t0
               for m in evaluate.METHODS + evaluate.OPTIONAL_METHODS}
    model = Model.load(db)
    rng = np.random.default_rng(0)
    estimators = {}
    for method in (m for m in SYSTEMS if m in BASELINES):
        key = label(method)
        t0 = time.perf_counter()
        try:
            estimators[key] = make_estimator(method, **PARAMS.get(method, {})).fit(train)
        except AnimeGraphError as exc:
            print(f"# {name}: {key} not fitted: {exc}", flush=True)
            continue
        train_s[key] = time.perf_counter() - t0
        print(f"# {name}: {key} fitted in {train_s[key]:.1f} s", flush=True)
    for peer in PEER_ROWS:  # published tools from PyPI
        t0 = time.perf_counter()
        try:
            est = PEERS[peer](**({"phones_engine": INGEST.get("phones_engine")}
                                 if peer == "openfacefx" else {}))
            estimators[peer] = est.fit(train)
        except AnimeGraphError as exc:
            print(f"# {name}: {peer} not fitted: {exc}", flush=True)
            continue
        train_s[peer] = time.perf_counter() - t0
    for cls in (Loudness, MeanPose):  # reference rows in every table
        t0 = time.perf_counter()
        estimators[cls.method] = cls().fit(train)
        train_s[cls.method] = time.perf_counter() - t0
    norm = measures.displacement_scale(np.concatenate([c.motion for c in train]))
    return {"model": model, "estimators": estimators, "train_s": train_s, "norm": norm,
            "rng": rng}


def score_fold(fold: dict, name: str, test) -> list[dict]:
    """Score the held-out clips of ``test`` (any iterable: consumed one clip at a time)."""
    model, estimators, train_s = fold["model"], fold["estimators"], fold["train_s"]
    norm, rng = fold["norm"], fold["rng"]
    methods = GRAPH_METHODS if "anime-graph" in SYSTEMS else ()
    dataset = name.rstrip("0123456789").split("-")[0]
    rows = []
    for k, clip in enumerate(test):
        preds = {} if k == 0 else None
        guide = [estimators.get(label(g)) for g in GUIDE]
        guide = None if not GUIDE or None in guide else guide[0] if len(guide) == 1 else guide
        if GUIDE and guide is None:  # a guide could not be fitted on this fold
            methods = [m for m in methods if evaluate.split_guide(m) == (m, False, False)]
        row = evaluate.score_heldout(model, clip, methods=methods, estimators=estimators,
                                     norm=norm, rng=rng, predictions=preds, guide=guide)
        for method, scores in row["methods"].items():
            scores["train_s"] = train_s[method]
        rows.append(row)
        if preds is None or dataset not in PLOTS:
            continue
        if "anime-graph" in SYSTEMS and not PLOTS[dataset].exists():
            plot_heldout(model, clip, PLOTS[dataset])
        both = PLOTS[dataset].with_name(PLOTS[dataset].stem + "_systems.png")
        if not both.exists():
            names = {"exact": "anime-graph", "kbest20": "anime-graph k-best 20"}
            shown = {names.get(m, m): p for m, p in preds.items()
                     if m in names or m in estimators}
            plot_systems(clip, shown, model.names, model.kind, both, seconds=PLOT_SECONDS)
    return rows


def synthetic(tmp: Path, corpus: Path | None, workers: int) -> list[dict]:
    if corpus is None:
        corpus = tmp / "corpus"
        generate_corpus(corpus, CorpusConfig(), workers=workers)
    meta = json.loads((corpus / "corpus.json").read_text())
    clips, reference = prepare_sources(discover([corpus]), IngestConfig(**INGEST),
                                         workers=workers)
    parallel = meta["parallel_sentences"][-2:]
    singles = sorted({c.sentence_id for c in clips} - set(meta["parallel_sentences"]))[-6:]
    held = set(parallel) | set(singles)
    train = [c for c in clips if c.sentence_id not in held]
    test = [c for c in clips if c.sentence_id in held]
    print(f"# synthetic: database {len(train)} clips, held out {len(held)} sentences "
          f"({len(test)} clips)", flush=True)
    return run_fold(tmp, "synthetic", train, test, reference)


def facegood(tmp: Path, workers: int) -> list[dict]:
    clips, reference = prepare_sources(discover([SHARED / "facegood"]), IngestConfig(**INGEST),
                                         workers=workers)
    out = []
    for k, held in enumerate(clips):
        print(f"# facegood fold {k + 1}/{len(clips)}: hold out {held.clip_id}", flush=True)
        out += run_fold(tmp, f"fg{k}", [c for c in clips if c is not held], [held], reference)
    return out


def talkingface(tmp: Path, workers: int) -> list[dict]:
    clips, reference = prepare_sources(discover([SHARED / "talkingface"]), IngestConfig(**INGEST),
                                         workers=workers)
    long_ids = ("dfrf_cnn2", "edtalk_pose_source2")
    out = []
    for clip in clips if "within-speaker" in TALKINGFACE_SPLITS else ():
        if clip.clip_id in long_ids:
            cut = 0.7 * clip.duration
            train = [slice_clip(clip, 0.0, cut, suffix="_first70")]
            test = [slice_clip(clip, cut, clip.duration, suffix="_last30")]
            print(f"# talkingface within-speaker: {clip.clip_id}", flush=True)
            for row in run_fold(tmp, f"tf-{clip.clip_id}", train, test, reference):
                out.append({**row, "split": "within-speaker"})
    others = [c for c in clips if c.clip_id not in long_ids
              and "leave-one-clip-out" in TALKINGFACE_SPLITS]
    for k, held in enumerate(others):
        print(f"# talkingface leave-one-out {k + 1}/{len(others)}: {held.clip_id}", flush=True)
        train = [c for c in clips if c is not held]
        for row in run_fold(tmp, f"tf{k}", train, [held], reference):
            out.append({**row, "split": "leave-one-clip-out"})
    return out


def grid(tmp: Path, workers: int, db: Path | None,
         engines: list[str] | None = None) -> dict[str, list[dict]]:
    if db is not None:
        from db.store import Database

        clips = prepared_from_database(Database.open(db))
        reference = Database.open(db).arrays().get("head_reference")
    else:
        clips, reference = prepare_sources(discover([SHARED / "grid" / "s1"]),
                                           workers=workers)
    train, test = evaluate.grid_split(clips)
    print(f"# grid: database {len(train)} clips, held out {len(test)} (every "
          f"{evaluate.GRID_HOLDOUT}th in clip-id order); phones: "
          f"{sorted({c.segmentation for c in clips})}", flush=True)
    del clips
    fold = fit_fold(tmp, "grid", train, reference)
    del train

    def recognised(engine, agreement):
        for clip in test:  # one at a time: recognised, scored, dropped
            audio = clip.audio.astype(np.float32) / 32767.0
            phones, _ = segment(audio, clip.sample_rate, engine=engine)
            phones = tuple(phones)
            opening = measures.mouth_opening(clip.motion, clip.schema.names, clip.schema.kind)
            agreement.append(phone_agreement(list(clip.phones), list(phones), opening,
                                             clip.fps))
            yield dataclasses.replace(clip, phones=phones, segmentation="recognized")

    out = {"aligned": score_fold(fold, "grid", test)}
    for engine in engines or [INGEST.get("phones_engine")]:
        part = "recognized" if not engines else f"recognized-{engine}"
        print(f"# grid: recognising phones of {len(test)} clips ({part}, engine "
              f"{engine or 'auto'})", flush=True)
        agreement: list[dict] = []
        rows = score_fold(fold, "grid", recognised(engine, agreement))
        for row, agree in zip(rows, agreement, strict=True):
            row["phones_vs_aligned"] = agree
        with warnings.catch_warnings():  # a measure no clip has (no pauses) is NaN
            warnings.simplefilter("ignore", RuntimeWarning)
            means = {k: np.nanmean([a[k] for a in agreement]) for k in agreement[0]}
        print(f"# grid {part}: phones against the aligned ones (means over clips): " + ", ".join(
            f"{k} {v:.3f}" for k, v in means.items()), flush=True)
        out[part] = rows
    return out


def peak_rss_mb() -> float:
    """Largest resident memory of this process so far (MB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def summarise(name: str, rows: list[dict]) -> dict:
    methods = list(dict.fromkeys(m for r in rows for m in r["methods"]))
    keys = sorted({k for r in rows for m in r["methods"].values() for k in m})
    print(f"\n## {name}: {len(rows)} held-out clips (means)")
    print(f"{'method':9s} " + " ".join(f"{k:>14s}" for k in keys))
    table = {}
    for method in methods:
        with warnings.catch_warnings():  # a measure a method does not have is NaN
            warnings.simplefilter("ignore", RuntimeWarning)
            vals = {k: float(np.nanmean([r["methods"][method].get(k, np.nan) for r in rows
                                         if method in r["methods"]])) for k in keys}
        table[method] = vals
        print(f"{method:9s} " + " ".join(f"{vals[k]:14.3f}" for k in keys))
    return table


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--datasets", nargs="+", default=["synthetic", "facegood",
                                                          "talkingface"])
    parser.add_argument("--systems", nargs="+", default=list(METHODS), choices=METHODS,
                        help="systems to compare (default: all four)")
    parser.add_argument("--corpus", type=Path, help="synthetic corpus (default: generate one)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--graph-methods", nargs="+", default=list(evaluate.DEFAULT_METHODS),
                        choices=evaluate.METHODS + evaluate.OPTIONAL_METHODS,
                        help="the Anime Graph's rows (default: those of the paper's audio "
                             "cost; -pg / -mix: posteriorgram DTW alone / beside RASTA-PLP; "
                             "exact-<helper>: the §4.3 helper-pair variants)")
    parser.add_argument("--phones-engine", choices=ENGINES, default=None,
                        help="phone engine for clips without labels (default: auto)")
    parser.add_argument("--peers", nargs="+", default=[], choices=sorted(PEERS),
                        help="published tools as peer rows (pip install -e \".[peers]\")")
    parser.add_argument("--grid-engines", nargs="+", choices=ENGINES, default=None,
                        help="grid: score the recognised phones of each of these engines "
                             "(parts recognized-ENGINE; default: one part, --phones-engine)")
    parser.add_argument("--grid-db", type=Path,
                        help="database ingested from grid/s1 (default: prepare the clips)")
    parser.add_argument("--guide", choices=GUIDES, default="mu-mlp",
                        help="the baseline guiding the -guided / -blend rows (fitted on each "
                             "fold's training clips, as its own row; default mu-mlp)")
    parser.add_argument("--talkingface-splits", nargs="+", choices=TALKINGFACE_SPLITS,
                        default=list(TALKINGFACE_SPLITS),
                        help="talkingface: the splits scored (default both)")
    parser.add_argument("--json", type=Path)
    parser.add_argument("--plots", type=Path,
                        help="folder for one held-out clip's plot per dataset")
    parser.add_argument("--param", type=parse_param, action="append", default=[],
                        metavar="METHOD:NAME=VALUE",
                        help="a baseline hyper-parameter, e.g. av-hmm:n_states=8 (repeatable)")
    args = parser.parse_args()
    SYSTEMS[:] = args.systems
    INGEST["phones_engine"] = args.phones_engine
    # The posteriorgram rows need the training clips' posteriorgrams (not stored by default).
    INGEST["posteriorgrams"] = any(
        evaluate.split_method(evaluate.split_guide(m)[0])[1] != "plp" for m in args.graph_methods)
    guided = [m for m in args.graph_methods if evaluate.split_guide(m) != (m, False, False)]
    if guided and not set(args.guide.split("+")) <= set(args.systems):
        parser.error(f"{', '.join(guided)} need the guide {args.guide} among --systems")
    GUIDE[:] = args.guide.split("+") if guided else []
    GRAPH_METHODS[:] = args.graph_methods
    TALKINGFACE_SPLITS[:] = args.talkingface_splits
    PEER_ROWS[:] = args.peers
    for method, name, value in args.param:
        PARAMS.setdefault(method, {})[name] = value
    if args.plots:
        args.plots.mkdir(parents=True, exist_ok=True)
        PLOTS.update({"synthetic": args.plots / "lipsync_synthetic.png",
                      "fg": args.plots / "lipsync_facegood.png",
                      "tf": args.plots / "lipsync_talkingface.png"})
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for name in args.datasets:
            if name not in ("synthetic", "grid") and not (SHARED / name).exists() or (
                    name == "grid" and args.grid_db is None and not (SHARED / name).exists()):
                print(f"# {name}: skipped, {SHARED / name} is absent")
                continue
            if name == "grid":
                parts = grid(tmp, args.workers, args.grid_db, args.grid_engines)
                results[name] = {phones: {"summary": summarise(f"grid, phones {phones}", rows),
                                          "clips": rows} for phones, rows in parts.items()}
                results[name]["peak_rss_mb"] = peak_rss_mb()
                print(f"# peak memory {peak_rss_mb():.0f} MB", flush=True)
                if args.json:
                    args.json.write_text(json.dumps(results, indent=1))
                continue
            if name == "synthetic":
                rows = synthetic(tmp, args.corpus, args.workers)
            elif name == "facegood":
                rows = facegood(tmp, args.workers)
            else:
                rows = talkingface(tmp, args.workers)
            results[name] = {"summary": summarise(name, rows), "clips": rows}
            if name == "talkingface":
                for split in TALKINGFACE_SPLITS:
                    part = [r for r in rows if r.get("split") == split]
                    results[name][split] = summarise(f"{name} {split}", part)
            if args.json:  # after every dataset, so a long run keeps what it finished
                args.json.write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
