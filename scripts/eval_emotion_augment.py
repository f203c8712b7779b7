"""Speed perturbation of the training folds, nested, on EmoDB
(docs/results/emotion.md).

Usage::

    python scripts/eval_emotion_augment.py [--emodb DIR] [--cache DIR] [--factors 0.9 1.1]
                                           [--kinds 10fold loso] [--json OUT]

Speed perturbation (Ko, Peddinti, Povey & Khudanpur 2015, "Audio augmentation for speech
recognition", INTERSPEECH; used for speech emotion by Aldeneh & Provost 2017, ICASSP):
every *training* utterance is added again played 0.9 and 1.1 times as fast
(:func:`ingest.emotion.audio.speed_perturb`: tempo, pitch and formants move together), each
perturbed copy of a speaker counted as a new speaker (Ko et al.; Kaldi's ``sp0.9-``
speakers), so per-speaker normalisation treats it as another voice. Test utterances are
never perturbed. Everything else is ``scripts/eval_emotion.py``'s default pipeline and
protocol: rich + cepstrum features, per-speaker normalisation, scaling, SVM; kernel and C
chosen inside each training fold (inner stratified 5-fold for the outer stratified
10-fold, inner leave-one-speaker-out for the outer LOSO), the inner training folds
augmented the same way and the inner test folds not. The unaugmented default is run by
the same code beside it.

The features of the perturbed copies are cached beside the corpus' other features in
``--cache``. **The shared EmoDB copy is cut to 2.0 s per file** (its README): not
comparable with published figures.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from eval_emotion import (  # scripts/ is sys.path[0] when run as a script
    GRID,
    SEED,
    cache_folder,
    common_arguments,
    emodb_default,
    finish,
    report_row,
)
from joblib import Parallel, delayed
from sklearn.model_selection import LeaveOneGroupOut, ParameterGrid, StratifiedKFold
from tqdm import tqdm

from ingest.emotion.audio import speed_perturb
from ingest.emotion.classifier import FUNCTIONALS, EmotionClassifier
from ingest.emotion.features import block_features

#: Speed factors of the perturbed copies (Ko et al. 2015).
FACTORS = (0.9, 1.1)


def perturbed_features(utt, cache: Path, factor: float, spec: str = FUNCTIONALS):
    """Features (n, width) of every utterance played ``factor`` times as fast (cached)."""
    path = cache_folder("emodb", utt, cache) / f"speed{factor:g}-{spec}.npy"
    if path.exists():
        return np.load(path, allow_pickle=False)
    rows = []
    for audio, sr in tqdm(utt, desc=f"speed {factor:g}", file=sys.stderr):
        blocks = block_features(speed_perturb(audio, sr, factor), sr, spec)
        rows.append(np.concatenate(list(blocks.values())))
    F = np.vstack(rows)
    np.save(path, F)
    return F


def expand(idx, F, augmented, y, spk, factors):
    """Rows ``idx`` of the original and of every perturbed copy (copies as new speakers)."""
    Fs = [F[idx]] + [A[idx] for A in augmented]
    ss = [spk[idx]] + [np.char.add(spk[idx], f"@sp{f:g}") for f in factors]
    return np.vstack(Fs), np.tile(y[idx], 1 + len(augmented)), np.concatenate(ss)


def _fit(params, F, augmented, y, spk, factors, idx):
    Fa, ya, sa = expand(idx, F, augmented, y, spk, factors)
    return EmotionClassifier(**params).fit(Fa, ya, speakers=sa)


def _outer_fold(F, augmented, y, spk, train, test, kind, factors, grid):
    """Tune inside ``train`` (inner training folds augmented), score ``test`` unperturbed."""
    if kind == "10fold":
        inner = StratifiedKFold(5, shuffle=True, random_state=SEED).split(train, y[train])
    else:
        inner = LeaveOneGroupOut().split(train, y[train], spk[train])
    inner = [(train[a], train[b]) for a, b in inner]
    best, best_score = None, -1.0
    for params in ParameterGrid(grid):
        p = {"normalize": "speaker", **params}
        s = np.mean([_fit(p, F, augmented, y, spk, factors, a)
                     .score(F[b], y[b], speakers=spk[b]) for a, b in inner])
        if s > best_score:
            best, best_score = p, s
    t = time.perf_counter()
    model = _fit(best, F, augmented, y, spk, factors, train)
    out = {"pred": model.predict(F[test], speakers=spk[test]),
           "chosen": f"{best['kernel']} C={best['C']:g}", "fit_s": time.perf_counter() - t}
    if kind == "loso":
        out["pred_single"] = model.predict(F[test])
    return out


def nested(F, augmented, y, spk, factors, kinds, grid=GRID) -> dict:
    res = {}
    for kind in kinds:
        splits = (list(StratifiedKFold(10, shuffle=True, random_state=SEED).split(F, y))
                  if kind == "10fold" else list(LeaveOneGroupOut().split(F, y, spk)))
        folds = Parallel(n_jobs=2)(delayed(_outer_fold)(F, augmented, y, spk, tr, te, kind,
                                                        factors, grid) for tr, te in splits)
        pred = np.empty(y.size, dtype=y.dtype)
        accs = []
        for (_, te), f in zip(splits, folds, strict=True):
            pred[te] = f["pred"]
            accs.append(float(np.mean(f["pred"] == y[te])))
        r = {"acc": float(np.mean(accs)), "std": float(np.std(accs)),
             "folds": accs, "chosen": sorted({f["chosen"] for f in folds}),
             "fit_s": float(np.mean([f["fit_s"] for f in folds])), "pred": pred}
        if kind == "loso":
            r["acc_single"] = float(np.mean([np.mean(f["pred_single"] == y[te])
                                             for (_, te), f in zip(splits, folds,
                                                                   strict=True)]))
        res[kind] = r
    return res


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    common_arguments(parser)
    parser.add_argument("--factors", type=float, nargs="+", default=list(FACTORS))
    args = parser.parse_args()

    t0 = time.perf_counter()
    utt, y, spk, feats, F = emodb_default(args.emodb, args.cache)
    augmented = [perturbed_features(utt, args.cache, f) for f in args.factors]
    print(f"EmoDB (the shared copy, cut to 2.0 s): {y.size} files, {np.unique(spk).size} "
          f"speakers; training folds augmented by speed factors "
          f"{', '.join(f'{f:g}' for f in args.factors)}", flush=True)
    report = {}
    rows = {"default": ([], ()), "speed perturbation": (augmented, tuple(args.factors))}
    for label, (aug, factors) in rows.items():
        t = time.perf_counter()
        r = nested(F, aug, y, spk, factors, args.kinds)
        report[label] = report_row(label, r, args.kinds, y, time.perf_counter() - t)
    return finish(report, t0, args.json)


if __name__ == "__main__":
    sys.exit(main())
