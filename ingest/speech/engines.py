"""The phone engines and the choice between them (kept light: imports nothing heavy).

* ``"hama"`` -- the CTC phone recogniser whose model ships in the ``hama`` wheel
  (:mod:`ingest.speech.ctc`): recognition, CTC-Viterbi forced alignment, posteriors;
* ``"pocketsphinx"`` -- PocketSphinx with its US-English model (:mod:`ingest.speech.sphinx`);
* ``"auto"`` (the default) -- each task by the engine that measured better at it
  (``scripts/eval_segmentation.py``, docs/results/segmentation.md): forced alignment of a
  transcript by PocketSphinx (finer boundaries: median phone onset error 3.8 ms against
  5.2 ms on eSpeak speech); in recognition hama names the phones (phone error rate 0.40
  against 0.75 on GRID, 0.27 against 0.58 on eSpeak speech) and PocketSphinx places them,
  aligning hama's phone sequence as it aligns a transcript (its 10 ms frames against
  hama's 20 ms, and its silence model: hama gave a phone to 22 % of GRID's edge silence,
  PocketSphinx to 9 %). Recognise-then-align is the usual two-pass use of a recogniser
  whose timing is coarse; where PocketSphinx finds no path, hama's own timing stands.
  PocketSphinx's aligner finds a path through any transcript, so hama first checks that
  the transcript is what the audio says (:func:`ingest.speech.ctc.check_transcript`).
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from db.errors import ParameterError

logger = logging.getLogger(__name__)

__all__ = ["DEFAULT_ENGINE", "ENGINES", "aligner", "check_engine", "check_transcript",
           "recognizer"]

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
    engine = check_engine(engine)
    if engine == "hama":
        from ingest.speech.ctc import align
    elif engine == "pocketsphinx":
        from ingest.speech.sphinx import align
    else:
        align = align_auto
    return align


def recognizer(engine: str | None = None) -> Callable:
    """``recognize(audio, sample_rate)`` of ``engine``."""
    engine = check_engine(engine)
    if engine == "pocketsphinx":
        from ingest.speech.sphinx import recognize
    elif engine == "hama":
        from ingest.speech.ctc import recognize
    else:
        recognize = recognize_auto
    return recognize


def check_transcript(audio, sample_rate, text: str, engine: str | None = None) -> None:
    """Raise :class:`~db.errors.DataError` if ``engine``'s alignment would reject ``text``
    as not what the audio says (:func:`ingest.speech.ctc.check_transcript`: ``"auto"`` and
    ``"hama"``, when hama's native library loads; ``"pocketsphinx"`` checks nothing)."""
    from ingest.speech import ctc

    if check_engine(engine) == "pocketsphinx":
        return
    if ctc.available():
        ctc.check_transcript(audio, sample_rate, text)
    else:  # a platform hama's wheel does not cover
        logger.debug("hama is unavailable: the transcript is aligned unchecked")


def align_auto(audio, sample_rate, text: str, *, refine: bool = True) -> list:
    """PocketSphinx's forced alignment of ``text`` (the ``"auto"`` alignment), once hama
    has found that it is what the audio says.

    Parameters, result and errors as :func:`ingest.speech.sphinx.align`; also
    :class:`~db.errors.DataError` when the transcript does not match the audio
    (:func:`check_transcript`).
    """
    from ingest.speech.sphinx import align

    check_transcript(audio, sample_rate, text, "auto")
    return align(audio, sample_rate, text, refine=refine)


def recognize_auto(audio, sample_rate, *, refine: bool = True) -> list:
    """Phones named by hama and placed by PocketSphinx (the ``"auto"`` recognition).

    Parameters and result as :func:`ingest.speech.ctc.recognize`: hama's recognised phone
    sequence force-aligned by :func:`ingest.speech.sphinx.align_phones`; hama's own
    segments when PocketSphinx finds no path (or nothing was recognised).
    """
    from ingest.speech.ctc import recognize, recognized_phones
    from ingest.speech.sphinx import align_phones

    # hama's phones untimed: its own timing is worked out only if PocketSphinx fails
    named = recognized_phones(audio, sample_rate)
    placed = align_phones(audio, sample_rate, named, refine=refine)
    if placed is None:
        if named:
            logger.debug("PocketSphinx found no path through hama's %d phones: hama's "
                         "timing kept", len(named))
        return recognize(audio, sample_rate, refine=refine)
    return placed
