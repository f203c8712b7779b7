"""Audio-to-motion regressors on FACEGOOD, leave one clip out: how far a statistical map
alone gets, linear or not, on the guide's features.

Usage::

    python scripts/diag_audio_regressors.py [--models ridge mlp nystroem]

Features at every motion frame (30 fps), each at 11 offsets over +-200 ms (as ppg-ridge,
:mod:`animegraph.baselines.ppg_forward`): ``ppg`` (hama's posteriorgram, the CTC blank and
the relative loudness: ppg-ridge's input), ``mfcc`` (13 MFCCs over 25 ms every 10 ms,
mean and variance normalised per clip), and both. Targets: every channel, standardised.
Models: ridge with generalised cross-validation over 10^-2..10^6 (ppg-ridge's rule); an
MLP of 256 ReLU units (scikit-learn, L2 10^-2, early stopping, seed 0); an RBF
kernel approximation (PCA to 100, Nystroem 1,500 components, gamma 1/100, then the
ridge). Printed: the mean over the 5 folds of the held-out clip's mouth-opening R
(:func:`animegraph.motion.measures.mouth_opening`, Pearson) and each fold's.

A diagnostic, not a system: none of these is a guide of ``synth``. The settings were set
once, before the run, not tuned.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from animegraph.baselines.base import sample_times
from animegraph.baselines.data import training_set
from animegraph.baselines.ppg_forward import _at, context_offsets, ppg_features
from animegraph.motion.measures import mouth_opening, pearson
from ingest.pipeline import IngestConfig, prepare_sources
from ingest.readers import discover

FACEGOOD = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "facegood"
RATE = 30.0  # FACEGOOD's frame rate
MFCC_HOP_S = 0.01
ALPHAS = np.logspace(-2, 6, 17)


def mfcc_features(audio: np.ndarray, sample_rate: int, times: np.ndarray) -> np.ndarray:
    """13 MFCCs, normalised per clip, at ``times`` +- 200 ms: shape (len(times), 143)."""
    import librosa

    win = int(sample_rate * 0.025)
    m = librosa.feature.mfcc(y=audio.astype(np.float32), sr=sample_rate, n_mfcc=13,
                             hop_length=int(sample_rate * MFCC_HOP_S), n_fft=2 * win,
                             win_length=win, center=False).T
    m = (m - m.mean(0)) / (m.std(0) + 1e-9)
    return np.concatenate([_at(m, MFCC_HOP_S, times + o)
                           for o in context_offsets(0.2, 0.04)], axis=1)


def models(names: list[str]) -> dict:
    from sklearn.decomposition import PCA
    from sklearn.kernel_approximation import Nystroem
    from sklearn.linear_model import RidgeCV
    from sklearn.neural_network import MLPRegressor
    from sklearn.pipeline import make_pipeline

    made = {
        "ridge": lambda: RidgeCV(alphas=ALPHAS),
        "mlp": lambda: MLPRegressor(hidden_layer_sizes=(256,), alpha=1e-2,
                                    early_stopping=True, random_state=0, max_iter=200),
        "nystroem": lambda: make_pipeline(
            PCA(100, random_state=0),
            Nystroem(gamma=1 / 100, n_components=1500, random_state=0),
            RidgeCV(alphas=ALPHAS)),
    }
    return {name: made[name] for name in names}


def loco(data: list[dict], feature: str, make, names, kind) -> list[float]:
    """Held-out mouth-opening R of each fold (one clip out)."""
    rs = []
    for k, held in enumerate(data):
        train = [d for i, d in enumerate(data) if i != k]
        x = np.concatenate([d[feature] for d in train])
        y = np.concatenate([d["motion"] for d in train])
        xm, xs = x.mean(0), x.std(0)
        xs[xs == 0] = 1
        ym, ys = y.mean(0), y.std(0)
        ys[ys == 0] = 1
        fitted = make().fit((x - xm) / xs, (y - ym) / ys)
        pred = fitted.predict((held[feature] - xm) / xs) * ys + ym
        rs.append(pearson(mouth_opening(pred, names, kind),
                          mouth_opening(held["motion"], names, kind)))
    return rs


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", nargs="+", default=["ridge", "mlp", "nystroem"],
                        choices=["ridge", "mlp", "nystroem"])
    args = parser.parse_args(argv)
    if not FACEGOOD.is_dir():
        print(f"diag_audio_regressors: {FACEGOOD} not found (the shared data)",
              file=sys.stderr)
        return 1
    clips, _ = prepare_sources(discover([FACEGOOD]), IngestConfig(), workers=1)
    ts = training_set(clips)
    data = []
    for clip, times, motion in sample_times(ts.clips, RATE):
        ppg = ppg_features(clip.audio, clip.sample_rate, times)
        mfcc = mfcc_features(clip.audio, clip.sample_rate, times)
        data.append({"motion": motion, "ppg": ppg, "mfcc": mfcc,
                     "ppg+mfcc": np.hstack([ppg, mfcc])})
    print("| model | features | mouth R (mean of 5 folds) | folds | s |")
    print("|---|---|---|---|---|")
    for name, make in models(args.models).items():
        for feature in ("ppg", "mfcc", "ppg+mfcc"):
            t0 = time.perf_counter()
            rs = loco(data, feature, make, ts.names, ts.kind)
            print(f"| {name} | {feature} | {np.mean(rs):.3f} | "
                  f"{' '.join(f'{r:.3f}' for r in rs)} | {time.perf_counter() - t0:.0f} |",
                  flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
