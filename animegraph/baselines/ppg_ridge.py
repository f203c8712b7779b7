"""``ppg-ridge``: motion as a ridge regression of phonetic posteriorgrams (beyond the papers).

Not one of the three papers Cao et al. is measured against: a speaker-independent
statistical mapping added as a **guide** for the audio-only path
(:mod:`animegraph.synthesis.guide`), and measured beside them as a row of its own.

Why: the papers' mappings hear speech through spectral features (MFCCs), which carry
the speaker and the channel as much as the phone, so a mapping fitted on one voice is a
weak guide for another (mu-mlp across talkingface's speakers, docs/results/lipsync.md,
"talkingface"). Speech-
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

import contextvars
import sys
from concurrent.futures import ThreadPoolExecutor
from typing import ClassVar

import numpy as np

from animegraph.baselines.base import BaselineModel, check_enough, clip_times
from animegraph.baselines.data import TrainingSet, resample_to
from animegraph.baselines.ppg_forward import (
    CONTEXT_S,
    CONTEXT_STEP_S,
    PpgForward,
    n_offsets,
    stored_posteriors,
)
from db.errors import ParameterError
from db.system import usable_cpus
from ingest.speech import ctc

#: Ridge penalties tried by leave-one-out error (standardised data).
ALPHAS = tuple(float(a) for a in np.logspace(-2, 6, 17))
#: How :func:`ridge_loo` searches :data:`ALPHAS`: from generalised cross-validation's
#: choice downhill (the default), or every penalty (the fit before that search).
SEARCHES = ("local", "all")


class PpgRidge(PpgForward, BaselineModel):
    """Motion as a ridge regression of the speech's posteriorgram and loudness in context.

    Parameters
    ----------
    context_s : float
        Context each side of a frame (s), default :data:`.ppg_forward.CONTEXT_S`.
    step_s : float
        Step between context frames (s), default :data:`.ppg_forward.CONTEXT_STEP_S`.
    alpha_search : {"local", "all"}
        How the penalty is searched (:func:`ridge_loo`): ``"local"`` tries the penalties
        from generalised cross-validation's choice downhill in leave-one-out error,
        ``"all"`` every one of :data:`ALPHAS` (the same choice whenever the error falls
        and then rises along them, at about five times the cost).

    Attributes
    ----------
    coef_ : np.ndarray, shape (1 + n_features, n_channels)
        Intercept row, then one row per feature (raw, not standardised).
    alpha_ : float
        The penalty generalised cross-validation chose.
    """

    method: ClassVar[str] = "ppg-ridge"

    def __init__(self, context_s: float = CONTEXT_S, step_s: float = CONTEXT_STEP_S,
                 alpha_search: str = "local"):
        self.context_s = context_s
        self.step_s = step_s
        self.alpha_search = alpha_search

    def _fit(self, data: TrainingSet) -> None:
        from tqdm import tqdm

        n_offsets(self.context_s, self.step_s)  # ParameterError on a bad context
        if self.alpha_search not in SEARCHES:
            raise ParameterError(f"alpha_search must be one of {', '.join(SEARCHES)}, got "
                                 f"{self.alpha_search!r}")
        # No more motion frames than the posteriorgram has (50 a second): a 120 fps
        # capture's extra frames repeat what their neighbours say, at 2.4 x the memory.
        rate = min(float(data.fps), float(ctc.FRAME_RATE))
        # The motion straight into one array (GRID s1: 60,000 frames of 1,411 channels,
        # 0.7 GB in float64), and the clips' times kept for their features.
        samples = [(clip, clip_times(clip, rate)) for clip in data.clips]
        y = np.empty((sum(len(t) for _, t in samples), len(data.names)))
        row = 0
        for clip, times in samples:
            y[row:row + len(times)] = resample_to(clip.motion, clip.fps, times)
            row += len(times)

        def features(sample) -> np.ndarray:
            clip, times = sample
            return self.features(clip.audio, clip.sample_rate, times,
                                 stored=stored_posteriors(clip))

        # hama hears every clip whose posteriors ingest did not store (about 0.1 s a
        # second of speech, on one core a call): the clips on one thread per core, in
        # order, with a bar on a terminal.
        # Each clip in a copy of this context: a pool's threads do not inherit it, and
        # hama keeps its outputs on disk only where the caller asked (ctc.kept_on_disk).
        jobs = [(contextvars.copy_context(), sample) for sample in samples]
        with ThreadPoolExecutor(usable_cpus(), thread_name_prefix="ppg-ridge") as pool:
            x = list(tqdm(pool.map(lambda job: job[0].run(features, job[1]), jobs),
                          total=len(samples), unit="clip",
                          desc="ppg-ridge: phone posteriors", leave=False, disable=None,
                          file=sys.stderr, dynamic_ncols=True))
        x = np.concatenate(x)
        del samples, jobs
        check_enough(len(x), x.shape[1] + 1, "the ppg-ridge mapping")
        # Standardised both ways, so that the penalty treats every feature alike and the
        # cross-validation weighs every channel alike; then mapped back to raw units.
        # In place: a copy of the motion is another 0.7 GB on GRID s1.
        x_mean, x_sd = x.mean(axis=0), x.std(axis=0)
        x_sd[x_sd == 0] = 1.0
        y_mean, y_sd = y.mean(axis=0), y.std(axis=0)
        y_sd[y_sd == 0] = 1.0
        x -= x_mean
        x /= x_sd
        y -= y_mean
        y /= y_sd
        self.alpha_, weights = ridge_loo(x, y, ALPHAS, search=self.alpha_search)
        del x, y
        weights = weights / x_sd[:, None] * y_sd[None, :]  # (n_features, n_channels)
        self.coef_ = np.vstack([y_mean - x_mean @ weights, weights])


def ridge_loo(x: np.ndarray, y: np.ndarray, alphas, *, search: str = "local",
              ) -> tuple[float, np.ndarray]:
    """Ridge regression with an intercept, its penalty chosen by leave-one-out error.

    The criterion and the solution of scikit-learn's ``RidgeCV`` (its default ``cv=None``:
    the exact leave-one-out error of every sample, summed over the targets; Golub,
    Heath & Wahba 1979; Rifkin & Lippert 2007), computed through one eigendecomposition
    of the features' Gram matrix: with ``Z = X V`` (``XᵀX = V diag(s²) Vᵀ``) the fitted
    values are ``Z (Zᵀy / (s² + α))`` and the leverages ``1/n + (Z ∘ Z) 1/(s² + α)``.
    No division by a singular value, so the features may be collinear.

    A penalty's leave-one-out error needs every sample's residual norm, a product of
    the data with the coefficients (n x p x t multiply-adds) for each penalty tried;
    with more targets than features it is taken instead from ``‖y_i‖²``,
    ``y_i · ŷ_i`` (one product ``y (Zᵀy)ᵀ`` for all penalties) and ``‖ŷ_i‖²`` (a
    quadratic form in the p x p matrix ``(Zᵀy)(Zᵀy)ᵀ``). And ``search="local"`` does
    not try every penalty: it starts at the one generalised cross-validation chooses
    (GCV, Golub, Heath & Wahba 1979: the total residual and the trace of the hat
    matrix, a few operations per singular value, no pass over the data) and moves to
    the neighbouring penalty while that one's leave-one-out error is lower, so it
    takes the same penalty as ``"all"`` whenever the error falls and then rises along
    ``alphas`` (it usually tries three or four). On GRID s1's database (60,000 frames,
    451 features, 1,411 channels) the whole fit took 9.3 CPU-s so, 16.5 with every
    penalty tried, for the same penalty and coefficients (docs/results/speed.md, "The
    guides' fit on GRID s1").

    Parameters
    ----------
    x : np.ndarray, shape (n_samples, n_features)
        Centred features (each column's mean 0).
    y : np.ndarray, shape (n_samples, n_targets)
        Centred targets.
    alphas : sequence of float
        Penalties to try (> 0); the first (smallest) of the lowest error is taken.
    search : {"local", "all"}
        Try the penalties from GCV's choice downhill, or every one of them.

    Returns
    -------
    alpha : float
    weights : np.ndarray, shape (n_features, n_targets)
        The coefficients at ``alpha`` (the intercept is 0 for centred data).
    """
    if search not in SEARCHES:
        raise ParameterError(f"search must be one of {', '.join(SEARCHES)}, got {search!r}")
    alphas = sorted(float(a) for a in alphas)
    n, p = x.shape
    t = y.shape[1]
    s2, v = np.linalg.eigh(x.T @ x)
    s2 = np.maximum(s2, 0.0)  # rounding can leave a null direction slightly negative
    z = x @ v  # (n, p): the data in the principal directions
    zty = z.T @ y  # (p, t)
    z2 = z * z
    by_norms = t > p
    if by_norms:
        yy = np.einsum("ij,ij->i", y, y)
        y_zty = y @ zty.T  # (n, p): y_i · (Zᵀy)_k
        zty_gram = zty @ zty.T  # (p, p)
    errors: dict[int, float] = {}

    def loo(i: int) -> float:
        if i not in errors:
            scale = 1.0 / (s2 + alphas[i])
            leverage = 1.0 / n + z2 @ scale  # the intercept's own 1/n: y is centred
            if by_norms:
                zs = z * scale
                rss = (yy - 2.0 * np.einsum("ij,ij->i", zs, y_zty)
                       + np.einsum("ij,ij->i", zs @ zty_gram, zs))
                rss = np.maximum(rss, 0.0)
            else:
                residual = y - z @ (scale[:, None] * zty)
                rss = np.einsum("ij,ij->i", residual, residual)
            errors[i] = float(np.sum(rss / (1.0 - leverage) ** 2) / (n * t))
        return errors[i]

    if search == "all":
        k = int(np.argmin([loo(i) for i in range(len(alphas))]))
    else:
        yy_all = float(np.einsum("ij,ij->", y, y))
        k = int(np.argmin([_gcv(s2, zty, yy_all, n, a) for a in alphas]))
        while k > 0 and loo(k - 1) <= loo(k):
            k -= 1
        while k + 1 < len(alphas) and loo(k + 1) < loo(k):
            k += 1
    best = alphas[k]
    return best, v @ (zty / (s2 + best)[:, None])


def _gcv(s2: np.ndarray, zty: np.ndarray, yy: float, n: int, alpha: float) -> float:
    """Generalised cross-validation error of the ridge of :func:`ridge_loo` at ``alpha``
    from its eigenvalues ``s2`` (p,), ``Zᵀy`` (p, t) and ``‖y‖²``: the residual
    ``‖y‖² - 2 Σ g ‖Zᵀy‖² + Σ g² s² ‖Zᵀy‖²`` (``g = 1/(s² + α)``) over
    ``n (1 - tr H / n)²``, the intercept counted in ``tr H``."""
    g = 1.0 / (s2 + alpha)
    m2 = np.einsum("ij,ij->i", zty, zty)
    rss = yy - 2.0 * np.sum(g * m2) + np.sum(g * g * s2 * m2)
    return float(rss / (n * (1.0 - (1.0 + np.sum(s2 * g)) / n) ** 2))
