"""Frame-level analysis of prepared speech, shared by the ``rich`` feature block
(:mod:`ingest.emotion.features`) and the bag-of-audio-words (:mod:`ingest.emotion.boaw`).

Frames more than ``silence_floor`` dB below the loudest frame of the utterance are
*silence* and are replaced by that floor (why: :mod:`ingest.emotion.features`, "Silence
floor").
"""

from __future__ import annotations

import numpy as np

from db.errors import ParameterError
from ingest.emotion.audio import FEATURE_SAMPLE_RATE

__all__ = ["SILENCE_FLOOR", "check_floor", "frame_analysis", "silent_frames"]

#: Frames more than this many dB below the loudest frame of the utterance are silence
#: (the module docstring; HTK's ``SILFLOOR`` default). The synthetic corpus' noise floor lies
#: about 59 dB below its loudest frames, its speech above -45 dB.
SILENCE_FLOOR = 50.0


def check_floor(silence_floor) -> None:
    """Refuse a ``silence_floor`` that is neither None nor a number of dB in (0, 200)."""
    if silence_floor is not None and (
            isinstance(silence_floor, bool) or not isinstance(silence_floor, int | float)
            or not 0 < silence_floor < 200):
        raise ParameterError(f"silence_floor must be None or a number of dB in (0, 200), "
                             f"got {silence_floor!r}")


def silent_frames(spec: np.ndarray, silence_floor: float | None = SILENCE_FLOOR
                  ) -> tuple[np.ndarray, float]:
    """Which frames of a magnitude spectrogram are silence, and the floor's power.

    Parameters
    ----------
    spec : np.ndarray, shape (n_bins, n_frames)
    silence_floor : float or None
        dB below the loudest frame's mean power (None: no frame is silence).

    Returns
    -------
    silent : np.ndarray of bool, shape (n_frames,)
    floor : float
        Mean power per bin of the floor (0 when ``silence_floor`` is None).
    """
    power = np.mean(spec.astype(np.float64) ** 2, axis=0)
    if silence_floor is None or power.size == 0:
        return np.zeros(power.shape, dtype=bool), 0.0
    floor = float(power.max()) * 10 ** (-silence_floor / 10)
    return power < floor, floor


def frame_analysis(x: np.ndarray, silence_floor: float | None = SILENCE_FLOOR
                   ) -> dict[str, np.ndarray]:
    """Frame-level analysis of prepared 16 kHz speech ``x`` (shared by the ``rich``
    block and :mod:`ingest.emotion.boaw`), 32 ms frames, hop 10 ms: the magnitude
    spectrogram ``spec`` (257, T), 20 MFCCs ``mfcc`` (20, T) from 40 mel bands, ``rms``
    (T,), the YIN F0 ``f0`` (Hz, about T frames; 60-500 Hz) and ``silent`` (T,), the
    frames below the silence floor (``silence_floor`` dB under the loudest; None: none),
    whose spectrum is replaced by the floor's, flat (the module docstring)."""
    import librosa

    sr, n_fft, hop = FEATURE_SAMPLE_RATE, 512, 160
    xf = x.astype(np.float32)
    spec = np.abs(librosa.stft(xf, n_fft=n_fft, hop_length=hop))
    silent, floor = silent_frames(spec, silence_floor)
    # Silent frames become the floor, flat; in the others every bin is floored too, so that
    # a noise floor under it does not fill the spectral valleys of speech either.
    spec[:, silent] = np.sqrt(floor)
    np.maximum(spec, np.float32(np.sqrt(floor)), out=spec)
    mel = librosa.feature.melspectrogram(S=spec**2, sr=sr, n_mels=40)
    return {
        "spec": spec,
        "mfcc": librosa.feature.mfcc(S=librosa.power_to_db(mel), n_mfcc=20),
        "rms": librosa.feature.rms(S=spec, frame_length=n_fft, hop_length=hop)[0],
        "f0": librosa.yin(xf, fmin=60, fmax=500, sr=sr, frame_length=1024, hop_length=hop),
        "silent": silent,
    }
