"""Utterance-level emotion features of speech (Cao et al. 2005, §6, and issue #16).

Every function takes audio as :func:`ingest.emotion.audio.prepare_audio` accepts it (any
rate, mono or stereo, integer or float PCM; level-normalised, silence refused). Feature
*blocks*, joined with ``+`` in a feature specification (``"rich+cepstrum"``):

======== ===================================================================== =========
block    content                                                               width
======== ===================================================================== =========
paper    the paper's vector (§6): mean, variance, RMS of the signal and the    3 + n
         first ``n_cepstrum`` real-cepstrum coefficients (:func:`emotion_features`)
rich     prosody and spectral shape (:func:`rich_features`; not in the paper)  121
cepstrum the first :data:`CEPSTRUM_BLOCK` coefficients of the frame-averaged   50
         cepstrum (the paper's cepstrum, made robust to utterance length)
egemaps  openSMILE eGeMAPS v02 functionals (Eyben et al. 2016)                 88
compare  openSMILE ComParE 2016 functionals (Schuller et al. 2016)             6373
boaw     bag-of-audio-words of frame descriptors (:mod:`ingest.emotion.boaw`)  1000
         (2 x 500 words learned at fit by the classifier, its columns after all
         the others; :func:`block_features` gives the frame descriptors)
======== ===================================================================== =========

``egemaps`` and ``compare`` need the optional ``opensmile`` package
(``pip install "animegraph[opensmile]"``). Choices where the paper is silent:

* Audio is resampled to 16 kHz first, so coefficient ``k`` always means a quefrency of
  ``k / 16000`` s whatever the input rate.
* ``cepstrum="utterance"`` (paper-literal): one real cepstrum of the whole utterance (FFT
  length = number of samples). ``cepstrum="frames"``: the mean real cepstrum of 2048-sample
  Hann frames (hop 512), silent frames (below the silence floor, below) left out.
* "RMS error" of the signal is read as the root mean square of the (16 kHz) samples.
* The level is normalised first (issue #16), so mean, variance and RMS describe the
  signal's shape (its crest factor), not how loud it was recorded.

Silence floor (issue s18). A pause is digital silence (exact zeros) in synthetic, noise-gated
or clean studio speech, and a noise floor some 60 dB below the speech elsewhere (the
synthetic corpus, most recordings). Frame statistics that include the pauses then describe
the recording, not the speaker: the 10th percentile of the log energy *is* the pause level
(-18.4 for zeros against -8 for the corpus' floor), and an all-zero frame has a spectral
centroid and a zero-crossing rate of 0 where noise has 4 kHz and 0.5 -- enough for the
database classifier, trained on one noise floor, to call any speech with zero pauses
"angry". So, as HTK's energy floor (``SILFLOOR``, 50 dB below the utterance's loudest
frame: Young et al., *The HTK Book*, §5.6), every frame more than ``silence_floor`` dB below
the loudest frame of the utterance is *silence* and is replaced by that floor
(:func:`frame_analysis`): a flat spectrum of the floor's power, the zero-crossing rate of
white noise (0.5); in the other frames every bin of the spectrum is floored at the same
power, so that a noise floor does not fill the spectral valleys of quiet speech either (the
spectral contrast of the upper bands moved most after the silent frames were floored); the
frame-averaged cepstrum leaves silent frames out. Whatever lies below the floor -- zeros,
dither, a quiet noise floor -- then gives nearly the same features (what is left: the
zero-crossing rate of speech frames and the cepstrum block, about one corpus standard
deviation at most); a noise floor above it still shows. ``silence_floor=None`` is the
analysis before the floor (no floor; the frame-averaged cepstrum dropping frames 60 dB
down), which classifiers stored before it (format < 6) were fitted on.
"""

from __future__ import annotations

import numpy as np

from db.errors import DataError, ParameterError
from ingest.emotion.audio import FEATURE_SAMPLE_RATE, prepare_audio
from ingest.emotion.boaw import descriptors
from ingest.emotion.frames import SILENCE_FLOOR, check_floor, frame_analysis

__all__ = [
    "BLOCKS",
    "CEPSTRUM_BLOCK",
    "CEPSTRUM_FRAME",
    "CEPSTRUM_HOP",
    "N_CEPSTRUM",
    "WORDS_BLOCK",
    "block_features",
    "emotion_features",
    "parse_features",
    "real_cepstrum",
    "rich_features",
]

#: Cepstrum coefficients in the paper's feature vector (§6).
N_CEPSTRUM = 500
#: Frame length and hop (samples at 16 kHz) of the frame-averaged cepstrum.
CEPSTRUM_FRAME = 2048
CEPSTRUM_HOP = 512
#: Coefficients of the ``cepstrum`` block (frame-averaged; 50 measured best beside ``rich``
#: in docs/results.md, "Emotion classification").
CEPSTRUM_BLOCK = 50
#: Feature blocks a specification may join with "+".
BLOCKS = ("paper", "rich", "cepstrum", "egemaps", "compare", "boaw")
#: The block learned at fit (:class:`ingest.emotion.classifier.EmotionClassifier`).
WORDS_BLOCK = "boaw"
#: Width of each block (``paper``: 3 + n_cepstrum).
RICH_WIDTH, EGEMAPS_WIDTH, COMPARE_WIDTH = 121, 88, 6373

_CEPSTRA = ("utterance", "frames")
_LEGACY_CEPSTRUM_FLOOR = 60.0  # dB: the frame-averaged cepstrum's cut without the floor
_LOG_FLOOR = 1e-10  # |FFT| floor relative to its peak before the log (-200 dB)
_OPENSMILE_SETS = {"egemaps": "eGeMAPSv02", "compare": "ComParE_2016"}
_smiles: dict = {}


# --------------------------------------------------------------------------- the paper's
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


def _frame_cepstrum(x: np.ndarray, n_cepstrum: int,
                    silence_floor: float | None = SILENCE_FLOOR) -> np.ndarray:
    if x.size < CEPSTRUM_FRAME:
        x = np.pad(x, (0, CEPSTRUM_FRAME - x.size))
    n_frames = 1 + (x.size - CEPSTRUM_FRAME) // CEPSTRUM_HOP
    idx = np.arange(CEPSTRUM_FRAME)[None, :] + CEPSTRUM_HOP * np.arange(n_frames)[:, None]
    frames = x[idx] * np.hanning(CEPSTRUM_FRAME)
    energy = np.sum(frames * frames, axis=1)
    cut = _LEGACY_CEPSTRUM_FLOOR if silence_floor is None else silence_floor
    frames = frames[energy >= 10 ** (-cut / 10) * energy.max()]  # silence says nothing
    mag = np.abs(np.fft.rfft(frames, axis=1))
    logmag = np.log(np.maximum(mag, _LOG_FLOOR * mag.max(axis=1, keepdims=True)))
    return np.fft.irfft(logmag, CEPSTRUM_FRAME, axis=1).mean(axis=0)[:n_cepstrum]


def _check_cepstrum(n_cepstrum, cepstrum: str) -> None:
    if cepstrum not in _CEPSTRA:
        raise ParameterError(f"cepstrum must be one of {_CEPSTRA}, got {cepstrum!r}")
    limit = CEPSTRUM_FRAME // 2 if cepstrum == "frames" else None
    if isinstance(n_cepstrum, bool) or not isinstance(n_cepstrum, int | np.integer) \
            or n_cepstrum < 1 or (limit is not None and n_cepstrum > limit):
        raise ParameterError(
            f"n_cepstrum must be an integer in [1, {limit or 'n_samples // 2'}], "
            f"got {n_cepstrum!r}"
        )


def _paper(x: np.ndarray, n_cepstrum: int, cepstrum: str,
           silence_floor: float | None = SILENCE_FLOOR) -> np.ndarray:
    if cepstrum == "utterance":
        if n_cepstrum > x.size // 2:
            raise DataError(
                f"audio too short for n_cepstrum={n_cepstrum}: {x.size} samples at 16 kHz"
            )
        ceps = real_cepstrum(x)[:n_cepstrum]
    else:
        ceps = _frame_cepstrum(x, n_cepstrum, silence_floor)
    return np.concatenate([[x.mean(), x.var(), np.sqrt(np.mean(x * x))], ceps])


def emotion_features(
    audio: np.ndarray,
    sample_rate: float,
    *,
    n_cepstrum: int = N_CEPSTRUM,
    cepstrum: str = "utterance",
    silence_floor: float | None = SILENCE_FLOOR,
) -> np.ndarray:
    """The paper's emotion feature vector of one utterance (§6).

    Parameters
    ----------
    audio : np.ndarray, shape (n_samples,) or (n_samples, n_channels)
        Speech, integer PCM or float; resampled to 16 kHz and level-normalised first.
    sample_rate : int or float
        Sampling rate of ``audio`` in Hz.
    n_cepstrum : int, optional
        Number of real-cepstrum coefficients, ``c[0] .. c[n_cepstrum - 1]`` (paper: 500).
    cepstrum : {"utterance", "frames"}, optional
        ``"utterance"`` (paper-literal): one cepstrum of the whole signal;
        ``"frames"``: the mean cepstrum of 2048-sample Hann frames (``n_cepstrum`` at most
        1024).
    silence_floor : float or None, optional
        dB below the loudest frame under which a frame is silence, left out of the
        frame-averaged cepstrum (the module docstring; None: the cut before the floor).

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
    _check_cepstrum(n_cepstrum, cepstrum)
    check_floor(silence_floor)
    return _paper(prepare_audio(audio, sample_rate), n_cepstrum, cepstrum, silence_floor)


# --------------------------------------------------------------------------- rich
def _stats(v: np.ndarray) -> list[float]:
    if v.size == 0:
        return [0.0] * 5
    p10, p90 = np.percentile(v, [10, 90])
    return [float(v.mean()), float(v.std()), float(p10), float(p90), float(p90 - p10)]


def _rich(x: np.ndarray, fr: dict | None = None,
          silence_floor: float | None = SILENCE_FLOOR) -> np.ndarray:
    import librosa

    sr, n_fft, hop = FEATURE_SAMPLE_RATE, 512, 160
    xf = x.astype(np.float32)
    fr = frame_analysis(x, silence_floor) if fr is None else fr
    spec, mfcc, rms, f0 = fr["spec"], fr["mfcc"], fr["rms"], fr["f0"]
    zcr = librosa.feature.zero_crossing_rate(xf, frame_length=n_fft, hop_length=hop)
    n = min(zcr.shape[1], fr["silent"].size)
    zcr[0, :n][fr["silent"][:n]] = 0.5  # the floor is white: half the samples cross
    d1 = librosa.feature.delta(mfcc, width=5)
    d2 = librosa.feature.delta(mfcc, order=2, width=5)
    parts = [mfcc.mean(1), mfcc.std(1), d1.std(1), d2.std(1)]

    log_e = np.log(rms + 1e-8)
    parts.append(_stats(log_e) + [float(np.diff(log_e).std()) if log_e.size > 1 else 0.0])

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
        zcr,
        librosa.feature.spectral_contrast(S=spec, sr=sr, n_bands=6),
    ):
        parts += [feat.mean(1), feat.std(1)]
    parts.append([x.mean(), x.var(), np.sqrt(np.mean(x * x)), x.size / sr])
    out = np.concatenate([np.ravel(np.asarray(p, dtype=np.float64)) for p in parts])
    return np.nan_to_num(out, nan=0.0, posinf=0.0, neginf=0.0)


def rich_features(audio: np.ndarray, sample_rate: float,
                  silence_floor: float | None = SILENCE_FLOOR) -> np.ndarray:
    """A richer utterance-level feature set (not in the paper).

    Computed at 16 kHz with 32 ms frames (hop 10 ms): 20 MFCCs (mean and standard
    deviation of the coefficients, of their deltas and delta-deltas), log-F0 from
    :func:`librosa.yin` (60-500 Hz) over voiced frames (statistics, delta spread and the
    voiced fraction), log energy (statistics and delta spread), spectral centroid,
    bandwidth, roll-off, flatness, zero-crossing rate (mean, std) and 7-band spectral
    contrast (mean, std), the paper's mean/variance/RMS, and the duration.

    Parameters
    ----------
    audio : np.ndarray, shape (n_samples,) or (n_samples, n_channels)
        Speech.
    sample_rate : int or float
        Its sampling rate in Hz.
    silence_floor : float or None, optional
        dB below the loudest frame under which frames are silence, replaced by the floor
        (the module docstring; None: no floor).

    Returns
    -------
    np.ndarray, shape (121,)
        float64, finite.

    Raises
    ------
    DataError
        Audio shorter than 0.25 s, silent, or non-finite.
    """
    check_floor(silence_floor)
    return _rich(prepare_audio(audio, sample_rate), silence_floor=silence_floor)


# --------------------------------------------------------------------------- openSMILE
def _opensmile(x: np.ndarray, name: str) -> np.ndarray:
    if name not in _smiles:
        try:
            import opensmile
        except ImportError:
            raise ParameterError(f"features {name!r} need openSMILE: pip install "
                                 "'animegraph[opensmile]'") from None
        _smiles[name] = opensmile.Smile(
            feature_set=getattr(opensmile.FeatureSet, _OPENSMILE_SETS[name]),
            feature_level=opensmile.FeatureLevel.Functionals)
    out = _smiles[name].process_signal(x.astype(np.float32), FEATURE_SAMPLE_RATE)
    return np.nan_to_num(np.asarray(out, dtype=np.float64).ravel(),
                         nan=0.0, posinf=0.0, neginf=0.0)


# --------------------------------------------------------------------------- blocks
def parse_features(spec: str) -> tuple[str, ...]:
    """The blocks of a feature specification such as ``"rich+cepstrum"``.

    Raises
    ------
    ParameterError
        Not a string, an unknown block or a repeated one.
    """
    if not isinstance(spec, str) or not spec:
        raise ParameterError(f"features must be blocks of {BLOCKS} joined by '+', "
                             f"got {spec!r}")
    blocks = tuple(spec.split("+"))
    bad = [b for b in blocks if b not in BLOCKS]
    if bad or len(set(blocks)) != len(blocks):
        raise ParameterError(f"features must be distinct blocks of {BLOCKS} joined by '+', "
                             f"got {spec!r}")
    return blocks


def block_features(audio, sample_rate, spec: str = "paper", *, n_cepstrum: int = N_CEPSTRUM,
                   cepstrum: str = "utterance", silence_floor: float | None = SILENCE_FLOOR
                   ) -> dict[str, np.ndarray]:
    """Each block of ``spec`` for one utterance (the audio prepared once).

    Parameters
    ----------
    audio : np.ndarray, shape (n_samples,) or (n_samples, n_channels)
    sample_rate : int or float
    spec : str
        Blocks joined by ``+`` (see the module docstring).
    n_cepstrum, cepstrum
        Of the ``paper`` block (:func:`emotion_features`).
    silence_floor : float or None, optional
        dB below the loudest frame under which frames are silence (the module docstring;
        None: the analysis before the floor, of classifiers stored before it).

    Returns
    -------
    dict of str to np.ndarray, each shape (block_width,)
        In the order of ``spec``; ``boaw``'s entry is not a vector but the frame
        descriptors, shape (n_frames, 44) (:func:`ingest.emotion.boaw.frame_descriptors`:
        the words are learned from them at fit), sharing the ``rich`` block's frame
        analysis.
    """
    blocks = parse_features(spec)
    if "paper" in blocks:
        _check_cepstrum(n_cepstrum, cepstrum)
    check_floor(silence_floor)
    x = prepare_audio(audio, sample_rate)
    fr = frame_analysis(x, silence_floor) if "rich" in blocks or WORDS_BLOCK in blocks \
        else None
    out = {}
    for block in blocks:
        if block == "paper":
            out[block] = _paper(x, n_cepstrum, cepstrum, silence_floor)
        elif block == "rich":
            out[block] = _rich(x, fr)
        elif block == WORDS_BLOCK:
            out[block] = descriptors(fr)
        elif block == "cepstrum":
            out[block] = _frame_cepstrum(x, CEPSTRUM_BLOCK, silence_floor)
        else:
            out[block] = _opensmile(x, block)
    return out
