"""eSpeak NG's English phoneme mnemonics mapped to the project's ARPAbet phones
(:data:`ingest.speech.phones.PHONES`): what :func:`ingest.speech.espeak.speak` labels its
phone segments with.

Mapping eSpeak NG's English phonemes to ARPAbet
-----------------------------------------------
The table covers every phoneme of eSpeak NG's English phoneme tables (``en``, ``en-us``,
``en-rp``, ``en-sc``, ``en-n``, ``en-wm``, ``en-wi``, ``en-us-nyc``, read from the shipped
``phontab``) and the base-table consonants those voices use (``x``, ``?``, ``t[``, ``d[``
...), and was checked by speaking every word of CMUdict. Choices worth knowing:

* Stress marks (``'`` primary, ``,`` secondary) are stripped into
  :attr:`ingest.speech.espeak.PhoneSegment.stress`; only vowels carry stress (for a
  two-phone mnemonic, its vowel part).
* Pauses (every mnemonic starting with ``_``: ``_``, ``_:``, ``_!``, ``_|`` ...) are ``SIL``.
* American values, as CMUdict has them: ``0`` (LOT) and ``A:`` -> ``AA``; ``O:``, ``O``,
  ``O2`` (THOUGHT, CLOTH) -> ``AO``; ``a``, ``aa`` (BATH) -> ``AE``; reduced vowels ``@``,
  ``@2``, ``@5``, ``@-``, ``a#``, ``V`` -> ``AH``; ``3``, ``3:`` -> ``ER``; ``I``, ``I2``,
  ``I#`` -> ``IH``; ``i``, ``i:`` -> ``IY``.
* Flaps and glottal stops stand for /t/ or /d/ as in CMUdict: ``t#``, ``t2``, ``?`` -> ``T``
  ("water", "button"), ``d#`` -> ``D``. ``x`` (loch, Bach) -> ``K`` as in CMUdict.
* Nasalised vowels of French loans: ``A~`` -> ``AA``, ``O~`` -> ``AO`` (one phone each).

Unknown mnemonics (from a non-English word eSpeak switched language for, say) do not stop
synthesis: they are logged as a warning and mapped by :func:`fallback`.

How the mapped phones share an event's span, and the context rules between neighbours,
are :mod:`ingest.speech.espeak`'s (its docstring).
"""

from __future__ import annotations

from ingest.speech.phones import PHONE_SET, SILENCE

__all__ = ["ABSORBED", "ESPEAK_TO_ARPABET", "R_COLOURED", "R_MNEMONICS", "fallback",
           "map_mnemonic"]

#: eSpeak NG English phoneme mnemonic (without stress mark) -> ARPAbet phones. Pauses (any
#: mnemonic starting with ``_``) are handled apart and map to ``SIL``. An empty tuple means
#: "lengthen the previous segment" (the context rules of :mod:`ingest.speech.espeak`).
ESPEAK_TO_ARPABET: dict[str, tuple[str, ...]] = {
    # --- monophthongs -------------------------------------------------------------------
    "@": ("AH",),  # schwa (comma)
    "@2": ("AH",),  # weak schwa, "the" before consonants
    "@5": ("AH",),  # weak schwa from /u/, "to"
    "@-": ("AH",),  # very short schwa, "additional"
    "@#": ("AH",),  # schwa variant
    "V": ("AH",),  # STRUT
    "a#": ("AH",),  # reduced a, "about"
    "a2": ("AH",),  # reduced a
    "a#2": ("AH",),  # reduced a
    "3": ("ER",),  # unstressed r-coloured schwa, "butter"
    "3:": ("ER",),  # NURSE
    "a": ("AE",),  # TRAP
    "aa": ("AE",),  # BATH (American: AE)
    "a/": ("AE",),  # Scottish TRAP/BATH
    "A#": ("AE",),  # en-us "can't" class
    "A:": ("AA",),  # PALM
    "0": ("AA",),  # LOT (American: AA)
    "0#": ("AA",),  # LOT variant
    "02": ("AA",),  # LOT variant, "want"
    "O:": ("AO",),  # THOUGHT
    "O": ("AO",),  # THOUGHT, short
    "O2": ("AO",),  # CLOTH, "cost"
    "E": ("EH",),  # DRESS
    "E#": ("EH",),  # DRESS, reduced
    "E2": ("EH",),  # DRESS variant
    "e#": ("EH",),  # DRESS variant
    "e:": ("EY",),  # long e of loans, "cafe"
    "I": ("IH",),  # KIT
    "I2": ("IH",),  # unstressed KIT, "roses"
    "I#": ("IH",),  # unstressed KIT, "wanted"
    "I2#": ("IH",),  # unstressed KIT variant
    "i": ("IY",),  # happY
    "i:": ("IY",),  # FLEECE
    "U": ("UH",),  # FOOT
    "u:": ("UW",),  # GOOSE
    "A~": ("AA",),  # nasal vowel of French loans, "croissant"
    "O~": ("AO",),  # nasal vowel of French loans, "denouement"
    # --- diphthongs ---------------------------------------------------------------------
    "aI": ("AY",),  # PRICE
    "aI2": ("AY",),  # Scottish PRICE
    "aU": ("AW",),  # MOUTH
    "eI": ("EY",),  # FACE
    "OI": ("OY",),  # CHOICE
    "oU": ("OW",),  # GOAT
    "oU#": ("OW",),  # GOAT variant
    "o:": ("OW",),  # GOAT monophthong
    "o": ("OW",),  # GOAT, short, "tolkien"
    # --- r-coloured vowels and vowel + glide: split VOWEL_SPLIT ------------------------
    "A@": ("AA", "R"),  # START
    "O@": ("AO", "R"),  # NORTH
    "o@": ("AO", "R"),  # FORCE
    "e@": ("EH", "R"),  # SQUARE
    "U@": ("UH", "R"),  # CURE
    "i@3": ("IH", "R"),  # NEAR
    "IR": ("IH", "R"),  # "mirror"
    "VR": ("AH", "R"),  # "hurry"
    "i@": ("IY", "AH"),  # "-ia", "idea"
    "aI@": ("AY", "AH"),  # "science"
    "aI3": ("AY", "ER"),  # "fire"
    "aU@": ("AW", "ER"),  # "hour"
    # --- syllabic consonants: split SYLLABIC_SPLIT -------------------------------------
    "@L": ("AH", "L"),  # "little"
    "l-": ("AH", "L"),
    "n-": ("AH", "N"),  # "button"
    "m-": ("AH", "M"),
    "N-": ("AH", "NG"),
    # --- consonants ---------------------------------------------------------------------
    "p": ("P",),
    "b": ("B",),
    "t": ("T",),
    "t#": ("T",),  # flap, "water"
    "t2": ("T",),  # unreleased t, "airtight"
    "?": ("T",),  # glottal stop for t, "button"
    "d": ("D",),
    "d#": ("D",),  # flap from d
    "t[": ("TH",),  # dental t for "th" (en-029, Caribbean)
    "d[": ("DH",),  # dental d for "th"
    "k": ("K",),
    "g": ("G",),
    "x": ("K",),  # velar fricative, "Bach", "loch"
    "f": ("F",),
    "v": ("V",),
    "T": ("TH",),
    "D": ("DH",),
    "s": ("S",),
    "z": ("Z",),
    "z#": ("Z",),  # z variant
    "z/2": ("Z",),  # z variant, "-s" endings
    "S": ("SH",),
    "Z": ("ZH",),
    "h": ("HH",),
    "tS": ("CH",),
    "dZ": ("JH",),
    "m": ("M",),
    "n": ("N",),
    "N": ("NG",),
    "l": ("L",),
    "l#": ("L",),  # l variant, "llano"
    "l/": ("L",),  # l variant
    "l/2": ("L",),  # dark l, en-us-nyc
    "r": ("R",),
    "r/": ("R",),  # en-us r
    "r-": ("R",),  # linking r after an r-coloured vowel
    "w": ("W",),
    "w#": ("W",),  # "wh"
    "j": ("Y",),
    ";": (),  # palatal glide between i and a vowel: lengthens the previous segment
}

#: Mnemonics of r-coloured vowels whose ``R`` is dropped before one of :data:`R_MNEMONICS`.
R_COLOURED = frozenset(m for m, p in ESPEAK_TO_ARPABET.items() if len(p) == 2 and p[1] == "R")
R_MNEMONICS = frozenset({"r", "r/", "r-"})
#: Mnemonics that lengthen the previous segment: always (``;``), or after an ``ER`` (the
#: r's), as CMUdict writes ER for eSpeak's ``3 r`` ("aberration" AE B ER EY SH AH N).
#: Their mapping when nothing can be lengthened:
ABSORBED: dict[str, tuple[str, ...]] = {";": ("Y",), "r": ("R",), "r/": ("R",), "r-": ("R",)}

#: Last resort for unknown mnemonics: their first character, read as Kirshenbaum ASCII-IPA.
_FALLBACK_CHAR: dict[str, str] = {
    "@": "AH", "3": "ER", "V": "AH", "a": "AE", "A": "AA", "0": "AA", "O": "AO", "o": "OW",
    "E": "EH", "e": "EY", "I": "IH", "i": "IY", "y": "IY", "Y": "UH", "U": "UH", "u": "UW",
    "W": "UW", "p": "P", "b": "B", "t": "T", "d": "D", "k": "K", "g": "G", "q": "K",
    "G": "G", "c": "K", "J": "JH", "f": "F", "v": "V", "B": "V", "T": "TH", "D": "DH",
    "s": "S", "z": "Z", "S": "SH", "Z": "ZH", "C": "HH", "x": "K", "X": "HH", "h": "HH",
    "H": "HH", "Q": "G", "m": "M", "n": "N", "N": "NG", "l": "L", "L": "L", "r": "R",
    "R": "R", "w": "W", "j": "Y", "?": "T",
}


def _check_table() -> None:
    for mnemonic, phones in ESPEAK_TO_ARPABET.items():
        if not set(phones) <= PHONE_SET or SILENCE in phones or len(phones) > 2:
            raise AssertionError(f"bad mapping {mnemonic!r} -> {phones}")


_check_table()


def fallback(mnemonic: str) -> tuple[str, ...]:
    """Best-effort ARPAbet for a mnemonic missing from :data:`ESPEAK_TO_ARPABET`.

    Tries ever shorter prefixes (``"aI2#"`` -> ``"aI2"`` -> ``"aI"``), then the first
    character alone, then ``AH``.
    """
    for k in range(len(mnemonic) - 1, 0, -1):
        phones = ESPEAK_TO_ARPABET.get(mnemonic[:k])
        if phones:
            return phones
    return (_FALLBACK_CHAR.get(mnemonic[:1], "AH"),)


def map_mnemonic(mnemonic: str) -> tuple[tuple[str, ...], int, bool]:
    """Convert one eSpeak phoneme mnemonic (as reported by its phoneme events) to ARPAbet.

    Context rules (:mod:`ingest.speech.espeak`) are not applied here.

    Parameters
    ----------
    mnemonic : str
        eSpeak mnemonic with its optional stress mark, e.g. ``"'aU"``, ``",oU"``, ``"_:"``.

    Returns
    -------
    phones : tuple of str
        One or two ARPAbet phones (``("SIL",)`` for a pause, ``()`` for a mnemonic that only
        lengthens its predecessor).
    stress : int
        0 none, 1 primary, 2 secondary.
    known : bool
        False if the mnemonic is not in :data:`ESPEAK_TO_ARPABET` and was mapped by the
        fallback.
    """
    body = mnemonic.lstrip("',%=")
    marks = mnemonic[: len(mnemonic) - len(body)]
    stress = 1 if "'" in marks else 2 if "," in marks else 0
    if body.startswith("_") or body == "":
        return (SILENCE,), 0, True
    phones = ESPEAK_TO_ARPABET.get(body)
    if phones is None:
        return fallback(body), stress, False
    return phones, stress, True
