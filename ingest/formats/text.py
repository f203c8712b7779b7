"""Reading a text file the one way every reader does: UTF-8, a byte-order mark dropped."""

from __future__ import annotations

import csv
import io
from pathlib import Path

from db.errors import DataError


def read_utf8(path, what: str) -> str:
    """The text of ``path``; DataError naming ``what`` and the file if it is absent,
    unreadable or not UTF-8 (``utf-8-sig``: a leading BOM, as spreadsheets write, is
    dropped)."""
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{what} not found: {path}")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise DataError(f"cannot read {what} {path}: {exc.strerror or exc}") from None
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
