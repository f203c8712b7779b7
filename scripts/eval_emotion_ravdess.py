"""Emotion classification on RAVDESS, leaving actors out, and across corpora with EmoDB
(docs/results/emotion.md, "RAVDESS: unseen actors").

Usage::

    python scripts/eval_emotion_ravdess.py [--ravdess DIR] [--emodb DIR] [--cache DIR]
                                           [--systems NAME ...] [--json OUT]

Split: **leave two actors out, balanced by sex** -- six deterministic folds over the 12
shared actors, fold k holding out actors 2k-1 (male) and 2k (female); the model learns on
the other ten. Never tuned on anything else (the other twelve actors are held back).

Each system is scored

* **one utterance** at a time, no speaker given (what ``classify`` and ``synth --emotion
  auto`` do);
* **grouped**: the held-out actor's utterances given together with their speaker (the
  per-speaker normalisation from their own label-free statistics);

on the 8 emotions, and on 4 (neutral, happy, sad, angry: the model is trained on those
four only, the usual RAVDESS subset and the one the issue's figure used), with per-class
recall and confusion (in the JSON). Cross-corpus rows (TESS is not here, so EmoDB stands
in): learnt on all 12 RAVDESS actors, tested on EmoDB, and the reverse, on the six
emotions both have (neutral, happy, sad, angry, disgust, fear), one utterance and speakers
grouped, with neutral's recall. Then EmoDB's own leave-one-speaker-out (7 emotions, C
fixed: no nesting), unless ``--no-emodb-loso``.

Systems (``--systems``; :data:`SYSTEMS` says what each is): ``speaker`` (the default
before), ``functionals``, ``balanced``, ``no-norm``, ``nearest-3``, ``+emodb``,
``default`` (the estimator's default), ``default, nested C``, ``default, speed`` (speed
perturbation of the training folds; its copies are described and cached once, about as
long as the corpus itself), ``default, prior``.

Features are the stored estimator's (:meth:`EmotionClassifier.describe`: the functionals
and the audio words' frame descriptors), computed once and cached in ``--cache`` as
``.npz`` (no pickles). The audio words are learned on each training fold's frames only and
cached per fold too; then every system is an SVM on those matrices (systems differ in
normalisation, class weights, C, training data), so a rerun takes a minute or two.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from pathlib import Path

import numpy as np
import soundfile as sf

from ingest.emotion.audio import speed_perturb
from ingest.emotion.boaw import CODEBOOK_SIZE, ENSEMBLE, BagOfAudioWords
from ingest.emotion.classifier import EmotionClassifier, load_emodb

ROOT = Path(__file__).resolve().parents[2] / "shared" / "data"
DEFAULT_CACHE = Path("/tmp/animegraph-emotion-features")
#: RAVDESS' emotion codes (its README).
RAVDESS_EMOTIONS = {"01": "neutral", "02": "calm", "03": "happy", "04": "sad", "05": "angry",
                    "06": "fearful", "07": "disgust", "08": "surprised"}
FOUR = ("neutral", "happy", "sad", "angry")
#: EmoDB label -> RAVDESS label, the emotions both corpora have.
EMODB_TO_RAVDESS = {"neutral": "neutral", "happiness": "happy", "sadness": "sad",
                    "anger": "angry", "disgust": "disgust", "fear": "fearful"}
#: Actors 01-12 only (the shared copy); odd = male, even = female.
ACTORS = tuple(f"{a:02d}" for a in range(1, 13))
FOLDS = tuple((ACTORS[2 * k], ACTORS[2 * k + 1]) for k in range(6))


def load_ravdess(root: Path):
    """Utterances, labels, actors and intensities of the shared RAVDESS actors.

    Returns
    -------
    utterances : list of (np.ndarray, int)
    labels, actors, intensity : np.ndarray, shape (720,)
    """
    utt, labels, actors, intensity = [], [], [], []
    for actor in ACTORS:
        for path in sorted((root / f"Actor_{actor}").glob("03-01-*.flac")):
            parts = path.stem.split("-")
            if len(parts) != 7 or parts[6] != actor or parts[2] not in RAVDESS_EMOTIONS:
                raise SystemExit(f"eval_emotion_ravdess: unexpected file name {path}")
            audio, rate = sf.read(path, dtype="float32", always_2d=False)
            utt.append((audio, rate))
            labels.append(RAVDESS_EMOTIONS[parts[2]])
            actors.append(actor)
            intensity.append(parts[3])
    if not utt:
        raise SystemExit(f"eval_emotion_ravdess: no RAVDESS files under {root}")
    return utt, np.array(labels), np.array(actors), np.array(intensity)


def described(name: str, utt, cache: Path):
    """The estimator's functionals and frame descriptors of every utterance, cached.

    Returns
    -------
    F : np.ndarray, shape (n, n_functionals)
    frames : list of np.ndarray, each (n_frames_k, n_descriptors)
    """
    digest = hashlib.sha1(b"".join(np.ascontiguousarray(a[:4000]).tobytes()
                                   for a, _ in utt)).hexdigest()[:10]
    path = cache / f"{name}-{len(utt)}-{digest}" / "described.npz"
    if not path.exists():
        model, rows, frames = EmotionClassifier(), [], []
        t = time.perf_counter()
        for i, pair in enumerate(utt):
            d = model.describe([pair])
            rows.append(d.functionals[0])
            frames.append(d.frames[0])
            if i % 100 == 99:
                print(f"{name}: {i + 1}/{len(utt)} described, "
                      f"{time.perf_counter() - t:.0f} s", file=sys.stderr)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp.npz")
        np.savez(tmp, functionals=np.vstack(rows), frames=np.vstack(frames),
                 offsets=np.cumsum([0] + [f.shape[0] for f in frames]))
        tmp.replace(path)
    with np.load(path, allow_pickle=False) as z:
        F, X, off = z["functionals"], z["frames"], z["offsets"]
    return F, [X[a:b] for a, b in zip(off[:-1], off[1:], strict=True)]


# --------------------------------------------------------------------------- audio words
def fold_words(name: str, frames, train: np.ndarray, cache: Path) -> np.ndarray:
    """The default ensemble's audio words of every utterance, learned on ``train`` only.

    Returns
    -------
    np.ndarray, shape (n, 2 * ENSEMBLE * CODEBOOK_SIZE)
    """
    key = hashlib.sha1(np.asarray(train, dtype=np.int64).tobytes()).hexdigest()[:10]
    path = cache / f"{name}-words-{key}.npz"
    if not path.exists():
        bag = BagOfAudioWords(n_codebooks=ENSEMBLE, random_state=0).fit(
            [frames[i] for i in train])
        tmp = path.with_suffix(".tmp.npz")
        np.savez(tmp, words=bag.transform(frames))
        tmp.replace(path)
    with np.load(path, allow_pickle=False) as z:
        return z["words"]


# --------------------------------------------------------------------------- systems
#: Each system: EmotionClassifier parameters, the feature blocks, how training and lone
#: utterances are normalised, extra training data, C chosen in the folds or not.
SPEAKER = dict(normalize="speaker")
SYSTEMS = {
    "speaker": dict(params=SPEAKER, doc="the default before: functionals + 5 codebook "
                    "pairs, the SVM trained on speaker-normalised features, C = 0.1"),
    "functionals": dict(params=SPEAKER, words=False, doc="'speaker' without the audio "
                        "words (rich + cepstrum)"),
    "balanced": dict(params=dict(SPEAKER, class_weight="balanced"),
                     doc="'speaker', class-balanced SVM (C per class inversely to its "
                         "frequency)"),
    "no-norm": dict(params=dict(normalize="none"), doc="no speaker normalisation at all"),
    "nearest-3": dict(params=SPEAKER, nearest=3, doc="'speaker', a lone utterance "
                      "normalised by its 3 nearest training speakers' statistics"),
    "+emodb": dict(params=SPEAKER, emodb=True, doc="'speaker', EmoDB's utterances of the "
                   "shared emotions added to training"),
    "default": dict(doc="the default now: 'speaker' with the SVM trained on speaker- and "
                        "population-normalised copies of every utterance "
                        "(normalize='speaker+population')"),
    "default, nested C": dict(grid=(0.001, 0.01, 0.1), doc="the default, C in {0.001, "
                              "0.01, 0.1} chosen by inner leave-2-actors-out"),
    "default, speed": dict(speed=(0.9, 1.1), doc="the default, training folds with "
                           "copies at 0.9 and 1.1 times the speed (each a new speaker)"),
    "default, prior": dict(prior=True, doc="the default, its calibrated probabilities "
                           "divided by the class priors (every class equally likely)"),
}


def fit_fixed(system: dict, F, y, spk, widths, C=None):
    """``system`` fitted on (F, y, spk) with C (or its default).

    Returns
    -------
    callable
        ``predict(F, speakers=None)``, shape (n,); speakers None for lone utterances.
    """
    params = dict(system.get("params", {}))
    if C is not None:
        params["C"] = C
    if widths is not None:
        params.update(block_widths=widths, kernel_width=widths[0] + 2 * CODEBOOK_SIZE)
    prior = None
    if system.get("prior"):
        params["probability"] = True
        _, counts = np.unique(y, return_counts=True)
        prior = counts / counts.sum()
    model = EmotionClassifier(**params).fit(F, y, speakers=spk)
    k = system.get("nearest")

    def predict(X, speakers=None) -> np.ndarray:
        if prior is not None:
            return model.classes_[np.argmax(model.predict_proba(X, speakers) / prior, axis=1)]
        if k and speakers is None:
            norm = model.normalizer_
            centres = (norm.means_ - norm.mean_) / norm.scale_    # (n_speakers, n_features)
            d = ((((X - norm.mean_) / norm.scale_)[:, None, :] - centres[None]) ** 2).sum(-1)
            near = np.argsort(d, axis=1)[:, :k]                   # (n, k)
            mean, scale = norm.means_[near].mean(1), norm.scales_[near].mean(1)
            return model.pipeline_.predict((X - mean) / scale)
        return model.predict(X, speakers)
    return predict


def fit_system(system: dict, F, y, spk, widths, inner_groups=None):
    """``system`` fitted on (F, y, spk); with a grid, C chosen by one-utterance accuracy
    over ``inner_groups`` (a list of held-out speaker sets inside this training set)."""
    grid = system.get("grid")
    if not grid or not inner_groups:
        return fit_fixed(system, F, y, spk, widths)
    scores = []
    for C in grid:
        acc = []
        for held in inner_groups:
            test = np.isin(spk, held)
            fitted = fit_fixed(system, F[~test], y[~test], spk[~test], widths, C)
            acc.append(np.mean(fitted(F[test]) == y[test]))
        scores.append(np.mean(acc))
    return fit_fixed(system, F, y, spk, widths, grid[int(np.argmax(scores))])


# --------------------------------------------------------------------------- evaluation
def corpora(ravdess: Path, emodb: Path, cache: Path) -> dict:
    """RAVDESS then EmoDB, side by side.

    Returns
    -------
    dict
        ``F`` (n, n_functionals), ``frames``, ``y`` (EmoDB's labels in RAVDESS' names),
        ``spk`` (``r01``..., ``e03``...), ``ravdess`` (bool mask), ``name`` and ``cache``
        (the words' cache), ``r_utt`` (RAVDESS' audio).
    """
    r_utt, r_y, r_actor, _ = load_ravdess(ravdess)
    r_F, r_frames = described("ravdess", r_utt, cache)
    e_utt, e_y, e_spk = load_emodb(emodb)
    e_F, e_frames = described("emodb", e_utt, cache)
    e_y = np.array([EMODB_TO_RAVDESS.get(v, "emodb-" + v) for v in e_y])
    c = dict(F=np.vstack([r_F, e_F]), frames=r_frames + e_frames,
                y=np.concatenate([r_y, e_y]),
                spk=np.array([f"r{a}" for a in r_actor] + [f"e{s}" for s in e_spk]),
                ravdess=np.arange(len(r_utt) + len(e_utt)) < len(r_utt), cache=cache)
    c["name"] = f"ravdess+emodb-{r_F.shape[0]}-{e_F.shape[0]}"
    c["r_utt"] = r_utt
    return c


def speed_copies(c: dict, factors) -> tuple:
    """Speed-perturbed copies of the RAVDESS utterances (:func:`speed_perturb`, as
    ``scripts/eval_emotion_augment.py``), described and cached.

    Returns
    -------
    F : np.ndarray, shape (len(factors) * 720, n_functionals)
    frames : list of np.ndarray
    y, spk : np.ndarray, shape (len(factors) * 720,)
        Labels, and speakers named ``r01@0.9``: a perturbed actor is another speaker.
    """
    parts = []
    for f in factors:
        utt = [(speed_perturb(a, sr, f).astype(np.float32), sr) for a, sr in c["r_utt"]]
        parts.append(described(f"ravdess-speed{f}", utt, c["cache"]))
    rav = c["ravdess"]
    return (np.vstack([F for F, _ in parts]), [x for _, fr in parts for x in fr],
            np.tile(c["y"][rav], len(factors)),
            np.concatenate([[f"{s}@{f}" for s in c["spk"][rav]] for f in factors]))


def matrix(c: dict, system: dict, train: np.ndarray, extra=None):
    """The system's features for every utterance (then ``extra``'s, a
    :func:`speed_copies`), words learned on ``train``."""
    F, frames, name = c["F"], c["frames"], c["name"]
    if extra is not None:
        F, frames, name = np.vstack([F, extra[0]]), frames + extra[1], name + "-speed"
    if not system.get("words", True):
        return F, None
    W = fold_words(name, frames, train, c["cache"])
    return np.hstack([F, W]), (F.shape[1], W.shape[1])


def leave_actors_out(c: dict, system: dict) -> dict:
    """The six folds, 8 and 4 emotions, one utterance and grouped."""
    y, spk, rav = c["y"], c["spk"], c["ravdess"]
    extra = speed_copies(c, system["speed"]) if system.get("speed") else None
    if extra is not None:  # the copies after the corpora; trained on, never tested
        n = extra[0].shape[0]
        y, spk = np.concatenate([y, extra[2]]), np.concatenate([spk, extra[3]])
        rav = np.concatenate([rav, np.zeros(n, dtype=bool)])
    out = {"per_fold": []}
    pooled = {key: ([], []) for key in ("8 one", "8 grouped", "4 one", "4 grouped")}
    for held in FOLDS:
        test = rav & np.isin(spk, [f"r{a}" for a in held])
        train_base = rav & ~test
        X, widths = matrix(c, system, np.flatnonzero(train_base), extra)
        if extra is not None:
            actor = np.array([s.split("@")[0] for s in spk])
            train_base = train_base | (np.char.find(spk.astype(str), "@") >= 0) & np.isin(
                actor, spk[train_base])
        inner = [[f"r{a}" for a in pair] for pair in FOLDS if pair != held]
        fold = {}
        for n, labels in (("8", None), ("4", FOUR)):
            train = train_base | (~rav & np.isin(y, list(EMODB_TO_RAVDESS.values()))
                                  if system.get("emodb") else np.zeros_like(rav))
            te = test
            if labels is not None:
                train, te = train & np.isin(y, labels), te & np.isin(y, labels)
            fitted = fit_system(system, X[train], y[train], spk[train], widths, inner)
            for mode, who in (("one", None), ("grouped", spk[te])):
                pred = fitted(X[te], who)
                pooled[f"{n} {mode}"][0].append(y[te])
                pooled[f"{n} {mode}"][1].append(pred)
                fold[f"{n} {mode}"] = float(np.mean(pred == y[te]) * 100)
        out["per_fold"].append(fold)
    for key, (truth, pred) in pooled.items():
        truth, pred = np.concatenate(truth), np.concatenate(pred)
        out[key] = float(np.mean(truth == pred) * 100)
        out[key + " sd"] = float(np.std([f[key] for f in out["per_fold"]]))
        out[key + " recall"] = {e: float(np.mean(pred[truth == e] == e) * 100)
                                for e in np.unique(truth)}
        labels = np.unique(truth)  # rows: truth, columns: predicted, in this order
        out[key + " confusion"] = [[int(np.sum((truth == t) & (pred == p))) for p in labels]
                                   for t in labels]
    return out


def across(c: dict, system: dict) -> dict:
    """Learnt on one corpus (all of it), tested on the other: the shared emotions."""
    y, spk, rav = c["y"], c["spk"], c["ravdess"]
    shared = np.isin(y, list(EMODB_TO_RAVDESS.values()))
    out = {}
    for name, src in (("ravdess->emodb", rav), ("emodb->ravdess", ~rav)):
        train, test = src & shared, ~src & shared
        X, widths = matrix(c, system, np.flatnonzero(train))
        fitted = fit_fixed(system, X[train], y[train], spk[train], widths)
        for mode, who in (("one", None), ("grouped", spk[test])):
            pred = fitted(X[test], who)
            neutral = y[test] == "neutral"
            out[f"{name} {mode}"] = float(np.mean(pred == y[test]) * 100)
            out[f"{name} {mode} neutral"] = float(np.mean(pred[neutral] == "neutral") * 100)
    return out


def emodb_loso(c: dict, system: dict) -> dict:
    """EmoDB's own leave-one-speaker-out, 7 emotions (the results page's protocol with
    this system's fixed C: no nesting), grouped and one utterance."""
    y, spk, emo = c["y"], c["spk"], ~c["ravdess"]
    preds = {"one": [], "grouped": []}
    for s in np.unique(spk[emo]):
        test, train = spk == s, emo & (spk != s)
        X, widths = matrix(c, system, np.flatnonzero(train))
        fitted = fit_fixed(system, X[train], y[train], spk[train], widths)
        preds["one"].append(np.mean(fitted(X[test]) == y[test]) * 100)
        preds["grouped"].append(np.mean(fitted(X[test], spk[test]) == y[test]) * 100)
    # mean and s.d. over the speakers, as the results page's EmoDB figures
    out = {f"emodb loso {m}{stat}": float(f(p)) for m, p in preds.items()
           for stat, f in (("", np.mean), (" sd", np.std))}
    out.update({f"emodb loso {m} per speaker": [float(v) for v in p]
                for m, p in preds.items()})
    return out


# --------------------------------------------------------------------------- report
COLUMNS = (("8 one", "8 emo, one"), ("4 one", "4 emo, one"), ("8 grouped", "8 emo, grouped"),
           ("4 grouped", "4 emo, grouped"), ("min recall", "lowest recall (8, one)"),
           ("ravdess->emodb one", "R->E one"), ("ravdess->emodb one neutral", "R->E neutral"),
           ("emodb->ravdess one", "E->R one"), ("emodb->ravdess one neutral", "E->R neutral"),
           ("emodb loso grouped", "EmoDB LOSO"), ("emodb loso one", "EmoDB LOSO, one"))


def print_table(rows: dict) -> None:
    print("| system | " + " | ".join(title for _, title in COLUMNS) + " |")
    print("|---" * (len(COLUMNS) + 1) + "|")
    for name, r in rows.items():
        cells = [f"{r[k]:.1f}" if k in r else "" for k, _ in COLUMNS]
        print(f"| {name} | " + " | ".join(cells) + " |")
    for name, r in rows.items():
        recall = r.get("8 one recall", {})
        print(f"{name}: recall (8 emotions, one utterance): "
              + ", ".join(f"{e} {v:.0f}" for e, v in recall.items()))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--ravdess", type=Path, default=ROOT / "ravdess")
    parser.add_argument("--emodb", type=Path, default=ROOT / "emodb")
    parser.add_argument("--cache", type=Path, default=DEFAULT_CACHE)
    parser.add_argument("--systems", nargs="+", default=list(SYSTEMS), choices=list(SYSTEMS))
    parser.add_argument("--no-emodb-loso", action="store_true",
                        help="skip EmoDB's own leave-one-speaker-out rows")
    parser.add_argument("--json", type=Path, help="write every figure here")
    args = parser.parse_args()
    for folder in (args.ravdess, args.emodb):
        if not folder.is_dir():
            print(f"eval_emotion_ravdess: no such folder: {folder}", file=sys.stderr)
            return 2
    t0 = time.perf_counter()
    c = corpora(args.ravdess, args.emodb, args.cache)
    rows = {}
    for name in args.systems:
        system, t = SYSTEMS[name], time.perf_counter()
        r = leave_actors_out(c, system)
        r["min recall"] = min(r["8 one recall"].values())
        r.update(across(c, system))
        if not args.no_emodb_loso and not system.get("emodb"):
            r.update(emodb_loso(c, system))
        r["seconds"] = time.perf_counter() - t
        rows[name] = r
        print(f"{name}: {r['8 one']:.1f} / {r['4 one']:.1f} one utterance, "
              f"{r['8 grouped']:.1f} / {r['4 grouped']:.1f} grouped "
              f"({r['seconds']:.0f} s)", file=sys.stderr)
    print("RAVDESS actors 01-12, leave two actors out (6 folds, one male and one female "
          "actor each); accuracy % pooled over the folds")
    print_table(rows)
    if args.json:
        args.json.write_text(json.dumps({"split": "leave-2-actors-out, 6 folds by sex",
                                         "folds": FOLDS, "systems": rows,
                                         "seconds": time.perf_counter() - t0}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
