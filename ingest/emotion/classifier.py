"""Emotion classification of speech: one estimator from audio to emotion (Cao et al. 2005,
§6, Table I; issue #16).

:class:`EmotionClassifier` holds the whole pipeline -- input handling
(:mod:`ingest.emotion.audio`), features (:mod:`ingest.emotion.features`), per-speaker
normalisation (:mod:`ingest.emotion.speakers`), scaling to ``[-1, 1]`` and a Support Vector
Machine (Libsvm's C-SVC, one-vs-one, as the paper) -- and stores it as plain arrays.

Defaults are what measures best on EmoDB with every choice nested inside the training
folds (``scripts/eval_emotion.py``, ``docs/results/emotion.md``, "EmoDB: the default and the
alternatives"); the paper's configuration stays one call away, :meth:`EmotionClassifier.paper`:
mean, variance and RMS of the signal and its first 500 real-cepstrum coefficients, a
linear kernel, no speaker normalisation.

Probabilities (``probability=True``, what ``ingest`` stores for ``classify`` and
``synth --emotion auto``) come from a multinomial logistic regression fitted on
*out-of-fold* SVM decision values (stacked Platt scaling; ``SVC(probability=True)`` is
deprecated); without them :meth:`~EmotionClassifier.fit` fits the SVM once.
"""

from __future__ import annotations

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
from ingest.emotion.classifier_arrays import classifier_arrays, classifier_from_arrays
from ingest.emotion.emodb import EMODB_EMOTIONS, load_emodb
from ingest.emotion.features import (
    N_CEPSTRUM,
    WORDS_BLOCK,
    block_features,
    emotion_features,
    parse_features,
    real_cepstrum,
    rich_features,
)
from ingest.emotion.frames import SILENCE_FLOOR, one_blas_thread
from ingest.emotion.speakers import SpeakerNormalizer, speaker_normalize

__all__ = [
    "DEFAULT_C",
    "DEFAULT_FEATURES",
    "DEFAULT_NORMALIZE",
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
#: Feature blocks of the default pipeline: the functionals and the bag-of-audio-words,
#: with its ensemble of codebooks (``n_codebooks``), measured best
#: (docs/results/emotion.md, "EmoDB: the default and the alternatives").
DEFAULT_FEATURES = "rich+cepstrum+boaw"
#: The functionals alone (the default before the bag-of-audio-words).
FUNCTIONALS = "rich+cepstrum"
#: SVM penalty of the default pipeline (the value nested tuning picks on EmoDB).
DEFAULT_C = 0.1

logger = logging.getLogger(__name__)

_KERNELS = ("linear", "rbf", "poly", "sigmoid")

#: The default normalisation: per-speaker, and the SVM learns every training utterance
#: normalised both ways prediction normalises it -- by its speaker's statistics (speakers
#: given together) and by the population's (a lone utterance). Trained on the first alone
#: (``"speaker"``) the SVM meets the second only at prediction: on RAVDESS, leaving actors
#: out, one utterance at a time, 52.4 % against 58.1 % (docs/results/emotion.md, "RAVDESS:
#: unseen actors").
DEFAULT_NORMALIZE = "speaker+population"
_NORMALIZE = ("speaker+population", "speaker", "none")


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
    normalize : {"speaker+population", "speaker", "none"}, optional
        Per-speaker z-normalisation before scaling (not in the paper;
        :class:`~ingest.emotion.speakers.SpeakerNormalizer`). ``"speaker+population"``
        (default): the SVM learns each training utterance twice, normalised by its
        speaker's statistics and by the training population's -- the two ways prediction
        normalises (speakers given together, or a lone utterance); :data:`DEFAULT_NORMALIZE`
        says what it measured. ``"speaker"``: by its speaker's statistics only (the
        default of classifiers stored before format 7). ``"none"``: no normalisation.
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
        the default by it, ``docs/results/emotion.md`` "EmoDB: the default and the
        alternatives"; 1: one pair, what classifiers of format 4 stored).
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
        normalize: str = DEFAULT_NORMALIZE,
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

    @one_blas_thread  # the limit set once for all the utterances (not once per utterance)
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
        if self.normalize != "none":
            self.normalizer_ = SpeakerNormalizer().fit(F, speakers)
        views = [self._normalized(F, speakers)]
        if self.normalize == "speaker+population" and speakers is not None:
            views.append(self.normalizer_.transform(F))  # as a lone utterance is
        self.calibrator_ = None
        self.kernel_width_ = self._kernel_width(F.shape[1])
        if self.probability:
            self.calibrator_ = self._fit_calibration(views, y, int(counts.min()))
        self.pipeline_ = self._make_pipeline(self.block_widths_, F.shape[1]).fit(
            np.vstack(views), np.tile(y, len(views)))
        self.classes_ = self.pipeline_.classes_
        self.n_features_in_ = F.shape[1]
        return self

    def _fit_calibration(self, views: list, y: np.ndarray, smallest: int):
        """The calibration on out-of-fold decision values of every view (the utterances'
        normalisations; an utterance's views stay on the same side of each split)."""
        folds = min(int(self.calibration_cv), smallest)
        if folds < 2:
            raise ParameterError(f"every class needs at least 2 utterances for "
                                 f"probabilities, got {smallest}")
        n, k = y.shape[0], len(views)
        oof = None
        for train, test in StratifiedKFold(folds, shuffle=True,
                                           random_state=self.random_state).split(views[0], y):
            svm = self._make_pipeline(self.block_widths_, views[0].shape[1]).fit(
                np.vstack([v[train] for v in views]), np.tile(y[train], k))
            for j, v in enumerate(views):
                d = self._as_2d(svm.decision_function(v[test]))
                if oof is None:
                    oof = np.zeros((k * n, d.shape[1]))
                oof[j * n + test] = d
        return LogisticRegression(C=1.0, max_iter=1000).fit(oof, np.tile(y, k))

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
            ``format`` (:data:`ingest.emotion.classifier_arrays.CLASSIFIER_FORMAT`), the
            parameters (``features``, ``n_cepstrum``, ``cepstrum``, ``normalize``,
            ``kernel``, ``C``, ``class_weight`` (``"none"``, ``"balanced"`` or a JSON
            object), ``calibration_cv``, ``random_state``, ``n_codebooks``, ``gamma``), the
            normalisation's ``norm_mean``/``norm_scale`` (n_features,) and
            ``norm_min_utterances`` (when
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
        return classifier_arrays(self)

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
        return classifier_from_arrays(cls, arrays)
