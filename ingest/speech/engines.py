"""The phone engines and the choice between them (kept light: imports nothing heavy).

* ``"hama"`` -- the CTC phone recogniser whose model ships in the ``hama`` wheel
  (:mod:`ingest.speech.ctc`): recognition, CTC-Viterbi forced alignment, posteriors;
* ``"pocketsphinx"`` -- PocketSphinx with its US-English model (:mod:`ingest.speech.segment`);
* ``"auto"`` (the default) -- each task by the engine that measured better at it
  (``scripts/eval_segmentation.py``, docs/results.md "Issue 13"): forced alignment of a
  transcript by PocketSphinx (finer boundaries: median phone onset error 3.8 ms against
  5.2 ms on eSpeak speech), recognition by hama (phone error rate 0.47 against 0.80 on
  GRID, 0.22 against 0.57 on eSpeak speech).
"""

from __future__ import annotations

from collections.abc import Callable

from db.errors import ParameterError

__all__ = ["DEFAULT_ENGINE", "ENGINES", "aligner", "check_engine", "recognizer"]

ENGINES: tuple[str, ...] = ("auto", "hama", "pocketsphinx")
#: The engine used when none is named.
DEFAULT_ENGINE = "auto"


def check_engine(engine: object) -> str:
    """``engine`` checked against :data:`ENGINES` (None: :data:`DEFAULT_ENGINE`)."""
    if engine is None:
        return DEFAULT_ENGINE
    if engine not in ENGINES:
        raise ParameterError(f"phone engine: expected one of {', '.join(ENGINES)}, "
                             f"got {engine!r}")
    return str(engine)


def aligner(engine: str | None = None) -> Callable:
    """``align(audio, sample_rate, text)`` of ``engine`` (raises DataError on no fit)."""
    if check_engine(engine) == "hama":
        from ingest.speech.ctc import align
    else:
        from ingest.speech.segment import align
    return align


def recognizer(engine: str | None = None) -> Callable:
    """``recognize(audio, sample_rate)`` of ``engine``."""
    if check_engine(engine) == "pocketsphinx":
        from ingest.speech.segment import recognize
    else:
        from ingest.speech.ctc import recognize
    return recognize
