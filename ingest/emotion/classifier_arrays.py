"""A fitted :class:`~ingest.emotion.classifier.EmotionClassifier` as plain NumPy arrays
(no pickles; what a database stores) and back, every stored array checked before use.

The SVC is restored by setting the attributes Libsvm's prediction reads (including
scikit-learn's private ``_dual_coef_``, ``_intercept_``, ``_n_support``, ``_gamma``);
checked against the installed scikit-learn by the test suite.
"""

from __future__ import annotations

import json
import logging

import numpy as np
from sklearn.linear_model import LogisticRegression
from sklearn.utils.validation import check_is_fitted

from db.errors import DataError
from ingest.emotion.boaw import BagOfAudioWords
from ingest.emotion.speakers import SpeakerNormalizer

__all__ = ["CLASSIFIER_FORMAT", "READABLE_FORMATS", "SILENCE_FLOOR_FORMAT",
           "classifier_arrays", "classifier_from_arrays"]

logger = logging.getLogger(__name__)

#: Version of the stored arrays; older databases hold none and must be re-ingested.
#: Format 2: no block weights; 3: ``block_widths``; 4: the fitted block widths
#: (``block_widths_fitted``, when any) and the bag-of-audio-words' codebooks (``boaw_*``,
#: when the ``boaw`` block is used); 5 (what is written): ``n_codebooks`` and the
#: ensemble's codebooks (``boaw_n_codebooks``, ``boaw_codebook0`` ... ``2K - 1``); 6 (what
#: is written): features with the silence floor, ``silence_floor`` (absent: None).
#: Formats 2 to 5 were fitted on features without the floor, and are read with
#: ``silence_floor=None`` (predicting as they did) and a warning. 7 (what is written):
#: ``normalize`` may be ``"speaker+population"`` (the default; read by older animegraph
#: it would predict without its normalisation, hence the new number); its arrays are
#: format 6's.
CLASSIFIER_FORMAT = 7
#: Formats :meth:`EmotionClassifier.from_arrays` reads.
READABLE_FORMATS = (2, 3, 4, 5, 6, 7)
#: The first format whose features have the silence floor.
SILENCE_FLOOR_FORMAT = 6


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


def classifier_arrays(model) -> dict[str, np.ndarray]:
    """:meth:`EmotionClassifier.to_arrays <ingest.emotion.classifier.EmotionClassifier.to_arrays>`
    of the fitted ``model`` (the arrays are listed there)."""
    check_is_fitted(model, ["pipeline_"])
    scaler, svm = model.pipeline_["scale"], model.pipeline_["svm"]
    out = {
        "format": np.array(CLASSIFIER_FORMAT),
        "features": np.array(model.features),
        "n_cepstrum": np.array(model.n_cepstrum),
        "cepstrum": np.array(model.cepstrum),
        "normalize": np.array(model.normalize),
        "kernel": np.array(model.kernel),
        "C": np.array(float(model.C)),
        "class_weight": np.array(_weight_text(model.class_weight)),
        "calibration_cv": np.array(model.calibration_cv),
        "random_state": np.array(model.random_state),
        "n_codebooks": np.array(int(model.n_codebooks)),
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
    if model.block_widths is not None:
        out["block_widths"] = np.array([int(w) for w in model.block_widths])
    if model.kernel_width is not None:
        out["kernel_width"] = np.array(int(model.kernel_width))
    if model.silence_floor is not None:
        out["silence_floor"] = np.array(float(model.silence_floor))
    if model.block_widths_ is not None:
        out["block_widths_fitted"] = np.array(model.block_widths_)
    if model.bag_ is not None:
        out.update(model.bag_.to_arrays())
    if model.normalizer_ is not None:
        out.update(model.normalizer_.to_arrays())
    if model.calibrator_ is not None:
        out["calib_coef"] = model.calibrator_.coef_.copy()
        out["calib_intercept"] = model.calibrator_.intercept_.copy()
    return out


def classifier_from_arrays(cls, arrays):
    """:meth:`EmotionClassifier.from_arrays
    <ingest.emotion.classifier.EmotionClassifier.from_arrays>`: an instance of ``cls``
    rebuilt from ``arrays`` (format checked, arrays checked, the model tried on a row of
    zeros); DataError naming what is wrong."""
    fmt = np.asarray(arrays["format"]) if "format" in arrays else None
    if fmt is None or fmt.shape != () or fmt.dtype.kind not in "iuf" \
            or float(fmt) not in READABLE_FORMATS:
        raise DataError("the stored emotion classifier is from an older animegraph: "
                        "re-ingest the database (animegraph ingest SRC --db DB) to "
                        "replace it")
    try:
        model = _restore(cls, arrays, int(fmt))
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


def _restore(cls, arrays, fmt: int):
    """:func:`classifier_from_arrays` after the format check (arrays checked, not tried)."""
    needed = ["features", "n_cepstrum", "cepstrum", "normalize", "kernel", "C",
              "calibration_cv", "random_state", "gamma", "scale_min", "scale_scale",
              "classes", "support_vectors", "support", "n_support", "dual_coef",
              "intercept"]
    if str(np.asarray(arrays.get("normalize", ""))) != "none":
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
    model.normalizer_ = (SpeakerNormalizer.from_arrays(a) if model.normalize != "none"
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
