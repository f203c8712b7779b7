"""``ppg-ridge``: motion as a ridge regression of phonetic posteriorgrams (beyond the papers).

Not one of the three papers Cao et al. is measured against: a speaker-independent
statistical mapping added as a **guide** for the audio-only path
(:mod:`animegraph.synthesis.guide`), and measured beside them as a row of its own.

Why: the papers' mappings hear speech through spectral features (MFCCs), which carry
the speaker and the channel as much as the phone, so a mapping fitted on one voice is a
weak guide for another (mu-mlp across talkingface's speakers, docs/results.md). Speech-
driven animation that must hold across speakers maps the output of a speech
*recogniser's* acoustic model instead: VOCA (D. Cudeiro, T. Bolkart, C. Laidlaw,
A. Ranjan & M. J. Black, "Capture, learning, and synthesis of 3D speaking styles",
CVPR 2019, §4) feeds DeepSpeech's per-frame character distributions to its decoder for
that reason, and voice conversion maps *phonetic posteriorgrams* (PPGs) for the same one
(L. Sun, K. Li, H. Wang, S. Kang & H. Meng, "Phonetic posteriorgrams for many-to-one voice
conversion without parallel data training", ICME 2016). Here:

* **Features** (:func:`.ppg_forward.ppg_features`), at each motion frame: the hama
  posteriorgram (:mod:`ingest.speech.posteriorgram`: CTC blank removed, renormalised over
  the 39 phones), the blank's own probability (a frame between phones), and the frame's
  log loudness relative to the clip's loud frames (:data:`.ppg_forward.LOUD_PERCENTILE`:
  gain-free, so a quiet microphone is not a closed mouth), each at every
  :data:`.ppg_forward.CONTEXT_STEP_S` within ±:data:`.ppg_forward.CONTEXT_S` of the frame
  (about a syllable each side: coarticulation reaches that far, and the within-clip
  reference of ``scripts/diag_within_clip.py`` uses the same ±200 ms).
* **Mapping**: one affine map to every motion channel, fitted by ridge regression on
  standardised features and channels (motion sampled at most at the posteriorgram's
  50 frames a second), its penalty chosen from :data:`ALPHAS` by the exact
  leave-one-out error (Golub, Heath & Wahba 1979; scikit-learn's ``RidgeCV``, computed
  here by :func:`ridge_loo`), so nothing is tuned by hand. Stored as its coefficients;
  prediction is NumPy only (:class:`.ppg_forward.StoredPpgRidge`).

The settings were fixed before the lip-sync evaluation and not tuned on it (the range of
penalties was widened once, when the first one's largest value was chosen). The model has
no notion of emotion (``emotion`` is ignored) and needs ``hama`` (a core dependency).
"""

from __future__ import annotations

import sys
from concurrent.futures import ThreadPoolExecutor
from typing import ClassVar

import numpy as np

from animegraph.baselines.base import BaselineModel, check_enough, sample_times
from animegraph.baselines.data import TrainingSet
from animegraph.baselines.ppg_forward import (
    CONTEXT_S,
    CONTEXT_STEP_S,
    PpgForward,
    n_offsets,
    stored_posteriors,
)
from db.system import usable_cpus
from ingest.speech import ctc

#: Ridge penalties tried by generalised cross-validation (standardised data).
ALPHAS = tuple(float(a) for a in np.logspace(-2, 6, 17))


class PpgRidge(PpgForward, BaselineModel):
    """Motion as a ridge regression of the speech's posteriorgram and loudness in context.

    Parameters
    ----------
    context_s : float
        Context each side of a frame (s), default :data:`.ppg_forward.CONTEXT_S`.
    step_s : float
        Step between context frames (s), default :data:`.ppg_forward.CONTEXT_STEP_S`.

    Attributes
    ----------
    coef_ : np.ndarray, shape (1 + n_features, n_channels)
        Intercept row, then one row per feature (raw, not standardised).
    alpha_ : float
        The penalty generalised cross-validation chose.
    """

    method: ClassVar[str] = "ppg-ridge"

    def __init__(self, context_s: float = CONTEXT_S, step_s: float = CONTEXT_STEP_S):
        self.context_s = context_s
        self.step_s = step_s

    def _fit(self, data: TrainingSet) -> None:
        from tqdm import tqdm

        n_offsets(self.context_s, self.step_s)  # ParameterError on a bad context
        # No more motion frames than the posteriorgram has (50 a second): a 120 fps
        # capture's extra frames repeat what their neighbours say, at 2.4 x the memory.
        rate = min(float(data.fps), float(ctc.FRAME_RATE))
        samples = list(sample_times(data.clips, rate))

        def features(sample) -> np.ndarray:
            clip, times, _ = sample
            return self.features(clip.audio, clip.sample_rate, times,
                                 stored=stored_posteriors(clip))

        # hama hears every clip whose posteriors ingest did not store (about 0.1 s a
        # second of speech, on one core a call): the clips on one thread per core, in
        # order, with a bar on a terminal.
        with ThreadPoolExecutor(usable_cpus(), thread_name_prefix="ppg-ridge") as pool:
            x = list(tqdm(pool.map(features, samples), total=len(samples), unit="clip",
                          desc="ppg-ridge: phone posteriors", leave=False, disable=None,
                          file=sys.stderr, dynamic_ncols=True))
        x, y = np.concatenate(x), np.concatenate([motion for _, _, motion in samples])
        del samples
        check_enough(len(x), x.shape[1] + 1, "the ppg-ridge mapping")
        # Standardised both ways, so that the penalty treats every feature alike and the
        # cross-validation weighs every channel alike; then mapped back to raw units.
        x_mean, x_sd = x.mean(axis=0), x.std(axis=0)
        x_sd[x_sd == 0] = 1.0
        y_mean, y_sd = y.mean(axis=0), y.std(axis=0)
        y_sd[y_sd == 0] = 1.0
        self.alpha_, weights = ridge_loo((x - x_mean) / x_sd, (y - y_mean) / y_sd, ALPHAS)
        weights = weights / x_sd[:, None] * y_sd[None, :]  # (n_features, n_channels)
        self.coef_ = np.vstack([y_mean - x_mean @ weights, weights])


def ridge_loo(x: np.ndarray, y: np.ndarray, alphas) -> tuple[float, np.ndarray]:
    """Ridge regression with an intercept, its penalty chosen by leave-one-out error.

    The criterion and the solution of scikit-learn's ``RidgeCV`` (its default ``cv=None``:
    the exact leave-one-out error of every sample, summed over the targets; Golub,
    Heath & Wahba 1979; Rifkin & Lippert 2007), computed through one eigendecomposition
    of the features' Gram matrix: with ``Z = X V`` (``XᵀX = V diag(s²) Vᵀ``) the fitted
    values are ``Z (Zᵀy / (s² + α))`` and the leverages ``1/n + (Z ∘ Z) 1/(s² + α)``,
    a matrix product for each penalty. No division by a singular value, so the features
    may be collinear. RidgeCV recomputes the leverages' squares for every penalty; on
    the ppg-ridge fit of the demo database (49,500 frames, 451 features, 216 channels)
    choosing the penalty took it 20.5 s, this 9.8 s, for the same penalty and
    coefficients (docs/results/speed.md, "Start-up").

    Parameters
    ----------
    x : np.ndarray, shape (n_samples, n_features)
        Centred features (each column's mean 0).
    y : np.ndarray, shape (n_samples, n_targets)
        Centred targets.
    alphas : sequence of float
        Penalties to try (> 0); the first of the lowest error is taken.

    Returns
    -------
    alpha : float
    weights : np.ndarray, shape (n_features, n_targets)
        The coefficients at ``alpha`` (the intercept is 0 for centred data).
    """
    n = len(x)
    gram = x.T @ x
    s2, v = np.linalg.eigh(gram)
    s2 = np.maximum(s2, 0.0)  # rounding can leave a null direction slightly negative
    z = x @ v  # (n, p): the data in the principal directions
    zty = v.T @ (x.T @ y)  # (p, t)
    z2 = z * z
    best, best_error = None, np.inf
    for alpha in alphas:
        scale = 1.0 / (s2 + alpha)
        leverage = 1.0 / n + z2 @ scale  # the intercept's own 1/n: y is centred
        residual = y - z @ (scale[:, None] * zty)
        error = float(np.mean((residual / (1.0 - leverage)[:, None]) ** 2))
        if error < best_error:
            best, best_error = float(alpha), error
    return best, v @ (zty / (s2 + best)[:, None])

