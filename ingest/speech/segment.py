"""Phoneme segmentation of speech with PocketSphinx (Cao et al. 2005, §4.1).

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
* :func:`segment` — the front door: given labels (checked and snapped to the audio), else
  alignment of a transcript, else recognition.

Every function returns :class:`~ingest.formats.phones_csv.Segment` lists that tile
``[0, len(audio) / sample_rate]`` exactly, in seconds of the input audio, with ARPAbet
phones of :data:`ingest.speech.phones.PHONE_SET` (pauses, edges and PocketSphinx's noise fillers
are ``SIL``; adjacent ``SIL`` are merged; no segment is empty).

:func:`boundary_errors` and :func:`phone_error_rate` score a segmentation against a
reference (``scripts/eval_segmentation.py`` uses them on eSpeak-synthesised speech).

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

Boundary refinement
-------------------
Decoded boundaries are quantised to 10 ms. Each is then moved to the largest spectral
change (distance of 13 mel cepstra 5 ms apart, every 2.5 ms) within
:data:`REFINE_WINDOW` (10 ms) of it, never leaving a segment shorter than
:data:`MIN_REFINED` (``refine=False`` turns this off). On eSpeak speech this halves the
median onset error (8.8 ms to 3.8 ms); the 90th percentile, dominated by boundaries
whose placement is a matter of convention (stop closures after a pause, vowel-glide
transitions), goes from 32 to 34 ms. ``scripts/eval_segmentation.py`` measures both
(``--no-refine``). The gain on natural speech, whose transitions are less abrupt than
a synthesiser's, will be smaller; a boundary never moves by more than the window.

Failures
--------
An empty transcript raises :class:`~db.errors.ParameterError`. Audio shorter than
:data:`MIN_DURATION`, or silent audio given to :func:`recognize`, gives one ``SIL``
segment. When the aligner finds no path through the transcript, :func:`align` raises
:class:`~db.errors.DataError`; :func:`segment` then logs a warning and falls back to
recognition (its method says ``"recognized"``).
"""

from __future__ import annotations

import functools
import logging
import math
import os
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from db.errors import DataError, ParameterError
from ingest.formats.phones_csv import Segment
from ingest.speech.engines import aligner, check_engine, recognizer
from ingest.speech.g2p import g2p, transcript_words
from ingest.speech.phones import PHONE_SET, SILENCE

logger = logging.getLogger(__name__)

__all__ = [
    "BOUNDARY_OFFSET",
    "DITHER_LSB",
    "MIN_DURATION",
    "SAMPLE_RATE",
    "align",
    "align_phones",
    "boundary_errors",
    "edit_alignment",
    "matched_onsets",
    "phone_error_rate",
    "recognize",
    "segment",
    "snap_labels",
]

#: Sampling rate of PocketSphinx's en-US acoustic model (Hz).
SAMPLE_RATE = 16000
#: Analysis frames per second (PocketSphinx's default; the model is trained at it).
FRAME_RATE = 100
#: Clips shorter than this (seconds) hold no phone to find: they give one SIL segment.
MIN_DURATION = 0.1
#: Peak below which audio counts as silent (about -80 dBFS).
SILENCE_PEAK = 1e-4
#: Peak level audio is normalised to before 16-bit quantisation (-6 dBFS).
TARGET_PEAK = 0.5
#: Standard deviation of the Gaussian dither added to the 16-bit samples (in LSB).
DITHER_LSB = 1.0
#: Seed of the dither: the same audio always gives the same segmentation.
DITHER_SEED = 0
#: Seconds added to ``frame / FRAME_RATE`` to place a decoded boundary (see the module
#: docstring).
BOUNDARY_OFFSET = 0.008
#: Decoded boundaries move to the largest spectral change this near (seconds); 0 = off.
REFINE_WINDOW = 0.01
#: Shortest segment (seconds) boundary refinement may leave.
MIN_REFINED = 0.015
#: Default tolerance (seconds) of :func:`snap_labels` for gaps and overlaps.
SNAP_TOLERANCE = 0.05
#: Interior boundaries are rounded to microseconds, as ``.phones.csv`` files store them.
_TIME_DECIMALS = 6


# ---------------------------------------------------------------------------------------------
# Audio
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class _Audio:
    duration: float  # seconds of the caller's audio
    samples: np.ndarray  # 16 kHz int16, dithered: what PocketSphinx hears
    peak: float  # peak of the caller's audio

    @property
    def pcm(self) -> bytes:
        return self.samples.astype("<i2", copy=False).tobytes()


def _check_audio(audio: object, sample_rate: object) -> tuple[np.ndarray, int]:
    if isinstance(sample_rate, bool) or not isinstance(sample_rate, int | np.integer):
        raise ParameterError(f"sample_rate: expected an int in Hz, got {sample_rate!r}")
    if not 1000 <= int(sample_rate) <= 384000:
        raise ParameterError(f"sample_rate: expected 1000..384000 Hz, got {sample_rate}")
    if not isinstance(audio, np.ndarray):
        raise ParameterError(f"audio: expected a numpy array, got {type(audio).__name__}")
    if audio.ndim == 2 and 1 in audio.shape:
        audio = audio.reshape(-1)
    if audio.ndim != 1:
        raise ParameterError(f"audio: expected mono samples (1-D), got shape {audio.shape}")
    if np.issubdtype(audio.dtype, np.integer):
        scale = float(np.iinfo(audio.dtype).max) + 1.0
        audio = audio.astype(np.float64) / scale
    elif np.issubdtype(audio.dtype, np.floating):
        audio = audio.astype(np.float64, copy=False)
    else:
        raise ParameterError(f"audio: expected float or integer samples, got {audio.dtype}")
    if audio.size and not np.all(np.isfinite(audio)):
        raise ParameterError("audio: contains NaN or infinite samples")
    return audio, int(sample_rate)


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


# ---------------------------------------------------------------------------------------------
# Decoders
# ---------------------------------------------------------------------------------------------


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


# ---------------------------------------------------------------------------------------------
# Frames -> segments
# ---------------------------------------------------------------------------------------------


def _as_phone(name: str) -> str:
    """A PocketSphinx phone or word label -> a PHONE_SET phone (fillers are SIL)."""
    name = name.upper()
    return name if name in PHONE_SET else SILENCE


def _tile(onsets: Sequence[tuple[str, float]], duration: float) -> list[Segment]:
    """(phone, onset seconds) in order -> segments tiling ``[0, duration]``.

    The first onset is moved to 0, each segment ends where the next starts, the last at
    ``duration``. Onsets are clipped to the clip and made non-decreasing; segments shorter
    than a microsecond are dropped (their neighbours close the gap), adjacent SIL merged.
    Interior boundaries are rounded to microseconds.
    """
    if duration <= 0:
        return []
    eps = 10.0**-_TIME_DECIMALS
    starts: list[float] = []
    for k, (_, onset) in enumerate(onsets):
        start = 0.0 if k == 0 else min(max(round(onset, _TIME_DECIMALS), starts[-1]), duration)
        starts.append(start)
    pieces: list[list] = []
    for k, (phone, _) in enumerate(onsets):
        end = starts[k + 1] if k + 1 < len(onsets) else duration
        if end - starts[k] < eps:
            continue
        if pieces and pieces[-1][0] == SILENCE and phone == SILENCE:
            pieces[-1][2] = end
            continue
        pieces.append([phone, starts[k], end])
    if not pieces:
        return [Segment(SILENCE, 0.0, duration)]
    pieces[0][1] = 0.0
    pieces[-1][2] = duration
    for prev, cur in zip(pieces, pieces[1:], strict=False):
        prev[2] = cur[1]
    return [Segment(phone, start, end) for phone, start, end in pieces]


def _frame_time(frame: int) -> float:
    return frame / FRAME_RATE + BOUNDARY_OFFSET


def _silence(duration: float) -> list[Segment]:
    return [Segment(SILENCE, 0.0, duration)] if duration > 0 else []


# ---------------------------------------------------------------------------------------------
# Boundary refinement
# ---------------------------------------------------------------------------------------------

_CHANGE_HOP = 40  # samples at 16 kHz: 2.5 ms
_CHANGE_WINDOW = 240  # 15 ms
_CHANGE_FFT = 512
_CHANGE_LAG = 2  # hops either side compared: 5 ms
_CHANGE_BLOCK = 4096  # hops computed at once
_N_MELS = 26
_N_CEPS = 13


@functools.lru_cache(maxsize=1)
def _mel_filterbank() -> np.ndarray:
    """Triangular mel filters, shape (_N_MELS, _CHANGE_FFT // 2 + 1), 100 Hz .. 7 kHz
    (built once a process: shared, read-only)."""

    def mel(f: np.ndarray | float) -> np.ndarray:
        return 2595.0 * np.log10(1.0 + np.asarray(f) / 700.0)

    edges_mel = np.linspace(mel(100.0), mel(7000.0), _N_MELS + 2)
    edges = 700.0 * (10.0 ** (edges_mel / 2595.0) - 1.0)
    freqs = np.fft.rfftfreq(_CHANGE_FFT, 1.0 / SAMPLE_RATE)
    bank = np.zeros((_N_MELS, freqs.size))
    for m in range(_N_MELS):
        lo, mid, hi = edges[m], edges[m + 1], edges[m + 2]
        rising = (freqs - lo) / (mid - lo)
        falling = (hi - freqs) / (hi - mid)
        bank[m] = np.clip(np.minimum(rising, falling), 0.0, None)
    return bank


def _spectral_change(samples: np.ndarray) -> np.ndarray:
    """Spectral change every 2.5 ms: distance of the cepstra 5 ms before and after.

    Parameters
    ----------
    samples : numpy.ndarray
        16 kHz audio (the dithered PCM PocketSphinx decodes).

    Returns
    -------
    numpy.ndarray, shape (n_hops,)
        Value ``t`` measures the change around sample ``t * 40``.
    """
    from scipy.fft import dct

    x = samples.astype(np.float64) / 32768.0
    half = _CHANGE_WINDOW // 2
    x = np.pad(x, (half, half))
    n_hops = max(0, (len(x) - _CHANGE_WINDOW) // _CHANGE_HOP + 1)
    if n_hops <= 2 * _CHANGE_LAG:
        return np.zeros(n_hops)
    frames = np.lib.stride_tricks.sliding_window_view(x, _CHANGE_WINDOW)[::_CHANGE_HOP][:n_hops]
    window = np.hanning(_CHANGE_WINDOW)
    bank = _mel_filterbank().T
    ceps = np.empty((n_hops, _N_CEPS))
    for a in range(0, n_hops, _CHANGE_BLOCK):  # in blocks: minutes of audio, bounded memory
        power = np.abs(np.fft.rfft(frames[a : a + _CHANGE_BLOCK] * window, _CHANGE_FFT)) ** 2
        logmel = np.log(power @ bank + 1e-12)
        ceps[a : a + _CHANGE_BLOCK] = dct(logmel, type=2, norm="ortho", axis=1)[:, :_N_CEPS]
    change = np.zeros(n_hops)
    lag = _CHANGE_LAG
    change[lag:-lag] = np.linalg.norm(ceps[2 * lag:] - ceps[: -2 * lag], axis=1)
    return change


def _refine(onsets: list[tuple[str, float]], samples: np.ndarray, window: float
            ) -> list[tuple[str, float]]:
    """Move each interior onset to the largest spectral change within ``window`` seconds.

    Segments keep at least :data:`MIN_REFINED` seconds; the first onset stays put.
    """
    if window <= 0 or len(onsets) < 2:
        return list(onsets)
    change = _spectral_change(samples)
    if change.size == 0:
        return list(onsets)
    hop = _CHANGE_HOP / SAMPLE_RATE
    reach = int(round(window / hop))
    refined = [onsets[0]]
    for k in range(1, len(onsets)):
        phone, onset = onsets[k]
        centre = int(round(onset / hop))
        following = onsets[k + 1][1] if k + 1 < len(onsets) else math.inf
        lo = max(centre - reach, math.ceil((refined[-1][1] + MIN_REFINED) / hop))
        hi = min(centre + reach, len(change) - 1)
        if math.isfinite(following):
            hi = min(hi, math.floor((following - MIN_REFINED) / hop))
        if hi >= lo:
            onset = (lo + int(np.argmax(change[lo : hi + 1]))) * hop
        refined.append((phone, onset))
    return refined


# ---------------------------------------------------------------------------------------------
# Alignment
# ---------------------------------------------------------------------------------------------


def _check_text(text: object) -> str:
    if not isinstance(text, str):
        raise ParameterError(f"text: expected a transcript string, got {type(text).__name__}")
    if not text.strip():
        raise ParameterError(f"text: the transcript is empty ({text!r})")
    return text


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
    text = _check_text(text)
    samples, sample_rate = _check_audio(audio, sample_rate)
    duration = len(samples) / sample_rate
    if duration < MIN_DURATION:
        logger.warning(
            "audio of %.3f s is too short to align %r: one SIL segment", duration, text[:40]
        )
        return _silence(duration)
    prepared = _prepare(samples, sample_rate)
    engine = _engine("align")
    start = time.perf_counter()
    with engine.lock:
        words = _dictionary_words(engine, text)
        entries = _align_phones(engine.decoder, " ".join(words), prepared.pcm)
    if entries is None:
        raise DataError(
            f"PocketSphinx found no alignment of the transcript {text[:60]!r} "
            f"to {duration:.2f} s of audio"
        )
    onsets = [(_as_phone(name), _frame_time(frame)) for name, frame in entries]
    if refine:
        onsets = _refine(onsets, prepared.samples, REFINE_WINDOW)
    segments = _tile(onsets, duration)
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
    samples, sample_rate = _check_audio(audio, sample_rate)
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
        entries = _align_phones(engine.decoder, " ".join(_phone_word(p) for p in spoken),
                                prepared.pcm, one_phone_words=True)
    if entries is None:
        return None
    onsets = [(_as_phone(name), _frame_time(frame)) for name, frame in entries]
    if refine:
        onsets = _refine(onsets, prepared.samples, REFINE_WINDOW)
    return _tile(onsets, duration)


# ---------------------------------------------------------------------------------------------
# Recognition
# ---------------------------------------------------------------------------------------------


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
    samples, sample_rate = _check_audio(audio, sample_rate)
    duration = len(samples) / sample_rate
    if duration < MIN_DURATION:
        return _silence(duration)
    prepared = _prepare(samples, sample_rate)
    if prepared.peak < SILENCE_PEAK:
        return _silence(duration)
    engine = _engine("allphone")
    with engine.lock:
        try:
            _decode(engine.decoder, prepared.pcm)
            entries = [(seg.word, seg.start_frame) for seg in engine.decoder.seg()]
        except RuntimeError as exc:
            raise DataError(f"PocketSphinx phone recognition failed: {exc}") from exc
    onsets = [(_as_phone(name), _frame_time(frame)) for name, frame in entries]
    if refine:
        onsets = _refine(onsets, prepared.samples, REFINE_WINDOW)
    return _tile(onsets, duration)


# ---------------------------------------------------------------------------------------------
# Given labels
# ---------------------------------------------------------------------------------------------


def _label(item: object, index: int) -> Segment:
    if all(hasattr(item, name) for name in ("phone", "start", "end")):
        phone, start, end = item.phone, item.start, item.end  # type: ignore[attr-defined]
    elif isinstance(item, tuple | list) and len(item) == 3:
        phone, start, end = item
    else:
        raise ParameterError(f"labels[{index}]: expected (phone, start, end), got {item!r}")
    if not isinstance(phone, str) or phone not in PHONE_SET:
        raise ParameterError(f"labels[{index}].phone: unknown phone {phone!r}")
    try:
        start, end = float(start), float(end)
    except (TypeError, ValueError) as exc:
        raise ParameterError(f"labels[{index}]: bad times {start!r}, {end!r}") from exc
    if not (math.isfinite(start) and math.isfinite(end)) or start < 0 or end <= start:
        raise ParameterError(f"labels[{index}]: expected 0 <= start < end, got {start}, {end}")
    return Segment(phone, start, end)


def snap_labels(
    labels: Sequence[Segment], duration: float, *, tolerance: float = SNAP_TOLERANCE
) -> list[Segment]:
    """Check phone labels and snap them to tile ``[0, duration]`` exactly.

    Gaps and overlaps between neighbours up to ``tolerance`` are closed at their middle;
    larger gaps (and a start or end further than ``tolerance`` from the clip's edges)
    are filled with ``SIL``. Labels running past the end by up to ``tolerance`` are cut.

    Parameters
    ----------
    labels : sequence of Segment
        ``(phone, start, end)`` items (or objects with those attributes), phones from
        :data:`ingest.speech.phones.PHONE_SET`, in time order.
    duration : float
        Length of the audio in seconds.
    tolerance : float, optional
        Largest gap, overlap or overrun (seconds) snapped without complaint.

    Returns
    -------
    list of Segment
        Segments tiling ``[0, duration]``, adjacent SIL merged, none empty.

    Raises
    ------
    ParameterError
        No labels; a bad item; labels out of order, overlapping by more than
        ``tolerance`` or reaching past ``duration + tolerance``.
    """
    if isinstance(labels, str | bytes) or not isinstance(labels, Sequence):
        raise ParameterError(f"labels: expected a sequence of segments, got {labels!r}")
    if not labels:
        raise ParameterError("labels: expected at least one segment, got none")
    items = [_label(item, k) for k, item in enumerate(labels)]
    for k in range(1, len(items)):
        if items[k].start < items[k - 1].start:
            raise ParameterError(
                f"labels[{k}]: starts at {items[k].start} before labels[{k - 1}] "
                f"({items[k - 1].start})"
            )
        if items[k - 1].end - items[k].start > tolerance:
            raise ParameterError(
                f"labels[{k}]: overlaps labels[{k - 1}] by "
                f"{items[k - 1].end - items[k].start:.3f} s (tolerance {tolerance} s)"
            )
    if items[-1].end > duration + tolerance:
        raise ParameterError(
            f"labels: end at {items[-1].end} s, past the audio's {duration:.3f} s "
            f"(tolerance {tolerance} s)"
        )
    onsets: list[tuple[str, float]] = []
    if items[0].start > tolerance:
        onsets.append((SILENCE, 0.0))
    for k, item in enumerate(items):
        if k == 0:
            start = item.start if items[0].start > tolerance else 0.0
        else:
            gap = item.start - items[k - 1].end
            if gap > tolerance:
                onsets.append((SILENCE, items[k - 1].end))
                start = item.start
            else:
                start = (item.start + items[k - 1].end) / 2
        onsets.append((item.phone, start))
    if duration - items[-1].end > tolerance:
        onsets.append((SILENCE, items[-1].end))
    return _tile(onsets, duration)


# ---------------------------------------------------------------------------------------------
# The front door
# ---------------------------------------------------------------------------------------------


def segment(
    audio: np.ndarray,
    sample_rate: int,
    *,
    text: str | None = None,
    labels: Sequence[Segment] | None = None,
    engine: str | None = None,
    on_fallback: Callable[[str], object] | None = None,
) -> tuple[list[Segment], str]:
    """Phone segments of speech by the best means at hand.

    In order of preference: ``labels`` (checked and snapped to the audio by
    :func:`snap_labels`), forced alignment of ``text``, phone recognition, by the phone
    engine ``engine`` (:mod:`ingest.speech.engines`: PocketSphinx's :func:`align` and
    :func:`recognize`, the CTC model of :mod:`ingest.speech.ctc`, or each task by the
    engine that measured better at it). If the alignment
    fails (:class:`~db.errors.DataError`) recognition is used instead, and a line saying
    so ("transcript alignment failed: ...; fell back to phone recognition") is logged as
    a warning, or given to ``on_fallback``.

    Parameters
    ----------
    audio : numpy.ndarray, shape (n_samples,)
        Mono audio.
    sample_rate : int
        Its sampling rate in Hz.
    text : str, optional
        The transcript.
    labels : sequence of Segment, optional
        Known phone labels (seconds).
    engine : str, optional
        One of :data:`ingest.speech.engines.ENGINES`; default ``"auto"``.
    on_fallback : callable, optional
        Receives the line on a failed alignment instead of the log.

    Returns
    -------
    segments : list of Segment
        Tiling ``[0, len(audio) / sample_rate]``.
    method : str
        ``"labels"``, ``"aligned"`` or ``"recognized"``: how they were obtained.

    Raises
    ------
    ParameterError
        Bad audio, sample rate or labels; an empty transcript.
    DataError
        If PocketSphinx is unusable.
    """
    samples, sample_rate = _check_audio(audio, sample_rate)
    engine = check_engine(engine)
    if labels is not None:
        return snap_labels(labels, len(samples) / sample_rate), "labels"
    do_align, do_recognize = aligner(engine), recognizer(engine)
    if text is not None:
        _check_text(text)
        try:
            return do_align(samples, sample_rate, text), "aligned"
        except DataError as exc:
            line = f"transcript alignment failed: {exc}; fell back to phone recognition"
            if on_fallback is None:
                logger.warning("%s", line)
            else:
                on_fallback(line)
    return do_recognize(samples, sample_rate), "recognized"


# ---------------------------------------------------------------------------------------------
# Scoring
# ---------------------------------------------------------------------------------------------


def edit_alignment(
    reference: Sequence[str], hypothesis: Sequence[str]
) -> list[tuple[int | None, int | None]]:
    """Minimum edit-distance alignment of two label sequences.

    Parameters
    ----------
    reference, hypothesis : sequence of str
        Labels.

    Returns
    -------
    list of (int or None, int or None)
        Pairs of indices in order: ``(i, j)`` a match or substitution, ``(i, None)`` a
        deletion, ``(None, j)`` an insertion. Ties prefer matches, then substitutions.
    """
    n, m = len(reference), len(hypothesis)
    cost = np.zeros((n + 1, m + 1), dtype=np.int64)
    cost[:, 0] = np.arange(n + 1)
    cost[0, :] = np.arange(m + 1)
    hyp = np.asarray(hypothesis, dtype=object)
    for i in range(1, n + 1):
        diff = (hyp != reference[i - 1]).astype(np.int64)
        row = np.minimum(cost[i - 1, 1:] + 1, cost[i - 1, :-1] + diff)
        # insertions run along the row: a cumulative minimum resolves them
        current = np.empty(m + 1, dtype=np.int64)
        current[0] = cost[i, 0]
        current[1:] = row
        current = np.minimum.accumulate(current - np.arange(m + 1)) + np.arange(m + 1)
        cost[i] = current
    pairs: list[tuple[int | None, int | None]] = []
    i, j = n, m
    while i > 0 or j > 0:
        if i > 0 and j > 0:
            same = reference[i - 1] == hypothesis[j - 1]
            if cost[i, j] == cost[i - 1, j - 1] + (0 if same else 1):
                pairs.append((i - 1, j - 1))
                i, j = i - 1, j - 1
                continue
        if i > 0 and cost[i, j] == cost[i - 1, j] + 1:
            pairs.append((i - 1, None))
            i -= 1
        else:
            pairs.append((None, j - 1))
            j -= 1
    pairs.reverse()
    return pairs


def _phones_of(segments: Sequence[Segment], name: str) -> list[Segment]:
    if isinstance(segments, str | bytes) or not isinstance(segments, Sequence):
        raise ParameterError(f"{name}: expected a sequence of segments, got {segments!r}")
    return [_label(item, k) for k, item in enumerate(segments)]


def boundary_errors(
    reference: Sequence[Segment], hypothesis: Sequence[Segment], *, signed: bool = False
) -> np.ndarray:
    """Absolute differences (seconds) between matched phone onsets of two segmentations.

    The two phone sequences (``SIL`` included) are aligned by minimum edit distance
    (:func:`edit_alignment`), so that differing pronunciations ("family" as F AE M AH L IY
    or F AE M L IY) or an extra pause on one side do not shift the comparison. Each pair
    of *matched* segments (same phone) whose reference onset is not the start of the
    clip contributes ``|reference.start - hypothesis.start|``: the boundary in front of
    that phone. Substituted, inserted and deleted phones contribute nothing, so the
    number of values tells how many boundaries were compared.

    Parameters
    ----------
    reference, hypothesis : sequence of Segment
        Segmentations of the same audio, in time order.
    signed : bool, optional
        Return ``hypothesis.start - reference.start`` instead of its absolute value (to
        see a bias).

    Returns
    -------
    numpy.ndarray, shape (n_matched,), float64
        Onset errors in seconds, in reference order.

    Raises
    ------
    ParameterError
        A bad segment.
    """
    errors = matched_onsets(reference, hypothesis)[1]
    return errors if signed else np.abs(errors)


def matched_onsets(reference: Sequence[Segment],
                   hypothesis: Sequence[Segment]) -> tuple[np.ndarray, np.ndarray]:
    """The reference phones :func:`boundary_errors` compares, and their signed errors.

    Returns
    -------
    index : numpy.ndarray, shape (n_matched,), int64
        Each matched phone's position in ``reference``: two hypotheses can then be
        compared on the phones both matched.
    errors : numpy.ndarray, shape (n_matched,), float64
        ``hypothesis.start - reference.start`` (s).
    """
    ref = _phones_of(reference, "reference")
    hyp = _phones_of(hypothesis, "hypothesis")
    pairs = [(i, j) for i, j in edit_alignment([s.phone for s in ref], [s.phone for s in hyp])
             if i is not None and j is not None and ref[i].phone == hyp[j].phone
             and ref[i].start > 0]
    return (np.asarray([i for i, _ in pairs], dtype=np.int64),
            np.asarray([hyp[j].start - ref[i].start for i, j in pairs], dtype=np.float64))


def phone_error_rate(reference: Sequence[Segment], hypothesis: Sequence[Segment]) -> float:
    """Phone error rate: edit distance of the phone sequences over the reference length.

    ``SIL`` is left out of both sequences (pauses are not phones), as usual for phone
    recognition scores.

    Parameters
    ----------
    reference, hypothesis : sequence of Segment
        Segmentations (or any items with ``.phone``, ``.start``, ``.end``).

    Returns
    -------
    float
        (substitutions + deletions + insertions) / reference phones; may exceed 1.

    Raises
    ------
    ParameterError
        A bad segment, or a reference without phones.
    """
    ref = [s.phone for s in _phones_of(reference, "reference") if s.phone != SILENCE]
    hyp = [s.phone for s in _phones_of(hypothesis, "hypothesis") if s.phone != SILENCE]
    if not ref:
        raise ParameterError("reference: has no phones other than SIL")
    pairs = edit_alignment(ref, hyp)
    errors = sum(1 for i, j in pairs if i is None or j is None or ref[i] != hyp[j])
    return errors / len(ref)
