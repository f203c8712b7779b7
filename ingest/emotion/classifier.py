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
from ingest.emotion.emodb import EMODB_EMOTIONS, load_emodb
from ingest.emotion.features import (
    N_CEPSTRUM,
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
    "MIN_DURATION",
    "N_CEPSTRUM",
    "EmotionClassifier",
    "emotion_features",
    "load_emodb",
    "real_cepstrum",
    "rich_features",
    "speaker_normalize",
]

#: Kernel the paper settles on (§6, Table I); also the best measured with the default
#: features.
KERNEL = "linear"
#: Feature blocks of the default pipeline (measured best, docs/results.md issue #16).
DEFAULT_FEATURES = "rich+cepstrum"
#: SVM penalty of the default pipeline (the value nested tuning picks on EmoDB).
DEFAULT_C = 0.1
#: Version of the stored arrays; older databases hold none and must be re-ingested.
#: Format 3 is written only by a classifier with ``block_widths`` (an animegraph that
#: reads format 2 alone would ignore the weights); the default still writes format 2.
CLASSIFIER_FORMAT = 3
#: Formats :meth:`EmotionClassifier.from_arrays` reads.
READABLE_FORMATS = (2, 3)

_KERNELS = ("linear", "rbf", "poly", "sigmoid")

_NORMALIZE = ("speaker", "none")


def block_weights(widths) -> np.ndarray:
    """Column weights giving every block of columns the same share of the variance.

    Block b of ``width_b`` columns is multiplied by ``sqrt(n / (n_blocks * width_b))``
    (n the total width): after scaling every column to [-1, 1], each block holds
    ``n / n_blocks`` of the total variance whatever its width (the equal-trace
    normalisation of multiple kernel learning), and the total stays ``n`` (so that
    ``gamma="auto"`` keeps its meaning).

    Parameters
    ----------
    widths : sequence of int
        Width of each block, in column order.

    Returns
    -------
    np.ndarray, shape (sum(widths),)
    """
    widths = [int(w) for w in widths]
    total = float(sum(widths))
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


class EmotionClassifier(ClassifierMixin, BaseEstimator):
    """Speech emotion classifier: audio -> features -> speaker normalisation -> SVM.

    ``X`` is a sequence (list, generator, object array) of ``(audio, sample_rate)`` pairs
    -- any rate, mono or ``(n_samples, n_channels)``, integer or float PCM -- or an
    already computed feature matrix (used as given). ``speakers`` (shape (n,)), passed to
    :meth:`fit` and optionally to the prediction methods, groups utterances by speaker
    for per-speaker normalisation; without it (a lone utterance of an unknown speaker)
    the training population's statistics are used.

    Parameters
    ----------
    features : str, optional
        Feature blocks joined by ``+`` (``paper``, ``rich``, ``cepstrum``, ``egemaps``,
        ``compare``; see :mod:`ingest.emotion.features`).
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
        block does not drown a narrow one. None (default): every column counts the same.
        Measured with the bag-of-audio-words (``scripts/eval_emotion_boaw.py``).
    probability : bool, optional
        Fit the probability calibration (costs ``calibration_cv`` extra SVM fits);
        :meth:`predict_proba` needs it.
    calibration_cv : int, optional
        Folds for the out-of-fold decision values of the calibration (reduced to the
        smallest class size when needed, at least 2).
    random_state : int, optional
        Seed of the calibration folds.

    Attributes
    ----------
    classes_ : np.ndarray, shape (n_classes,)
    n_features_in_ : int
        Feature width.
    normalizer_ : SpeakerNormalizer or None
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
        if isinstance(self.calibration_cv, bool) or not isinstance(
                self.calibration_cv, int | np.integer) or self.calibration_cv < 2:
            raise ParameterError(
                f"calibration_cv must be an integer >= 2, got {self.calibration_cv!r}"
            )

    def featurize(self, X) -> np.ndarray:
        """Raw (unnormalised) feature matrix of ``X``.

        A feature matrix (2-D numeric array or nested lists of numbers) is used as given:
        its width is not checked against ``features``, which only governs features
        computed from audio.

        Parameters
        ----------
        X : np.ndarray, shape (n, n_features), or sequence of (audio, sample_rate)
            Features, or utterances (a list, tuple, generator or object array of pairs).

        Returns
        -------
        np.ndarray, shape (n, n_features)
            float64 features.

        Raises
        ------
        DataError
            An utterance that is too short, silent or non-finite (naming it).
        """
        if issparse(X):
            raise ParameterError("X must be dense: sparse input is not supported")
        items = utterances(X)
        if items is None:
            if isinstance(X, list | tuple):
                return check_array(X, dtype=np.float64)  # nested lists of numbers
            arr = np.asarray(X)
            if arr.ndim != 2:
                raise ParameterError(
                    f"X must be a 2-D feature matrix or a sequence of (audio, sample_rate) "
                    f"pairs, got an array of shape {arr.shape}. Reshape your data"
                )
            return check_array(arr, dtype=np.float64)  # sklearn's checks (ValueError)
        if not items:
            raise DataError("X holds no utterances")
        rows = []
        for i, (audio, sr) in enumerate(items):
            try:
                blocks = block_features(audio, sr, self.features, n_cepstrum=self.n_cepstrum,
                                        cepstrum=self.cepstrum)
            except DataError as exc:
                raise DataError(f"utterance {i}: {exc}") from exc
            rows.append(np.concatenate(list(blocks.values())))
        return np.vstack(rows)

    def _make_pipeline(self) -> Pipeline:
        steps = [("scale", MinMaxScaler(feature_range=(-1, 1)))]
        if self.block_widths is not None:
            steps.append(("weigh", FunctionTransformer(
                _weigh, kw_args={"w": block_weights(self.block_widths)})))
        steps.append(("svm", SVC(kernel=self.kernel, C=float(self.C), gamma="auto",
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
        F = self.featurize(X)
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
        if self.block_widths is not None and sum(self.block_widths) != F.shape[1]:
            raise ParameterError(f"block_widths sum to {sum(self.block_widths)}, but X has "
                                 f"{F.shape[1]} features")
        self.normalizer_ = None
        if self.normalize == "speaker":
            self.normalizer_ = SpeakerNormalizer().fit(F, speakers)
        Fn = self._normalized(F, speakers)
        self.calibrator_ = None
        if self.probability:
            self.calibrator_ = self._fit_calibration(Fn, y, int(counts.min()))
        self.pipeline_ = self._make_pipeline().fit(Fn, y)
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
            d = self._as_2d(self._make_pipeline().fit(F[train], y[train])
                            .decision_function(F[test]))
            if oof is None:
                oof = np.zeros((F.shape[0], d.shape[1]))
            oof[test] = d
        return LogisticRegression(C=1.0, max_iter=1000).fit(oof, y)

    def _checked(self, X, speakers) -> np.ndarray:
        check_is_fitted(self, ["pipeline_"])
        F = self.featurize(X)
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
            ``format`` (2, or :data:`CLASSIFIER_FORMAT` with ``block_widths``, then
            stored as an int array), the parameters (``features``,
            ``n_cepstrum``, ``cepstrum``, ``normalize``, ``kernel``, ``C``,
            ``class_weight`` (``"none"``, ``"balanced"`` or a JSON object),
            ``calibration_cv``, ``random_state``, ``gamma``), the normalisation's
            ``norm_mean``/``norm_scale`` (n_features,) and ``norm_min_utterances`` (when
            ``normalize="speaker"``), the scaler's ``scale_min``/``scale_scale``
            (n_features,), the SVM's ``classes`` (n_classes,), ``support_vectors``
            (n_sv, n_features), ``support`` (n_sv,), ``n_support`` (n_classes,),
            ``dual_coef`` (n_classes - 1, n_sv), ``intercept`` (n_classes * (n_classes -
            1) / 2,), and, with probabilities, ``calib_coef`` and ``calib_intercept``.
        """
        check_is_fitted(self, ["pipeline_"])
        scaler, svm = self.pipeline_["scale"], self.pipeline_["svm"]
        out = {
            "format": np.array(2 if self.block_widths is None else CLASSIFIER_FORMAT),
            "features": np.array(self.features),
            "n_cepstrum": np.array(self.n_cepstrum),
            "cepstrum": np.array(self.cepstrum),
            "normalize": np.array(self.normalize),
            "kernel": np.array(self.kernel),
            "C": np.array(float(self.C)),
            "class_weight": np.array(_weight_text(self.class_weight)),
            "calibration_cv": np.array(self.calibration_cv),
            "random_state": np.array(self.random_state),
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
            Arrays missing, or stored by an older animegraph (no ``format``; its features
            were not level-normalised): re-ingest.
        """
        if "format" not in arrays or int(np.asarray(arrays["format"])) not in READABLE_FORMATS:
            raise DataError("the stored emotion classifier is from an older animegraph: "
                            "re-ingest the database (animegraph ingest SRC --db DB) to "
                            "replace it")
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
        weight = _weight_from_text(str(np.asarray(arrays["class_weight"]))
                                   if "class_weight" in arrays else "none")
        widths = None
        if int(np.asarray(arrays["format"])) >= 3:
            if "block_widths" not in arrays:
                raise DataError("stored emotion classifier lacks array 'block_widths'")
            widths = tuple(int(w) for w in np.asarray(arrays["block_widths"]).ravel())
        model = cls(features=str(a["features"]), n_cepstrum=int(a["n_cepstrum"]),
                    cepstrum=str(a["cepstrum"]), normalize=str(a["normalize"]),
                    kernel=str(a["kernel"]), C=float(a["C"]),
                    class_weight=weight, block_widths=widths, probability=probability,
                    calibration_cv=int(a["calibration_cv"]),
                    random_state=int(a["random_state"]))
        model._check_params()
        n_features = a["scale_min"].shape[0]
        classes = a["classes"]
        pipe = model._make_pipeline()
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
