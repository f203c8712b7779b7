"""The phone set: CMU's 39 ARPAbet phones plus ``SIL``, and their visual classes.

All phone labels in the project are upper-case ARPAbet without stress digits
(``AA``, ``CH``, ``SIL`` ...). Other labellings (eSpeak mnemonics, SAMPA, IPA) are
converted to this set at the boundary where they are read.
"""

from __future__ import annotations

#: CMU dictionary phones (39), in CMUdict's own order, plus silence.
VOWELS: tuple[str, ...] = (
    "AA", "AE", "AH", "AO", "AW", "AY", "EH", "ER", "EY", "IH", "IY", "OW", "OY", "UH", "UW",
)
CONSONANTS: tuple[str, ...] = (
    "B", "CH", "D", "DH", "F", "G", "HH", "JH", "K", "L", "M", "N", "NG", "P", "R", "S", "SH",
    "T", "TH", "V", "W", "Y", "Z", "ZH",
)
SILENCE = "SIL"
PHONES: tuple[str, ...] = VOWELS + CONSONANTS + (SILENCE,)
PHONE_SET: frozenset[str] = frozenset(PHONES)

#: Visual phone classes (visemes). Phones in one class look alike on the lips; the search
#: backs off to a class-mate when a phone is missing from the database.
VISEME_CLASSES: dict[str, tuple[str, ...]] = {
    "bilabial": ("P", "B", "M"),
    "labiodental": ("F", "V"),
    "dental": ("TH", "DH"),
    "alveolar": ("T", "D", "N", "L", "S", "Z"),
    "postalveolar": ("SH", "ZH", "CH", "JH"),
    "velar": ("K", "G", "NG", "HH"),
    "rounded": ("W", "UW", "UH", "OW", "OY", "R", "ER"),
    "open": ("AA", "AO", "AW", "AY", "AH"),
    "front": ("AE", "EH", "EY", "IH", "IY", "Y"),
    "silence": (SILENCE,),
}
VISEME_OF: dict[str, str] = {p: v for v, ps in VISEME_CLASSES.items() for p in ps}


def is_phone(label: str) -> bool:
    """Return True if ``label`` is one of the 40 phones of :data:`PHONES`."""
    return label in PHONE_SET
