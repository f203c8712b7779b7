"""Phones from speech with a CTC phone recogniser whose model ships in its wheel (``hama``).

The second phonetic engine beside PocketSphinx (:mod:`ingest.speech.sphinx`). ``hama``
(Apache-2.0, on PyPI) ships a 4.7 MB waveform-to-IPA CTC acoustic model and the small
native library that runs it (numpy and ctypes, no onnxruntime, no download at run time).
Its output is one distribution over 191 symbols (IPA phones, diacritics, a word-boundary
symbol and the CTC *blank*) every 20 ms (:data:`FRAME_RATE`). From it:

* :func:`posteriors` -- per-frame phone posteriors over the project's phone set
  (:data:`ingest.speech.phones.PHONES`): the probability of each IPA symbol is added to the
  ARPAbet phone it maps to (:data:`IPA_TO_ARPABET`); the blank, the word boundary and the
  symbols that carry no phone of their own (length, aspiration and tone marks, the glottal
  stop) go to ``SIL``, which therefore reads "no phone starts here", as CTC's blank does.
* :func:`recognize` -- phone recognition: best class per frame, repeats collapsed,
  blanks removed (CTC greedy decoding, Graves et al., ICML 2006, §3.2), then timed as
  :func:`align` times a transcript's phones.
* :func:`align` -- forced alignment of a transcript by CTC Viterbi: the transcript's words
  are pronounced by the project's CMUdict/eSpeak NG (:func:`ingest.speech.g2p.pronounce`;
  the model's own English letter-to-sound is weak), and the best path through
  ``blank, p1, blank, p2, ..., blank`` (a phone may repeat, a blank may be skipped
  between different phones; Graves et al. 2006 §4.1) is found by dynamic programming over
  the log posteriors. Phone ``k`` starts at the first frame of its state.

Timing
------
CTC posteriors are *peaky*; how a phone's segment is placed, and where the pauses are:
:mod:`ingest.speech.ctc_timing`.

Pieces
------
The model hears at most 30 s per call and its engine runs a call on one core, so audio
is heard in pieces (:func:`_pieces`): one per started :data:`CHUNK_SECONDS`, and two from
:data:`SPLIT_SECONDS` on, so that a sentence of a few seconds is heard on two cores at
once; each cut at the quietest 100 ms near its even place, each piece with
:data:`CHUNK_CONTEXT` of context either side. The layout is a function of the audio
alone (never of the cores: one core hears the same pieces one after another, with the
same posteriors bit for bit). The model's output depends on all of its input (1 s of
silence appended to a 9 s sentence moves one of its 109 best-path phones), so a cut costs
a little everywhere, not only at the seam: see :data:`SPLIT_SECONDS`.

Failures
--------
An alignment whose mean per-frame log posterior falls more than :data:`MAX_ALIGN_LOSS`
nats below that of the unconstrained best path, a transcript with more phones than
the audio has frames, or one that names fewer than :data:`MIN_PHONE_SHARE` of the phones
the unconstrained best path hears, raises :class:`~db.errors.DataError` (the transcript
does not match the audio): :func:`ingest.speech.segment.segment` then warns and
recognises instead. The share test is needed because CTC's blank absorbs speech the
transcript leaves out at little cost per frame: a one-word transcript of a six-word GRID
sentence falls only 0.3 nats per frame below recognition, inside the right transcripts'
range.
An alignment that passes but falls more than :data:`DOUBT_ALIGN_LOSS` below is aligned
with a warning (collected by :func:`doubts`): most transcripts of another utterance of the
same words' kind land there.
``hama`` missing or unusable raises :class:`~db.errors.DataError` with one line saying so.
"""

from __future__ import annotations

import contextvars
import logging
import math
import os
import queue
import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from db.errors import DataError
from db.system import thread_budget, usable_cpus
from ingest.formats.phones_csv import Segment
from ingest.speech.ctc_store import (
    alias_path,
    audio_key,
    disk_path,
    from_disk,
    kept_on_disk,
    on_disk,
    read_alias,
    to_disk,
    write_alias,
)
from ingest.speech.ctc_timing import (
    FRAME_RATE,
    PAUSE_SMOOTH,
    SAMPLE_RATE,
    ctc_viterbi,
    frame_energy,
    last_frames,
    timed,
)
from ingest.speech.g2p import pronounce, transcript_words
from ingest.speech.inputs import MIN_DURATION, SILENCE_PEAK, check_audio, check_text
from ingest.speech.phones import PHONES, SILENCE
from ingest.speech.tiling import silence

logger = logging.getLogger(__name__)

__all__ = [
    "FRAME_RATE",
    "IPA_TO_ARPABET",
    "DOUBT_ALIGN_LOSS",
    "MAX_ALIGN_LOSS",
    "MIN_PHONE_SHARE",
    "align",
    "available",
    "check_transcript",
    "doubt",
    "doubts",
    "kept_on_disk",
    "phone_probs",
    "phone_share",
    "posteriors",
    "remember",
    "recognize",
    "recognized_phones",
    "transcript_loss",
]

#: Largest drop (nats per frame) of an alignment's log posterior below the free best
#: path before the transcript is judged not to match the audio. Measured: 0.11-0.29 with
#: the right transcript (eSpeak speech, GRID), 0.9-1.9 with another sentence of the
#: synthetic corpus; GRID's look-alike sentences (same grammar) 0.17-0.97, most of them
#: above :data:`DOUBT_ALIGN_LOSS`.
MAX_ALIGN_LOSS = 0.6
#: Above this drop (and up to :data:`MAX_ALIGN_LOSS`) the transcript is aligned with a
#: warning that it may be another utterance's. Measured (``scripts/eval_transcript_check.py``,
#: 100 GRID clips): right transcripts 0.00-0.35 (clean, white noise to 0 dB SNR, telephone
#: band, room echo of RT60 0.5 s), above 0.4 on 6 of 100 with 1 s of echo; the next
#: clip's transcript (same grammar and length) on 68 of 100 (18 of them above the limit).
DOUBT_ALIGN_LOSS = 0.4
#: Fewest phones a transcript must name per phone heard (the unconstrained best path's,
#: repeats merged). Measured (``scripts/eval_transcript_check.py``): right transcripts
#: 0.81-1.24 on 100 GRID clips (0.86-2.83 in white noise down to 0 dB SNR; noise hides
#: phones rather than adding them), 0.94-1.00 on eSpeak speech; a GRID sentence's last
#: word alone 0.12-0.31, its first three words of six 0.33-0.71.
MIN_PHONE_SHARE = 0.5
#: Audio is fed to the model in pieces (:func:`_pieces`): as many as it has started
#: stretches of this many seconds, each piece with :data:`CHUNK_CONTEXT` seconds of
#: context either side (the model gives at most 1,500 frames, 30 s, per call: longer
#: input is cut short; a piece is at most this plus twice :data:`CUT_WINDOW`).
CHUNK_SECONDS = 20.0
#: Measured on 66 eSpeak recordings of 6-15 s (synthetic clips joined in twos and
#: threes) cut in two: recognition's phone error rate 0.265 with 1 s, 0.264 with 2 s,
#: 0.260 with 3 s, against 0.253 uncut; each second costs about 15 % more model time.
CHUNK_CONTEXT = 1.0
#: Audio at least this many seconds long is heard in two pieces at least, so that two
#: cores hear it at once (the same pieces on one core: the output depends on the audio
#: alone). ``scripts/bench_e2e.py``'s 9.3 s sentence on an idle 2-core machine: hama's
#: call 0.80 -> 0.56 s, the ``segment`` phase 1.18 -> 0.78 s (medians of 3 interleaved
#: runs of each; no gain while another process keeps the second core busy). The model
#: hears better with more of the utterance, at the seam and away from it alike: on the 66
#: recordings above, cut in two, the phone error rate of recognition rose from 0.253 to
#: 0.265 (paired 95 % interval +0.006 to +0.018; errors within 1 s of a cut 0.260,
#: elsewhere 0.258); alignment's did not change (its phones are the transcript's). Below
#: it (EmoDB's 2 s, GRID's 3 s, single synthetic sentences of 2.4-5.9 s) nothing changes.
SPLIT_SECONDS = 6.0
#: Each cut lies at the quietest 100 ms (:data:`PAUSE_SMOOTH` frames) within this many
#: seconds of its even place: in a pause if there is one, not in a phone (measured as
#: above: 0.265 against 0.268 cut at the even place, a difference within noise).
CUT_WINDOW = 1.0
#: Version of the piece layout (:func:`_pieces`), part of the name of the posteriors kept
#: on disk: posteriors heard in other pieces are not this layout's (layout 1: 20 s
#: pieces from the start, the names without a version).
PIECE_LAYOUT = 2

#: The model's IPA symbols -> ARPAbet. Symbols of other languages go to the nearest
#: English phone (aspirated and tense Korean stops to the plain stop, front rounded vowels
#: to the nearest rounded or central vowel, the alveolar flap to D); glide-vowel symbols
#: (``ja``, ``wa`` ...) to their glide. Symbols absent here carry no phone (blank).
IPA_TO_ARPABET: dict[str, str] = {
    "a": "AA", "aɪ": "AY", "aʊ": "AW", "b": "B", "c": "K", "d": "D", "d͡ʒ": "JH",
    "e": "EH", "eə": "EH", "eɪ": "EY", "f": "F", "g": "G", "h": "HH", "i": "IY", "j": "Y",
    "ja": "Y", "je": "Y", "jo": "Y", "ju": "Y", "jʌ": "Y", "k": "K", "kʰ": "K", "k͈": "K",
    "l": "L", "m": "M", "n": "N", "o": "OW", "oʊ": "OW", "p": "P", "pʰ": "P", "p͈": "P",
    "r": "R", "s": "S", "s͈": "S", "t": "T", "tʰ": "T", "t͈": "T", "t͡ɕ": "CH",
    "t͡ɕʰ": "CH", "t͡ɕ͈": "CH", "t͡ʃ": "CH", "u": "UW", "v": "V", "w": "W", "wa": "W",
    "we": "W", "wi": "W", "wʌ": "W", "x": "HH", "y": "UW", "z": "Z", "à": "AA", "ã": "AA",
    "ä": "AA", "å": "AO", "æ": "AE", "ç": "HH", "ì": "IY", "ð": "DH", "ñ": "N", "õ": "OW",
    "ø": "ER", "ħ": "HH", "ĩ": "IY", "ŋ": "NG", "œ": "ER", "ũ": "UW", "ǐ": "IY", "ɐ": "AH",
    "ɑ": "AA", "ɒ": "AA", "ɓ": "B", "ɔ": "AO", "ɔɪ": "OY", "ɕ": "SH", "ɖ": "D", "ɗ": "D",
    "ɘ": "AH", "ə": "AH", "ɚ": "ER", "ɛ": "EH", "ɜ": "ER", "ɝ": "ER", "ɟ": "JH", "ɡ": "G",
    "ɣ": "G", "ɤ": "AH", "ɥ": "Y", "ɦ": "HH", "ɨ": "IH", "ɪ": "IH", "ɪə": "IH", "ɫ": "L",
    "ɮ": "L", "ɯ": "UW", "ɯi": "IY", "ɰ": "W", "ɱ": "M", "ɲ": "N", "ɴ": "NG", "ɵ": "UH",
    "ɸ": "F", "ɹ": "R", "ɻ": "R", "ɽ": "R", "ɾ": "D", "ʀ": "R", "ʁ": "R", "ʂ": "SH",
    "ʃ": "SH", "ʈ": "T", "ʉ": "UW", "ʊ": "UH", "ʋ": "V", "ʌ": "AH", "ʎ": "L", "ʏ": "UH",
    "ʐ": "ZH", "ʑ": "ZH", "ʒ": "ZH", "ʙ": "B", "ʝ": "Y", "β": "V", "θ": "TH", "χ": "HH",
    "ẑ": "Z", "ẽ": "EH",
}

_INDEX = {p: k for k, p in enumerate(PHONES)}
_SIL = _INDEX[SILENCE]


# ---------------------------------------------------------------------------------------------
# The model
# ---------------------------------------------------------------------------------------------


@dataclass
class _Model:
    """The model's symbol map and its inference sessions.

    One session runs one call at a time on one core (hama's engine is single-threaded and
    releases the GIL), so callers on several threads (a baseline hearing every clip of a
    database) each take a session of their own: up to ``limit``, made when first needed.
    """

    merge: np.ndarray  # (n_symbols, n_phones) 0/1: symbol -> PHONES column
    new_session: Callable[[], object]
    limit: int
    idle: queue.SimpleQueue = field(default_factory=queue.SimpleQueue)
    made: int = 0
    lock: threading.Lock = field(default_factory=threading.Lock)

    @contextmanager
    def session(self) -> Iterator[object]:
        """A session for this thread's call, back to the idle ones after it."""
        try:
            session = self.idle.get_nowait()
        except queue.Empty:
            with self.lock:
                make = self.made < self.limit
                if make:
                    session = self.new_session()
                    self.made += 1
            if not make:
                session = self.idle.get()  # all in use: wait for one
        try:
            yield session
        finally:
            self.idle.put(session)


_MODEL: _Model | None = None
_MODEL_LOCK = threading.Lock()


def _reset_after_fork() -> None:  # pragma: no cover - exercised only in forked children
    global _MODEL, _MODEL_LOCK
    _MODEL = None
    _MODEL_LOCK = threading.Lock()


os.register_at_fork(after_in_child=_reset_after_fork)


def available() -> bool:
    """True if the ``hama`` package and its native library can be loaded."""
    try:
        from hama import _engine
    except ImportError:
        return False
    return bool(_engine.available())


def _model() -> _Model:
    global _MODEL
    with _MODEL_LOCK:
        if _MODEL is not None:
            return _MODEL
        try:
            from hama import ASRModel
        except ImportError as exc:
            raise DataError(f"the hama phone engine is not installed ({exc}); "
                            "pip install hama, or use --phones-engine pocketsphinx") from exc
        start = time.perf_counter()

        def load() -> ASRModel:
            try:
                return ASRModel()
            except (RuntimeError, OSError, ValueError) as exc:
                raise DataError(f"cannot load the hama phone model: {exc}") from exc

        asr = load()
        symbols = asr.decoder_tokens
        merge = np.zeros((len(symbols), len(PHONES)), dtype=np.float32)
        for k, symbol in enumerate(symbols):
            merge[k, _INDEX[IPA_TO_ARPABET.get(symbol, SILENCE)]] = 1.0
        logger.debug("hama model loaded in %.2f s", time.perf_counter() - start)
        _MODEL = _Model(merge, lambda: load().session, usable_cpus(), made=1)
        _MODEL.idle.put(asr.session)
        return _MODEL


def _pieces(samples16: np.ndarray) -> np.ndarray:
    """Where the model's pieces of this audio begin and end, in 20 ms frames.

    ``n = ceil(seconds / CHUNK_SECONDS)`` pieces, at least two from
    :data:`SPLIT_SECONDS`; cut ``k`` lies at the quietest 100 ms (energy averaged over
    :data:`PAUSE_SMOOTH` frames; of equals, the nearest) within :data:`CUT_WINDOW` of
    frame ``k * n_frames / n``. A function of the audio alone, never of the cores that
    hear it.

    Parameters
    ----------
    samples16 : numpy.ndarray, shape (n_samples,)
        16 kHz audio.

    Returns
    -------
    numpy.ndarray, shape (n_pieces + 1,), int
        Frame bounds, from 0 to ``ceil(n_samples / 320)``; piece ``k`` gives frames
        ``bounds[k]`` to ``bounds[k + 1]``.
    """
    n_frames = math.ceil(len(samples16) / (SAMPLE_RATE // FRAME_RATE))
    seconds = len(samples16) / SAMPLE_RATE
    n = max(1, math.ceil(seconds / CHUNK_SECONDS), 2 if seconds >= SPLIT_SECONDS else 1)
    bounds = [0]
    if n > 1:
        energy = np.convolve(frame_energy(samples16, n_frames),
                             np.full(PAUSE_SMOOTH, 1.0 / PAUSE_SMOOTH), mode="same")
        reach = int(round(CUT_WINDOW * FRAME_RATE))
        for k in range(1, n):
            ideal = round(k * n_frames / n)
            frames = np.arange(max(bounds[-1] + 1, ideal - reach),
                               min(n_frames - 1, ideal + reach) + 1)
            best = np.lexsort((np.abs(frames - ideal), energy[frames]))[0]
            bounds.append(int(frames[best]))
    bounds.append(n_frames)
    return np.asarray(bounds, dtype=np.int64)


def _log_probs(samples: np.ndarray) -> np.ndarray:
    """16 kHz float audio -> the model's log posteriors, shape (n_frames, n_symbols).

    The audio is heard in the pieces of :func:`_pieces`, on as many threads as this
    process has cores for (:func:`db.system.thread_budget`; each thread its own session,
    :class:`_Model`): the same pieces as one after another, so the same output.
    """
    model = _model()
    context = int(CHUNK_CONTEXT * SAMPLE_RATE)
    hop = SAMPLE_RATE // FRAME_RATE
    bounds = _pieces(samples)

    def piece(k: int) -> np.ndarray:
        a, b = int(bounds[k]) * hop, min(len(samples), int(bounds[k + 1]) * hop)
        lo, hi = max(0, a - context), min(len(samples), b + context)
        wav = np.ascontiguousarray(samples[lo:hi], dtype=np.float32)
        with model.session() as session:
            try:
                log_probs, lengths = session.run(
                    ["log_probs", "out_lengths"],
                    {"waveform": wav[None], "waveform_lengths": np.array([len(wav)])})
            except RuntimeError as exc:
                raise DataError(f"hama phone recognition failed: {exc}") from exc
        out = np.asarray(log_probs[0][: int(np.asarray(lengths).reshape(-1)[0])])
        first = (a - lo) // hop
        count = int(bounds[k + 1] - bounds[k])
        out = out[first: first + count]
        if 0 < len(out) < count:  # the model's last frame may fall short of the end
            out = np.concatenate([out, np.repeat(out[-1:], count - len(out), axis=0)])
        return out

    pieces = range(len(bounds) - 1)
    threads = min(len(pieces), model.limit, thread_budget())
    if threads > 1:
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(threads, thread_name_prefix="hama") as pool:
            out = list(pool.map(piece, pieces))
    else:
        out = [piece(k) for k in pieces]
    return np.concatenate(out) if out else np.zeros((0, model.merge.shape[0]))


def _resample(samples: np.ndarray, sample_rate: int) -> np.ndarray:
    if sample_rate != SAMPLE_RATE:
        g = math.gcd(SAMPLE_RATE, sample_rate)
        from scipy.signal import resample_poly  # deferred: a second of a one-shot synth

        samples = resample_poly(samples, SAMPLE_RATE // g, sample_rate // g)
    peak = float(np.max(np.abs(samples))) if samples.size else 0.0
    if peak > 0:
        samples = samples * (0.9 / peak)  # the model hears every clip at one level
    return samples.astype(np.float32)


def posteriors(audio: np.ndarray, sample_rate: int) -> np.ndarray:
    """Per-frame phone posteriors (a *posteriorgram*), 50 frames per second.

    Parameters
    ----------
    audio : numpy.ndarray, shape (n_samples,)
        Mono audio, float in [-1, 1] or integer PCM.
    sample_rate : int
        Its sampling rate in Hz.

    Returns
    -------
    numpy.ndarray, shape (n_frames, len(PHONES)), float32
        Row ``t`` (audio from ``t / FRAME_RATE`` s) holds the probability of each phone of
        :data:`ingest.speech.phones.PHONES`; rows sum to 1; the ``SIL`` column holds the
        CTC blank (no phone starts here) and the symbols without a phone.

    Raises
    ------
    ParameterError
        Bad audio or sample rate.
    DataError
        If the model cannot be loaded or run.
    """
    samples, sample_rate = check_audio(audio, sample_rate)
    if sample_rate == SAMPLE_RATE or not on_disk():
        return _phone_log_probs(_resample(samples, sample_rate))[0]
    # Outputs kept for this very input are found without resampling it: importing
    # scipy.signal for the resampler is about a second of a one-shot synth that has
    # heard the recording before (its checks and guide ask for the posteriors again).
    alias = alias_path(samples, sample_rate)
    key = read_alias(alias)
    if key is not None:
        found = _kept(key, math.ceil(len(samples) * SAMPLE_RATE / sample_rate))
        if found is not None:
            return found[0]
    samples16 = _resample(samples, sample_rate)
    out = _phone_log_probs(samples16)
    if key != (key16 := audio_key(samples16)):  # kept once the outputs are
        write_alias(alias, key16)
    return out[0]


#: The last few model outputs, by a digest of their 16 kHz input: recognition, the
#: posteriorgram and the input checks of one utterance run the model once.
_RECENT: OrderedDict[bytes, tuple[np.ndarray, np.ndarray]] = OrderedDict()
_RECENT_SIZE = 2
_RECENT_LOCK = threading.Lock()


def forget() -> None:
    """Drop the remembered model outputs (e.g. to time a fresh run on the same audio)."""
    with _RECENT_LOCK:
        _RECENT.clear()


def _kept(key: bytes, n_samples16: int) -> tuple[np.ndarray, np.ndarray] | None:
    """The outputs for the 16 kHz audio of digest ``key`` (``n_samples16`` samples) as
    this process remembers them or (:func:`kept_on_disk`) the cache keeps them, or None."""
    with _RECENT_LOCK:
        if key in _RECENT:
            _RECENT.move_to_end(key)
            return _RECENT[key]
    path = disk_path(key, PIECE_LAYOUT) if on_disk() else None
    probs = from_disk(path, n_samples16) if path is not None and path.is_file() else None
    return None if probs is None else _remember(key, probs)


def _remember(key: bytes, probs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    out = probs.astype(np.float32), np.log(np.maximum(probs, 1e-30))
    for a in out:
        a.flags.writeable = False
    with _RECENT_LOCK:
        _RECENT[key] = out
        while len(_RECENT) > _RECENT_SIZE:
            _RECENT.popitem(last=False)
    return out


def _phone_log_probs(samples16: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(posteriors, log posteriors) over PHONES, each (n_frames, len(PHONES))."""
    key = audio_key(samples16)
    found = _kept(key, len(samples16))
    if found is not None:
        return found
    probs = phone_probs(samples16)
    if on_disk():
        # float64: what is read back gives the same results
        to_disk(disk_path(key, PIECE_LAYOUT), probs)
    return _remember(key, probs)


def phone_probs(samples16: np.ndarray) -> np.ndarray:
    """The model's output for 16 kHz audio at the level given (not normalised, not
    remembered), folded onto the project's phones: shape (ceil(n_samples / 320),
    len(PHONES)), float64, rows summing to 1. :func:`posteriors` is this on audio scaled
    to one level; a live stream (:mod:`animegraph.live.frontend`) calls it on the audio
    it has not heard yet and a little before."""
    log_probs = _log_probs(np.asarray(samples16, dtype=np.float32))
    probs = np.exp(log_probs.astype(np.float64)) @ _model().merge.astype(np.float64)
    probs /= np.maximum(probs.sum(axis=1, keepdims=True), 1e-30)
    return probs


def remember(audio: np.ndarray, sample_rate: int, probs: np.ndarray) -> None:
    """Take ``probs`` (shape (n_frames, len(PHONES)), n_frames as the model would give, within 2)
    as the posteriors of ``audio``: :func:`recognize` and :func:`posteriors` of this very
    audio then use them instead of running the model (the two most recent are kept). A
    live stream computes a window's posteriors piece by piece, reusing those it had."""
    samples, sample_rate = check_audio(audio, sample_rate)
    samples16 = _resample(samples, sample_rate)
    n = math.ceil(len(samples16) / (SAMPLE_RATE // FRAME_RATE))
    probs = np.asarray(probs, dtype=np.float64)
    if probs.ndim != 2 or probs.shape[1] != len(PHONES) or abs(len(probs) - n) > 2:
        raise ValueError(f"posteriors of shape {probs.shape} for audio of {n} frames")
    if len(probs) != n:  # the model's last frame may fall short of the end, or past it
        probs = probs[np.minimum(np.arange(n), len(probs) - 1)]
    _remember(audio_key(samples16), probs)


# ---------------------------------------------------------------------------------------------
# ---------------------------------------------------------------------------------------------
# Recognition and alignment
# ---------------------------------------------------------------------------------------------


def recognize(audio: np.ndarray, sample_rate: int, *, refine: bool = True) -> list[Segment]:
    """Recognise phones without a transcript (CTC greedy decoding of :func:`posteriors`).

    Parameters
    ----------
    audio : numpy.ndarray, shape (n_samples,)
        Mono audio, float or integer PCM, any level.
    sample_rate : int
        Its sampling rate in Hz.
    refine : bool, optional
        Move boundaries to the largest spectral change within
        :data:`ingest.speech.ctc_timing.REFINE_WINDOW`.

    Returns
    -------
    list of Segment
        ARPAbet phones and ``SIL`` tiling ``[0, len(audio) / sample_rate]``; one ``SIL``
        segment when nothing is recognised.

    Raises
    ------
    ParameterError
        Bad audio or sample rate.
    DataError
        If the model cannot be loaded or run.
    """
    samples, sample_rate = check_audio(audio, sample_rate)
    duration = len(samples) / sample_rate
    peak = float(np.max(np.abs(samples))) if samples.size else 0.0
    if duration < MIN_DURATION or peak < SILENCE_PEAK:
        return silence(duration)
    samples16 = _resample(samples, sample_rate)
    _, log_probs = _phone_log_probs(samples16)
    starts = _best_path_starts(log_probs)
    if starts.size == 0:
        return silence(duration)
    labels = np.argmax(log_probs[starts], axis=1)
    last = last_frames(starts, log_probs, labels)
    return timed([PHONES[i] for i in labels], starts, last, samples16, len(log_probs),
                  duration, refine)


def recognized_phones(audio: np.ndarray, sample_rate: int) -> list[str]:
    """The phones :func:`recognize` names, in order, without timing them (no ``SIL``;
    none for audio too short or too quiet to recognise): for an engine that places
    them itself (:func:`ingest.speech.engines.recognize_auto`). Timing is most of
    :func:`recognize`'s work once the model has heard the audio (its boundary
    refinement: 22 ms of 23 ms for 9.3 s of speech)."""
    samples, sample_rate = check_audio(audio, sample_rate)
    peak = float(np.max(np.abs(samples))) if samples.size else 0.0
    if len(samples) / sample_rate < MIN_DURATION or peak < SILENCE_PEAK:
        return []
    _, log_probs = _phone_log_probs(_resample(samples, sample_rate))
    starts = _best_path_starts(log_probs)
    return [PHONES[i] for i in np.argmax(log_probs[starts], axis=1)]


def transcript_phones(text: str) -> list[str]:
    """The ARPAbet phones of a transcript (CMUdict, else eSpeak NG letter-to-sound)."""
    phones: list[str] = []
    for word in transcript_words(text):
        phones += [p for p in pronounce(word) if p in _INDEX and p != SILENCE]
    return phones


def check_transcript(audio: np.ndarray, sample_rate: int, text: str) -> None:
    """Raise :class:`~db.errors.DataError` unless ``text`` is what ``audio`` says.

    The tests of :func:`align` (:data:`MAX_ALIGN_LOSS` on :func:`transcript_loss`,
    :data:`MIN_PHONE_SHARE` on :func:`phone_share`), for a transcript another engine
    aligns: a forced aligner finds a path through almost any transcript, so without them
    a transcript of another utterance, or one that leaves words out, would be timed as if
    spoken.

    Raises
    ------
    ParameterError
        Bad audio, sample rate or an empty transcript.
    DataError
        As :func:`align`; or hama cannot be loaded.
    """
    transcript_loss(audio, sample_rate, text, check=True)


def transcript_loss(audio: np.ndarray, sample_rate: int, text: str, *,
                    check: bool = False) -> float:
    """How much worse ``text``'s CTC alignment fits the audio than free recognition does:
    the mean drop of the log posterior along the best path, in nats per 20 ms frame
    (0 for audio shorter than a phone; ``check``: raise as :func:`check_transcript`)."""
    text = check_text(text)
    samples, sample_rate = check_audio(audio, sample_rate)
    if len(samples) / sample_rate < MIN_DURATION:
        return 0.0
    return _fit_transcript(_resample(samples, sample_rate), text, check=check, path=False)[4]


def _fit_transcript(samples16: np.ndarray, text: str, *, check: bool = True,
                    path: bool = True
                    ) -> tuple[list[str], np.ndarray, np.ndarray | None, np.ndarray, float]:
    """The transcript's phones, their indices, CTC Viterbi start frames (None without
    ``path``), the log posteriors they were aligned on, and the loss; DataError if the
    transcript has no phone or (``check``) does not fit."""
    phones = transcript_phones(text)
    if not phones:
        raise DataError(f"the transcript {text[:60]!r} has no pronounceable word")
    _, log_probs = _phone_log_probs(samples16)
    labels = np.asarray([_INDEX[p] for p in phones], dtype=np.int64)
    starts, score = ctc_viterbi(log_probs, labels, _SIL, path=path)
    free = float(np.sum(np.max(log_probs, axis=1)))
    loss = (free - score) / max(len(log_probs), 1)
    if check and loss > MAX_ALIGN_LOSS:
        raise DataError(f"the transcript {text[:60]!r} does not match the audio "
                        f"(alignment {loss:.2f} nats/frame below recognition)")
    heard = len(_best_path_starts(log_probs))
    if check and len(phones) < MIN_PHONE_SHARE * heard:
        raise DataError(f"the transcript {text[:60]!r} does not match the audio (it names "
                        f"{len(phones)} phones, the audio has about {heard}: words missing?)")
    if check and loss > DOUBT_ALIGN_LOSS:
        doubt(f"the transcript {text[:60]!r} fits the audio poorly (alignment {loss:.2f} "
               "nats/frame below recognition): is it this recording's? (much room echo "
               "can also do this)")
    return phones, labels, starts, log_probs, loss


#: Where :func:`doubts` collects the lines of transcripts aligned with doubt (None: logged).
_DOUBTS: contextvars.ContextVar[list[str] | None] = contextvars.ContextVar(
    "transcript_doubts", default=None)


@contextmanager
def doubts() -> Iterator[list[str]]:
    """Collect, instead of logging them as warnings, the lines of the transcripts that
    :func:`check_transcript` or :func:`align` passed with doubt (:data:`DOUBT_ALIGN_LOSS`)
    in this block, each once: for a caller that reports them its own way."""
    found: list[str] = []
    token = _DOUBTS.set(found)
    try:
        yield found
    finally:
        _DOUBTS.reset(token)


def doubt(line: str) -> None:
    """Say a doubted transcript's ``line``: to the :func:`doubts` block around this call,
    else as a warning (also what :mod:`ingest.speech.heard` says again from its cache)."""
    found = _DOUBTS.get()
    if found is None:
        logger.warning("%s", line)
    elif line not in found:
        found.append(line)


def phone_share(audio: np.ndarray, sample_rate: int, text: str) -> float:
    """How many phones ``text`` names per phone free recognition hears in ``audio`` (the
    unconstrained best path's, repeats merged; inf when it hears none): the second test
    of :func:`check_transcript` (:data:`MIN_PHONE_SHARE`)."""
    samples, sample_rate = check_audio(audio, sample_rate)
    _, log_probs = _phone_log_probs(_resample(samples, sample_rate))
    heard = len(_best_path_starts(log_probs))
    return len(transcript_phones(check_text(text))) / heard if heard else math.inf


def _best_path_starts(log_probs: np.ndarray) -> np.ndarray:
    """First frames of the phones on the unconstrained best CTC path (the most likely
    class per frame, repeats merged, blanks dropped): int, shape (n_phones,), of log
    posteriors shaped (n_frames, len(PHONES))."""
    best = np.argmax(log_probs, axis=1)
    change = np.concatenate(([True], best[1:] != best[:-1]))
    return np.flatnonzero(change & (best != _SIL))


def align(audio: np.ndarray, sample_rate: int, text: str, *, refine: bool = True
          ) -> list[Segment]:
    """Forced alignment of a transcript by CTC Viterbi over :func:`posteriors`.

    Parameters
    ----------
    audio : numpy.ndarray, shape (n_samples,)
        Mono audio.
    sample_rate : int
        Its sampling rate in Hz.
    text : str
        What is said (English; numbers and symbols are spelled out).
    refine : bool, optional
        Move boundaries to the largest spectral change within
        :data:`ingest.speech.ctc_timing.REFINE_WINDOW`.

    Returns
    -------
    list of Segment
        The transcript's phones and pauses tiling ``[0, len(audio) / sample_rate]``.

    Raises
    ------
    ParameterError
        Bad audio, sample rate or an empty transcript.
    DataError
        If the transcript has no pronounceable word, needs more frames than the audio
        has, or fits the audio much worse than recognition does (:data:`MAX_ALIGN_LOSS`):
        it does not match the audio.
    """
    text = check_text(text)
    samples, sample_rate = check_audio(audio, sample_rate)
    duration = len(samples) / sample_rate
    if duration < MIN_DURATION:
        return silence(duration)
    samples16 = _resample(samples, sample_rate)
    phones, labels, starts, log_probs, _ = _fit_transcript(samples16, text)
    last = last_frames(starts, log_probs, labels)
    return timed(phones, starts, last, samples16, len(log_probs), duration, refine)
