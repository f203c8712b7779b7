"""Reading a text file the one way every reader does: UTF-8, a byte-order mark dropped;
side files (labels, transcripts, marker maps) up to :data:`MAX_SIDE_FILE_BYTES`, motion
tables (marker CSV, TRC, curves and Live Link Face CSV) up to
:data:`MAX_MOTION_TABLE_BYTES`: every read has a bound."""

from __future__ import annotations

import csv
import io
from pathlib import Path

from db.errors import DataError

#: Largest side file read (phone labels, word alignments, transcripts, marker maps):
#: Praat's long TextGrid format takes ~90 bytes an interval, so this holds hours of
#: phones and words. Parsed, a value costs ~80 bytes however short it is written (a
#: TextGrid of 17.5 MB of two-byte values took 1.4 GB): a larger file is a memory bomb,
#: not a clip's labels.
MAX_SIDE_FILE_BYTES = 16 << 20
#: Largest motion table read (marker CSV, TRC, curves CSV, Live Link Face CSV; the
#: ``frame,time,...`` CSV that synth, render and plot read). Live Link Face writes ~50 KB
#: a second (85 minutes fit), a landmark database's 1,434 channels as CSV ~400 KB a second
#: at 30 fps (11 minutes). Parsed, the text costs up to ~12 times its size (a 64 MB Live
#: Link CSV of one-digit cells peaked at 741 MB, as a channel CSV at 334 MB): a larger
#: file is a memory bomb, not a take.
MAX_MOTION_TABLE_BYTES = 256 << 20


def read_bytes(path, what: str, limit: int) -> bytes:
    """The bytes of ``path``; DataError naming ``what`` and the file if it is absent,
    unreadable or larger than ``limit`` bytes (checked before reading more), or not a file
    (a FIFO or a device would block the read, or never end it)."""
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{what} {path} is not a file" if path.exists() else
                        f"{what} not found: {path}")
    try:
        if path.stat().st_size > limit:  # said without reading it (and the read is bounded)
            raise DataError(f"{what} {path} is larger than {limit:,} bytes")
        with path.open("rb") as handle:
            data = handle.read(limit + 1)
    except OSError as exc:
        raise DataError(f"cannot read {what} {path}: {exc.strerror or exc}") from None
    if len(data) > limit:
        raise DataError(f"{what} {path} is larger than {limit:,} bytes")
    return data


def read_utf8(path, what: str, *, limit: int) -> str:
    """The text of ``path``; DataError naming ``what`` and the file if it is absent,
    unreadable, larger than ``limit`` bytes (:func:`read_bytes`) or not UTF-8
    (``utf-8-sig``: a leading BOM, as spreadsheets write, is dropped)."""
    data = read_bytes(path, what, limit)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise DataError(f"{what} is not UTF-8 text: {path}") from None


def read_csv_rows(path, what: str, *, limit: int = MAX_MOTION_TABLE_BYTES
                  ) -> list[tuple[int, list[str]]]:
    """The non-blank rows of a CSV file (a motion table, unless ``limit`` says otherwise)
    as ``(line number, cells)``; DataError naming the file (and line) if it is unreadable
    or too large (:func:`read_utf8`) or malformed."""
    reader = csv.reader(io.StringIO(read_utf8(path, what, limit=limit)))
    try:
        return [(reader.line_num, row) for row in reader if any(c.strip() for c in row)]
    except csv.Error as exc:
        raise DataError(f"{path}:{reader.line_num}: malformed CSV: {exc}") from None


def read_csv_records(path, what: str, columns: tuple[str, ...], *,
                     limit: int = MAX_SIDE_FILE_BYTES
                     ) -> tuple[list[str], list[tuple[str, dict[str, str]]]]:
    """A side file's CSV of named columns (a marker table, a marker map): its header and
    its rows, as the readers of such files need them.

    Column names are matched stripped and in any case; every row is given as
    ``(where, cells)``, ``where`` the ``path:line`` its messages start with and ``cells``
    each column's stripped text (``""`` where a row is short).

    Returns
    -------
    (names, rows)
        The header's names (stripped, lower case), and the rows.

    Raises
    ------
    DataError
        If the file is unreadable, too large or not UTF-8 (:func:`read_utf8`), malformed,
        or lacks one of ``columns`` (named as ``what`` needs them).
    """
    reader = csv.DictReader(io.StringIO(read_utf8(path, what, limit=limit)))
    try:
        names = [f.strip().lower() for f in reader.fieldnames or []]
        if any(c not in names for c in columns):
            need = " and ".join(repr(c) for c in columns)
            raise DataError(f"{path}:1: {what} needs {need} columns, got {names}")
        reader.fieldnames = names
        rows = [(f"{path}:{reader.line_num}",
                 {name: (row.get(name) or "").strip() for name in names}) for row in reader]
    except csv.Error as exc:  # DictReader's own line_num is the last row it returned
        raise DataError(f"{path}:{reader.reader.line_num}: malformed CSV: {exc}") from None
    return names, rows
