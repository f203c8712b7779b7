"""Grapheme-to-phoneme conversion and transcript normalisation for the aligner.

The forced aligner (:mod:`ingest.speech.sphinx`) needs a pronunciation for every word of a
transcript. CMUdict (shipped with PocketSphinx) covers most English words; the others
(names, coinages such as "blorptastic", misspellings) get one from this module:

1. :func:`espeak_g2p` — eSpeak NG's own letter-to-sound rules and exception lists, read
   back from the phone labels of speaking the word alone (:func:`ingest.speech.espeak.speak`).
   This is an excellent G2P and needs nothing beyond what the project already ships.
2. :func:`rule_g2p` — a small rule-based English letter-to-sound converter (digraphs,
   vowel teams, r-coloured vowels, final silent *e* ...), used only when eSpeak fails.

:func:`g2p` chains the two; :func:`pronounce` tries CMUdict first. :func:`transcript_words`
turns free text into dictionary-style words: lower case, typographic apostrophes made
plain, accents stripped, numbers spelled out (:func:`number_to_words`), ``&`` and ``%``
read, hyphenated compounds kept whole only when the dictionary knows them.

All phones are ARPAbet from :data:`ingest.speech.phones.PHONE_SET`, without stress digits.
"""

from __future__ import annotations

import functools
import logging
import re
import unicodedata
from collections.abc import Callable

from db.errors import AnimeGraphError, DataError, ParameterError
from ingest.speech.phones import PHONE_SET, SILENCE

logger = logging.getLogger(__name__)

__all__ = [
    "espeak_g2p",
    "g2p",
    "number_to_words",
    "pronounce",
    "rule_g2p",
    "split_words",
    "transcript_words",
]

# ---------------------------------------------------------------------------------------------
# Numbers
# ---------------------------------------------------------------------------------------------

_ONES = (
    "zero one two three four five six seven eight nine ten eleven twelve thirteen fourteen "
    "fifteen sixteen seventeen eighteen nineteen"
).split()
_TENS = "_ _ twenty thirty forty fifty sixty seventy eighty ninety".split()
_SCALES = ((10**12, "trillion"), (10**9, "billion"), (10**6, "million"), (1000, "thousand"))
_ORDINAL_WORD = {
    "one": "first", "two": "second", "three": "third", "five": "fifth", "eight": "eighth",
    "nine": "ninth", "twelve": "twelfth",
}


def _below_thousand(n: int) -> list[str]:
    out: list[str] = []
    if n >= 100:
        out += [_ONES[n // 100], "hundred"]
        n %= 100
    if n >= 20:
        out.append(_TENS[n // 10])
        n %= 10
        if n:
            out.append(_ONES[n])
    elif n or not out:
        out.append(_ONES[n])
    return out


def number_to_words(number: int, *, ordinal: bool = False) -> list[str]:
    """Spell out a non-negative integer in English words (American style, no "and").

    Parameters
    ----------
    number : int
        0 <= number < 10**15.
    ordinal : bool, optional
        Spell the ordinal ("twenty first") instead of the cardinal ("twenty one").

    Returns
    -------
    list of str
        Lower-case words, e.g. ``number_to_words(1987) == ["one", "thousand", "nine",
        "hundred", "eighty", "seven"]``.

    Raises
    ------
    ParameterError
        If ``number`` is not an int in range.
    """
    if isinstance(number, bool) or not isinstance(number, int) or not 0 <= number < 10**15:
        raise ParameterError(f"number: expected an int in [0, 10**15), got {number!r}")
    words: list[str] = []
    rest = number
    for scale, name in _SCALES:
        if rest >= scale:
            words += _below_thousand(rest // scale) + [name]
            rest %= scale
    if rest or not words:
        words += _below_thousand(rest)
    if ordinal:
        last = words[-1]
        if last in _ORDINAL_WORD:
            words[-1] = _ORDINAL_WORD[last]
        elif last.endswith("y"):
            words[-1] = last[:-1] + "ieth"
        else:
            words[-1] = last + "th"
    return words


def _digits_to_words(match: re.Match[str]) -> str:
    """Spell out one number token: ``1,000``, ``3.14``, ``21st``, ``1987``."""
    whole, fraction, suffix = match.group(1), match.group(2), match.group(3)
    whole = whole.replace(",", "")
    if len(whole) > 15:  # a long digit string (a phone number, an id): read digit by digit
        words = [_ONES[int(d)] for d in whole]
    elif suffix:
        words = number_to_words(int(whole), ordinal=True)
    elif len(whole) == 4 and not fraction and 1100 <= int(whole) <= 1999 and whole[2] != "0":
        # years read in pairs: 1987 -> nineteen eighty seven
        words = _below_thousand(int(whole[:2])) + _below_thousand(int(whole[2:]))
    else:
        words = number_to_words(int(whole))
    if fraction:
        words.append("point")
        words += [_ONES[int(d)] for d in fraction]
    return " " + " ".join(words) + " "


_NUMBER = re.compile(r"(\d{1,3}(?:,\d{3})+|\d+)(?:\.(\d+))?(st|nd|rd|th)?\b", re.IGNORECASE)
_SYMBOLS = {"&": " and ", "%": " percent ", "+": " plus ", "@": " at ", "=": " equals "}
_TOKEN = re.compile(r"[a-z0-9]+(?:['\-][a-z0-9]+)*")


def _ascii_fold(text: str) -> str:
    """Strip accents (crème -> creme) and make typographic apostrophes and dashes plain."""
    text = text.replace("\u2019", "'").replace("\u2018", "'").replace("\u02bc", "'")
    text = text.replace("\u2010", "-").replace("\u2011", "-")
    decomposed = unicodedata.normalize("NFKD", text)
    return "".join(c for c in decomposed if not unicodedata.combining(c))


def split_words(text: str) -> list[str]:
    """The words of ``text`` as written, lower case: accents stripped, typographic
    apostrophes and hyphens made plain, punctuation around words dropped (``"Boat,"`` ->
    ``boat``); numbers and symbols stay as they are (:func:`transcript_words` reads them).

    Parameters
    ----------
    text : str
        Free text.

    Returns
    -------
    list of str
        Tokens of letters and digits, joined by inner ``'`` or ``-`` (empty if none).
    """
    return _TOKEN.findall(_ascii_fold(text).lower())


def transcript_words(
    text: str, in_dictionary: Callable[[str], bool] | None = None
) -> list[str]:
    """Normalise a transcript into lower-case dictionary-style words.

    Case is folded; accents are stripped; typographic apostrophes become ``'`` and are
    kept inside words (``father's``, ``o'clock``); other punctuation is dropped; numbers
    are spelled out (``1,000`` -> one thousand, ``3.5`` -> three point five, ``21st`` ->
    twenty first, ``1987`` -> nineteen eighty seven); ``&``, ``%``, ``+``, ``@``, ``=``
    are read as words. A hyphenated token (``well-known``) is kept whole if
    ``in_dictionary`` knows it, else split at its hyphens; a word with an apostrophe the
    dictionary does not know is kept as it is (its pronunciation comes from :func:`g2p`).

    Parameters
    ----------
    text : str
        Free English text.
    in_dictionary : callable, optional
        ``in_dictionary(word) -> bool``; by default CMUdict (:func:`_in_cmudict`).

    Returns
    -------
    list of str
        The words in order (empty if the text has none).

    Raises
    ------
    ParameterError
        If ``text`` is not a str.
    """
    if not isinstance(text, str):
        raise ParameterError(f"text: expected str, got {type(text).__name__}")
    known = in_dictionary if in_dictionary is not None else _in_cmudict
    text = _ascii_fold(text).lower()
    for symbol, spoken in _SYMBOLS.items():
        text = text.replace(symbol, spoken)
    text = _NUMBER.sub(_digits_to_words, text)
    words: list[str] = []
    for token in split_words(text):
        if "-" in token and not known(token):
            words += [part for part in token.split("-") if part]
        else:
            words.append(token)
    return words


# ---------------------------------------------------------------------------------------------
# Dictionary, eSpeak and rule-based pronunciations
# ---------------------------------------------------------------------------------------------


def _in_cmudict(word: str) -> bool:
    from ingest.corpus.sentences import cmudict

    return word in cmudict()


def _check_word(word: object) -> str:
    if not isinstance(word, str) or not word.strip():
        raise ParameterError(f"word: expected a non-empty string, got {word!r}")
    return word.strip().lower()


@functools.lru_cache(maxsize=4096)
def espeak_g2p(word: str) -> tuple[str, ...]:
    """Pronounce ``word`` with eSpeak NG's letter-to-sound rules.

    The word is spoken alone (American English voice) and the phone labels of the
    result, without pauses, are its pronunciation.

    Parameters
    ----------
    word : str
        One word (letters, apostrophes; digits are read as eSpeak reads them).

    Returns
    -------
    tuple of str
        ARPAbet phones, never empty.

    Raises
    ------
    ParameterError
        If ``word`` is empty.
    DataError
        If eSpeak NG is unusable or says nothing for the word.
    """
    word = _check_word(word)
    from ingest.speech.espeak import ESPEAK_SAMPLE_RATE, speak

    try:
        utterance = speak(word, sample_rate=ESPEAK_SAMPLE_RATE, pad=0.0)
    except (AnimeGraphError, OSError) as exc:
        raise DataError(f"eSpeak NG cannot pronounce {word!r}: {exc}") from exc
    phones = tuple(p.phone for p in utterance.phones if p.phone != SILENCE)
    if not phones:
        raise DataError(f"eSpeak NG said nothing for {word!r}")
    return phones


# Longest match first. Each rule: grapheme -> phones; context is handled in _rule_phones.
_CONSONANT_GRAPHEMES: dict[str, tuple[str, ...]] = {
    "tch": ("CH",), "dge": ("JH",), "sch": ("S", "K"), "ght": ("T",), "dg": ("JH",),
    "th": ("TH",), "sh": ("SH",), "ch": ("CH",), "ph": ("F",), "ck": ("K",), "ng": ("NG",),
    "nk": ("NG", "K"), "qu": ("K", "W"), "wh": ("W",), "gh": (), "zh": ("ZH",),
    "b": ("B",), "d": ("D",), "f": ("F",), "h": ("HH",), "j": ("JH",), "k": ("K",),
    "l": ("L",), "m": ("M",), "n": ("N",), "p": ("P",), "q": ("K",), "r": ("R",),
    "s": ("S",), "t": ("T",), "v": ("V",), "w": ("W",), "x": ("K", "S"), "y": ("Y",),
    "z": ("Z",), "c": ("K",), "g": ("G",),
}
_VOWEL_TEAMS: dict[str, tuple[str, ...]] = {
    "eigh": ("EY",), "augh": ("AO",), "ough": ("AO",),
    "igh": ("AY",), "air": ("EH", "R"), "are": ("EH", "R"), "ear": ("IH", "R"),
    "eer": ("IH", "R"), "ier": ("IH", "R"), "oor": ("AO", "R"), "our": ("AW", "ER"),
    "ore": ("AO", "R"), "ure": ("Y", "UH", "R"), "ire": ("AY", "ER"),
    "ar": ("AA", "R"), "or": ("AO", "R"), "er": ("ER",), "ir": ("ER",), "ur": ("ER",),
    "ee": ("IY",), "ea": ("IY",), "ai": ("EY",), "ay": ("EY",), "ei": ("EY",),
    "ey": ("EY",), "oa": ("OW",), "oe": ("OW",), "oo": ("UW",), "ou": ("AW",),
    "ow": ("AW",), "oi": ("OY",), "oy": ("OY",), "au": ("AO",), "aw": ("AO",),
    "ue": ("UW",), "ui": ("UW",), "ew": ("UW",), "ie": ("IY",),
}
_SHORT = {"a": ("AE",), "e": ("EH",), "i": ("IH",), "o": ("AA",), "u": ("AH",), "y": ("IH",)}
_LONG = {"a": ("EY",), "e": ("IY",), "i": ("AY",), "o": ("OW",), "u": ("UW",), "y": ("AY",)}
_SUFFIXES: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("tion", ("SH", "AH", "N")), ("sion", ("ZH", "AH", "N")), ("cian", ("SH", "AH", "N")),
    ("ture", ("CH", "ER")), ("ous", ("AH", "S")), ("ble", ("B", "AH", "L")),
    ("cle", ("K", "AH", "L")), ("dle", ("D", "AH", "L")), ("ple", ("P", "AH", "L")),
    ("tle", ("T", "AH", "L")), ("gle", ("G", "AH", "L")), ("ful", ("F", "AH", "L")),
    ("ness", ("N", "AH", "S")), ("less", ("L", "AH", "S")), ("ment", ("M", "AH", "N", "T")),
    ("ing", ("IH", "NG")), ("ism", ("IH", "Z", "AH", "M")), ("ly", ("L", "IY")),
)
_GRAPHEMES_BY_LENGTH = sorted(_CONSONANT_GRAPHEMES, key=len, reverse=True)
_VOWEL_LETTERS = frozenset("aeiouy")
#: Consonants after which a long u is /Y UW/ (cute, music, pure) rather than /UW/ (rule).
_YOD = frozenset("bcfhkmpv")
_FRONT = frozenset("eiy")


def _is_vowel(word: str, i: int) -> bool:
    """Whether ``word[i]`` is a vowel letter (``y`` only when not before a vowel)."""
    if not 0 <= i < len(word):
        return False
    c = word[i]
    if c == "y":
        return i > 0 and not _is_vowel(word, i + 1)
    return c in _VOWEL_LETTERS


_VOICELESS = frozenset({"P", "K", "S", "SH", "CH", "F", "TH"})


def _rule_phones(word: str) -> list[str]:
    """Letter-to-sound rules over a lower-case ``a-z`` word (see :func:`rule_g2p`)."""
    if len(word) > 4 and word.endswith("ed") and not _is_vowel(word, len(word) - 3):
        # past tense: wanted -> IH D, pushed -> T, covered -> D
        stem = _rule_phones(word[:-2] + ("e" if word[-3] in "cgsvz" else ""))
        if stem and stem[-1] in ("T", "D"):
            return stem + ["IH", "D"]
        return stem + (["T"] if stem and stem[-1] in _VOICELESS else ["D"])
    suffix: tuple[str, ...] = ()
    for ending, phones in _SUFFIXES:
        if word.endswith(ending) and len(word) > len(ending) + 1:
            word, suffix = word[: -len(ending)], phones
            break
    silent_e = len(word) > 2 and word.endswith("e") and not _is_vowel(word, len(word) - 2)
    if silent_e and any(_is_vowel(word, k) for k in range(len(word) - 2)):
        word = word[:-1]
    else:
        silent_e = False
    out: list[str] = []
    i, n = 0, len(word)
    while i < n:
        rest = word[i:]
        c = word[i]
        # initial silent letters: kn, gn, wr, ps, pn
        if i == 0 and rest[:2] in ("kn", "gn", "wr", "ps", "pn"):
            i += 1
            continue
        if rest.startswith("mb") and i + 2 == n:
            out.append("M")
            break
        if c == "y" and i == 0:
            out.append("Y")
            i += 1
            continue
        if _is_vowel(word, i):
            team = next((t for t in _VOWEL_TEAMS if rest.startswith(t)), None)
            if team is not None and not (team.endswith("r") and _is_vowel(word, i + len(team))):
                out += _VOWEL_TEAMS[team]
                i += len(team)
                continue
            # open syllable or magic e: vowel + one consonant + vowel (or the silent final e)
            one_consonant = i + 1 < n and not _is_vowel(word, i + 1)
            # not before a final y: city, body, very are short
            next_vowel = i + 2 < n and _is_vowel(word, i + 2) and not (
                word[i + 2] == "y" and i + 3 == n
            )
            magic = one_consonant and ((silent_e and i + 2 == n) or next_vowel)
            magic = magic or (bool(suffix) and i == n - 1)  # open syllable: na-tion, ta-ble
            if magic and c == "u" and (i == 0 or word[i - 1] in _YOD):
                out += ("Y", "UW")
            elif c == "y" and i == n - 1:
                vowels = sum(_is_vowel(word, k) for k in range(n - 1))
                out += ("IY",) if vowels else ("AY",)
            elif c in "ei" and i == n - 1 and n > 1 and not silent_e:
                out += _LONG[c] if n <= 3 else ("IY",)
            elif c == "o" and i == n - 1:
                out += ("OW",)
            else:
                out += (_LONG if magic else _SHORT)[c]
            i += 1
            continue
        grapheme = next((g for g in _GRAPHEMES_BY_LENGTH if rest.startswith(g)), None)
        if grapheme is not None and len(grapheme) > 1 and not (grapheme == "gh" and i == 0):
            out += _CONSONANT_GRAPHEMES[grapheme]
            i += len(grapheme)
            continue
        soft = (i + 1 < n and word[i + 1] in _FRONT) or (silent_e and i == n - 1)
        if c == "c":
            out += ("S",) if soft else ("K",)
            i += 1 + (rest.startswith("cc") and not (len(rest) > 2 and rest[2] in _FRONT))
            continue
        if c == "g" and not rest.startswith(("gh", "ng")):
            out += ("JH",) if soft and i > 0 else ("G",)
            i += 2 if rest.startswith("gg") else 1
            continue
        if c == "h" and i > 0 and _is_vowel(word, i - 1) and not _is_vowel(word, i + 1):
            i += 1  # silent after a vowel: oh, ah, hurrah
            continue
        if c == "x" and i == 0:
            out.append("Z")
            i += 1
            continue
        if c == "s" and i == n - 1 and out and out[-1] not in ("P", "T", "K", "F", "TH"):
            out.append("Z")
            i += 1
            continue
        if grapheme == "gh":  # initial gh: ghost
            out.append("G")
            i += 2
            continue
        out += _CONSONANT_GRAPHEMES.get(c, ())
        i += 1
        if i < n and word[i] == c:  # double consonant
            i += 1
    out += suffix
    # collapse repeats the rules may have produced across a boundary (e.g. "ck" + "k")
    return [p for k, p in enumerate(out) if k == 0 or p != out[k - 1]]


@functools.lru_cache(maxsize=4096)
def rule_g2p(word: str) -> tuple[str, ...]:
    """Pronounce ``word`` with simple English letter-to-sound rules.

    A fallback for when eSpeak NG is unavailable: common suffixes (-tion, -ture, -ble,
    -ing ...), consonant digraphs (th, sh, ch, ph, ck, ng, qu, wh, tch, dge, ght, silent
    kn/wr/gn/mb/gh), soft c and g, vowel teams (ee, ea, ai, oa, oo, ou, oi, igh ...),
    r-coloured vowels (ar, or, er, ir, ur, air, ear ...), long vowels in open syllables
    and before a final silent e, short vowels otherwise. No stress, no reduction.

    Parameters
    ----------
    word : str
        One word; characters other than ``a-z`` (after lower-casing and stripping
        accents) are ignored.

    Returns
    -------
    tuple of str
        ARPAbet phones; empty only if the word has no letters.

    Raises
    ------
    ParameterError
        If ``word`` is empty.
    """
    word = _check_word(word)
    letters = re.sub(r"[^a-z]", "", _ascii_fold(word).lower())
    if not letters:
        return ()
    phones = tuple(_rule_phones(letters))
    if not set(phones) <= PHONE_SET:  # pragma: no cover - the tables only hold PHONE_SET
        raise AssertionError(f"rule_g2p({word!r}) gave {phones}")
    return phones


def g2p(word: str) -> tuple[str, ...]:
    """Pronounce a word the dictionary does not know: eSpeak NG, else the letter rules.

    Parameters
    ----------
    word : str
        One word.

    Returns
    -------
    tuple of str
        ARPAbet phones (empty only if eSpeak fails and the word has no letters).

    Raises
    ------
    ParameterError
        If ``word`` is empty.
    """
    word = _check_word(word)
    try:
        return espeak_g2p(word)
    except DataError as exc:
        logger.warning("eSpeak G2P failed for %r (%s); using letter-to-sound rules", word, exc)
        return rule_g2p(word)


def pronounce(word: str) -> tuple[str, ...]:
    """Pronounce a word: CMUdict's first pronunciation, else :func:`g2p`.

    Parameters
    ----------
    word : str
        One word (case-insensitive).

    Returns
    -------
    tuple of str
        ARPAbet phones.

    Raises
    ------
    ParameterError
        If ``word`` is empty.
    """
    word = _check_word(word)
    from ingest.corpus.sentences import cmudict

    entries = cmudict().get(word)
    if entries:
        return entries[0]
    return g2p(word)
