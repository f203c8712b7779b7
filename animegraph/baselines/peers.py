"""Published lip-sync tools that install from PyPI, as peer rows of lip-sync tables.

Neither tool outputs this project's channels: each gives per-frame weights of its own
mouth shapes. Both are mapped to the face **the same documented way**, the way
:class:`animegraph.baselines.reference.Loudness` maps the loudness: motion ≈ a + B · w,
per channel, fitted by least squares on the training clips, where ``w`` (n_frames, k)
are the tool's shape weights at the motion's frames. The mapping is the most a linear
rig could get out of the tool's output; mouth opening follows from it.

* :class:`OpenFaceFX` -- ``openfacefx`` (MIT; rule-based: phone timings -> the 15
  Oculus visemes with a coarticulation model, ``build_viseme_curves``). It needs timed
  phones and has no recogniser of its own: audio only, it gets the phones of this
  project's phone engine (:func:`ingest.speech.segment.segment`, as ``synth`` does);
  training clips use their stored phones.
* :class:`PyLipSync` -- ``pylipsync`` (MIT; a Python port of uLipSync: MFCC of each
  64 ms window compared with the shipped templates of the vowels A I U E O and silence,
  weighted by loudness).

``pip install -e ".[peers]"``; without the package, ``fit`` raises one line saying so.
Yardsticks for ``scripts/eval_lipsync.py`` (``--systems openfacefx pylipsync``), not
``synth --method`` choices.
"""

from __future__ import annotations

import hashlib
from typing import ClassVar

import numpy as np

from animegraph.baselines.reference import FeatureLine
from db.errors import DataError
from ingest.motion import interpolate

__all__ = ["PEERS", "OpenFaceFX", "PyLipSync"]

#: Shape weights of the last clips seen, by tool and audio (:meth:`_ShapeWeights._features`).
_REMEMBERED: dict[tuple, np.ndarray] = {}
_REMEMBER = 512
#: Frame rate the tools are run at (their shape weights are then interpolated to the
#: motion's frame times).
PEER_FPS = 50


def _missing(package: str, exc: ImportError) -> DataError:
    return DataError(f"the {package} peer is not installed ({exc}); "
                     f"pip install -e \".[peers]\"")


class _ShapeWeights(FeatureLine):
    """Motion as a per-channel affine function of a tool's per-frame shape weights."""

    def _weights(self, audio: np.ndarray, sample_rate: int, times: np.ndarray,
                 phones=None) -> np.ndarray:
        raise NotImplementedError

    def _features(self, audio, sample_rate, times, phones=None) -> np.ndarray:
        """:meth:`_weights`, remembered for the last clips seen (an evaluation refits on
        the same clips fold after fold; the tools run at 20-60x real time)."""
        digest = hashlib.blake2b(np.ascontiguousarray(audio).tobytes(), digest_size=16)
        digest.update(np.ascontiguousarray(times, dtype=np.float64).tobytes())
        key = (self.method, repr(self.get_params()), int(sample_rate), phones is None,
               digest.digest())
        if key not in _REMEMBERED:
            if len(_REMEMBERED) >= _REMEMBER:
                _REMEMBERED.pop(next(iter(_REMEMBERED)))
            _REMEMBERED[key] = self._weights(audio, sample_rate, times, phones)
        return _REMEMBERED[key]


class OpenFaceFX(_ShapeWeights):
    """openfacefx's 15 viseme curves from timed phones, mapped linearly to the face.

    Parameters
    ----------
    phones_engine : str, optional
        Phone engine for audio without phones (:data:`ingest.speech.engines.ENGINES`).
    """

    method: ClassVar[str] = "openfacefx"

    def __init__(self, phones_engine: str | None = None):
        self.phones_engine = phones_engine

    def _weights(self, audio, sample_rate, times, phones=None):
        try:
            from openfacefx import PhonemeSegment, build_viseme_curves
            from openfacefx.phonemes import SILENCE
        except ImportError as exc:
            raise _missing("openfacefx", exc) from None
        from ingest.speech.segment import segment

        if phones is None:
            phones, _ = segment(audio, sample_rate, engine=self.phones_engine)
        segments = [PhonemeSegment(SILENCE if p.phone == "SIL" else p.phone, float(p.start),
                                   float(p.end)) for p in phones]
        t, matrix = build_viseme_curves(segments, fps=PEER_FPS)
        return interpolate(np.asarray(t), matrix, times)


class PyLipSync(_ShapeWeights):
    """pylipsync's (uLipSync's) vowel and silence weights, mapped linearly to the face."""

    method: ClassVar[str] = "pylipsync"

    def _weights(self, audio, sample_rate, times, phones=None):
        try:
            from pylipsync import PhonemeAnalyzer
        except ImportError as exc:
            raise _missing("pylipsync", exc) from None
        analyzer = PhonemeAnalyzer()
        frames = analyzer.extract_phoneme_segments(np.asarray(audio, dtype=np.float32),
                                                   int(sample_rate), fps=PEER_FPS,
                                                   return_seconds=True)
        if not frames:
            return np.zeros((len(times), 1))
        names = sorted(p.name for p in frames[0].phonemes)
        centre = np.array([(f.start + f.end) / 2 for f in frames])
        w = np.array([[{p.name: p.target for p in f.phonemes}[n] for n in names]
                      for f in frames], dtype=np.float64)
        return interpolate(centre, w, times)


#: The peer rows, by name.
PEERS = {cls.method: cls for cls in (OpenFaceFX, PyLipSync)}
