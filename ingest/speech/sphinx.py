"""Phones in speech with PocketSphinx (Cao et al. 2005, §4.1): one of the phone engines of
:mod:`ingest.speech.engines`.

Cao et al. cut their recordings into phones with Festival; here PocketSphinx does it, with
the US-English acoustic model, CMUdict and phone language model its wheel ships:

* :func:`align` — forced alignment of a known transcript. Words are normalised
  (:func:`ingest.speech.g2p.transcript_words`); words CMUdict lacks get a pronunciation from
  :func:`ingest.speech.g2p.g2p` (eSpeak NG, else letter-to-sound rules) and are added to the
  decoder's dictionary. A first pass aligns words (with optional pauses between them), a
  second pass aligns phones inside them.
* :func:`recognize` — phone recognition without a transcript (PocketSphinx's *allphone*
  search with its phone trigram model). Much less accurate than alignment: use it only
  when no transcript exists.
* :func:`align_phones` — forced alignment of a known phone sequence (each phone a word of
  one phone): how the ``"auto"`` engine times the phones hama recognises.

Their segments tile the clip (:mod:`ingest.speech.tiling`) and their boundaries are
refined (:mod:`ingest.speech.refine`) unless ``refine=False``.

PocketSphinx quirks handled here
--------------------------------
* Audio is resampled to 16 kHz (:func:`scipy.signal.resample_poly`), peak-normalised and
  quantised to 16-bit PCM, with a tiny seeded Gaussian dither (:data:`DITHER_LSB`): the
  phone-alignment pass fails ("Final result does not match the grammar") on runs of exact
  digital silence such as eSpeak's padding.
* The word-alignment pass runs with ``bestpath`` off (a bestpath lattice can end in a
  one-frame ``</s>`` that the phone pass cannot fit).
* ``Decoder.add_word`` on a word already in the dictionary raises ``RuntimeError``
  ("Failed to add word"): words are looked up first, and the words this process added
  are tracked.
* The model's ``feat.params`` turn on noise removal, whose noise statistics carry over
  from one utterance to the next: the same clip came out differently after a failed
  alignment or a noisy clip. The feature extractor is reset (``reinit_feat``, 0.1 ms)
  before every decoding pass, so a segmentation depends on its clip only. (Options in
  ``feat.params`` override the same options given to ``Decoder(...)``.)
* A decoder is built once per process and mode (about 0.15 s each) and shared behind a
  lock; a forked child builds its own.
* The decoder keeps Python's lock for a whole utterance (its binding never lets go of
  it): a Ctrl-C on ``synth`` waited for the phones of a long recording to be placed
  (2.4-5.3 s on 158 s of speech). Where the main thread waits to act on a Ctrl-C
  (:func:`db.system.interrupt_awaited`), each decoding runs in a forked child instead
  (:func:`ingest.workers.in_forked_child`), which dies at the Ctrl-C. The child is a copy
  of this process, decoder and dictionary included, so the result is the same; feeding
  the decoder in blocks would free the lock too, but it switches PocketSphinx from the
  utterance's cepstral mean (``-cmn batch``) to a running one, which moves boundaries.
* The first (word) pass can lose the only path through the transcript with the default
  beams ("Final result does not match the grammar"), seen on slow, low-pitched speech:
  the aligner's beams are widened (:data:`ALIGNER_OPTIONS`), at no measurable cost.
* PocketSphinx writes its own errors to stderr; its log level is set to ``FATAL`` and
  failures are reported through exceptions and this module's logger instead.
* Frame ``i`` of the 100 frames/s analysis covers samples from ``i`` * 10 ms over a
  25.6 ms window, so a change between frames ``i - 1`` and ``i`` lies about 7.8 ms after
  ``i`` * 10 ms: a boundary decoded at frame ``i`` is placed at ``i * 10 ms +``
  :data:`BOUNDARY_OFFSET` (8 ms; measured bias on synthetic speech: -10 ms without it,
  under 2 ms with it). A 200 frames/s analysis would halve the quantisation, but the
  model is trained at 100 frames/s and its phone recognition error rises from 0.56 to
  0.76 at 200: it is not used.
"""

from __future__ import annotations

import logging
import math
import os
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from db.errors import DataError, ParameterError
from ingest.formats.phones_csv import Segment
from ingest.speech.g2p import g2p, transcript_words
from ingest.speech.inputs import MIN_DURATION, SILENCE_PEAK, check_audio, check_text
from ingest.speech.phones import PHONE_SET, SILENCE
from ingest.speech.refine import REFINE_WINDOW, refine_onsets
from ingest.speech.tiling import silence, tile

logger = logging.getLogger(__name__)

__all__ = [
    "ALIGNER_OPTIONS",
    "BOUNDARY_OFFSET",
    "DITHER_LSB",
    "RECOGNIZER_OPTIONS",
    "SAMPLE_RATE",
    "align",
    "align_phones",
    "recognize",
]

#: Sampling rate of PocketSphinx's en-US acoustic model (Hz).
SAMPLE_RATE = 16000
#: Analysis frames per second (PocketSphinx's default; the model is trained at it).
FRAME_RATE = 100
#: Peak level audio is normalised to before 16-bit quantisation (-6 dBFS).
TARGET_PEAK = 0.5
#: Standard deviation of the Gaussian dither added to the 16-bit samples (in LSB).
DITHER_LSB = 1.0
#: Seed of the dither: the same audio always gives the same segmentation.
DITHER_SEED = 0
#: Seconds added to ``frame / FRAME_RATE`` to place a decoded boundary (see the module
#: docstring).
BOUNDARY_OFFSET = 0.008


@dataclass(frozen=True, eq=False)
class _Audio:
    duration: float  # seconds of the caller's audio
    samples: np.ndarray  # 16 kHz int16, dithered: what PocketSphinx hears
    peak: float  # peak of the caller's audio

    @property
    def pcm(self) -> bytes:
        return self.samples.astype("<i2", copy=False).tobytes()


def _prepare(audio: np.ndarray, sample_rate: int) -> _Audio:
    """Checked float audio -> 16 kHz dithered 16-bit PCM for PocketSphinx."""
    from scipy.signal import resample_poly  # deferred: importing scipy.signal takes a second

    duration = len(audio) / sample_rate
    peak = float(np.max(np.abs(audio))) if audio.size else 0.0
    if sample_rate != SAMPLE_RATE:
        g = math.gcd(SAMPLE_RATE, sample_rate)
        audio = resample_poly(audio, SAMPLE_RATE // g, sample_rate // g)
    resampled_peak = float(np.max(np.abs(audio))) if audio.size else 0.0
    gain = TARGET_PEAK * 32767.0 / resampled_peak if resampled_peak > 0 else 0.0
    noise = np.random.default_rng(DITHER_SEED).normal(0.0, DITHER_LSB, len(audio))
    pcm = np.clip(np.round(audio * gain + noise), -32768, 32767).astype(np.int16)
    return _Audio(duration=duration, samples=pcm, peak=peak)


def _model_paths() -> dict[str, str]:
    try:
        from pocketsphinx import get_model_path
    except ImportError as exc:  # pragma: no cover - pocketsphinx is a dependency
        raise DataError(f"pocketsphinx is not installed: {exc}") from exc
    root = Path(get_model_path()) / "en-us"
    paths = {
        "hmm": root / "en-us",
        "dict": root / "cmudict-en-us.dict",
        "allphone": root / "en-us-phone.lm.bin",
    }
    for name, path in paths.items():
        if not path.exists():
            raise DataError(f"PocketSphinx {name} model not found: {path}")
    return {name: str(path) for name, path in paths.items()}


@dataclass
class _Engine:
    """One PocketSphinx decoder and the lock that serialises its use."""

    decoder: object
    lock: threading.Lock = field(default_factory=threading.Lock)
    added: set[str] = field(default_factory=set)  # words this process added to the dict


_ENGINES: dict[str, _Engine] = {}
_ENGINES_LOCK = threading.Lock()


def _reset_after_fork() -> None:  # pragma: no cover - exercised only in forked children
    global _ENGINES_LOCK
    _ENGINES.clear()
    _ENGINES_LOCK = threading.Lock()


os.register_at_fork(after_in_child=_reset_after_fork)


def _engine(mode: str) -> _Engine:
    """The process's decoder for ``mode`` ("align" or "allphone"), built on first use."""
    with _ENGINES_LOCK:
        engine = _ENGINES.get(mode)
        if engine is not None:
            return engine
        from pocketsphinx import Decoder

        paths = _model_paths()
        options: dict[str, object] = {
            "hmm": paths["hmm"], "dict": paths["dict"], "samprate": SAMPLE_RATE,
            "frate": FRAME_RATE, "loglevel": "FATAL", "bestpath": False,
        }
        if mode == "align":
            options.update(lm=None, **ALIGNER_OPTIONS)
        else:
            options.update(allphone=paths["allphone"], **RECOGNIZER_OPTIONS)
        start = time.perf_counter()
        try:
            decoder = Decoder(**options)
        except (RuntimeError, ValueError) as exc:
            raise DataError(f"cannot set up the PocketSphinx {mode} decoder: {exc}") from exc
        logger.debug("PocketSphinx %s decoder built in %.2f s", mode,
                     time.perf_counter() - start)
        engine = _ENGINES[mode] = _Engine(decoder)
        return engine


#: Settings of the aligner (beams, see the module docstring).
ALIGNER_OPTIONS: dict[str, object] = {
    "beam": 1e-80, "pbeam": 1e-80, "wbeam": 1e-60, "lpbeam": 1e-80, "lponlybeam": 1e-60,
}
#: Settings of the allphone recogniser (phone language-model weight and beams, as CMU's
#: phoneme-recognition example has them; lw 2 to 4 gave the lowest error rate).
RECOGNIZER_OPTIONS: dict[str, object] = {"lw": 2.0, "beam": 1e-20, "pbeam": 1e-20}


def _decode(decoder, pcm: bytes) -> None:
    """Decode one whole utterance, with the feature extractor reset first.

    The model's noise removal (``remove_noise`` in its ``feat.params``) keeps noise
    statistics from one utterance to the next, which made a clip's segmentation depend
    on the clips decoded before it; :meth:`reinit_feat` (some 0.1 ms) starts afresh.
    """
    decoder.reinit_feat()
    decoder.start_utt()
    decoder.process_raw(pcm, no_search=False, full_utt=True)
    decoder.end_utt()


def _decoded(work):
    """``work()``, a decoding: here, or in a forked child where the main thread waits to
    act on a Ctrl-C (see the module docstring). Its value JSON round-trips (tuples come
    back as lists); a decoder's ``RuntimeError`` stays a ``RuntimeError``."""
    from db.system import interrupt_awaited

    if not interrupt_awaited():
        return work()
    from ingest.workers import in_forked_child

    return in_forked_child(work)


def _as_phone(name: str) -> str:
    """A PocketSphinx phone or word label -> a PHONE_SET phone (fillers are SIL)."""
    name = name.upper()
    return name if name in PHONE_SET else SILENCE


def _frame_time(frame: int) -> float:
    return frame / FRAME_RATE + BOUNDARY_OFFSET


def _segments(entries: list[tuple[str, int]], prepared: _Audio, refine: bool
              ) -> list[Segment]:
    """Decoded ``(label, start frame)`` entries -> segments tiling the clip, boundaries
    refined unless ``refine`` is False."""
    onsets = [(_as_phone(name), _frame_time(frame)) for name, frame in entries]
    if refine:
        onsets = refine_onsets(onsets, prepared.samples, REFINE_WINDOW)
    return tile(onsets, prepared.duration)


def _dictionary_words(engine: _Engine, text: str) -> list[str]:
    """Normalise ``text`` and make sure the decoder can pronounce every word.

    Call with ``engine.lock`` held.
    """
    decoder = engine.decoder

    def known(word: str) -> bool:
        return word in engine.added or decoder.lookup_word(word) is not None

    words: list[str] = []
    new: list[tuple[str, str]] = []
    for word in transcript_words(text, known):
        if known(word) or any(w == word for w, _ in new):
            words.append(word)
            continue
        phones = g2p(word)
        if not phones:
            logger.warning("transcript word %r has no pronunciation: skipped", word)
            continue
        logger.debug("out-of-vocabulary word %r pronounced %s", word, " ".join(phones))
        new.append((word, " ".join(phones)))
        words.append(word)
    _add_words(engine, new)
    if not words:
        raise ParameterError(f"text: the transcript has no words to align ({text[:60]!r})")
    return words


def _add_words(engine: _Engine, new: Sequence[tuple[str, str]]) -> None:
    """Add ``(word, "PH ON ES")`` pairs to the decoder's dictionary (the search updated
    once, after the last). Call with ``engine.lock`` held."""
    for k, (word, phones) in enumerate(new):
        try:
            engine.decoder.add_word(word, phones, k == len(new) - 1)
        except RuntimeError as exc:
            raise DataError(f"cannot add word {word!r} /{phones}/ to the dictionary: {exc}") \
                from exc
        engine.added.add(word)


def align(
    audio: np.ndarray, sample_rate: int, text: str, *, refine: bool = True
) -> list[Segment]:
    """Force-align a transcript to speech: ARPAbet phone segments with their timing.

    Parameters
    ----------
    audio : numpy.ndarray, shape (n_samples,)
        Mono audio, float (in [-1, 1]) or integer PCM, any level.
    sample_rate : int
        Its sampling rate in Hz (resampled to 16 kHz internally).
    text : str
        What is said. Case and punctuation do not matter; numbers are spelled out;
        words CMUdict lacks are pronounced by :func:`ingest.speech.g2p.g2p`.
    refine : bool, optional
        Move boundaries to the nearest spectral change (see the module docstring).

    Returns
    -------
    list of Segment
        Phones of the transcript (CMUdict's pronunciation, or one of its variants) and
        ``SIL`` for the pauses PocketSphinx finds between words and at the edges, tiling
        ``[0, len(audio) / sample_rate]``. Audio shorter than :data:`MIN_DURATION` gives
        one ``SIL`` segment (with a warning).

    Raises
    ------
    ParameterError
        Bad audio or sample rate; an empty transcript or one without words.
    DataError
        PocketSphinx finds no alignment of the transcript to the audio (e.g. the audio
        is silent or much too short for the text), or its models are missing.
    """
    text = check_text(text)
    samples, sample_rate = check_audio(audio, sample_rate)
    duration = len(samples) / sample_rate
    if duration < MIN_DURATION:
        logger.warning(
            "audio of %.3f s is too short to align %r: one SIL segment", duration, text[:40]
        )
        return silence(duration)
    prepared = _prepare(samples, sample_rate)
    engine = _engine("align")
    start = time.perf_counter()
    with engine.lock:
        words = _dictionary_words(engine, text)
        logger.debug("PocketSphinx aligns %d words to %.2f s of audio", len(words),
                     duration)
        entries = _decoded(lambda: _align_phones(engine.decoder, " ".join(words),
                                                 prepared.pcm))
    if entries is None:
        raise DataError(
            f"PocketSphinx found no alignment of the transcript {text[:60]!r} "
            f"to {duration:.2f} s of audio"
        )
    segments = _segments(entries, prepared, refine)
    logger.debug("aligned %d words in %.2f s of audio: %d segments, %.3f s", len(words),
                 duration, len(segments), time.perf_counter() - start)
    return segments


def _align_phones(decoder, words: str, pcm: bytes, *,
                  one_phone_words: bool = False) -> list[tuple[str, int]] | None:
    """Two-pass alignment; ``[(phone, start frame)]`` or None if there is no path.

    With ``one_phone_words`` (each word is :func:`_phone_word`) the first, word-level
    pass already places every phone: PocketSphinx (>= 5) pins the phone pass to the
    word pass's boundaries, so the second pass only repeats them (the same frames on 63
    clips of eSpeak, EmoDB, FACEGOOD and talkingface speech) and is skipped.
    """
    try:
        decoder.set_align_text(words)
        _decode(decoder, pcm)
        if decoder.hyp() is None:
            return None
        if one_phone_words:
            return [(seg.word.strip("_"), seg.start_frame) for seg in decoder.seg()] or None
        decoder.set_alignment()
        _decode(decoder, pcm)
        alignment = decoder.get_alignment()
    except RuntimeError as exc:
        logger.debug("alignment of %r failed: %s", words[:60], exc)
        return None
    if alignment is None:
        return None
    entries = [(phone.name, phone.start) for phone in alignment.phones()]
    return entries or None


def _recognized(decoder, pcm: bytes) -> list[tuple[str, int]]:
    """Allphone decoding of ``pcm``: ``[(phone, start frame)]``."""
    _decode(decoder, pcm)
    return [(seg.word, seg.start_frame) for seg in decoder.seg()]


def _phone_word(phone: str) -> str:
    """The dictionary word of a one-phone pseudo-word (no transcript word has ``_``)."""
    return f"_{phone.lower()}_"


def align_phones(
    audio: np.ndarray, sample_rate: int, phones: Sequence[str], *, refine: bool = True
) -> list[Segment] | None:
    """Place a known phone sequence in speech: PocketSphinx forced alignment of phones.

    Each phone is aligned as a word of one phone, so that PocketSphinx's silence model may
    put a pause between any two of them, and before and after them. This is how
    recognition by another engine is timed (:func:`ingest.speech.engines.recognizer`,
    ``"auto"``): that engine names the phones, PocketSphinx's 10 ms frames and its
    silence model place them.

    Parameters
    ----------
    audio : numpy.ndarray, shape (n_samples,)
        Mono audio, float (in [-1, 1]) or integer PCM, any level.
    sample_rate : int
        Its sampling rate in Hz.
    phones : sequence of str
        ARPAbet phones of :data:`~ingest.speech.phones.PHONE_SET` in the order spoken;
        ``SIL`` entries are dropped (PocketSphinx finds the pauses).
    refine : bool, optional
        Move boundaries to the nearest spectral change (see the module docstring).

    Returns
    -------
    list of Segment or None
        The phones and ``SIL`` tiling ``[0, len(audio) / sample_rate]``; None when there
        is no phone to place, the audio is too short, or PocketSphinx finds no path.

    Raises
    ------
    ParameterError
        Bad audio or sample rate, or a phone outside the phone set.
    DataError
        If PocketSphinx or its models are unusable.
    """
    samples, sample_rate = check_audio(audio, sample_rate)
    spoken = [p for p in phones if p != SILENCE]
    unknown = sorted({p for p in spoken if p not in PHONE_SET})
    if unknown:
        raise ParameterError(f"phones: not ARPAbet phones of the phone set: {unknown[:4]}")
    duration = len(samples) / sample_rate
    if not spoken or duration < MIN_DURATION:
        return None
    prepared = _prepare(samples, sample_rate)
    engine = _engine("align")
    with engine.lock:
        _add_words(engine, [(_phone_word(p), p) for p in sorted(set(spoken))
                            if _phone_word(p) not in engine.added])
        words = " ".join(_phone_word(p) for p in spoken)
        logger.debug("PocketSphinx places %d phones in %.2f s of audio", len(spoken),
                     duration)
        entries = _decoded(lambda: _align_phones(engine.decoder, words, prepared.pcm,
                                                 one_phone_words=True))
    if entries is None:
        return None
    return _segments(entries, prepared, refine)


def recognize(audio: np.ndarray, sample_rate: int, *, refine: bool = True) -> list[Segment]:
    """Recognise phones in speech without a transcript (PocketSphinx allphone search).

    Parameters
    ----------
    audio : numpy.ndarray, shape (n_samples,)
        Mono audio, float (in [-1, 1]) or integer PCM, any level.
    sample_rate : int
        Its sampling rate in Hz.
    refine : bool, optional
        Move boundaries to the nearest spectral change (see the module docstring).

    Returns
    -------
    list of Segment
        Recognised phones and ``SIL`` tiling ``[0, len(audio) / sample_rate]``. Audio
        shorter than :data:`MIN_DURATION`, silent audio (peak below
        :data:`SILENCE_PEAK`) or audio where nothing is recognised give one ``SIL``
        segment.

    Raises
    ------
    ParameterError
        Bad audio or sample rate.
    DataError
        If PocketSphinx or its models are unusable.
    """
    samples, sample_rate = check_audio(audio, sample_rate)
    duration = len(samples) / sample_rate
    if duration < MIN_DURATION:
        return silence(duration)
    prepared = _prepare(samples, sample_rate)
    if prepared.peak < SILENCE_PEAK:
        return silence(duration)
    engine = _engine("allphone")
    with engine.lock:
        try:
            entries = _decoded(lambda: _recognized(engine.decoder, prepared.pcm))
        except RuntimeError as exc:
            raise DataError(f"PocketSphinx phone recognition failed: {exc}") from exc
    return _segments(entries, prepared, refine)
