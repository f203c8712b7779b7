"""Bag-of-audio-words and block-weighted fusion with the functionals, nested, on EmoDB
(docs/results/emotion.md).

Usage::

    python scripts/eval_emotion_boaw.py [--emodb DIR] [--cache DIR] [--kinds 10fold loso]
                                        [--systems ...] [--json OUT]

Systems (all with per-speaker normalisation, scaling to [-1, 1] and the SVM, kernel and C
chosen inside each training fold exactly as ``scripts/eval_emotion.py``: inner stratified
5-fold for the outer stratified 10-fold, inner leave-one-speaker-out for the outer LOSO):

* ``default``: rich + cepstrum functionals (171), the stored default, for reference;
* ``default-weighted``: the same two blocks, each block's scaled columns multiplied so
  that every block holds the same share of the total variance whatever its width
  (``EmotionClassifier(block_widths=...)``, :func:`ingest.emotion.classifier.block_weights`:
  weight ``sqrt(n_total / (n_blocks * width))``, the equal-trace normalisation of
  multiple-kernel learning);
* ``boaw``: bag-of-audio-words of frame descriptors (:mod:`ingest.emotion.boaw`, after
  Schmitt, Ringeval & Schuller 2016, INTERSPEECH; openXBOW's defaults), 2 x 500 words;
* ``default+boaw``: the functionals and the bag of words concatenated, block-weighted as
  ``default-weighted`` (plain concatenation would let the 1,000 words drown the 171
  functionals; ``scripts/eval_emotion_fusion.py --feature-level`` weights the blocks
  *before* the classifier's per-speaker normalisation and scaling, which undo any
  per-column weight, so it measures plain concatenation);
* ``stored``: default+boaw through the stored estimator, what ``ingest`` stores and
  ``classify`` / ``synth --emotion auto`` use: kernel and C
  chosen as ``default+boaw``'s, then ``EmotionClassifier()`` (features
  ``rich+cepstrum+boaw``, probabilities) fitted on the outer training fold's
  :class:`~ingest.emotion.classifier.SpeechFeatures` (functionals and frame descriptors:
  it learns its codebooks itself), written with ``to_arrays``, read back with
  ``from_arrays`` and scored; LOSO one utterance at a time is also scored by the
  highest probability (what ``classify`` lists first). One codebook pair
  (``n_codebooks=1``);
* ``ensemble``: ``stored`` with the ensemble of :data:`ingest.emotion.boaw.ENSEMBLE`
  codebook pairs (``EmotionClassifier(n_codebooks=5)``, the default; their
  histograms one block), tuned on the same ensemble's features at the estimator's kernel
  scale (``kernel_width``: one pair's width); its first pair is ``stored``'s (the same
  seed), the others drawn from it.

``--choose`` prints the kernel and C the stored default's tuning picks on all of EmoDB
(the grid above, inner leave-one-speaker-out over the 10 speakers and inner stratified
5-fold, the codebooks learned on all of it): what :data:`DEFAULT_C` is set from.

``--synthetic``: the synthetic corpus (one speaker, 240 clips, 5 emotions;
``scripts/eval_emotion.py --synthetic`` generates and caches it): nested 10-fold of
``default`` and ``default+boaw``, and cross-corpus on the four shared emotions with the
stored estimator's default parameters (trained on one corpus, codebooks included, tested
on the other; the target's speakers normalised together, and one utterance at a time).

``--seed S`` seeds the codebooks (``BagOfAudioWords(random_state=S)``, the estimator's
``random_state``; 0 is the stored default's; the seed of the ensemble's first pair):
their random variation, measured.

``--mcnemar A B`` compares two systems' per-utterance correctness (LOSO, one utterance
at a time; and the grouped LOSO and 10-fold predictions) with McNemar's exact test
(two-sided binomial test on the discordant utterances; McNemar 1947, Dietterich 1998).

The codebooks (and their standardisation) are learned on the outer training fold's frames
alone, anew for every outer fold; the inner tuning folds use that fold's codebooks (they
see no outer test audio). Frame descriptors are cached in ``--cache``. **The shared EmoDB
copy is cut to 2.0 s per file** (its README): not comparable with published figures.
"""

from __future__ import annotations

import argparse
import sys
import time
from functools import partial
from pathlib import Path

import numpy as np
from eval_emotion import (  # scripts/ is sys.path[0] when run as a script
    GRID,
    SHARED_EMOTIONS,
    _inner,
    cache_folder,
    cached_features,
    common_arguments,
    emodb_default,
    finish,
    matrix,
    nested,
    print_confusion,
    report_row,
    synthetic_corpus,
)
from tqdm import tqdm

from ingest.emotion.boaw import ENSEMBLE, BagOfAudioWords, frame_descriptors
from ingest.emotion.classifier import FUNCTIONALS, EmotionClassifier, SpeechFeatures

SYSTEMS = ("default", "default-weighted", "boaw", "default+boaw", "stored", "ensemble")


def cached_frames(utt, cache: Path, name: str = "emodb") -> list[np.ndarray]:
    """:func:`frame_descriptors` of every utterance (cached as one array and offsets)."""
    folder = cache_folder(name, utt, cache)
    path, offsets_path = folder / "boaw_frames.npy", folder / "boaw_offsets.npy"
    if not path.exists():
        rows = [frame_descriptors(a, sr) for a, sr in tqdm(utt, desc="frames",
                                                           file=sys.stderr)]
        np.save(offsets_path, np.cumsum([0] + [r.shape[0] for r in rows]))
        np.save(path, np.vstack(rows))
    X, off = np.load(path, allow_pickle=False), np.load(offsets_path, allow_pickle=False)
    return [X[a:b] for a, b in zip(off[:-1], off[1:], strict=True)]


def boaw_features(frames, default: np.ndarray, with_default: bool, seed: int = 0,
                  n_codebooks: int = 1):
    """``fold_features``: the bag of words learned on the training fold (with the
    functionals in front if ``with_default``; codebooks seeded by ``seed``)."""
    def make(train):
        H = BagOfAudioWords(n_codebooks=n_codebooks, random_state=seed).fit(
            [frames[i] for i in train]).transform(frames)
        return np.hstack([default, H]) if with_default else H
    return make


def stored_final(frames, F, y, spk, seed: int = 0, n_codebooks: int = 1):
    """``final`` of :func:`eval_emotion.nested`: the stored estimator, fitted on the fold's
    functionals and frames (it learns the codebooks), round-tripped through its arrays."""
    def fit(params, train, test):
        model = EmotionClassifier(kernel=params["kernel"], C=params["C"], probability=True,
                                  n_codebooks=n_codebooks, random_state=seed)
        model.fit(SpeechFeatures(F[train], [frames[i] for i in train]), y[train],
                  speakers=spk[train])
        back = EmotionClassifier.from_arrays(model.to_arrays())
        return back, SpeechFeatures(F[test], [frames[i] for i in test])
    return fit


def choose(F, frames, y, spk) -> dict:
    """Kernel and C the stored default's tuning picks on all the data (both inner
    schemes), the codebooks learned on all of it."""
    from sklearn.model_selection import ParameterGrid

    H = BagOfAudioWords().fit(frames).transform(frames)
    X = np.hstack([F, H])
    every = np.arange(y.size)
    out = {}
    for kind in ("loso", "10fold"):
        scores = {}
        for params in ParameterGrid(GRID):
            scores[f"{params['kernel']} C={params['C']:g}"] = float(np.mean([
                EmotionClassifier(block_widths=(F.shape[1], H.shape[1]), **params)
                .fit(X[a], y[a], speakers=spk[a]).score(X[b], y[b], speakers=spk[b])
                for a, b in _inner(X, y, spk, every, kind)]))
        out[kind] = scores
        print(f"  tuning on all of EmoDB, inner {kind}: " + ", ".join(
            f"{k} {100 * v:.1f}" for k, v in scores.items())
            + f"; best {max(scores, key=scores.get)}", flush=True)
    return out


def synthetic(cache: Path, emodb) -> dict:
    """Nested 10-fold on the synthetic corpus, and cross-corpus with EmoDB, both ways."""
    s_utt, s_y = synthetic_corpus(cache)
    s_feats, _ = cached_features("synthetic", s_utt, cache, ["paper_frames", "rich"])
    s_F, s_frames = matrix(s_feats, FUNCTIONALS), cached_frames(s_utt, cache, "synthetic")
    s_spk = np.array(["synth01"] * s_y.size)
    n_words = 2 * BagOfAudioWords().size
    out = {}
    print(f"\nsynthetic corpus: {s_y.size} clips, one speaker")
    for label, setup in (("default", {}), ("default+boaw", dict(
            factory=partial(EmotionClassifier, block_widths=(s_F.shape[1], n_words)),
            fold_features=boaw_features(s_frames, s_F, True)))):
        r = nested(s_F, s_y, s_spk, dict(normalize="speaker"), GRID, kinds=("10fold",),
                   **setup)["10fold"]
        out[label] = {k: v for k, v in r.items() if not k.startswith("pred")}
        print(f"  {label:<22}nested 10-fold {100 * r['acc']:.1f} ± {100 * r['std']:.1f}  "
              f"chosen {', '.join(r['chosen'])}", flush=True)
    y, spk, F, frames = emodb
    keep_s = np.isin(s_y, list(SHARED_EMOTIONS))
    keep_e = np.isin(y, list(SHARED_EMOTIONS.values()))
    ys = np.array([SHARED_EMOTIONS[v] for v in s_y[keep_s]])
    corpora = {"synthetic": (SpeechFeatures(s_F[keep_s], [f for f, k in zip(
                   s_frames, keep_s, strict=True) if k]), ys, s_spk[keep_s]),
               "EmoDB": (SpeechFeatures(F[keep_e], [f for f, k in zip(
                   frames, keep_e, strict=True) if k]), y[keep_e], spk[keep_e])}
    for src, dst in (("synthetic", "EmoDB"), ("EmoDB", "synthetic")):
        (Xs, ys_, ss), (Xd, yd, sd) = corpora[src], corpora[dst]
        for label, make in (("default", lambda: EmotionClassifier(features=FUNCTIONALS)),
                            ("stored default", EmotionClassifier)):
            model = make()
            Xs_, Xd_ = (Xs.functionals, Xd.functionals) if label == "default" else (Xs, Xd)
            model.fit(Xs_, ys_, speakers=ss)
            grouped, single = model.predict(Xd_, speakers=sd), model.predict(Xd_)
            r = {"grouped": float(np.mean(grouped == yd)), "single": float(np.mean(single == yd)),
                 "chance": float(np.max(np.unique(yd, return_counts=True)[1]) / yd.size)}
            print(f"  {src} -> {dst}, {label}: {100 * r['grouped']:.1f} % speakers grouped, "
                  f"{100 * r['single']:.1f} % one utterance at a time (majority class "
                  f"{100 * r['chance']:.1f} %)", flush=True)
            r["confusion"] = print_confusion(f"{src} -> {dst}, {label}, speakers grouped",
                                             yd, grouped)
            out[f"{src}->{dst}/{label}"] = r
    return out


def mcnemar(y, a, b) -> dict:
    """McNemar's exact test of two systems' per-utterance correctness (two-sided)."""
    from scipy.stats import binomtest

    ra, rb = np.asarray(a) == y, np.asarray(b) == y
    only_a, only_b = int(np.sum(ra & ~rb)), int(np.sum(~ra & rb))
    p = binomtest(min(only_a, only_b), only_a + only_b, 0.5).pvalue if only_a + only_b else 1.0
    return {"only_first_right": only_a, "only_second_right": only_b, "p": float(p),
            "first": float(ra.mean()), "second": float(rb.mean())}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    common_arguments(parser)
    parser.add_argument("--systems", nargs="*", default=list(SYSTEMS), choices=SYSTEMS)
    parser.add_argument("--seed", type=int, default=0,
                        help="seed of the codebooks (the estimator's random_state)")
    parser.add_argument("--choose", action="store_true")
    parser.add_argument("--synthetic", action="store_true")
    parser.add_argument("--mcnemar", nargs=2, metavar=("A", "B"), choices=SYSTEMS,
                        help="McNemar's exact test between two of the systems run")
    args = parser.parse_args()

    t0 = time.perf_counter()
    utt, y, spk, feats, F = emodb_default(args.emodb, args.cache)
    frames = cached_frames(utt, args.cache)
    n_words = 2 * BagOfAudioWords().size
    print(f"EmoDB (the shared copy, cut to 2.0 s): {y.size} files, {np.unique(spk).size} "
          f"speakers, {sum(f.shape[0] for f in frames)} frames; codebooks learned in each "
          "outer training fold", flush=True)
    setups = {
        "default": dict(factory=EmotionClassifier),
        "default-weighted": dict(factory=partial(
            EmotionClassifier, block_widths=(feats["rich"].shape[1],
                                             feats["cepstrum"].shape[1]))),
        "boaw": dict(fold_features=boaw_features(frames, F, False, args.seed)),
        "default+boaw": dict(factory=partial(EmotionClassifier,
                                             block_widths=(F.shape[1], n_words)),
                             fold_features=boaw_features(frames, F, True, args.seed)),
    }
    setups["stored"] = dict(setups["default+boaw"],
                            final=stored_final(frames, F, y, spk, args.seed))
    setups["ensemble"] = dict(
        factory=partial(EmotionClassifier, block_widths=(F.shape[1], ENSEMBLE * n_words),
                        kernel_width=F.shape[1] + n_words),  # the estimator's kernel scale
        fold_features=boaw_features(frames, F, True, args.seed, ENSEMBLE),
        final=stored_final(frames, F, y, spk, args.seed, ENSEMBLE))
    report, preds = {}, {}
    for label in args.systems:
        t = time.perf_counter()
        r = nested(F, y, spk, dict(normalize="speaker"), GRID, kinds=tuple(args.kinds),
                   **setups[label])
        preds[label] = {f"{k}/{m}": r[k][m] for k in r for m in r[k] if m.startswith("pred")}
        report[label] = report_row(label, r, args.kinds, y, time.perf_counter() - t)
        report[label]["per_utterance"] = {k: v.tolist() for k, v in preds[label].items()}
    if args.choose:
        report["choose"] = choose(F, frames, y, spk)
    if args.synthetic:
        report["synthetic"] = synthetic(args.cache, (y, spk, F, frames))
    if args.mcnemar:
        a, b = args.mcnemar
        report["mcnemar"] = {}
        for key in sorted(set(preds.get(a, {})) & set(preds.get(b, {}))):
            m = mcnemar(y, preds[a][key], preds[b][key])
            report["mcnemar"][key] = m
            print(f"McNemar {a} vs {b}, {key}: {100 * m['first']:.1f} vs "
                  f"{100 * m['second']:.1f} %; only {a} right {m['only_first_right']}, only "
                  f"{b} right {m['only_second_right']}; exact p = {m['p']:.3f}")
    return finish(report, t0, args.json)


if __name__ == "__main__":
    sys.exit(main())
