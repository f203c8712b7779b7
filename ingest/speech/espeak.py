"""Speech synthesis with eSpeak NG, returning the audio and its exact ARPAbet phone timing.

A :mod:`ctypes` binding to the eSpeak NG library shipped by the ``espeakng-loader`` wheel.
eSpeak reports a phoneme event at the sample where it starts to synthesise each phoneme;
those events are the ground truth of :func:`speak`'s phone segments, so a corpus built from
it knows its phone timing exactly. eSpeak's phoneme mnemonics are converted to the project's
phone set (:data:`ingest.speech.phones.PHONES`) by
:data:`ingest.speech.espeak_phones.ESPEAK_TO_ARPABET`.

The library is global state and not thread-safe: every synthesis holds a module-level lock.
eSpeak also carries synthesis state from one call to the next in static variables that no
API call resets (the pitch-flutter phase, the gain control, the glottal phase), so the same
text would come out a few samples different each time. Each call therefore loads the
library (on Linux a private in-memory copy, made lazily once per process), initialises it,
selects the voice, sets every prosody parameter, seeds C's ``rand()`` (breathy voices draw
noise from it), speaks, terminates and unloads it (well under a millisecond): calls are
independent and deterministic, the same text and voice always give bit-identical audio.
A fork waits for a synthesis under way to finish (``os.register_at_fork``); spawned workers
set themselves up on first use.

Timing of the mapped phones
---------------------------
Phone labels come from :mod:`ingest.speech.espeak_phones` (how each eSpeak NG mnemonic
maps to ARPAbet). Their timing:

* Two-phone mnemonics are split into two consecutive segments sharing the event's span.
  A vowel followed by its r-colour or glide (``A@`` AA R, ``O@``/``o@`` AO R, ``e@`` EH R,
  ``U@`` UH R, ``i@3``/``IR`` IH R, ``VR`` AH R, ``i@`` IY AH, ``aI@`` AY AH, ``aI3`` AY ER,
  ``aU@`` AW ER) gives the vowel the first 60 % (:data:`VOWEL_SPLIT`). A syllabic consonant
  (``@L``/``l-`` AH L, ``n-`` AH N, ``m-`` AH M, ``N-`` AH NG) gives its notional schwa only
  the first 30 % (:data:`SYLLABIC_SPLIT`): the mouth holds the consonant nearly throughout.
* Context rules, so that a sound is not counted twice: the ``R`` of an r-coloured vowel is
  dropped when eSpeak itself follows it with an ``r`` ("aaron" ``e@ r @ n`` -> EH R AH N);
  an ``r`` after an ``ER`` ("aberration" ``3 r`` -> ER, as CMUdict has it) and the palatal
  glide ``;`` eSpeak inserts between ``i`` and a vowel ("abbreviate" ``I2 ; eI``) lengthen
  the previous segment instead of adding one.
* eSpeak emits a stop's closure silence before the stop's phoneme event; that silence is
  given to the stop (and to the other obstruents eSpeak precedes with silence), see
  :func:`_move_closures`.
* A phone eSpeak reports with zero duration (a post-vocalic ``l`` it folds into the vowel:
  "all", "tell") takes the last 30 % of the segment before it (:data:`ZERO_LENGTH_SHARE`).

Unknown mnemonics do not stop synthesis: they are logged as a warning and mapped by
:func:`ingest.speech.espeak_phones.fallback`.
"""

from __future__ import annotations

import _ctypes
import ctypes
import ctypes.util
import logging
import math
import os
import threading
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.signal import resample_poly

from db.errors import DataError, ParameterError
from ingest.speech.espeak_phones import ABSORBED, R_COLOURED, R_MNEMONICS, fallback, map_mnemonic
from ingest.speech.phones import CONSONANTS, SILENCE, VOWELS

logger = logging.getLogger(__name__)

__all__ = [
    "ESPEAK_SAMPLE_RATE",
    "PhoneSegment",
    "Utterance",
    "Voice",
    "speak",
]

#: Sample rate of eSpeak NG's own output (Hz); phoneme events count samples at this rate.
ESPEAK_SAMPLE_RATE = 22050

#: Fraction of a two-phone mnemonic's span given to its first phone when that is a vowel
#: followed by an r-colour or glide (``A@`` -> AA R).
VOWEL_SPLIT = 0.6
#: Fraction given to the notional schwa of a syllabic consonant (``n-`` -> AH N).
SYLLABIC_SPLIT = 0.3
#: Fraction of the preceding segment given to a phone eSpeak reports with no duration (a
#: post-vocalic ``l`` that eSpeak folds into the vowel before it: "all", "tell").
ZERO_LENGTH_SHARE = 0.3

_VOWEL_SET = frozenset(VOWELS)
_OBSTRUENTS = frozenset("P B T D K G CH JH F V TH DH S Z SH ZH HH".split())
#: Shortest run of digital silence (eSpeak samples, 1 ms) taken for a closure.
_MIN_CLOSURE = 22
_CONSONANT_SET = frozenset(CONSONANTS)


# ---------------------------------------------------------------------------------------------
# Public data types
# ---------------------------------------------------------------------------------------------

_RANGES: dict[str, tuple[int, int]] = {
    "rate": (80, 450),
    "pitch": (0, 100),
    "pitch_range": (0, 100),
    "volume": (0, 200),
    "word_gap": (0, 500),
}


@dataclass(frozen=True)
class Voice:
    """eSpeak NG prosody settings.

    Out-of-range or non-integer settings raise :class:`~db.errors.ParameterError` on
    construction; whether eSpeak knows the voice ``name`` is checked by :func:`speak`.
    """

    name: str = "en-us"  # eSpeak voice, variants allowed, e.g. "en-us+m3"; English only
    rate: int = 165  # words per minute (espeakRATE, 80..450)
    pitch: int = 50  # base pitch 0..100 (espeakPITCH, 50 = voice's normal)
    pitch_range: int = 50  # 0..100 (espeakRANGE, 0 = monotone, 50 = normal)
    volume: int = 100  # 0..200 (espeakVOLUME, 100 = normal; above may clip)
    word_gap: int = 0  # extra pause between words, in units of 10 ms (espeakWORDGAP, 0..500)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip() or "\x00" in self.name:
            raise ParameterError(f"voice name must be a non-empty string, got {self.name!r}")
        for field, (lo, hi) in _RANGES.items():
            value = getattr(self, field)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise ParameterError(f"voice {field} must be an integer, got {value!r}")
            if not lo <= value <= hi:
                raise ParameterError(f"voice {field} must be in [{lo}, {hi}], got {value}")


@dataclass(frozen=True)
class PhoneSegment:
    """One phone of an utterance."""

    phone: str  # ARPAbet: ingest.speech.phones.PHONES, no stress digits
    start: float  # seconds
    end: float  # seconds
    stress: int  # 0 none, 1 primary ("'" in eSpeak), 2 secondary (",")

    @property
    def duration(self) -> float:
        """``end - start`` in seconds."""
        return self.end - self.start


@dataclass(frozen=True, eq=False)
class Utterance:
    """Synthesised speech and its phone segmentation.

    Attributes
    ----------
    text : str
        The text spoken.
    audio : numpy.ndarray, shape (n_samples,), float32
        Mono audio in [-1, 1].
    sample_rate : int
        Sampling rate of ``audio`` in Hz.
    phones : tuple of PhoneSegment
        Segments tiling ``audio`` exactly: the first starts at 0, each starts where the
        previous ends, the last ends at ``n_samples / sample_rate``; ``SIL`` at both ends.

    Notes
    -----
    Equality is identity (comparing audio arrays element-wise has no single truth value).
    """

    text: str
    audio: np.ndarray
    sample_rate: int
    phones: tuple[PhoneSegment, ...]

    @property
    def duration(self) -> float:
        """Length of :attr:`audio` in seconds."""
        return len(self.audio) / self.sample_rate


# ---------------------------------------------------------------------------------------------
# The ctypes binding (speak_lib.h, ESPEAK_API_REVISION 12)
# ---------------------------------------------------------------------------------------------

_AUDIO_OUTPUT_SYNCHRONOUS = 2
_INITIALIZE_PHONEME_EVENTS = 0x0001
_POS_CHARACTER = 1
_CHARS_UTF8 = 1
_EE_OK = 0
_EVENT_LIST_TERMINATED = 0
_EVENT_PHONEME = 7
# espeak_PARAMETER. The others (punctuation, capitals, intonation ...) are never changed
# from the voice's defaults here, so they need no reset.
_RATE, _VOLUME, _PITCH, _RANGE, _WORDGAP = 1, 2, 3, 4, 7


class _EventId(ctypes.Union):
    _fields_ = [
        ("number", ctypes.c_int),
        ("name", ctypes.c_char_p),
        ("string", ctypes.c_char * 8),
    ]


class _Event(ctypes.Structure):
    _fields_ = [
        ("type", ctypes.c_int),
        ("unique_identifier", ctypes.c_uint),
        ("text_position", ctypes.c_int),
        ("length", ctypes.c_int),
        ("audio_position", ctypes.c_int),
        ("sample", ctypes.c_int),
        ("user_data", ctypes.c_void_p),
        ("id", _EventId),
    ]


class _VoiceInfo(ctypes.Structure):
    _fields_ = [
        ("name", ctypes.c_char_p),
        ("languages", ctypes.c_char_p),
        ("identifier", ctypes.c_char_p),
        ("gender", ctypes.c_ubyte),
        ("age", ctypes.c_ubyte),
        ("variant", ctypes.c_ubyte),
        ("xx1", ctypes.c_ubyte),
        ("score", ctypes.c_int),
        ("spare", ctypes.c_void_p),
    ]


_SynthCallback = ctypes.CFUNCTYPE(
    ctypes.c_int, ctypes.POINTER(ctypes.c_short), ctypes.c_int, ctypes.POINTER(_Event)
)


def _declare(lib: ctypes.CDLL) -> None:
    """Set argtypes/restype of every function used (speak_lib.h)."""
    lib.espeak_Initialize.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_char_p, ctypes.c_int]
    lib.espeak_Initialize.restype = ctypes.c_int
    lib.espeak_SetSynthCallback.argtypes = [_SynthCallback]
    lib.espeak_SetSynthCallback.restype = None
    lib.espeak_SetVoiceByName.argtypes = [ctypes.c_char_p]
    lib.espeak_SetVoiceByName.restype = ctypes.c_int
    lib.espeak_GetCurrentVoice.argtypes = []
    lib.espeak_GetCurrentVoice.restype = ctypes.POINTER(_VoiceInfo)
    lib.espeak_SetParameter.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int]
    lib.espeak_SetParameter.restype = ctypes.c_int
    lib.espeak_Synth.argtypes = [
        ctypes.c_void_p, ctypes.c_size_t, ctypes.c_uint, ctypes.c_int, ctypes.c_uint,
        ctypes.c_uint, ctypes.POINTER(ctypes.c_uint), ctypes.c_void_p,
    ]
    lib.espeak_Synth.restype = ctypes.c_int
    lib.espeak_Synchronize.argtypes = []
    lib.espeak_Synchronize.restype = ctypes.c_int
    lib.espeak_Terminate.argtypes = []
    lib.espeak_Terminate.restype = ctypes.c_int


def _unload(lib: ctypes.CDLL) -> None:
    """Drop ctypes' handle on ``lib`` (the library unmaps when no one else holds it)."""
    close = getattr(_ctypes, "dlclose", None) or getattr(_ctypes, "FreeLibrary", None)
    if close is not None:
        close(lib._handle)


class _Engine:
    """eSpeak NG for this process: where to load the library from, and the callback's buffers.

    eSpeak keeps synthesis state in static variables that neither re-initialisation nor
    ``espeak_Terminate`` resets, so each synthesis loads the library afresh, initialises it,
    speaks, terminates and unloads it. On Linux the library is loaded from a private
    in-memory copy (``memfd``), so unloading really unloads it even if other code in the
    process holds the wheel's library; elsewhere from the wheel's file.
    """

    def __init__(self) -> None:
        import espeakng_loader

        self.data_path = espeakng_loader.get_data_path()
        self.lib_path = espeakng_loader.get_library_path()
        self._memfd: int | None = None
        if hasattr(os, "memfd_create") and os.path.isdir("/proc/self/fd"):
            fd = -1
            try:
                with open(self.lib_path, "rb") as source:
                    image = source.read()
                fd = os.memfd_create("animegraph-libespeak-ng", os.MFD_CLOEXEC)
                view = memoryview(image)
                while view:
                    view = view[os.write(fd, view) :]
                private = f"/proc/self/fd/{fd}"
                _unload(ctypes.CDLL(private))  # loadable from there?
            except OSError as exc:
                if fd >= 0:
                    os.close(fd)
                logger.debug("loading eSpeak NG from %s: %s", self.lib_path, exc)
            else:
                self._memfd, self.lib_path = fd, private
        self.chunks: list[np.ndarray] = []
        self.events: list[tuple[int, str]] = []
        self.error: BaseException | None = None
        self._callback = _SynthCallback(self._on_synth)  # keep a reference: C holds it
        self._checked_unload = False
        logger.debug("eSpeak NG library %s, data %s", self.lib_path, self.data_path)

    def _on_synth(self, wav, n_samples: int, events) -> int:
        try:
            if n_samples > 0 and wav:
                self.chunks.append(np.ctypeslib.as_array(wav, (n_samples,)).copy())
            if events:
                i = 0
                while (event := events[i]).type != _EVENT_LIST_TERMINATED:
                    if event.type == _EVENT_PHONEME:
                        self.events.append(
                            (event.sample, event.id.string.decode("utf-8", "replace"))
                        )
                    i += 1
        except BaseException as exc:  # must not unwind through C
            self.error = exc
            return 1
        return 0

    def _load(self) -> ctypes.CDLL:
        lib = ctypes.CDLL(self.lib_path)
        _declare(lib)
        rate = lib.espeak_Initialize(
            _AUDIO_OUTPUT_SYNCHRONOUS, 0, self.data_path.encode(), _INITIALIZE_PHONEME_EVENTS
        )
        if rate != ESPEAK_SAMPLE_RATE:
            _unload(lib)
            raise DataError(
                f"eSpeak NG failed to initialise from {self.data_path} (returned {rate}, "
                f"expected sample rate {ESPEAK_SAMPLE_RATE})"
            )
        lib.espeak_SetSynthCallback(self._callback)
        return lib

    def _close(self, lib: ctypes.CDLL) -> None:
        lib.espeak_Terminate()
        _unload(lib)
        if not self._checked_unload and hasattr(os, "RTLD_NOLOAD"):
            self._checked_unload = True
            try:
                still = ctypes.CDLL(self.lib_path, mode=os.RTLD_NOLOAD | os.RTLD_LAZY)
            except OSError:
                return
            _unload(still)
            logger.warning(
                "eSpeak NG stays loaded between calls (%s): audio may not be bit-identical "
                "from call to call", self.lib_path,
            )

    @staticmethod
    def _select(lib: ctypes.CDLL, voice: Voice) -> None:
        """Select ``voice`` and set every parameter :class:`Voice` controls."""
        name = voice.name.strip()
        if lib.espeak_SetVoiceByName(name.encode("utf-8")) != _EE_OK:
            raise ParameterError(f"voice name {voice.name!r} is not an eSpeak NG voice")
        current = lib.espeak_GetCurrentVoice()
        languages = (current.contents.languages or b"")[1:] if current else b""
        identifier = (current.contents.identifier or b"").decode("utf-8", "replace")
        if not languages.lower().startswith(b"en"):
            raise ParameterError(
                f"voice name {voice.name!r} is not an English voice "
                f"(language {languages.decode('utf-8', 'replace')!r})"
            )
        if "+" in name and not identifier.lower().endswith(
            "+" + name.split("+", 1)[1].lower()
        ):
            raise ParameterError(f"voice name {voice.name!r} has a variant eSpeak NG lacks")
        for parameter, value in (
            (_RATE, voice.rate),
            (_VOLUME, voice.volume),
            (_PITCH, voice.pitch),
            (_RANGE, voice.pitch_range),
            (_WORDGAP, voice.word_gap),
        ):
            if lib.espeak_SetParameter(parameter, int(value), 0) != _EE_OK:
                raise DataError(f"eSpeak NG rejected parameter {parameter} = {value}")

    def synthesize(self, text: str, voice: Voice) -> tuple[np.ndarray, list[tuple[int, str]]]:
        """Speak ``text``.

        Returns
        -------
        audio : numpy.ndarray, shape (n_samples,), int16
            Samples at :data:`ESPEAK_SAMPLE_RATE`.
        events : list of (int, str)
            Phoneme events: the sample where each phoneme starts and its mnemonic.
        """
        self.chunks, self.events, self.error = [], [], None
        lib = self._load()
        try:
            self._select(lib, voice)
            _seed_libc_rand()
            data = text.encode("utf-8")
            buf = ctypes.create_string_buffer(data)
            rc = lib.espeak_Synth(
                buf, len(data) + 1, 0, _POS_CHARACTER, 0, _CHARS_UTF8, None, None
            )
            lib.espeak_Synchronize()
        finally:
            self._close(lib)
        if self.error is not None:
            raise self.error
        if rc != _EE_OK:
            raise DataError(f"eSpeak NG failed to synthesise {text[:60]!r} (error {rc})")
        audio = np.concatenate(self.chunks) if self.chunks else np.zeros(0, np.int16)
        events = self.events
        self.chunks, self.events = [], []
        return audio, events


def _seed_libc_rand() -> None:
    """Seed C's ``rand()``, which eSpeak's breath and Klatt noise draw on, to its default."""
    global _LIBC_SRAND
    if _LIBC_SRAND is None:
        try:
            libc = ctypes.CDLL(ctypes.util.find_library("c") or None)
            _LIBC_SRAND = libc.srand
            _LIBC_SRAND.argtypes = [ctypes.c_uint]
            _LIBC_SRAND.restype = None
        except (OSError, AttributeError):
            _LIBC_SRAND = False
    if _LIBC_SRAND:
        _LIBC_SRAND(1)


_LIBC_SRAND = None
_LOCK = threading.Lock()
_ENGINE: _Engine | None = None

# A child forked while another thread synthesises would inherit a held lock (and buffers
# half filled): fork only between syntheses.
os.register_at_fork(
    before=_LOCK.acquire, after_in_parent=_LOCK.release, after_in_child=_LOCK.release
)


def _engine() -> _Engine:
    """The process's engine, created on first use (a forked child inherits it).

    Call with :data:`_LOCK` held.
    """
    global _ENGINE
    if _ENGINE is None:
        _ENGINE = _Engine()
    return _ENGINE


# ---------------------------------------------------------------------------------------------
# Events -> phone segments
# ---------------------------------------------------------------------------------------------


@dataclass
class _Span:
    phones: tuple[str, ...]
    stress: int
    start: int  # sample at ESPEAK_SAMPLE_RATE
    end: int


def _spans(events: Sequence[tuple[int, str]], raw: np.ndarray) -> list[_Span]:
    """Phoneme events -> mapped spans in eSpeak samples, with the context rules applied.

    Parameters
    ----------
    events : sequence of (int, str)
        (sample, mnemonic) phoneme events.
    raw : numpy.ndarray, shape (n_samples,), int16
        eSpeak's audio, for :func:`_move_closures`.
    """
    n_samples = len(raw)
    mnemonics: list[tuple[int, str, tuple[str, ...], int]] = []
    unknown: set[str] = set()
    for sample, mnemonic in sorted(events, key=lambda event: event[0]):
        phones, stress, known = map_mnemonic(mnemonic)
        if not known:
            unknown.add(mnemonic)
        body = mnemonic.lstrip("',%=")
        mnemonics.append((min(max(sample, 0), n_samples), body, phones, stress))
    for mnemonic in sorted(unknown):
        logger.warning(
            "unknown eSpeak phoneme %r mapped to %s", mnemonic,
            " ".join(fallback(mnemonic.lstrip("',%="))),
        )

    spans: list[_Span] = []
    first = mnemonics[0][0] if mnemonics else n_samples
    if first > 0:
        spans.append(_Span((SILENCE,), 0, 0, first))
    for k, (start, body, phones, stress) in enumerate(mnemonics):
        end = mnemonics[k + 1][0] if k + 1 < len(mnemonics) else n_samples
        end = max(end, start)
        following = mnemonics[k + 1][1] if k + 1 < len(mnemonics) else ""
        previous = spans[-1] if spans else None
        if body in R_COLOURED and following in R_MNEMONICS:
            phones = phones[:1]
        absorbed = body == ";" or (
            body in R_MNEMONICS and previous is not None and previous.phones[-1] == "ER"
        )
        if absorbed and previous is not None and previous.phones != (SILENCE,):
            previous.end = end
            continue
        if not phones:
            phones = ABSORBED.get(body, ("AH",))
        if (
            end == start
            and phones != (SILENCE,)
            and previous is not None
            and previous.phones != (SILENCE,)
            and previous.end - previous.start >= 2
        ):
            # eSpeak gives a post-vocalic l (rarely r) no time of its own: the vowel glides
            # into it. It takes the end of that vowel instead of vanishing.
            share = round(ZERO_LENGTH_SHARE * (previous.end - previous.start))
            start = previous.end - max(1, share)
            previous.end = start
        spans.append(_Span(phones, stress, start, end))
    _move_closures(spans, raw)
    return spans


def _move_closures(spans: list[_Span], raw: np.ndarray) -> None:
    """Give the digital silence at the end of a segment to the obstruent that follows it.

    eSpeak emits a stop's closure (its "prepause", 40-50 ms at normal rate) before the stop's
    phoneme event, so the silence would count as the end of the vowel before. The face
    closes for the stop during that silence (the lips, for ``P``), so it belongs to the
    stop; likewise the short silence eSpeak puts before some fricatives. Voices with echo
    (variants ``f2``..``f5``, ``m2`` ...) fill the silence with echo and keep eSpeak's
    boundary. The previous segment keeps at least half its length.
    """
    silent = raw == 0
    for prev, span in zip(spans, spans[1:], strict=False):
        if span.phones[0] not in _OBSTRUENTS or prev.phones == (SILENCE,):
            continue
        limit = prev.end - (prev.end - prev.start) // 2
        start = span.start
        while start > limit and silent[start - 1]:
            start -= 1
        if span.start - start >= _MIN_CLOSURE:
            prev.end = span.start = start


def _segments(
    spans: Sequence[_Span], n_speech: int, offset: int, n_total: int, ratio: tuple[int, int],
    sample_rate: int,
) -> tuple[PhoneSegment, ...]:
    """Spans in eSpeak samples -> PhoneSegments tiling ``n_total`` output samples.

    ``ratio = (up, down)`` converts eSpeak samples to output samples; the speech occupies
    output samples ``[offset, offset + n_speech)``, the pads are silence.
    """
    up, down = ratio

    def out(sample: int) -> int:
        return offset + min(n_speech, (sample * up + down // 2) // down)

    pieces: list[tuple[str, int, int, int]] = [(SILENCE, 0, 0, offset)]  # phone, stress, a, b
    for i, span in enumerate(spans):
        a = out(span.start)
        b = offset + n_speech if i == len(spans) - 1 else out(span.end)
        stress = span.stress
        if len(span.phones) == 1:
            phone = span.phones[0]
            pieces.append((phone, stress if phone in _VOWEL_SET else 0, a, b))
            continue
        first, second = span.phones
        syllabic = first == "AH" and second in _CONSONANT_SET
        fraction = SYLLABIC_SPLIT if syllabic else VOWEL_SPLIT
        mid = a + int(round(fraction * (b - a)))
        if mid <= a or mid >= b:  # too short to split: keep the dominant phone
            phone = first if fraction >= 0.5 else second
            pieces.append((phone, stress if phone in _VOWEL_SET else 0, a, b))
            continue
        pieces.append((first, stress if first in _VOWEL_SET else 0, a, mid))
        pieces.append((second, 0, mid, b))
    pieces.append((SILENCE, 0, offset + n_speech, n_total))

    merged: list[list] = []
    for phone, stress, a, b in pieces:
        if b <= a:
            if phone != SILENCE:
                logger.debug("dropped %s: shorter than one sample at %d Hz", phone, sample_rate)
            continue
        if merged and merged[-1][0] == SILENCE and phone == SILENCE:
            merged[-1][3] = b
            continue
        merged.append([phone, stress, a, b])
    # Tiling: close any gap a dropped segment left by extending the previous segment.
    for prev, cur in zip(merged, merged[1:], strict=False):
        prev[3] = cur[2]
    return tuple(
        PhoneSegment(phone=p, start=a / sample_rate, end=b / sample_rate, stress=s)
        for p, s, a, b in merged
    )


# ---------------------------------------------------------------------------------------------
# speak
# ---------------------------------------------------------------------------------------------


def speak(
    text: str,
    voice: Voice = Voice(),
    *,
    sample_rate: int = 16000,
    pad: float = 0.25,
) -> Utterance:
    """Synthesise English ``text`` with eSpeak NG and segment it into ARPAbet phones.

    Parameters
    ----------
    text : str
        English text (UTF-8; digits, abbreviations and punctuation are read as eSpeak does).
    voice : Voice, optional
        Voice and prosody; defaults to ``Voice()`` (American English, 165 wpm).
    sample_rate : int, optional
        Sampling rate of the returned audio in Hz, at least 8000. eSpeak synthesises at
        22050 Hz; other rates are resampled with :func:`scipy.signal.resample_poly`.
    pad : float, optional
        Seconds of digital silence added before and after the speech (rounded to whole
        samples), labelled ``SIL`` together with eSpeak's own pauses next to them.

    Returns
    -------
    Utterance
        ``audio`` has shape ``(n_samples,)``, float32; ``phones`` tile it exactly.

    Raises
    ------
    ParameterError
        Empty text, an unknown or non-English voice, an out-of-range setting, a bad
        ``sample_rate`` or ``pad``.
    DataError
        eSpeak produced no speech for ``text`` (e.g. only punctuation it does not read).
    """
    if not isinstance(text, str) or not text.strip():
        raise ParameterError(f"text must be a non-empty string, got {text!r}")
    if "\x00" in text:
        raise ParameterError(f"text must not contain NUL characters, got {text[:60]!r}")
    if not isinstance(voice, Voice):
        raise ParameterError(f"voice must be a Voice, got {type(voice).__name__}")
    if (
        isinstance(sample_rate, bool)
        or not isinstance(sample_rate, (int, np.integer))
        or not 8000 <= sample_rate <= 384000
    ):
        raise ParameterError(
            f"sample_rate must be an integer in [8000, 384000], got {sample_rate!r}"
        )
    if isinstance(pad, bool) or not isinstance(pad, (int, float)) or not (
        math.isfinite(pad) and 0 <= pad <= 60
    ):
        raise ParameterError(f"pad must be a number of seconds in [0, 60], got {pad!r}")
    sample_rate = int(sample_rate)

    with _LOCK:
        raw, events = _engine().synthesize(text, voice)

    spans = _spans(events, raw)
    if len(raw) == 0 or all(span.phones == (SILENCE,) for span in spans):
        raise DataError(f"eSpeak NG produced no speech for text {text[:60]!r}")

    g = math.gcd(sample_rate, ESPEAK_SAMPLE_RATE)
    up, down = sample_rate // g, ESPEAK_SAMPLE_RATE // g
    speech = raw.astype(np.float32) / np.float32(32768.0)
    if (up, down) != (1, 1):
        speech = resample_poly(speech, up, down).astype(np.float32, copy=False)
        np.clip(speech, -1.0, 1.0, out=speech)
    n_pad = int(round(pad * sample_rate))
    audio = np.zeros(len(speech) + 2 * n_pad, dtype=np.float32)
    audio[n_pad : n_pad + len(speech)] = speech

    phones = _segments(spans, len(speech), n_pad, len(audio), (up, down), sample_rate)
    return Utterance(text=text, audio=audio, sample_rate=sample_rate, phones=phones)
