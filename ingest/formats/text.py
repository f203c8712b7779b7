"""Reading a text file the one way every reader does: UTF-8, a byte-order mark dropped;
side files (labels, transcripts, marker maps) up to :data:`MAX_SIDE_FILE_BYTES`."""

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


def read_bytes(path, what: str, limit: int | None = None) -> bytes:
    """The bytes of ``path``; DataError naming ``what`` and the file if it is absent,
    unreadable or larger than ``limit`` bytes (checked before reading more), or not a file
    (a FIFO or a device would block the read, or never end it)."""
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{what} {path} is not a file" if path.exists() else
                        f"{what} not found: {path}")
    try:
        with path.open("rb") as handle:
            data = handle.read(-1 if limit is None else limit + 1)
    except OSError as exc:
        raise DataError(f"cannot read {what} {path}: {exc.strerror or exc}") from None
    if limit is not None and len(data) > limit:
        raise DataError(f"{what} {path} is larger than {limit:,} bytes")
    return data


def read_utf8(path, what: str, *, limit: int | None = None) -> str:
    """The text of ``path``; DataError naming ``what`` and the file if it is absent,
    unreadable, larger than ``limit`` bytes (:func:`read_bytes`) or not UTF-8
    (``utf-8-sig``: a leading BOM, as spreadsheets write, is dropped)."""
    data = read_bytes(path, what, limit)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise DataError(f"{what} is not UTF-8 text: {path}") from None


def read_csv_rows(path, what: str) -> list[tuple[int, list[str]]]:
    """The non-blank rows of a CSV file as ``(line number, cells)``; DataError naming the
    file (and line) if it is unreadable (:func:`read_utf8`) or malformed."""
    reader = csv.reader(io.StringIO(read_utf8(path, what)))
    try:
        return [(reader.line_num, row) for row in reader if any(c.strip() for c in row)]
    except csv.Error as exc:
        raise DataError(f"{path}:{reader.line_num}: malformed CSV: {exc}") from None
