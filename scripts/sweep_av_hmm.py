"""The (N states, M mixtures) sweep of the av-hmm baseline (Terissi et al. 2013, §6.1).

Usage::

    python scripts/sweep_av_hmm.py [--datasets synthetic facegood] [--corpus DIR]
                                   [--states 4 8 16 28] [--mixtures 2 3 5] [--quick]
                                   [--json OUT]

For every (N, M) an AV-HMM is trained on the training clips and the held-out clips'
visual parameters are estimated from their audio by HMM inversion. Reported, over all
held-out frames pooled (the paper's "testing audio-visual database"):

* AMSE and ACC (Eq. 11-12) of the visual parameters — the model's principal components
  of the motion, the truth projected on the same components;
* the same two after the first Eq. 7 update alone (AMSE1, ACC1: occupancies from the
  audio part only, no iteration);
* RMSE of the reconstructed motion over all channels (the database's units);
* training time (s) and synthesis real-time factor (synthesis seconds per audio second).

Splits: synthetic — the held-out sentences of ``scripts/eval_lipsync.py`` (two spoken in
all five emotions, six single-emotion ones); facegood — leave one clip out (the sweep
uses the first fold only unless ``--all-folds``). ``--quick`` uses a smaller grid and
fewer Baum–Welch iterations (a few minutes on two cores).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from animegraph.baselines.av_hmm import AVHMMBaseline
from animegraph.baselines.data import training_set
from animegraph.motion import measures
from ingest.corpus.synthetic import CorpusConfig, generate_corpus
from ingest.pipeline import prepare_sources
from ingest.readers import discover

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def synthetic_split(corpus: Path | None, tmp: Path, workers: int):
    if corpus is None:
        corpus = tmp / "corpus"
        generate_corpus(corpus, CorpusConfig(), workers=workers)
    meta = json.loads((corpus / "corpus.json").read_text())
    clips, _ = prepare_sources(discover([corpus]), workers=workers)
    parallel = meta["parallel_sentences"][-2:]
    singles = sorted({c.sentence_id for c in clips} - set(meta["parallel_sentences"]))[-6:]
    held = set(parallel) | set(singles)
    train = [c for c in clips if c.sentence_id not in held]
    test = [c for c in clips if c.sentence_id in held]
    return [("synthetic", train, test)]


def facegood_splits(workers: int, all_folds: bool):
    clips, _ = prepare_sources(discover([SHARED / "facegood"]), workers=workers)
    folds = range(len(clips)) if all_folds else range(1)
    return [(f"facegood-{k}", [c for c in clips if c is not clips[k]], [clips[k]])
            for k in folds]


def evaluate_model(model: AVHMMBaseline, test) -> dict:
    """Scores of the converged inversion, and of its first Eq. 7 update alone (``_1``)."""
    data = training_set(test)
    est, first, truth, motion_err = [], [], [], []
    synth_s = audio_s = 0.0
    iters = []
    for clip in data.clips:
        t0 = time.perf_counter()
        pred = model.predict(clip.audio, clip.sample_rate, n_frames=clip.n_frames)
        synth_s += time.perf_counter() - t0
        iters.append(model.hmm_.n_iter_)
        audio_s += len(clip.audio) / clip.sample_rate
        est.append((pred - model.motion_mean_) @ model.components_.T)
        truth.append((clip.motion - model.motion_mean_) @ model.components_.T)
        motion_err.append((pred - clip.motion) ** 2)
        model.hmm_.max_iter, keep = 1, model.hmm_.max_iter
        one = model.predict(clip.audio, clip.sample_rate, n_frames=clip.n_frames)
        model.hmm_.max_iter = keep
        first.append((one - model.motion_mean_) @ model.components_.T)
    est, first, truth = np.vstack(est), np.vstack(first), np.vstack(truth)
    return {"amse": measures.amse(est, truth), "acc": measures.acc(est, truth),
            "acc_per_param": [measures.acc(est[:, r], truth[:, r])
                              for r in range(truth.shape[1])],
            "amse_1": measures.amse(first, truth), "acc_1": measures.acc(first, truth),
            "rmse": float(np.sqrt(np.mean(np.vstack(motion_err)))),
            "inversion_iters": float(np.mean(iters)),
            "rtf": synth_s / audio_s, "test_frames": len(truth)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--datasets", nargs="+", default=["synthetic"],
                        choices=["synthetic", "facegood"])
    parser.add_argument("--corpus", type=Path, help="synthetic corpus (default: generate one)")
    parser.add_argument("--states", type=int, nargs="+", default=[4, 8, 16, 28])
    parser.add_argument("--mixtures", type=int, nargs="+", default=[2, 3, 5])
    parser.add_argument("--n-iter", type=int, default=None,
                        help="Baum-Welch iterations (default: the estimator's)")
    parser.add_argument("--quick", action="store_true",
                        help="N in {4, 8}, M in {2, 3}, 8 Baum-Welch iterations")
    parser.add_argument("--init", choices=["audio", "random"], default="audio",
                        help="start of the HMM inversion (random: the paper's)")
    parser.add_argument("--all-folds", action="store_true", help="every FACEGOOD fold")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    if args.quick:
        args.states, args.mixtures = [4, 8], [2, 3]
        args.n_iter = args.n_iter or 8
    extra = {"init": args.init, **({"n_iter": args.n_iter} if args.n_iter else {})}
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.datasets:
            if name == "synthetic":
                splits = synthetic_split(args.corpus, Path(tmp), args.workers)
            elif not (SHARED / "facegood").exists():
                print(f"# facegood: skipped, {SHARED / 'facegood'} is absent")
                continue
            else:
                splits = facegood_splits(args.workers, args.all_folds)
            rows = []
            for split, train, test in splits:
                print(f"# {split}: {len(train)} training clips, {len(test)} held out",
                      flush=True)
                print(f"{'N':>3s} {'M':>2s} {'AMSE':>7s} {'ACC':>6s} {'AMSE1':>7s} "
                      f"{'ACC1':>6s} {'RMSE':>8s} {'fit s':>7s} {'cpu s':>7s} {'iters':>5s} "
                      f"{'RTF':>6s}", flush=True)
                for n in args.states:
                    for m in args.mixtures:
                        t0, c0 = time.perf_counter(), time.process_time()
                        model = AVHMMBaseline(n_states=n, n_mix=m, **extra).fit(train)
                        fit_s = time.perf_counter() - t0
                        cpu_s = time.process_time() - c0
                        row = {"split": split, "n_states": n, "n_mix": m, "fit_s": fit_s,
                               "fit_cpu_s": cpu_s,
                               "bw_iters": model.hmm_.train_iter_,
                               "pca_variance": float(model.explained_variance_ratio_.sum()),
                               **evaluate_model(model, test)}
                        rows.append(row)
                        print(f"{n:3d} {m:2d} {row['amse']:7.3f} {row['acc']:6.3f} "
                              f"{row['amse_1']:7.3f} {row['acc_1']:6.3f} "
                              f"{row['rmse']:8.4f} {fit_s:7.1f} {cpu_s:7.1f} "
                              f"{row['bw_iters']:5d} "
                              f"{row['rtf']:6.3f}", flush=True)
            results[name] = rows
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
