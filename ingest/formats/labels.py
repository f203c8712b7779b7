"""Phone labels from other tools mapped to the project's ARPAbet set, in one place.

Every label reader (:mod:`ingest.formats.textgrid`, :mod:`ingest.formats.htk_lab`)
passes each label through :func:`to_arpabet`:

- surrounding white space is removed;
- silence and non-speech markers (empty, ``sp``, ``sil``, ``<sil>``, ``spn``, ``pau``,
  ``h#`` ... see :data:`SILENCE_LABELS`, any case) become ``"SIL"``;
- otherwise stress digits are stripped and the label is upper-cased (``ah0`` -> ``AH``);
- a few ARPAbet variants outside CMU's 39 phones are folded onto them
  (:data:`ALIASES`, e.g. TIMIT's ``ax`` -> ``AH``);
- anything else is an error (the readers name the file, line and label).
"""

from __future__ import annotations

from db.errors import DataError, ParameterError
from ingest.speech.phones import PHONE_SET, SILENCE

#: Labels (compared in lower case, white space stripped) that mean silence or non-speech:
#: Montreal Forced Aligner / Kaldi (``sil``, ``sp``, ``spn``), HTK/HTS (``sil``, ``pau``),
#: TIMIT (``h#``, ``pau``, ``epi``), CMU Sphinx (``<sil>``, ``<s>``, ``</s>``), Praat's
#: empty interval, and a few more.
SILENCE_LABELS: frozenset[str] = frozenset({
    "", "sil", "sp", "spn", "<sil>", "<sp>", "<spn>", "sl", "pau", "h#", "#", "epi",
    "<s>", "</s>", "<p:>", "<eps>", "silence", "_", "nsn", "<noise>", "noise",
})

#: ARPAbet variants (TIMIT, Festival) outside CMU's 39 phones -> the nearest CMU phone.
ALIASES: dict[str, str] = {
    "AX": "AH", "AX-H": "AH", "AXH": "AH", "AXR": "ER", "IX": "IH", "UX": "UW",
    "EL": "L", "EM": "M", "EN": "N", "ENG": "NG", "NX": "N", "HV": "HH",
    "DX": "D",  # the alveolar flap of "butter": alveolar, as D and T look alike
}


def to_arpabet(label: str) -> str:
    """Map one phone label to a phone of :data:`ingest.speech.phones.PHONE_SET`.

    Parameters
    ----------
    label : str
        A phone label as an aligner or annotator wrote it (``"AH0"``, ``"sp"``, ``""``).

    Returns
    -------
    str
        Upper-case ARPAbet without stress digit, or ``"SIL"``.

    Raises
    ------
    ParameterError
        If ``label`` is not a str.
    DataError
        If the label is neither a silence marker, an ARPAbet phone nor a known variant.
    """
    if not isinstance(label, str):
        raise ParameterError(f"label: expected str, got {label!r}")
    text = label.strip()
    if text.lower() in SILENCE_LABELS:
        return SILENCE
    base = text.rstrip("0123456789").upper()
    if base in PHONE_SET:
        return base
    if base in ALIASES:
        return ALIASES[base]
    # An aligner's other phone sets (MFA's english_mfa model writes IPA, WebMAUS SAMPA)
    # are common: say what is read.
    raise DataError(f"unknown phone label {label!r} (phone labels are ARPAbet: CMU's 39 "
                    "phones, stress digits allowed; not IPA or SAMPA)")


def format_seconds(value: float) -> str:
    """Shortest text that reads back as the same float (``0`` rather than ``0.0``)."""
    text = repr(float(value))
    return text[:-2] if text.endswith(".0") else text


def decode_text(data: bytes, path: object, what: str) -> str:
    """Decode a label file: UTF-8 (with or without BOM) or UTF-16 (BOM or NUL pattern).

    Raises
    ------
    DataError
        If the bytes are neither, naming ``path``.
    """
    try:
        if data.startswith((b"\xff\xfe", b"\xfe\xff")):
            return data.decode("utf-16")
        if len(data) >= 2 and data[0] == 0 and data[1] != 0:
            return data.decode("utf-16-be")
        if len(data) >= 2 and data[1] == 0 and data[0] != 0:
            return data.decode("utf-16-le")
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise DataError(f"{what} is neither UTF-8 nor UTF-16 text: {path}") from exc
