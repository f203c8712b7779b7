"""Emotion classification of speech: one estimator from audio to emotion (Cao et al. 2005,
§6, Table I; issue #16).

:class:`EmotionClassifier` holds the whole pipeline -- input handling
(:mod:`ingest.emotion.audio`), features (:mod:`ingest.emotion.features`), per-speaker
normalisation (:mod:`ingest.emotion.speakers`), scaling to ``[-1, 1]`` and a Support Vector
Machine (Libsvm's C-SVC, one-vs-one, as the paper) -- and stores it as plain arrays.

Defaults are what measures best on EmoDB with every choice nested inside the training
folds (``scripts/eval_emotion.py``, ``docs/results.md`` "Emotion classification (issue
#16)"); the paper's configuration stays one call away, :meth:`EmotionClassifier.paper`:
mean, variance and RMS of the signal and its first 500 real-cepstrum coefficients, a
linear kernel, no speaker normalisation.

Probabilities (``probability=True``, what ``ingest`` stores for ``classify`` and
``synth --emotion auto``) come from a multinomial logistic regression fitted on
*out-of-fold* SVM decision values (stacked Platt scaling; ``SVC(probability=True)`` is
deprecated); without them :meth:`~EmotionClassifier.fit` fits the SVM once.
"""

from __future__ import annotations

import json
import logging
from typing import NamedTuple

import numpy as np
from scipy.sparse import issparse
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.linear_model import LogisticRegression
from sklearn.model_selection import StratifiedKFold
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import FunctionTransformer, MinMaxScaler
from sklearn.svm import SVC
from sklearn.utils.metaestimators import available_if
from sklearn.utils.multiclass import check_classification_targets
from sklearn.utils.validation import check_array, check_is_fitted, column_or_1d

from db.errors import DataError, ParameterError
from ingest.emotion.audio import FEATURE_SAMPLE_RATE, MIN_DURATION, utterances
from ingest.emotion.boaw import ENSEMBLE, BagOfAudioWords
from ingest.emotion.emodb import EMODB_EMOTIONS, load_emodb
from ingest.emotion.features import (
    N_CEPSTRUM,
    SILENCE_FLOOR,
    WORDS_BLOCK,
    block_features,
    emotion_features,
    parse_features,
    real_cepstrum,
    rich_features,
)
from ingest.emotion.speakers import SpeakerNormalizer, speaker_normalize

__all__ = [
    "CLASSIFIER_FORMAT",
    "DEFAULT_C",
    "DEFAULT_FEATURES",
    "EMODB_EMOTIONS",
    "FEATURE_SAMPLE_RATE",
    "FUNCTIONALS",
    "MIN_DURATION",
    "N_CEPSTRUM",
    "SILENCE_FLOOR",
    "EmotionClassifier",
    "SpeechFeatures",
    "emotion_features",
    "load_emodb",
    "real_cepstrum",
    "rich_features",
    "speaker_normalize",
]

#: Kernel the paper settles on (§6, Table I); also the best measured with the default
#: features.
KERNEL = "linear"
#: Feature blocks of the default pipeline (measured best, docs/results.md issue #16:
#: the functionals and the bag-of-audio-words, "Issue 16, fourth session"; its ensemble
#: of codebooks, ``n_codebooks``, "Issue 16, fifth session").
DEFAULT_FEATURES = "rich+cepstrum+boaw"
#: The functionals alone (the default until issue #16's fourth session).
FUNCTIONALS = "rich+cepstrum"
#: SVM penalty of the default pipeline (the value nested tuning picks on EmoDB).
DEFAULT_C = 0.1
#: Version of the stored arrays; older databases hold none and must be re-ingested.
#: Format 2: no block weights; 3: ``block_widths``; 4: the fitted block widths
#: (``block_widths_fitted``, when any) and the bag-of-audio-words' codebooks (``boaw_*``,
#: when the ``boaw`` block is used); 5 (what is written): ``n_codebooks`` and the
#: ensemble's codebooks (``boaw_n_codebooks``, ``boaw_codebook0`` ... ``2K - 1``); 6 (what
#: is written): features with the silence floor, ``silence_floor`` (absent: None).
#: Formats 2 to 5 were fitted on features without the floor, and are read with
#: ``silence_floor=None`` (predicting as they did) and a warning.
CLASSIFIER_FORMAT = 6
#: Formats :meth:`EmotionClassifier.from_arrays` reads.
READABLE_FORMATS = (2, 3, 4, 5, 6)
#: The first format whose features have the silence floor.
SILENCE_FLOOR_FORMAT = 6

logger = logging.getLogger(__name__)

_KERNELS = ("linear", "rbf", "poly", "sigmoid")

_NORMALIZE = ("speaker", "none")


def block_weights(widths, total: float | None = None) -> np.ndarray:
    """Column weights giving every block of columns the same share of the variance.

    Block b of ``width_b`` columns is multiplied by ``sqrt(total / (n_blocks * width_b))``:
    after scaling every column to [-1, 1], each block holds ``total / n_blocks`` of the
    total variance whatever its width (the equal-trace normalisation of multiple kernel
    learning), and the total is ``total`` -- by default the width ``n``, so that
    ``gamma="auto"`` keeps its meaning.

    Parameters
    ----------
    widths : sequence of int
        Width of each block, in column order.
    total : float, optional
        Total variance (the kernel's scale; default ``sum(widths)``). An ensemble of K
        codebook pairs uses the width of one pair's features
        (:meth:`EmotionClassifier.fit`), so that C means the same whatever K.

    Returns
    -------
    np.ndarray, shape (sum(widths),)
    """
    widths = [int(w) for w in widths]
    total = float(sum(widths)) if total is None else float(total)
    return np.concatenate([np.full(w, np.sqrt(total / (len(widths) * w))) for w in widths])


def _weigh(X, w):
    return X * w


def _weight_text(weight) -> str:
    if weight is None:
        return "none"
    if isinstance(weight, dict):
        return json.dumps({str(k): float(v) for k, v in weight.items()}, sort_keys=True)
    return str(weight)


def _weight_from_text(text: str):
    if text == "none":
        return None
    if text.startswith("{"):
        try:
            weight = json.loads(text)
        except ValueError:
            weight = None
        if not isinstance(weight, dict):
            raise DataError("stored emotion classifier: class_weight is not a JSON object")
        return weight
    return text


_NUMERIC = ("n_cepstrum", "C", "calibration_cv", "random_state", "n_codebooks", "gamma",
            "scale_min",
            "scale_scale", "support_vectors", "support", "n_support", "dual_coef",
            "intercept", "norm_mean", "norm_scale", "norm_means", "norm_scales",
            "norm_min_utterances", "calib_coef", "calib_intercept")


def _stored_widths(arrays, key: str) -> tuple | None:
    if key not in arrays:
        return None
    w = np.asarray(arrays[key])
    if w.ndim != 1 or w.size == 0 or w.dtype.kind not in "iuf" or not np.all(np.isfinite(w)) \
            or np.any(w < 1) or np.any(w != np.round(w)):
        raise DataError(f"stored emotion classifier: {key} must be positive integers, "
                        f"got {w.tolist()}")
    return tuple(int(v) for v in w)


def _stored_count(arrays, key: str) -> int | None:
    """The stored integer ``arrays[key]`` (>= 1), checked; None when absent."""
    if key not in arrays:
        return None
    v = np.asarray(arrays[key])
    if v.shape != () or v.dtype.kind not in "iuf" or not np.isfinite(v) or float(v) < 1 \
            or float(v) != int(v):
        raise DataError(f"stored emotion classifier: {key} must be an integer >= 1, "
                        f"got {v.tolist()}")
    return int(v)


def _stored_floor(arrays, fmt: int) -> float | None:
    """The silence floor a stored classifier's features were computed with, checked."""
    if fmt < SILENCE_FLOOR_FORMAT:
        logger.warning(
            "the stored emotion classifier (format %d) predates the silence floor: speech "
            "whose pauses are digital silence may be misclassified; re-ingest the database "
            "(animegraph ingest SRC --db DB) to refit it", fmt)
        return None
    if "silence_floor" not in arrays:
        return None
    v = np.asarray(arrays["silence_floor"])
    if v.shape != () or v.dtype.kind not in "iuf" or not 0 < float(v) < 200:
        raise DataError(f"stored emotion classifier: silence_floor must be a number of dB in "
                        f"(0, 200), got {v.tolist()}")
    return float(v)


def _check_stored(a: dict, arrays, probability: bool) -> None:
    """Shapes and finiteness of a stored classifier's arrays (one line naming the array).

    ``a``: the needed arrays of :meth:`EmotionClassifier.from_arrays`; ``arrays`` all of
    them (for the calibration's)."""
    a = {**a, **({k: np.asarray(arrays[k]) for k in ("calib_coef", "calib_intercept")}
                 if probability else {})}
    for key in _NUMERIC:
        if key in a and (a[key].dtype.kind not in "biuf" or not np.all(np.isfinite(a[key]))):
            raise DataError(f"stored emotion classifier: array {key!r} is not finite numbers")
    n_classes = a["classes"].size
    n_sv = a["support_vectors"].shape[0] if a["support_vectors"].ndim == 2 else -1
    n_features = a["scale_min"].shape[0] if a["scale_min"].ndim == 1 else -1
    n_dec = n_classes if n_classes > 2 else 1
    shapes = {"classes": (n_classes,), "scale_min": (n_features,),
              "scale_scale": (n_features,), "support_vectors": (n_sv, n_features),
              "support": (n_sv,), "n_support": (n_classes,), "dual_coef": (n_classes - 1, n_sv),
              "intercept": (n_classes * (n_classes - 1) // 2,),
              "norm_mean": (n_features,), "norm_scale": (n_features,),
              "calib_coef": (n_dec, n_dec), "calib_intercept": (n_dec,)}
    if n_classes < 2 or n_sv < 1 or n_features < 1:
        raise DataError(f"stored emotion classifier: {n_classes} classes, support vectors "
                        f"of shape {a['support_vectors'].shape}, scaler of shape "
                        f"{a['scale_min'].shape}")
    for key, shape in shapes.items():
        if key in a and a[key].shape != shape:
            raise DataError(f"stored emotion classifier: array {key!r} has shape "
                            f"{a[key].shape}, expected {shape}")
    if np.any(a["n_support"] < 0) or int(a["n_support"].sum()) != n_sv:
        raise DataError(f"stored emotion classifier: n_support {a['n_support'].tolist()} "
                        f"does not count its {n_sv} support vectors")
    if "norm_means" in a:
        n_speakers = np.asarray(a["norm_speakers"]).size
        for key in ("norm_means", "norm_scales"):
            if a[key].size != n_speakers * n_features:
                raise DataError(f"stored emotion classifier: array {key!r} holds "
                                f"{a[key].size} numbers, expected {n_speakers} speakers x "
                                f"{n_features} features")


class SpeechFeatures(NamedTuple):
    """What :class:`EmotionClassifier` computes from audio before anything is fitted.

    What ingest's workers compute per clip (:func:`ingest.emotion.model.classifier_features`)
    so that fitting needs no audio; accepted as ``X`` wherever audio is.

    Attributes
    ----------
    functionals : np.ndarray, shape (n, n_functionals)
        The blocks of ``features`` other than ``boaw``, in their order.
    frames : list of np.ndarray, each (n_frames_k, 2 * N_DESCRIPTORS), or None
        Each utterance's frame descriptors (:func:`ingest.emotion.boaw.frame_descriptors`)
        when ``features`` holds ``boaw``; the codebooks are learned from them at fit.
    """

    functionals: np.ndarray
    frames: list | None = None


class EmotionClassifier(ClassifierMixin, BaseEstimator):
    """Speech emotion classifier: audio -> features -> speaker normalisation -> SVM.

    ``X`` is a sequence (list, generator, object array) of ``(audio, sample_rate)`` pairs
    -- any rate, mono or ``(n_samples, n_channels)``, integer or float PCM --, their
    :class:`SpeechFeatures` (:meth:`describe`), or an already computed feature matrix
    (used as given: no audio words are learned or added). ``speakers`` (shape (n,)), passed to
    :meth:`fit` and optionally to the prediction methods, groups utterances by speaker
    for per-speaker normalisation; without it (a lone utterance of an unknown speaker)
    the training population's statistics are used.

    Parameters
    ----------
    features : str, optional
        Feature blocks joined by ``+`` (``paper``, ``rich``, ``cepstrum``, ``egemaps``,
        ``compare``, ``boaw``; see :mod:`ingest.emotion.features`). With ``boaw`` the
        bag-of-audio-words (:class:`ingest.emotion.boaw.BagOfAudioWords`, openXBOW's
        defaults: 2 x 500 words, 10 assignments, k-means++ seeding on at most 50,000
        training frames drawn at random) is learned at :meth:`fit` from the training
        utterances' frames only, and its ``n_codebooks`` x 1,000 columns follow the other
        blocks'.
    n_cepstrum : int, optional
        Real-cepstrum coefficients of the ``paper`` block (500).
    cepstrum : {"utterance", "frames"}, optional
        Cepstrum variant of the ``paper`` block.
    normalize : {"speaker", "none"}, optional
        Per-speaker z-normalisation before scaling (not in the paper).
    kernel : {"linear", "rbf", "poly", "sigmoid"}, optional
        SVM kernel (paper: linear).
    C : float, optional
        SVM penalty.
    class_weight : None, "balanced" or dict, optional
        SVM class weights, as :class:`sklearn.svm.SVC`'s: None (every utterance counts the
        same, Libsvm's and the paper's C-SVC), ``"balanced"`` (C scaled per class
        inversely to its frequency) or ``{label: weight}`` (stored with ``str`` labels).
    block_widths : sequence of int, optional
        Widths of consecutive blocks of feature columns (summing to the feature width):
        after scaling, each block is weighted by :func:`block_weights` so that a wide
        block does not drown a narrow one. None (default): with audio words learned, two
        blocks (the functionals, the words) when there are functionals; otherwise every
        column counts the same. Measured with the bag-of-audio-words
        (``scripts/eval_emotion_boaw.py``).
    n_codebooks : int, optional
        Codebook pairs of the bag-of-audio-words drawn with different seeds, their
        histograms concatenated as one block (:mod:`ingest.emotion.boaw`: the ensemble
        that averages out the codebook's random draw; the default K =
        :data:`ingest.emotion.boaw.ENSEMBLE` = 5 was decided before measuring and made
        the default by it, ``docs/results.md`` "Issue 16, fifth session"; 1: one pair,
        the stored default of issue #16's fourth session).
    silence_floor : float or None, optional
        Frames more than this many dB below the utterance's loudest frame are silence,
        replaced by the floor so that digital silence and a quiet noise floor give the
        same features (:mod:`ingest.emotion.features`, "Silence floor"; 50 dB as HTK's
        ``SILFLOOR``). None: no floor, the features of classifiers stored before it.
    kernel_width : int, optional
        The total variance of the weighted columns (the linear kernel's scale, and
        ``gamma = 1 / kernel_width``). None (default): :attr:`kernel_width_` as described
        there. Set it when fitting on a precomputed feature matrix that holds an
        ensemble's words (e.g. 1,171 for the functionals and five pairs' 5,000 words), to
        get the kernel the estimator gives them when it learns the words itself.
    probability : bool, optional
        Fit the probability calibration (costs ``calibration_cv`` extra SVM fits);
        :meth:`predict_proba` needs it.
    calibration_cv : int, optional
        Folds for the out-of-fold decision values of the calibration (reduced to the
        smallest class size when needed, at least 2).
    random_state : int, optional
        Seed of the calibration folds and of the first codebook pair.

    Attributes
    ----------
    classes_ : np.ndarray, shape (n_classes,)
    n_features_in_ : int
        Feature width.
    normalizer_ : SpeakerNormalizer or None
    bag_ : BagOfAudioWords or None
        The codebooks, when ``features`` holds ``boaw`` and :meth:`fit` was given audio or
        :class:`SpeechFeatures`.
    block_widths_ : tuple of int or None
        The block widths the pipeline weights by.
    kernel_width_ : int
        The total variance of the weighted columns (the linear kernel's scale): the
        feature width, or with an ensemble of K codebook pairs the width one pair would
        give (``n_features_in_ - (K - 1) * 2 * size``): the K pairs' words are scaled as
        the mean of K one-pair kernels, so that C and the RBF's ``gamma = 1 /
        kernel_width_`` mean what they mean with one pair.
    pipeline_ : sklearn.pipeline.Pipeline
        ``MinMaxScaler((-1, 1))`` then ``SVC``.
    calibrator_ : LogisticRegression or None

    Notes
    -----
    Parameter errors are ``ValueError`` subclasses (scikit-learn's, or
    :class:`ParameterError`) so that the estimator passes scikit-learn's common checks;
    bad audio raises :class:`DataError`.

    Examples
    --------
    >>> model = EmotionClassifier(probability=True).fit(clips, labels, speakers=who)
    >>> model.predict([(audio, 48000.0)])          # an unknown speaker
    >>> EmotionClassifier.paper().fit(clips, labels)  # Cao et al. §6 as printed
    """

    def __init__(
        self,
        features: str = DEFAULT_FEATURES,
        n_cepstrum: int = N_CEPSTRUM,
        cepstrum: str = "utterance",
        normalize: str = "speaker",
        kernel: str = KERNEL,
        C: float = DEFAULT_C,
        class_weight: str | dict | None = None,
        block_widths: tuple | None = None,
        n_codebooks: int = ENSEMBLE,
        silence_floor: float | None = SILENCE_FLOOR,
        kernel_width: int | None = None,
        probability: bool = False,
        calibration_cv: int = 5,
        random_state: int = 0,
    ):
        self.features = features
        self.n_cepstrum = n_cepstrum
        self.cepstrum = cepstrum
        self.normalize = normalize
        self.kernel = kernel
        self.C = C
        self.class_weight = class_weight
        self.block_widths = block_widths
        self.n_codebooks = n_codebooks
        self.silence_floor = silence_floor
        self.kernel_width = kernel_width
        self.probability = probability
        self.calibration_cv = calibration_cv
        self.random_state = random_state

    @classmethod
    def paper(cls, **overrides) -> EmotionClassifier:
        """The paper's classifier (§6, Table I): its features, linear kernel, C = 1, no
        speaker normalisation (``overrides`` change any parameter)."""
        params = dict(features="paper", normalize="none", kernel="linear", C=1.0)
        return cls(**{**params, **overrides})

    # ------------------------------------------------------------------ helpers
    def _check_params(self) -> None:
        parse_features(self.features)
        if self.kernel not in _KERNELS:
            raise ParameterError(f"kernel must be one of {_KERNELS}, got {self.kernel!r}")
        if self.normalize not in _NORMALIZE:
            raise ParameterError(f"normalize must be one of {_NORMALIZE}, "
                                 f"got {self.normalize!r}")
        if isinstance(self.C, bool) or not isinstance(self.C, int | float | np.number) \
                or not float(self.C) > 0:
            raise ParameterError(f"C must be a positive number, got {self.C!r}")
        w = self.class_weight
        if not (w is None or w == "balanced" or isinstance(w, dict) and all(
                isinstance(v, int | float) and not isinstance(v, bool) and v >= 0
                for v in w.values())):
            raise ParameterError(f"class_weight must be None, 'balanced' or a dict of "
                                 f"non-negative weights, got {w!r}")
        b = self.block_widths
        if b is not None and (isinstance(b, str | bytes) or not hasattr(b, "__len__")
                              or len(b) == 0 or not all(
                isinstance(v, int | np.integer) and not isinstance(v, bool) and v > 0
                for v in b)):
            raise ParameterError(f"block_widths must be None or a sequence of positive "
                                 f"integers, got {b!r}")
        if self.cepstrum not in ("utterance", "frames"):
            raise ParameterError(f"cepstrum must be one of ('utterance', 'frames'), "
                                 f"got {self.cepstrum!r}")
        if isinstance(self.n_codebooks, bool) or not isinstance(
                self.n_codebooks, int | np.integer) or self.n_codebooks < 1:
            raise ParameterError(f"n_codebooks must be an integer >= 1, "
                                 f"got {self.n_codebooks!r}")
        sf = self.silence_floor
        if sf is not None and (isinstance(sf, bool) or not isinstance(sf, int | float | np.number)
                               or not 0 < float(sf) < 200):
            raise ParameterError(f"silence_floor must be None or a number of dB in (0, 200), "
                                 f"got {sf!r}")
        kw = self.kernel_width
        if kw is not None and (isinstance(kw, bool) or not isinstance(kw, int | np.integer)
                               or kw < 1):
            raise ParameterError(f"kernel_width must be None or a positive integer, "
                                 f"got {kw!r}")
        if isinstance(self.calibration_cv, bool) or not isinstance(
                self.calibration_cv, int | np.integer) or self.calibration_cv < 2:
            raise ParameterError(
                f"calibration_cv must be an integer >= 2, got {self.calibration_cv!r}"
            )

    def describe(self, X) -> SpeechFeatures:
        """What is computed from ``X`` before anything is fitted (for ingest's workers).

        Parameters
        ----------
        X : np.ndarray, shape (n, n_features), SpeechFeatures, or sequence of (audio, sample_rate)
            Features (used as given: ``frames`` None), or utterances (a list, tuple,
            generator or object array of pairs).

        Returns
        -------
        SpeechFeatures
            ``functionals`` (n, n_functionals) float64; ``frames`` when ``features``
            holds ``boaw`` and ``X`` is audio (or was given with them).

        Raises
        ------
        DataError
            An utterance that is too short, silent or non-finite (naming it).
        """
        if isinstance(X, SpeechFeatures):
            return self._checked_described(X)
        if issparse(X):
            raise ParameterError("X must be dense: sparse input is not supported")
        items = utterances(X)
        if items is None:
            if isinstance(X, list | tuple):
                return SpeechFeatures(check_array(X, dtype=np.float64))  # nested lists
            arr = np.asarray(X)
            if arr.ndim != 2:
                raise ParameterError(
                    f"X must be a 2-D feature matrix or a sequence of (audio, sample_rate) "
                    f"pairs, got an array of shape {arr.shape}. Reshape your data"
                )
            return SpeechFeatures(check_array(arr, dtype=np.float64))  # sklearn's checks
        if not items:
            raise DataError("X holds no utterances")
        words = WORDS_BLOCK in parse_features(self.features)
        rows, frames = [], [] if words else None
        for i, (audio, sr) in enumerate(items):
            try:
                part = block_features(audio, sr, self.features, n_cepstrum=self.n_cepstrum,
                                      cepstrum=self.cepstrum, silence_floor=self._floor())
            except DataError as exc:  # which one, when there are several
                raise DataError(f"utterance {i}: {exc}" if len(items) > 1 else str(exc)
                                ) from exc
            if words:
                frames.append(part.pop(WORDS_BLOCK))
            rows.append(np.concatenate([np.zeros(0), *part.values()]))
        return SpeechFeatures(np.vstack(rows), frames)

    @staticmethod
    def _checked_described(X: SpeechFeatures) -> SpeechFeatures:
        F = check_array(X.functionals, dtype=np.float64, ensure_min_features=0)
        if X.frames is None:
            return SpeechFeatures(F)
        frames = [np.asarray(f, dtype=np.float64) for f in X.frames]
        if len(frames) != F.shape[0]:
            raise ParameterError(f"SpeechFeatures holds {F.shape[0]} functionals rows but "
                                 f"{len(frames)} frame arrays")
        for i, f in enumerate(frames):
            if f.ndim != 2 or f.shape[0] == 0 or f.shape[1] != frames[0].shape[1] \
                    or not np.all(np.isfinite(f)):
                raise DataError(f"utterance {i}: frame descriptors must be a non-empty "
                                f"finite (n_frames, {frames[0].shape[-1]}) array, got shape "
                                f"{f.shape}")
        return SpeechFeatures(F, frames)

    def _words(self, described: SpeechFeatures) -> np.ndarray:
        """The full raw feature matrix: functionals, then (fitted) audio words."""
        if described.frames is None or self.bag_ is None:
            return described.functionals
        return np.hstack([described.functionals, self.bag_.transform(described.frames)])

    def featurize(self, X) -> np.ndarray:
        """Raw (unnormalised) feature matrix of ``X``, as the fitted pipeline takes it.

        A feature matrix (2-D numeric array or nested lists of numbers) is used as given:
        its width is not checked against ``features``, which only governs features
        computed from audio. The ``boaw`` block's words need the fitted codebooks: before
        :meth:`fit` only the other blocks are returned (:meth:`describe` has the frames).

        Parameters
        ----------
        X : np.ndarray, shape (n, n_features), SpeechFeatures, or sequence of (audio, sample_rate)

        Returns
        -------
        np.ndarray, shape (n, n_features)
            float64 features.

        Raises
        ------
        DataError
            An utterance that is too short, silent or non-finite (naming it).
        """
        described = self.describe(X)
        return self._words(described) if hasattr(self, "bag_") else described.functionals

    def _floor(self) -> float | None:
        return None if self.silence_floor is None else float(self.silence_floor)

    def _kernel_width(self, n_features: int) -> int:
        """:attr:`kernel_width_` of a fitted bag of words and ``n_features`` columns."""
        if self.kernel_width is not None:
            return int(self.kernel_width)
        bag = getattr(self, "bag_", None)
        if bag is None or bag.n_codebooks == 1:
            return int(n_features)
        return int(n_features - (bag.n_codebooks - 1) * 2 * bag.codebooks_[0].shape[0])

    def _make_pipeline(self, widths=None, n_features=None) -> Pipeline:
        """Scaler, block weights, SVM; ``n_features`` (needed with an ensemble of
        codebooks, or without ``widths``) sets :attr:`kernel_width_`'s scale."""
        n = sum(widths) if widths is not None else n_features
        total = n if n is None else self._kernel_width(n)
        steps = [("scale", MinMaxScaler(feature_range=(-1, 1)))]
        if widths is not None:
            steps.append(("weigh", FunctionTransformer(
                _weigh, kw_args={"w": block_weights(widths, total)})))
        elif total != n:  # the ensemble's words alone: one block
            steps.append(("weigh", FunctionTransformer(
                _weigh, kw_args={"w": block_weights((n,), total)})))
        gamma = "auto" if total == n else 1.0 / total  # "auto" is 1 / n_features
        steps.append(("svm", SVC(kernel=self.kernel, C=float(self.C), gamma=gamma,
                                 class_weight=self.class_weight,
                                 decision_function_shape="ovr")))
        return Pipeline(steps)

    @staticmethod
    def _as_2d(d: np.ndarray) -> np.ndarray:
        return d[:, None] if d.ndim == 1 else d

    def _normalized(self, F: np.ndarray, speakers) -> np.ndarray:
        if self.normalizer_ is None:
            return F
        return self.normalizer_.transform(F, speakers)

    # ------------------------------------------------------------------ API
    def fit(self, X, y, speakers=None):
        """Fit the normalisation, the scaler, the SVM (and the probability calibration).

        Parameters
        ----------
        X : np.ndarray, shape (n, n_features), or sequence of (audio, sample_rate)
            Training utterances or their raw features.
        y : array-like, shape (n,)
            Emotion labels (at least two classes).
        speakers : array-like, shape (n,), optional
            Speaker of each utterance (None: one speaker, or unknown).

        Returns
        -------
        EmotionClassifier
            ``self``.
        """
        self._check_params()
        described = self.describe(X)
        F = described.functionals
        if y is None:
            raise ParameterError(
                "EmotionClassifier requires y to be passed, but the target y is None"
            )
        y = column_or_1d(y, warn=True)
        if y.shape[0] != F.shape[0]:
            raise ParameterError(
                f"y must have shape ({F.shape[0]},) (one label per utterance), got {y.shape}"
            )
        check_classification_targets(y)
        classes, counts = np.unique(y, return_counts=True)
        if classes.size < 2:
            raise ParameterError(
                f"y has {classes.size} class; need at least two emotion classes, "
                f"got {classes.tolist()}"
            )
        self.bag_ = None
        widths = self.block_widths
        if described.frames is not None and WORDS_BLOCK in parse_features(self.features):
            self.bag_ = BagOfAudioWords(n_codebooks=int(self.n_codebooks),
                                        random_state=self.random_state).fit(described.frames)
            F = self._words(described)
            n_words = F.shape[1] - described.functionals.shape[1]
            if widths is None and described.functionals.shape[1]:
                widths = (described.functionals.shape[1], n_words)
        if widths is not None and sum(widths) != F.shape[1]:
            raise ParameterError(f"block_widths sum to {sum(widths)}, but X has "
                                 f"{F.shape[1]} features")
        self.block_widths_ = None if widths is None else tuple(int(w) for w in widths)
        self.normalizer_ = None
        if self.normalize == "speaker":
            self.normalizer_ = SpeakerNormalizer().fit(F, speakers)
        Fn = self._normalized(F, speakers)
        self.calibrator_ = None
        if self.probability:
            self.calibrator_ = self._fit_calibration(Fn, y, int(counts.min()))
        self.kernel_width_ = self._kernel_width(F.shape[1])
        self.pipeline_ = self._make_pipeline(self.block_widths_, F.shape[1]).fit(Fn, y)
        self.classes_ = self.pipeline_.classes_
        self.n_features_in_ = F.shape[1]
        return self

    def _fit_calibration(self, F: np.ndarray, y: np.ndarray, smallest: int):
        folds = min(int(self.calibration_cv), smallest)
        if folds < 2:
            raise ParameterError(f"every class needs at least 2 utterances for "
                                 f"probabilities, got {smallest}")
        oof = None
        for train, test in StratifiedKFold(folds, shuffle=True,
                                           random_state=self.random_state).split(F, y):
            d = self._as_2d(self._make_pipeline(self.block_widths_, F.shape[1])
                            .fit(F[train], y[train])
                            .decision_function(F[test]))
            if oof is None:
                oof = np.zeros((F.shape[0], d.shape[1]))
            oof[test] = d
        return LogisticRegression(C=1.0, max_iter=1000).fit(oof, y)

    def _checked(self, X, speakers) -> np.ndarray:
        check_is_fitted(self, ["pipeline_"])
        F = self._words(self.describe(X))
        if F.shape[1] != self.n_features_in_:
            raise ParameterError(
                f"X has {F.shape[1]} features, but EmotionClassifier is expecting "
                f"{self.n_features_in_} features as input"
            )
        return self._normalized(F, speakers)

    def decision_function(self, X, speakers=None) -> np.ndarray:
        """SVM decision values (one-vs-rest shape, from Libsvm's one-vs-one votes).

        Parameters
        ----------
        X : np.ndarray, shape (n, n_features), or sequence of (audio, sample_rate)
        speakers : array-like, shape (n,), optional

        Returns
        -------
        np.ndarray, shape (n, n_classes), or (n,) for two classes
        """
        F = self._checked(X, speakers)
        return self.pipeline_.decision_function(F)

    def predict(self, X, speakers=None) -> np.ndarray:
        """Most likely emotion of each utterance (the SVM's one-vs-one vote).

        Parameters
        ----------
        X : np.ndarray, shape (n, n_features), or sequence of (audio, sample_rate)
        speakers : array-like, shape (n,), optional
            Speakers of the utterances: one with at least
            :data:`~ingest.emotion.speakers.MIN_SPEAKER_UTTERANCES` utterances here is
            normalised by their own statistics.

        Returns
        -------
        np.ndarray, shape (n,)
        """
        F = self._checked(X, speakers)
        return self.pipeline_.predict(F)

    @available_if(lambda self: self.probability)
    def predict_proba(self, X, speakers=None) -> np.ndarray:
        """Calibrated class probabilities (columns in the order of ``classes_``).

        Parameters
        ----------
        X : np.ndarray, shape (n, n_features), or sequence of (audio, sample_rate)
        speakers : array-like, shape (n,), optional

        Returns
        -------
        np.ndarray, shape (n, n_classes)
            Rows sum to 1.

        Only available with ``probability=True``.
        """
        F = self._checked(X, speakers)
        d = self.pipeline_.decision_function(F)
        return self.calibrator_.predict_proba(self._as_2d(d))

    def score(self, X, y, sample_weight=None, speakers=None) -> float:
        """Accuracy of :meth:`predict` (``speakers`` as there)."""
        from sklearn.metrics import accuracy_score

        return float(accuracy_score(y, self.predict(X, speakers), sample_weight=sample_weight))

    # ------------------------------------------------------------------ storage
    def to_arrays(self) -> dict[str, np.ndarray]:
        """The fitted model as plain NumPy arrays (no pickles), e.g. for ``np.savez``.

        Returns
        -------
        dict of str to np.ndarray
            ``format`` (:data:`CLASSIFIER_FORMAT`), the parameters (``features``,
            ``n_cepstrum``, ``cepstrum``, ``normalize``, ``kernel``, ``C``,
            ``class_weight`` (``"none"``, ``"balanced"`` or a JSON object),
            ``calibration_cv``, ``random_state``, ``n_codebooks``, ``gamma``), the normalisation's
            ``norm_mean``/``norm_scale`` (n_features,) and ``norm_min_utterances`` (when
            ``normalize="speaker"``), the scaler's ``scale_min``/``scale_scale``
            (n_features,), the SVM's ``classes`` (n_classes,), ``support_vectors``
            (n_sv, n_features), ``support`` (n_sv,), ``n_support`` (n_classes,),
            ``dual_coef`` (n_classes - 1, n_sv), ``intercept`` (n_classes * (n_classes -
            1) / 2,), with probabilities ``calib_coef`` and ``calib_intercept``, with
            ``kernel_width`` set ``kernel_width``, with a silence floor ``silence_floor``
            (dB), with block widths ``block_widths`` (the
            parameter) and ``block_widths_fitted``
            (what the pipeline weights by), with audio words the codebooks
            (:meth:`ingest.emotion.boaw.BagOfAudioWords.to_arrays`: ``boaw_mean``,
            ``boaw_scale`` (n_descriptors,), ``boaw_codebook0`` ... ``boaw_codebook{2K -
            1}`` (n_words, n_descriptors / 2), ``boaw_assignments``,
            ``boaw_n_codebooks``).
        """
        check_is_fitted(self, ["pipeline_"])
        scaler, svm = self.pipeline_["scale"], self.pipeline_["svm"]
        out = {
            "format": np.array(CLASSIFIER_FORMAT),
            "features": np.array(self.features),
            "n_cepstrum": np.array(self.n_cepstrum),
            "cepstrum": np.array(self.cepstrum),
            "normalize": np.array(self.normalize),
            "kernel": np.array(self.kernel),
            "C": np.array(float(self.C)),
            "class_weight": np.array(_weight_text(self.class_weight)),
            "calibration_cv": np.array(self.calibration_cv),
            "random_state": np.array(self.random_state),
            "n_codebooks": np.array(int(self.n_codebooks)),
            "gamma": np.array(svm._gamma),
            "scale_min": scaler.min_.copy(),
            "scale_scale": scaler.scale_.copy(),
            "classes": svm.classes_.copy(),
            "support_vectors": svm.support_vectors_.copy(),
            "support": svm.support_.copy(),
            "n_support": svm.n_support_.copy(),
            "dual_coef": svm.dual_coef_.copy(),
            "intercept": svm.intercept_.copy(),
        }
        if self.block_widths is not None:
            out["block_widths"] = np.array([int(w) for w in self.block_widths])
        if self.kernel_width is not None:
            out["kernel_width"] = np.array(int(self.kernel_width))
        if self.silence_floor is not None:
            out["silence_floor"] = np.array(float(self.silence_floor))
        if self.block_widths_ is not None:
            out["block_widths_fitted"] = np.array(self.block_widths_)
        if self.bag_ is not None:
            out.update(self.bag_.to_arrays())
        if self.normalizer_ is not None:
            out.update(self.normalizer_.to_arrays())
        if self.calibrator_ is not None:
            out["calib_coef"] = self.calibrator_.coef_.copy()
            out["calib_intercept"] = self.calibrator_.intercept_.copy()
        return out

    @classmethod
    def from_arrays(cls, arrays) -> EmotionClassifier:
        """Rebuild a fitted classifier from :meth:`to_arrays` output.

        The SVC is restored by setting the attributes Libsvm's prediction reads
        (including scikit-learn's private ``_dual_coef_``, ``_intercept_``, ``_n_support``,
        ``_gamma``); checked against the installed scikit-learn by the test suite.

        Parameters
        ----------
        arrays : mapping of str to np.ndarray
            E.g. a dict or an ``np.load``-ed ``.npz``.

        Returns
        -------
        EmotionClassifier
            Predicting exactly as the stored model.

        Raises
        ------
        DataError
            Arrays missing, stored by an older animegraph (no ``format``; its features
            were not level-normalised), or damaged (a shape that does not fit the others,
            numbers that are not finite, a model that fails on a row of zeros): one line;
            re-ingest.
        """
        fmt = np.asarray(arrays["format"]) if "format" in arrays else None
        if fmt is None or fmt.shape != () or fmt.dtype.kind not in "iuf" \
                or float(fmt) not in READABLE_FORMATS:
            raise DataError("the stored emotion classifier is from an older animegraph: "
                            "re-ingest the database (animegraph ingest SRC --db DB) to "
                            "replace it")
        try:
            model = cls._restore(arrays, int(fmt))
            model.decision_function(np.zeros((1, model.n_features_in_)))  # a dry run
            if model.calibrator_ is not None:
                model.predict_proba(np.zeros((1, model.n_features_in_)))
        except DataError as exc:
            raise DataError(f"the stored emotion classifier is damaged ({exc}): re-ingest "
                            "the database (animegraph ingest SRC --db DB)") from None
        except (ValueError, TypeError, IndexError, AttributeError) as exc:
            raise DataError(f"the stored emotion classifier is damaged ({type(exc).__name__}: "
                            f"{str(exc).splitlines()[0] if str(exc) else exc!r}): re-ingest "
                            "the database (animegraph ingest SRC --db DB)") from None
        return model

    @classmethod
    def _restore(cls, arrays, fmt: int) -> EmotionClassifier:
        """:meth:`from_arrays` after the format check (arrays checked, not tried)."""
        needed = ["features", "n_cepstrum", "cepstrum", "normalize", "kernel", "C",
                  "calibration_cv", "random_state", "gamma", "scale_min", "scale_scale",
                  "classes", "support_vectors", "support", "n_support", "dual_coef",
                  "intercept"]
        if str(np.asarray(arrays.get("normalize", ""))) == "speaker":
            needed += ["norm_mean", "norm_scale", "norm_speakers", "norm_means",
                       "norm_scales", "norm_min_utterances"]
        try:
            a = {k: np.asarray(arrays[k]) for k in needed}
        except KeyError as exc:
            raise DataError(f"stored emotion classifier lacks array {exc.args[0]!r}") from None
        probability = "calib_coef" in arrays and "calib_intercept" in arrays
        _check_stored(a, arrays, probability)
        weight = _weight_from_text(str(np.asarray(arrays["class_weight"]))
                                   if "class_weight" in arrays else "none")
        widths = fitted = None
        if fmt == 3 and "block_widths" not in arrays:
            raise DataError("stored emotion classifier lacks array 'block_widths'")
        if "block_widths" in arrays:
            widths = _stored_widths(arrays, "block_widths")
        fitted = _stored_widths(arrays, "block_widths_fitted") if fmt >= 4 else widths
        if fitted is not None and sum(fitted) != a["scale_min"].shape[0]:
            raise DataError(f"stored emotion classifier: block widths {list(fitted)} do not "
                            f"sum to its {a['scale_min'].shape[0]} features")
        n_codebooks = _stored_count(arrays, "n_codebooks") if fmt >= 5 else 1
        if n_codebooks is None:
            raise DataError("stored emotion classifier lacks array 'n_codebooks'")
        bag = None
        if fmt >= 4 and "boaw_mean" in arrays:
            if fmt >= 5 and "boaw_n_codebooks" not in arrays:
                raise DataError("stored bag-of-audio-words lacks array 'boaw_n_codebooks'")
            bag = BagOfAudioWords.from_arrays(arrays)
            if bag.n_codebooks != n_codebooks:
                raise DataError(f"stored emotion classifier: {bag.n_codebooks} codebook "
                                f"pairs stored, n_codebooks says {n_codebooks}")
            words = bag.n_words
            # the words are the last columns; fitted on its own, one block of them
            if words > a["scale_min"].shape[0] or widths is None and fitted is not None \
                    and fitted[-1] != words:
                raise DataError(f"stored emotion classifier: its codebooks give {words} "
                                f"words, not its last block of columns "
                                f"({a['scale_min'].shape[0]} features, block widths "
                                f"{list(fitted) if fitted else None})")
        model = cls(features=str(a["features"]), n_cepstrum=int(a["n_cepstrum"]),
                    silence_floor=_stored_floor(arrays, fmt),
                    cepstrum=str(a["cepstrum"]), normalize=str(a["normalize"]),
                    kernel=str(a["kernel"]), C=float(a["C"]),
                    class_weight=weight, block_widths=widths, n_codebooks=n_codebooks,
                    kernel_width=_stored_count(arrays, "kernel_width"),
                    probability=probability,
                    calibration_cv=int(a["calibration_cv"]),
                    random_state=int(a["random_state"]))
        model._check_params()
        n_features = a["scale_min"].shape[0]
        classes = a["classes"]
        model.bag_ = bag
        model.block_widths_ = fitted
        model.kernel_width_ = model._kernel_width(n_features)
        pipe = model._make_pipeline(fitted, n_features)
        scaler, svm = pipe["scale"], pipe["svm"]
        scaler.min_ = a["scale_min"].astype(np.float64)
        scaler.scale_ = a["scale_scale"].astype(np.float64)
        scaler.n_features_in_ = n_features
        scaler.n_samples_seen_ = 0
        scaler.data_range_ = np.where(scaler.scale_ != 0, 2.0 / scaler.scale_, 1.0)
        scaler.data_min_ = (-1.0 - scaler.min_) / scaler.scale_
        scaler.data_max_ = scaler.data_min_ + scaler.data_range_
        sign = -1.0 if classes.size == 2 else 1.0  # sklearn flips the public binary signs
        dual = np.ascontiguousarray(a["dual_coef"], dtype=np.float64)
        intercept = np.ascontiguousarray(a["intercept"], dtype=np.float64)
        svm.classes_ = classes
        svm.support_vectors_ = np.ascontiguousarray(a["support_vectors"], dtype=np.float64)
        svm.support_ = np.ascontiguousarray(a["support"], dtype=np.int32)
        svm._n_support = np.ascontiguousarray(a["n_support"], dtype=np.int32)
        svm._dual_coef_ = sign * dual
        svm._intercept_ = sign * intercept
        svm.dual_coef_ = dual
        svm.intercept_ = intercept
        svm._probA = np.empty(0)
        svm._probB = np.empty(0)
        svm._gamma = float(a["gamma"])
        svm._sparse = False
        svm.fit_status_ = 0
        svm.shape_fit_ = (0, n_features)
        svm.class_weight_ = np.ones(classes.size, dtype=np.float64)
        svm.n_features_in_ = n_features
        svm.n_iter_ = np.zeros(classes.size * (classes.size - 1) // 2, dtype=np.int32)
        model.pipeline_ = pipe
        model.normalizer_ = (SpeakerNormalizer.from_arrays(a) if model.normalize == "speaker"
                             else None)
        model.calibrator_ = None
        if probability:
            calib = LogisticRegression(C=1.0, max_iter=1000)
            calib.classes_ = classes
            calib.coef_ = np.asarray(arrays["calib_coef"], dtype=np.float64)
            calib.intercept_ = np.asarray(arrays["calib_intercept"], dtype=np.float64)
            calib.n_features_in_ = calib.coef_.shape[1]
            model.calibrator_ = calib
        model.classes_ = classes
        model.n_features_in_ = n_features
        return model
