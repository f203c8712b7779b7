"""Fusion of emotion classifiers on EmoDB, nested (docs/results/emotion.md).

Usage::

    python scripts/eval_emotion_fusion.py [--emodb DIR] [--cache DIR] [--bases ...]
                                          [--no-opensmile] [--feature-level] [--json OUT]

Each *base* is one :class:`~ingest.emotion.classifier.EmotionClassifier` on one feature set
(per-speaker normalisation, scaling, SVM), its kernel and C chosen inside the training
folds exactly as ``scripts/eval_emotion.py`` does (inner stratified 5-fold for the outer
stratified 10-fold, inner leave-one-speaker-out for the outer leave-one-speaker-out). The
inner folds of the chosen setting also give every training utterance an *out-of-fold*
decision vector; on those alone (never on the outer test fold) two decision-level fusions
are fitted, for every combination of bases:

* **sum rule** (Kittler et al. 1998, "On combining classifiers", IEEE TPAMI 20(3)): each
  base's decision values are calibrated to probabilities by a multinomial logistic
  regression (Platt scaling, stacked as the classifier's own ``probability=True``), and
  the probabilities averaged;
* **stacking** (Wolpert 1992, "Stacked generalization"; the late fusion of the INTERSPEECH
  emotion challenges, Schuller et al. 2009/2013): one multinomial logistic regression on
  the concatenated out-of-fold decision values of the bases.

``--feature-level`` adds feature-level fusion with the same protocol: the blocks
concatenated, each block first z-scored over the training population and divided by the
square root of its width. **This weighting has no effect**:
the classifier's per-speaker z-normalisation and its scaling to [-1, 1] act per column and
undo any per-column factor applied before them, so this measures plain concatenation
(measured in ``eval_emotion.py``). A block weighting that holds is applied after the
scaler, inside the estimator: ``EmotionClassifier(block_widths=...)``, measured in
``scripts/eval_emotion_boaw.py``.

Scores: accuracy of the outer test folds (mean ± s.d. over folds); for leave-one-speaker-
out also one utterance at a time without a speaker (the ``classify`` case). **The shared
EmoDB copy is cut to 2.0 s per file** (its README): not comparable with published figures.
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time
from pathlib import Path

import numpy as np
from eval_emotion import (  # scripts/ is sys.path[0] when run as a script
    DEFAULT_CACHE,
    DEFAULT_EMODB,
    GRID,
    LINEAR_GRID,
    SEED,
    cached_features,
    finish,
    matrix,
    print_confusion,
)
from joblib import Parallel, delayed
from sklearn.linear_model import LogisticRegression
from sklearn.model_selection import LeaveOneGroupOut, ParameterGrid, StratifiedKFold
from tqdm import tqdm

from ingest.emotion.classifier import FUNCTIONALS, EmotionClassifier, load_emodb

#: Base feature sets and their tuning grids (ComParE: linear only, as in eval_emotion.py).
BASES = {"default": (FUNCTIONALS, GRID), "egemaps": ("egemaps", GRID),
         "compare": ("compare", LINEAR_GRID), "paper": ("paper", LINEAR_GRID)}
#: Penalty of the fusion's logistic regressions (scikit-learn's default; not tuned).
FUSION_C = 1.0


def _inner(y, spk, kind):
    if kind == "10fold":
        return list(StratifiedKFold(5, shuffle=True, random_state=SEED).split(y, y))
    return list(LeaveOneGroupOut().split(y, y, spk))


def _decisions(params, F, y, spk, splits):
    """Out-of-fold decision values (n, n_classes) and the mean fold accuracy (of predict)."""
    oof, accs = None, []
    for a, b in splits:
        m = EmotionClassifier(normalize="speaker", **params).fit(F[a], y[a], speakers=spk[a])
        d = m.decision_function(F[b], speakers=spk[b])
        if oof is None:
            oof = np.zeros((y.size, d.shape[1]))
        oof[b] = d
        accs.append(float(np.mean(m.predict(F[b], speakers=spk[b]) == y[b])))
    return oof, float(np.mean(accs))


def _base_fold(F, y, spk, train, test, kind, grid):
    """Tune one base inside ``train``; its out-of-fold train decisions and test decisions."""
    Ft, yt, st = F[train], y[train], spk[train]
    splits = _inner(yt, st, kind)
    best, best_acc, best_oof = None, -1.0, None
    for params in ParameterGrid(grid):
        oof, acc = _decisions(params, Ft, yt, st, splits)
        if acc > best_acc:
            best, best_acc, best_oof = params, acc, oof
    model = EmotionClassifier(normalize="speaker", **best).fit(Ft, yt, speakers=st)
    return {"oof": best_oof, "test": model.decision_function(F[test], speakers=spk[test]),
            "test_single": model.decision_function(F[test]),
            "pred": model.predict(F[test], speakers=spk[test]),
            "pred_single": model.predict(F[test]), "chosen": f"{best['kernel']} C={best['C']:g}"}


def _block_weighted(blocks: list[np.ndarray], train) -> np.ndarray:
    """Each block z-scored on ``train`` rows and divided by sqrt(its width), concatenated."""
    out = []
    for B in blocks:
        mu, sd = B[train].mean(0), B[train].std(0)
        out.append((B - mu) / np.where(sd > 0, sd, 1.0) / np.sqrt(B.shape[1]))
    return np.hstack(out)


def _fuse(bases: list[dict], yt):
    """Fit the sum rule's calibrators and the stacker on out-of-fold train decisions."""
    calibrators = [LogisticRegression(C=FUSION_C, max_iter=2000).fit(b["oof"], yt)
                   for b in bases]
    stacker = LogisticRegression(C=FUSION_C, max_iter=2000).fit(
        np.hstack([b["oof"] for b in bases]), yt)

    def predict(key):
        p = np.mean([c.predict_proba(b[key]) for c, b in zip(calibrators, bases, strict=True)],
                    axis=0)
        return {"sum": calibrators[0].classes_[p.argmax(1)],
                "stack": stacker.predict(np.hstack([b[key] for b in bases]))}
    return predict


def run(feats, y, spk, names, kinds, feature_level, n_jobs=2) -> dict:
    out = {}
    combos = [c for r in range(2, len(names) + 1) for c in itertools.combinations(names, r)]
    for kind in kinds:
        outer = (list(StratifiedKFold(10, shuffle=True, random_state=SEED).split(y, y))
                 if kind == "10fold" else list(LeaveOneGroupOut().split(y, y, spk)))
        jobs = [(name, k) for name in names for k in range(len(outer))]
        mats = {name: matrix(feats, BASES[name][0]) for name in names}
        t = time.perf_counter()
        done = list(tqdm(Parallel(n_jobs=n_jobs, return_as="generator")(
            delayed(_base_fold)(mats[name], y, spk, outer[k][0], outer[k][1], kind,
                                BASES[name][1]) for name, k in jobs),
            total=len(jobs), desc=f"{kind} bases", file=sys.stderr))
        base = {(name, k): r for (name, k), r in zip(jobs, done, strict=True)}
        if feature_level:
            for combo in [c for c in combos if len(c) == 2]:
                label = "blocks:" + "+".join(combo)
                done = Parallel(n_jobs=n_jobs)(
                    delayed(_base_fold)(_block_weighted([mats[n] for n in combo], tr), y, spk,
                                        tr, te, kind, LINEAR_GRID) for tr, te in outer)
                for k, r in enumerate(done):
                    base[(label, k)] = r
        wall = time.perf_counter() - t
        rows = {}
        singles = sorted({name for name, _ in base})
        for name in singles:
            rows[name] = _score(y, outer, [base[(name, k)] for k in range(len(outer))],
                                None, kind)
        for combo in combos:
            rows["+".join(combo)] = _score(
                y, outer, [[base[(n, k)] for n in combo] for k in range(len(outer))],
                "fusion", kind)
        out[kind] = {"rows": rows, "wall_s": wall}
    return out


def _score(y, outer, per_fold, fusion, kind) -> dict:
    preds = {}
    for (tr, te), b in zip(outer, per_fold, strict=True):
        if fusion is None:
            got = {"svm": {"test": b["pred"], "test_single": b["pred_single"]}}
        else:
            predict = _fuse(b, y[tr])
            got = {f"{rule}": {} for rule in ("sum", "stack")}
            for key in ("test", "test_single"):
                for rule, p in predict(key).items():
                    got[rule][key] = p
        for rule, g in got.items():
            for key, p in g.items():
                preds.setdefault(rule, {}).setdefault(key, np.empty(y.size, dtype=y.dtype))
                preds[rule][key][te] = p
    res = {}
    for rule, p in preds.items():
        accs = [float(np.mean(p["test"][te] == y[te])) for _, te in outer]
        res[rule] = {"acc": float(np.mean(accs)), "std": float(np.std(accs)),
                     "pred": p["test"]}
        if kind == "loso":
            res[rule]["acc_single"] = float(np.mean(
                [np.mean(p["test_single"][te] == y[te]) for _, te in outer]))
        if fusion is None:
            res[rule]["chosen"] = sorted({b["chosen"] for b in per_fold})
    return res


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--emodb", type=Path, default=DEFAULT_EMODB)
    parser.add_argument("--cache", type=Path, default=DEFAULT_CACHE)
    parser.add_argument("--bases", nargs="+", default=["default", "egemaps", "compare"],
                        choices=sorted(BASES))
    parser.add_argument("--kinds", nargs="+", default=["10fold", "loso"],
                        choices=["10fold", "loso"])
    parser.add_argument("--feature-level", action="store_true",
                        help="also concatenation of each pair of bases (the weighting "
                             "before the classifier is undone by its normalisation)")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()

    t0 = time.perf_counter()
    utt, y, spk = load_emodb(args.emodb)
    blocks = ["paper_utterance", "paper_frames", "rich"]
    blocks += [b for b in ("egemaps", "compare") if b in args.bases]
    feats, _ = cached_features("emodb", utt, args.cache, blocks)
    print(f"EmoDB (the shared copy, cut to 2.0 s): {y.size} files, {np.unique(spk).size} "
          f"speakers; bases {', '.join(args.bases)}; nested, all tuning and fusion fitting "
          "inside the training folds", flush=True)
    res = run(feats, y, spk, args.bases, args.kinds, args.feature_level, n_jobs=args.jobs)
    report = {}
    print(f"\n  {'system':<34}{'rule':<7}" + "".join(
        f"{k:>16}" for k in args.kinds) + ("    LOSO, 1 utt." if "loso" in args.kinds else ""))
    first = res[args.kinds[0]]["rows"]
    for system in first:
        for rule in first[system]:
            cells, single = [], ""
            for kind in args.kinds:
                r = res[kind]["rows"][system][rule]
                cells.append(f"{100 * r['acc']:9.1f} ± {100 * r['std']:3.1f}")
                if kind == "loso":
                    single = f"{100 * r['acc_single']:16.1f}"
                report.setdefault(system, {}).setdefault(rule, {})[kind] = {
                    m: v for m, v in r.items() if m != "pred"}
            chosen = first[system][rule].get("chosen")
            print(f"  {system:<34}{rule:<7}" + "".join(f"{c:>16}" for c in cells) + single
                  + (f"  {', '.join(chosen)}" if chosen else ""), flush=True)
    best = max(((s, r) for s in first for r in first[s] if "+" in s),
               key=lambda sr: np.mean([res[k]["rows"][sr[0]][sr[1]]["acc"]
                                       for k in args.kinds]), default=None)
    if best is not None and "loso" in args.kinds:
        report["confusion_loso_best_fusion"] = {"system": best, **print_confusion(
            f"EmoDB LOSO, {best[0]} ({best[1]})", y, res["loso"]["rows"][best[0]][best[1]]
            ["pred"])}
    report["wall_s"] = {k: res[k]["wall_s"] for k in args.kinds}
    return finish(report, t0, args.json)


if __name__ == "__main__":
    sys.exit(main())
