"""Emotion classification of speech (Cao et al. 2005, §6, Table I).

The paper classifies an utterance with a Support Vector Machine (Libsvm, C-SVC) on a
feature vector made of the **mean, variance and RMS of the speech signal and the first
500 coefficients of its real cepstrum**, scaled to ``[-1, 1]``; a linear kernel and 500
coefficients are "sufficient" (Table I). This module provides

* :func:`real_cepstrum` -- ``IFFT(log |FFT(x)|)``;
* :func:`emotion_features` -- the paper's feature vector (``features="paper"``) or an
  opt-in richer prosodic/spectral set (:func:`rich_features`);
* :class:`EmotionClassifier` -- a scikit-learn classifier: a
  ``Pipeline(MinMaxScaler((-1, 1)), SVC)`` whose probabilities come from a multinomial
  logistic regression fitted on *out-of-fold* SVM decision values (stacked Platt scaling;
  ``SVC(probability=True)`` is deprecated), storable as plain arrays;
* :func:`load_emodb` -- the Berlin Emotional Speech Database (EmoDB) reader.

Choices where the paper is silent
---------------------------------
* Audio is resampled to 16 kHz first, so coefficient ``k`` always means a quefrency of
  ``k / 16000`` s whatever the input rate.
* ``cepstrum="utterance"`` (default, paper-literal): one real cepstrum of the whole
  utterance (FFT length = number of samples). ``cepstrum="frames"``: the mean real
  cepstrum of 2048-sample Hann frames (hop 512), frames more than 60 dB below the
  loudest dropped -- less sensitive to utterance length. Both are measured by
  ``scripts/eval_emotion.py``.
* "RMS error" of the signal is read as the root mean square of the (16 kHz) samples.
* The SVM uses Libsvm's default RBF width ``gamma = 1 / n_features`` (``gamma="auto"``),
  as the paper keeps "the default value".
"""

from __future__ import annotations

import re
from math import gcd
from pathlib import Path

import numpy as np
from scipy.signal import resample_poly
from scipy.sparse import issparse
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.linear_model import LogisticRegression
from sklearn.model_selection import StratifiedKFold, cross_val_predict
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import MinMaxScaler
from sklearn.svm import SVC
from sklearn.utils.multiclass import check_classification_targets
from sklearn.utils.validation import check_array, check_is_fitted, column_or_1d

from db.errors import DataError, ParameterError

__all__ = [
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

#: Cepstrum coefficients in the paper's feature vector (§6).
N_CEPSTRUM = 500
#: Kernel the paper settles on (§6, Table I).
KERNEL = "linear"
#: Every signal is resampled to this rate (Hz) before features are computed.
FEATURE_SAMPLE_RATE = 16000
#: Shortest utterance accepted, in seconds.
MIN_DURATION = 0.25
#: Frame length and hop (samples at 16 kHz) of the frame-averaged cepstrum.
CEPSTRUM_FRAME = 2048
CEPSTRUM_HOP = 512
#: EmoDB file-name emotion letters (German initials) to English names.
EMODB_EMOTIONS = {
    "W": "anger",
    "L": "boredom",
    "E": "disgust",
    "A": "fear",
    "F": "happiness",
    "T": "sadness",
    "N": "neutral",
}

_FEATURE_SETS = ("paper", "rich")
_CEPSTRA = ("utterance", "frames")
_KERNELS = ("linear", "rbf", "poly", "sigmoid")
_LOG_FLOOR = 1e-10  # |FFT| floor relative to its peak before the log (-200 dB)
_SILENCE_RMS = 1e-6
_EMODB_NAME = re.compile(r"^(\d\d)([a-z]\d\d)([WLEAFTN])([a-z])$")


# --------------------------------------------------------------------------- features
def real_cepstrum(x: np.ndarray, n_fft: int | None = None) -> np.ndarray:
    """Real cepstrum ``IFFT(log |FFT(x)|)`` of a signal (§6).

    Parameters
    ----------
    x : np.ndarray, shape (n_samples,)
        Signal.
    n_fft : int, optional
        FFT length (zero-padding or truncating ``x``); defaults to ``len(x)``.

    Returns
    -------
    np.ndarray, shape (n_fft,)
        The real cepstrum, float64; ``c[0]`` is the mean log magnitude. Magnitudes are
        floored at ``1e-10`` times their peak before the log so that spectral zeros do
        not produce ``-inf``.
    """
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 1 or x.size == 0:
        raise ParameterError(f"x must be a non-empty 1-D signal, got shape {x.shape}")
    n = x.size if n_fft is None else int(n_fft)
    if n < 1:
        raise ParameterError(f"n_fft must be positive, got {n_fft}")
    mag = np.abs(np.fft.rfft(x, n))
    peak = mag.max()
    if not np.isfinite(peak) or peak <= 0:
        raise DataError("cannot take the cepstrum of an all-zero or non-finite signal")
    return np.fft.irfft(np.log(np.maximum(mag, _LOG_FLOOR * peak)), n)


def _prepare(audio: np.ndarray, sample_rate: int) -> np.ndarray:
    """Validate ``audio`` and resample it to :data:`FEATURE_SAMPLE_RATE` (float64)."""
    if isinstance(sample_rate, bool) or not isinstance(sample_rate, (int, np.integer)) \
            or sample_rate < 1000:
        raise ParameterError(f"sample_rate must be an integer >= 1000 Hz, got {sample_rate!r}")
    x = np.asarray(audio)
    if x.ndim != 1:
        raise ParameterError(f"audio must be mono with shape (n_samples,), got {x.shape}")
    x = x.astype(np.float64)
    if not np.all(np.isfinite(x)):
        raise DataError("audio contains NaN or infinite samples")
    if x.size < MIN_DURATION * sample_rate:
        raise DataError(
            f"audio too short: {x.size / sample_rate:.3f} s < {MIN_DURATION} s needed"
        )
    sample_rate = int(sample_rate)
    if sample_rate != FEATURE_SAMPLE_RATE:
        g = gcd(FEATURE_SAMPLE_RATE, sample_rate)
        x = resample_poly(x, FEATURE_SAMPLE_RATE // g, sample_rate // g)
    if np.sqrt(np.mean(x * x)) < _SILENCE_RMS:
        raise DataError("audio is silent (RMS < 1e-6)")
    return x


def _frame_cepstrum(x: np.ndarray, n_cepstrum: int) -> np.ndarray:
    if x.size < CEPSTRUM_FRAME:
        x = np.pad(x, (0, CEPSTRUM_FRAME - x.size))
    n_frames = 1 + (x.size - CEPSTRUM_FRAME) // CEPSTRUM_HOP
    idx = np.arange(CEPSTRUM_FRAME)[None, :] + CEPSTRUM_HOP * np.arange(n_frames)[:, None]
    frames = x[idx] * np.hanning(CEPSTRUM_FRAME)
    energy = np.sum(frames * frames, axis=1)
    frames = frames[energy >= 1e-6 * energy.max()]
    mag = np.abs(np.fft.rfft(frames, axis=1))
    logmag = np.log(np.maximum(mag, _LOG_FLOOR * mag.max(axis=1, keepdims=True)))
    return np.fft.irfft(logmag, CEPSTRUM_FRAME, axis=1).mean(axis=0)[:n_cepstrum]


def emotion_features(
    audio: np.ndarray,
    sample_rate: int,
    *,
    n_cepstrum: int = N_CEPSTRUM,
    cepstrum: str = "utterance",
) -> np.ndarray:
    """The paper's emotion feature vector of one utterance (§6).

    Parameters
    ----------
    audio : np.ndarray, shape (n_samples,)
        Mono speech, any scale; resampled to 16 kHz first.
    sample_rate : int
        Sampling rate of ``audio`` in Hz.
    n_cepstrum : int, optional
        Number of real-cepstrum coefficients, ``c[0] .. c[n_cepstrum - 1]`` (paper: 500).
    cepstrum : {"utterance", "frames"}, optional
        ``"utterance"`` (paper-literal): one cepstrum of the whole signal;
        ``"frames"``: the mean cepstrum of 2048-sample Hann frames (``n_cepstrum`` at most
        1024).

    Returns
    -------
    np.ndarray, shape (3 + n_cepstrum,)
        ``[mean, variance, RMS, c[0], ..., c[n_cepstrum - 1]]``, float64.

    Raises
    ------
    DataError
        Audio shorter than 0.25 s, silent, or non-finite.
    ParameterError
        Bad ``n_cepstrum``, ``cepstrum``, ``sample_rate`` or audio shape.
    """
    if cepstrum not in _CEPSTRA:
        raise ParameterError(f"cepstrum must be one of {_CEPSTRA}, got {cepstrum!r}")
    limit = CEPSTRUM_FRAME // 2 if cepstrum == "frames" else None
    if isinstance(n_cepstrum, bool) or not isinstance(n_cepstrum, (int, np.integer)) \
            or n_cepstrum < 1 or (limit is not None and n_cepstrum > limit):
        raise ParameterError(
            f"n_cepstrum must be an integer in [1, {limit or 'n_samples // 2'}], "
            f"got {n_cepstrum!r}"
        )
    x = _prepare(audio, sample_rate)
    if cepstrum == "utterance":
        if n_cepstrum > x.size // 2:
            raise DataError(
                f"audio too short for n_cepstrum={n_cepstrum}: {x.size} samples at 16 kHz"
            )
        ceps = real_cepstrum(x)[:n_cepstrum]
    else:
        ceps = _frame_cepstrum(x, n_cepstrum)
    stats = [x.mean(), x.var(), np.sqrt(np.mean(x * x))]
    return np.concatenate([stats, ceps])


def _stats(v: np.ndarray) -> list[float]:
    if v.size == 0:
        return [0.0] * 5
    p10, p90 = np.percentile(v, [10, 90])
    return [float(v.mean()), float(v.std()), float(p10), float(p90), float(p90 - p10)]


def rich_features(audio: np.ndarray, sample_rate: int) -> np.ndarray:
    """An opt-in richer utterance-level feature set (not in the paper).

    Computed at 16 kHz with 32 ms frames (hop 10 ms): 20 MFCCs (mean and standard
    deviation of the coefficients, of their deltas and delta-deltas), log-F0 from
    :func:`librosa.yin` (60-500 Hz) over voiced frames (statistics, delta spread and the
    voiced fraction), log energy (statistics and delta spread), spectral centroid,
    bandwidth, roll-off, flatness, zero-crossing rate (mean, std) and 7-band spectral
    contrast (mean, std), the paper's mean/variance/RMS, and the duration.

    Parameters
    ----------
    audio : np.ndarray, shape (n_samples,)
        Mono speech.
    sample_rate : int
        Its sampling rate in Hz.

    Returns
    -------
    np.ndarray, shape (n_rich,)
        ``n_rich`` = 121 (fixed); float64, finite.

    Raises
    ------
    DataError
        Audio shorter than 0.25 s, silent, or non-finite.
    """
    import librosa

    x = _prepare(audio, sample_rate)
    sr, n_fft, hop = FEATURE_SAMPLE_RATE, 512, 160
    xf = x.astype(np.float32)
    spec = np.abs(librosa.stft(xf, n_fft=n_fft, hop_length=hop))
    power = spec**2
    mel = librosa.feature.melspectrogram(S=power, sr=sr, n_mels=40)
    mfcc = librosa.feature.mfcc(S=librosa.power_to_db(mel), n_mfcc=20)
    d1 = librosa.feature.delta(mfcc, width=5)
    d2 = librosa.feature.delta(mfcc, order=2, width=5)
    parts = [mfcc.mean(1), mfcc.std(1), d1.std(1), d2.std(1)]

    rms = librosa.feature.rms(S=spec, frame_length=n_fft, hop_length=hop)[0]
    log_e = np.log(rms + 1e-8)
    parts.append(_stats(log_e) + [float(np.diff(log_e).std()) if log_e.size > 1 else 0.0])

    f0 = librosa.yin(xf, fmin=60, fmax=500, sr=sr, frame_length=1024, hop_length=hop)
    n = min(f0.size, rms.size)
    f0, r = f0[:n], rms[:n]
    voiced = (r > 0.1 * np.percentile(r, 95)) & (f0 > 62) & (f0 < 490)
    lf0 = np.log(f0[voiced])
    dlf0 = np.diff(np.log(f0))[voiced[1:] & voiced[:-1]]
    parts.append(_stats(lf0) + [float(dlf0.std()) if dlf0.size else 0.0,
                                float(voiced.mean())])

    for feat in (
        librosa.feature.spectral_centroid(S=spec, sr=sr),
        librosa.feature.spectral_bandwidth(S=spec, sr=sr),
        librosa.feature.spectral_rolloff(S=spec, sr=sr),
        librosa.feature.spectral_flatness(S=spec),
        librosa.feature.zero_crossing_rate(xf, frame_length=n_fft, hop_length=hop),
        librosa.feature.spectral_contrast(S=spec, sr=sr, n_bands=6),
    ):
        parts += [feat.mean(1), feat.std(1)]
    parts.append([x.mean(), x.var(), np.sqrt(np.mean(x * x)), x.size / sr])
    out = np.concatenate([np.ravel(np.asarray(p, dtype=np.float64)) for p in parts])
    return np.nan_to_num(out, nan=0.0, posinf=0.0, neginf=0.0)


def speaker_normalize(features: np.ndarray, speakers) -> np.ndarray:
    """Z-normalise each feature within each speaker (not in the paper).

    Uses only the speaker's own utterances and no labels, so it can be applied to an
    unseen test speaker with enough audio; it removes speaker identity (pitch level,
    voice quality) that otherwise dominates speaker-independent evaluation.

    Parameters
    ----------
    features : np.ndarray, shape (n, n_features)
        Feature matrix.
    speakers : array-like, shape (n,)
        Speaker of each row.

    Returns
    -------
    np.ndarray, shape (n, n_features)
        Zero mean, unit variance per speaker (constant features become 0).
    """
    F = np.asarray(features, dtype=np.float64)
    speakers = np.asarray(speakers)
    if F.ndim != 2 or speakers.shape != (F.shape[0],):
        raise ParameterError(
            f"speakers must have shape ({F.shape[0] if F.ndim else 0},), got {speakers.shape}"
        )
    out = np.empty_like(F)
    for s in np.unique(speakers):
        m = speakers == s
        sd = F[m].std(axis=0)
        out[m] = (F[m] - F[m].mean(axis=0)) / np.where(sd > 0, sd, 1.0)
    return out


# --------------------------------------------------------------------------- classifier
def _is_pair(item) -> bool:
    """Whether ``item`` looks like an ``(audio, sample_rate)`` pair."""
    try:
        audio, sr = item
    except (TypeError, ValueError):
        return False
    return np.ndim(audio) >= 1 and np.ndim(sr) == 0

class EmotionClassifier(ClassifierMixin, BaseEstimator):
    """Support-vector emotion classifier of utterances (§6, Table I).

    ``Pipeline(MinMaxScaler(feature_range=(-1, 1)), SVC(kernel, C, gamma="auto"))``
    -- Libsvm's C-SVC, one-vs-one, as in the paper -- on :func:`emotion_features`
    (``features="paper"``) or :func:`rich_features` (``features="rich"``).

    Probabilities: ``SVC(probability=True)`` is deprecated, so :meth:`fit` computes
    out-of-fold SVM decision values (``decision_function_shape="ovr"``, stratified
    ``calibration_cv``-fold, seeded) and fits a multinomial
    :class:`~sklearn.linear_model.LogisticRegression` on them (stacked Platt scaling);
    :meth:`predict_proba` applies it to the decision values of the SVM refitted on all
    the data. :meth:`predict` is the SVM's own one-vs-one vote, as in Libsvm, which can
    differ from ``argmax(predict_proba)`` near class boundaries.

    Parameters
    ----------
    n_cepstrum : int, optional
        Real-cepstrum coefficients in the paper's features (500); ignored for ``"rich"``.
    kernel : {"linear", "rbf", "poly", "sigmoid"}, optional
        SVM kernel (paper: linear).
    C : float, optional
        SVM penalty.
    features : {"paper", "rich"}, optional
        Feature set computed from audio passed to :meth:`fit` / :meth:`predict`.
    cepstrum : {"utterance", "frames"}, optional
        Cepstrum variant of the paper's features (see :func:`emotion_features`).
    calibration_cv : int, optional
        Folds for the out-of-fold decision values of the probability calibration
        (reduced to the smallest class size when needed, at least 2).
    random_state : int, optional
        Seed of the calibration folds.

    Attributes
    ----------
    classes_ : np.ndarray, shape (n_classes,)
        Class labels.
    n_features_in_ : int
        Width of the feature matrix.
    pipeline_ : sklearn.pipeline.Pipeline
        The fitted scaler + SVC.
    calibrator_ : sklearn.linear_model.LogisticRegression
        Maps decision values, shape (n, n_classes) (or (n, 1) for two classes), to
        probabilities.

    Notes
    -----
    ``fit``, ``predict`` and ``predict_proba`` accept either a feature matrix, shape
    ``(n_utterances, n_features)``, or a sequence of ``(audio, sample_rate)`` pairs whose
    features are then computed (see :meth:`featurize`). Malformed matrices and labels
    raise ``ValueError`` subclasses (scikit-learn's, or :class:`ParameterError`) so that
    the estimator passes scikit-learn's common checks; bad audio raises
    :class:`DataError`.
    """

    def __init__(
        self,
        n_cepstrum: int = N_CEPSTRUM,
        kernel: str = KERNEL,
        C: float = 1.0,
        features: str = "paper",
        cepstrum: str = "utterance",
        calibration_cv: int = 5,
        random_state: int = 0,
    ):
        self.n_cepstrum = n_cepstrum
        self.kernel = kernel
        self.C = C
        self.features = features
        self.cepstrum = cepstrum
        self.calibration_cv = calibration_cv
        self.random_state = random_state

    # ------------------------------------------------------------------ helpers
    def _check_params(self) -> None:
        if self.features not in _FEATURE_SETS:
            raise ParameterError(f"features must be one of {_FEATURE_SETS}, got {self.features!r}")
        if self.kernel not in _KERNELS:
            raise ParameterError(f"kernel must be one of {_KERNELS}, got {self.kernel!r}")
        if isinstance(self.C, bool) or not isinstance(self.C, (int, float, np.number)) \
                or not float(self.C) > 0:
            raise ParameterError(f"C must be a positive number, got {self.C!r}")
        if self.cepstrum not in _CEPSTRA:
            raise ParameterError(f"cepstrum must be one of {_CEPSTRA}, got {self.cepstrum!r}")
        if isinstance(self.calibration_cv, bool) or not isinstance(
                self.calibration_cv, (int, np.integer)) or self.calibration_cv < 2:
            raise ParameterError(
                f"calibration_cv must be an integer >= 2, got {self.calibration_cv!r}"
            )

    def featurize(self, X) -> np.ndarray:
        """Feature matrix of ``X`` (a 2-D numeric array passes through ``check_array``).

        A feature matrix is used as given: its width is not checked against
        ``n_cepstrum``/``features``, which only govern features computed from audio.

        Parameters
        ----------
        X : np.ndarray, shape (n, n_features), or sequence of (audio, sample_rate)
            Features, or utterances.

        Returns
        -------
        np.ndarray, shape (n, n_features)
            float64 features.
        """
        if issparse(X):
            raise ParameterError("X must be dense: sparse input is not supported")
        if isinstance(X, (list, tuple)):
            items = list(X)
            if items and not _is_pair(items[0]):
                return check_array(items, dtype=np.float64)  # nested lists of numbers
        else:
            arr = np.asarray(X)
            if arr.ndim != 2:
                raise ParameterError(
                    f"X must be a 2-D feature matrix or a sequence of (audio, sample_rate) "
                    f"pairs, got an array of shape {arr.shape}. Reshape your data"
                )
            # sklearn's own checks: finite, non-empty, numeric (ValueError subclasses).
            return check_array(arr, dtype=np.float64)
        rows = []
        for i, item in enumerate(X):
            try:
                audio, sr = item
            except (TypeError, ValueError):
                raise ParameterError(
                    f"X[{i}] must be an (audio, sample_rate) pair, got {type(item).__name__}"
                ) from None
            if self.features == "paper":
                rows.append(emotion_features(audio, sr, n_cepstrum=self.n_cepstrum,
                                             cepstrum=self.cepstrum))
            else:
                rows.append(rich_features(audio, sr))
        if not rows:
            raise DataError("X holds no utterances")
        return np.vstack(rows)

    def _make_pipeline(self) -> Pipeline:
        return Pipeline([
            ("scale", MinMaxScaler(feature_range=(-1, 1))),
            ("svm", SVC(kernel=self.kernel, C=float(self.C), gamma="auto",
                        decision_function_shape="ovr")),
        ])

    @staticmethod
    def _as_2d(d: np.ndarray) -> np.ndarray:
        return d[:, None] if d.ndim == 1 else d

    # ------------------------------------------------------------------ API
    def fit(self, X, y):
        """Fit the scaler, the SVM and the probability calibration.

        Parameters
        ----------
        X : np.ndarray, shape (n, n_features), or sequence of (audio, sample_rate)
            Training utterances or their features.
        y : array-like, shape (n,)
            Emotion labels (at least two classes).

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
        folds = min(int(self.calibration_cv), int(counts.min()))
        if folds < 2:
            raise ParameterError(
                f"every class needs at least 2 utterances for calibration, got {counts.min()}"
            )
        cv = StratifiedKFold(folds, shuffle=True, random_state=self.random_state)
        oof = cross_val_predict(self._make_pipeline(), F, y, cv=cv, method="decision_function")
        self.calibrator_ = LogisticRegression(C=1.0, max_iter=1000).fit(self._as_2d(oof), y)
        self.pipeline_ = self._make_pipeline().fit(F, y)
        self.classes_ = self.pipeline_.classes_
        self.n_features_in_ = F.shape[1]
        return self

    def _checked(self, X) -> np.ndarray:
        check_is_fitted(self, ["pipeline_", "calibrator_"])
        F = self.featurize(X)
        if F.shape[1] != self.n_features_in_:
            raise ParameterError(
                f"X has {F.shape[1]} features, but EmotionClassifier is expecting "
                f"{self.n_features_in_} features as input"
            )
        return F

    def decision_function(self, X) -> np.ndarray:
        """SVM decision values (one-vs-rest shape, from Libsvm's one-vs-one votes).

        Parameters
        ----------
        X : np.ndarray, shape (n, n_features), or sequence of (audio, sample_rate)

        Returns
        -------
        np.ndarray, shape (n, n_classes), or (n,) for two classes
        """
        F = self._checked(X)
        return self.pipeline_.decision_function(F)

    def predict(self, X) -> np.ndarray:
        """Most likely emotion of each utterance (the SVM's one-vs-one vote).

        Parameters
        ----------
        X : np.ndarray, shape (n, n_features), or sequence of (audio, sample_rate)

        Returns
        -------
        np.ndarray, shape (n,)
        """
        F = self._checked(X)
        return self.pipeline_.predict(F)

    def predict_proba(self, X) -> np.ndarray:
        """Calibrated class probabilities (columns in the order of ``classes_``).

        Parameters
        ----------
        X : np.ndarray, shape (n, n_features), or sequence of (audio, sample_rate)

        Returns
        -------
        np.ndarray, shape (n, n_classes)
            Rows sum to 1.
        """
        F = self._checked(X)
        d = self.pipeline_.decision_function(F)
        return self.calibrator_.predict_proba(self._as_2d(d))

    # ------------------------------------------------------------------ storage
    def to_arrays(self) -> dict[str, np.ndarray]:
        """The fitted model as plain NumPy arrays (no pickles), e.g. for ``np.savez``.

        Returns
        -------
        dict of str to np.ndarray
            Hyper-parameters (``n_cepstrum``, ``kernel``, ``C``, ``features``,
            ``cepstrum``, ``gamma``), the scaler's ``scale_min``/``scale_scale``
            (shape (n_features,)), the SVM's ``classes`` (n_classes,),
            ``support_vectors`` (n_sv, n_features), ``support`` (n_sv,), ``n_support``
            (n_classes,), ``dual_coef`` (n_classes - 1, n_sv), ``intercept``
            (n_classes * (n_classes - 1) / 2,), and the calibration's ``calib_coef``
            and ``calib_intercept``.
        """
        check_is_fitted(self, ["pipeline_", "calibrator_"])
        scaler, svm = self.pipeline_["scale"], self.pipeline_["svm"]
        return {
            "n_cepstrum": np.array(self.n_cepstrum),
            "kernel": np.array(self.kernel),
            "C": np.array(float(self.C)),
            "features": np.array(self.features),
            "cepstrum": np.array(self.cepstrum),
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
            "calib_coef": self.calibrator_.coef_.copy(),
            "calib_intercept": self.calibrator_.intercept_.copy(),
        }

    @classmethod
    def from_arrays(cls, arrays) -> EmotionClassifier:
        """Rebuild a fitted classifier from :meth:`to_arrays` output.

        The SVC is restored by setting the attributes Libsvm's prediction reads
        (including scikit-learn's private ``_dual_coef_``, ``_intercept_``, ``_n_support``,
        ``_gamma``); checked against scikit-learn 1.9 by the test suite.

        Parameters
        ----------
        arrays : mapping of str to np.ndarray
            E.g. a dict or an ``np.load``-ed ``.npz``.

        Returns
        -------
        EmotionClassifier
            Predicting exactly as the stored model.
        """
        try:
            a = {k: np.asarray(arrays[k]) for k in (
                "n_cepstrum", "kernel", "C", "features", "cepstrum", "calibration_cv",
                "random_state", "gamma", "scale_min", "scale_scale", "classes",
                "support_vectors", "support", "n_support", "dual_coef", "intercept",
                "calib_coef", "calib_intercept")}
        except KeyError as exc:
            raise DataError(f"stored emotion classifier lacks array {exc.args[0]!r}") from None
        model = cls(n_cepstrum=int(a["n_cepstrum"]), kernel=str(a["kernel"]), C=float(a["C"]),
                    features=str(a["features"]), cepstrum=str(a["cepstrum"]),
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
        sv = np.ascontiguousarray(a["support_vectors"], dtype=np.float64)
        dual = np.ascontiguousarray(a["dual_coef"], dtype=np.float64)
        intercept = np.ascontiguousarray(a["intercept"], dtype=np.float64)
        sign = -1.0 if classes.size == 2 else 1.0  # sklearn flips the public binary signs
        svm.classes_ = classes
        svm.support_vectors_ = sv
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
        calib = LogisticRegression(C=1.0, max_iter=1000)
        calib.classes_ = classes
        calib.coef_ = a["calib_coef"].astype(np.float64)
        calib.intercept_ = a["calib_intercept"].astype(np.float64)
        calib.n_features_in_ = calib.coef_.shape[1]
        model.calibrator_ = calib
        model.classes_ = classes
        model.n_features_in_ = n_features
        return model


# --------------------------------------------------------------------------- EmoDB
def load_emodb(root) -> tuple[list[tuple[np.ndarray, int]], np.ndarray, np.ndarray]:
    """Read the Berlin Emotional Speech Database (EmoDB).

    File names are ``SSTTTEV.wav``: speaker (2 digits), text code (3), emotion letter
    (W anger, L boredom, E disgust, A fear, F happiness, T sadness, N neutral) and
    version letter.

    Parameters
    ----------
    root : path-like
        The EmoDB folder (holding ``wav/``) or the ``wav`` folder itself.

    Returns
    -------
    utterances : list of (np.ndarray, int)
        ``(audio, sample_rate)`` per file in sorted file-name order; audio float32, shape
        (n_samples,).
    labels : np.ndarray of str, shape (n_files,)
        English emotion names.
    speakers : np.ndarray of str, shape (n_files,)
        Two-digit speaker codes.
    """
    import soundfile as sf

    root = Path(root)
    wav = root / "wav" if (root / "wav").is_dir() else root
    files = sorted(wav.glob("*.wav"))
    if not files:
        raise DataError(f"no EmoDB .wav files in {wav}")
    utterances, labels, speakers = [], [], []
    for f in files:
        m = _EMODB_NAME.match(f.stem)
        if m is None:
            raise DataError(f"not an EmoDB file name: {f.name}")
        audio, sr = sf.read(f, dtype="float32", always_2d=True)
        utterances.append((audio.mean(axis=1), int(sr)))
        labels.append(EMODB_EMOTIONS[m.group(3)])
        speakers.append(m.group(1))
    return utterances, np.array(labels), np.array(speakers)
