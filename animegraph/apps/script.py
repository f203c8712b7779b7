"""Dialogue scripts for ``animegraph batch``: CSV or JSON Lines, one row per line of dialogue.

Columns (CSV header or JSON keys; case-insensitive):

========== ======== ===================================================================
column     required meaning
========== ======== ===================================================================
``id``     yes      the line's name: letters, digits, ``.``, ``_``, ``-`` (its output
                    folder is ``OUT/<id>/``); unique, ignoring case
``text``   yes      what is said: spoken by eSpeak NG when there is no ``audio``, the
                    transcript for forced alignment when there is; at most 10,000
                    characters (a transcript's bound)
``audio``           a recording (WAV, or a video's or ``.m4a``'s sound track, as ``synth``
                    reads it), relative to the script's folder and inside it (a line's
                    ``speech.wav`` is its recording: a script from others must not
                    copy files from elsewhere into the output)
``emotion``         a name as the database spells it (``happy``), ``auto`` (detected
                    from the line's recording: a line with ``audio``), or a mix
                    ``happy=0.7,neutral=0.3``; empty: no emotion preference
``speaker``         who says it (kept in the report)
``voice``           eSpeak NG voice for lines without audio, e.g. ``en-us+f3``
``window``          the paper's bounded look-ahead of K phonemes (one anime a phoneme)
``exact``           ``true``: the paper's exact search, one anime a phoneme; not with
                    ``window``. Default (neither): k-best blending around the exact
                    search's sequence (:mod:`animegraph.synthesis.path`)
========== ======== ===================================================================

A script is at most :data:`ingest.formats.text.MAX_SIDE_FILE_BYTES` (16 MB). The whole
script is checked before any work: a malformed row (with its line number), a
duplicate id or an unknown column raises :class:`ScriptError`. Problems that depend on
the database or on files (an emotion the database lacks, a missing recording, text eSpeak
cannot speak) are left to the line itself (``animegraph.apps.batch`` fails a line with a
missing recording, a voice eSpeak NG lacks or an emotion the database cannot give before
any worker starts).
"""

from __future__ import annotations

import csv
import json
import re
from dataclasses import dataclass
from pathlib import Path

from db.errors import AnimeGraphError, DataError, ParameterError
from ingest.formats.text import MAX_SIDE_FILE_BYTES, read_bytes
from ingest.plausible import MAX_TEXT_CHARS

#: Every column a script may have.
COLUMNS = ("id", "text", "audio", "emotion", "speaker", "voice", "window", "exact")
REQUIRED = ("id", "text")
#: Names in the output folder that are not line folders.
RESERVED_IDS = frozenset({"report.csv"})

_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,99}$")
_TRUE = frozenset({"true", "yes", "1", "y"})
_FALSE = frozenset({"false", "no", "0", "n"})


class ScriptError(AnimeGraphError):
    """The script itself is wrong: the batch does not start."""


@dataclass(frozen=True)
class EmotionSpec:
    """A line's emotion as written, parsed.

    Attributes
    ----------
    source : str
        ``default`` (none given), ``given`` (one name), ``auto`` or ``mix``.
    weights : tuple of (str, float)
        The emotions and their weights (summing to 1); one entry for ``given``, none for
        ``default`` and ``auto``.
    """

    source: str
    weights: tuple[tuple[str, float], ...] = ()

    @property
    def text(self) -> str:
        """Canonical spelling: ``""``, ``happy``, ``auto`` or ``happy=0.7,neutral=0.3``."""
        if self.source == "default":
            return ""
        if self.source == "auto":
            return "auto"
        if self.source == "given":
            return self.weights[0][0]
        return ",".join(f"{name}={weight:.4g}" for name, weight in self.weights)

    @property
    def argument(self) -> str | None:
        """What ``synthesize(emotion=...)`` receives: ``None``, a name, ``"auto"`` or the
        mix spelled as on the command line (``"happy=0.7,neutral=0.3"``)."""
        return self.text or None


def parse_emotion(value: str | None) -> EmotionSpec:
    """Parse an emotion cell; raise ``ValueError`` with the reason when it is malformed.

    The syntax is synthesis' (:func:`animegraph.emotion.control.parse_emotion`): a name
    (kept in its spelling: it must match the database's labels), ``auto`` in any case, or
    a mix ``happy=0.7,neutral=0.3`` (weights normalised; a one-emotion mix is a name).
    """
    from animegraph.emotion.control import AUTO
    from animegraph.emotion.control import parse_emotion as parse

    text = (value or "").strip()
    if not text:
        return EmotionSpec("default")
    try:
        parsed = parse(text)
    except ParameterError as exc:
        what = "emotion mix" if "=" in text or "," in text else "emotion"
        raise ValueError(f"{what} {value!r}: {exc}") from None
    if parsed == AUTO:
        return EmotionSpec("auto")
    if isinstance(parsed, str):
        return EmotionSpec("given", ((parsed, 1.0),))
    return EmotionSpec("mix", tuple(parsed.items()))


@dataclass(frozen=True)
class ScriptLine:
    """One line of dialogue."""

    id: str
    text: str
    line_no: int  # where it is in the script file (1-based)
    audio: Path | None = None  # absolute
    emotion: EmotionSpec = EmotionSpec("default")
    speaker: str = ""
    voice: str | None = None
    window: int | None = None
    exact: bool = False  # the paper's synthesis asked for (column ``exact``)

    @property
    def method(self) -> str:
        """Search method: ``window`` with a look-ahead, else ``exact``."""
        return "window" if self.window is not None else "exact"

    def synthesis_path(self) -> tuple[int | None, str]:
        """(k-best K or None for the paper's synthesis, why): the phones of a line are
        known (its text, aligned or spoken by eSpeak NG), so ``synth``'s choice for a
        transcript applies (:func:`animegraph.synthesis.path.known_phones_path`)."""
        from animegraph.synthesis.path import known_phones_path

        given = "transcript given" if self.audio is not None else "eSpeak NG phones"
        return known_phones_path(given, searched=self.searched)

    @property
    def searched(self) -> bool:
        """The paper's search asked for (``exact`` or ``window``): one anime a phone."""
        return self.exact or self.window is not None


def read_script(path: str | Path) -> list[ScriptLine]:
    """Read and check a dialogue script (``.csv``, or ``.jsonl``/``.ndjson``/``.json`` for
    JSON Lines).

    Raises
    ------
    ScriptError
        The file is unreadable, or a row is malformed (the message names its line),
        an id repeats, a column is unknown, or there are no rows.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".csv", ".jsonl", ".ndjson", ".json"):
        raise ScriptError(f"script {path}: expected a .csv or .jsonl file")
    if not path.exists():
        raise ScriptError(f"script {path} does not exist")
    try:  # bounded: parsed, a short line costs ~50 times its bytes
        raw = read_bytes(path, "script", MAX_SIDE_FILE_BYTES).decode("utf-8-sig")
    except DataError as exc:  # not a file, unreadable, too large
        raise ScriptError(str(exc)) from None
    except UnicodeDecodeError as exc:
        raise ScriptError(f"script {path} is not UTF-8 text ({exc.reason} at byte "
                          f"{exc.start})") from None
    rows = _csv_rows(path, raw) if suffix == ".csv" else _jsonl_rows(path, raw)
    lines: list[ScriptLine] = []
    seen: dict[str, int] = {}
    for line_no, row in rows:
        line = _line(path, line_no, row)
        key = line.id.casefold()
        if key in seen:
            raise ScriptError(f"{path.name} line {line_no}: duplicate id {line.id!r} (first on "
                              f"line {seen[key]})")
        seen[key] = line_no
        lines.append(line)
    if not lines:
        raise ScriptError(f"script {path} has no lines of dialogue")
    return lines


def _check_columns(path: Path, line_no: int, names: list[str]) -> None:
    unknown = [n for n in names if n not in COLUMNS]
    if unknown:
        raise ScriptError(f"{path.name} line {line_no}: unknown column {unknown[0]!r} "
                          f"(columns: {', '.join(COLUMNS)})")
    dup = [n for i, n in enumerate(names) if n in names[:i]]
    if dup:
        raise ScriptError(f"{path.name} line {line_no}: column {dup[0]!r} appears twice")


def _csv_rows(path: Path, raw: str) -> list[tuple[int, dict]]:
    reader = csv.reader(raw.splitlines(keepends=True))
    header: list[str] | None = None
    header_line = 0
    rows = []
    try:
        for record in reader:
            line_no = reader.line_num
            if not any(cell.strip() for cell in record):
                continue
            if header is None:
                header = [cell.strip().lower() for cell in record]
                header_line = line_no
                _check_columns(path, line_no, header)
                missing = [c for c in REQUIRED if c not in header]
                if missing:
                    raise ScriptError(f"{path.name} line {line_no}: the header has no "
                                      f"{missing[0]!r} column (it needs id and text)")
                continue
            if len(record) != len(header):
                raise ScriptError(f"{path.name} line {line_no}: {len(record)} fields, the "
                                  f"header (line {header_line}) has {len(header)}")
            rows.append((line_no, dict(zip(header, record, strict=True))))
    except csv.Error as exc:
        raise ScriptError(f"{path.name} line {reader.line_num}: {exc}") from None
    if header is None:
        raise ScriptError(f"script {path} is empty (expected a header: id,text,...)")
    return rows


def _jsonl_rows(path: Path, raw: str) -> list[tuple[int, dict]]:
    rows = []
    for line_no, text in enumerate(raw.splitlines(), start=1):
        if not text.strip():
            continue
        try:
            row = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ScriptError(f"{path.name} line {line_no}: not JSON ({exc.msg} at column "
                              f"{exc.colno})") from None
        except RecursionError:  # the decoder recurses once per level of nesting
            raise ScriptError(f"{path.name} line {line_no}: JSON nested too deeply") from None
        if not isinstance(row, dict):
            raise ScriptError(f"{path.name} line {line_no}: expected a JSON object, got "
                              f"{type(row).__name__}")
        row = {str(k).strip().lower(): v for k, v in row.items()}
        _check_columns(path, line_no, list(row))
        missing = [c for c in REQUIRED if c not in row]
        if missing:
            raise ScriptError(f"{path.name} line {line_no}: no {missing[0]!r}")
        rows.append((line_no, row))
    return rows


def _line(path: Path, line_no: int, row: dict) -> ScriptLine:
    where = f"{path.name} line {line_no}"

    def text_of(name: str, *, numbers: bool = False) -> str:
        value = row.get(name)
        if value is None:
            return ""
        if numbers and isinstance(value, int) and not isinstance(value, bool):
            return str(value)
        if not isinstance(value, str):
            raise ScriptError(f"{where}: {name} must be text, got {json.dumps(value)}")
        if "\x00" in value:
            raise ScriptError(f"{where}: {name} contains a NUL character")
        return value.strip()

    ident = text_of("id", numbers=True)
    if not ident:
        raise ScriptError(f"{where}: empty id")
    if not _ID.match(ident) or ident.lower() in RESERVED_IDS:
        raise ScriptError(f"{where}: id {ident!r} must be 1-100 letters, digits, '.', '_' or "
                          "'-', starting with a letter or digit (it names the output folder)")
    text = text_of("text")
    if not text:
        raise ScriptError(f"{where}: empty text (line {ident!r})")
    if len(text) > MAX_TEXT_CHARS:  # eSpeak NG would speak it for hours
        raise ScriptError(f"{where}: text of {len(text):,} characters (at most "
                          f"{MAX_TEXT_CHARS:,}: a transcript's bound)")
    audio = text_of("audio")
    try:
        emotion = parse_emotion(text_of("emotion"))
    except ValueError as exc:
        raise ScriptError(f"{where}: {exc}") from None
    voice = text_of("voice") or None
    window = _window(row.get("window"), where)
    exact = _flag(row.get("exact"), where)
    if window is not None and exact:
        raise ScriptError(f"{where}: window and exact=true exclude each other")
    if audio and not (path.parent / audio).resolve().is_relative_to(path.parent.resolve()):
        raise ScriptError(f"{where}: audio {audio!r} is outside the script's folder "
                          "(recordings are read from it and its subfolders)")
    return ScriptLine(
        id=ident, text=text, line_no=line_no,
        audio=(path.parent / audio).absolute() if audio else None,
        emotion=emotion, speaker=text_of("speaker"), voice=voice, window=window,
        exact=exact,
    )


def _window(value, where: str) -> int | None:
    if value is None or (isinstance(value, str) and not value.strip()):
        return None
    if isinstance(value, bool):
        raise ScriptError(f"{where}: window must be a whole number of phonemes, got {value}")
    try:
        k = int(value.strip()) if isinstance(value, str) else value
    except ValueError:
        k = None
    if not isinstance(k, int) or k < 1:
        raise ScriptError(f"{where}: window must be a whole number of phonemes >= 1, got "
                          f"{value!r}")
    return k


def _flag(value, where: str) -> bool:
    if value is None or isinstance(value, bool):
        return bool(value)
    text = str(value).strip().lower()
    if text in _TRUE:
        return True
    if text in _FALSE or not text:
        return False
    raise ScriptError(f"{where}: exact must be true or false, got {value!r}")
