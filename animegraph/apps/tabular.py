"""Printing query results: a readable table, or CSV, JSON, JSON Lines, Parquet."""

from __future__ import annotations

import io
import math
from pathlib import Path

import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

from db.atomic import atomic_write


def visible(text: str) -> str:
    """``text`` for a terminal: each control or format character (ESC, newline, BEL, a
    right-to-left override ...) written as its Python escape, ``\\x1b``.

    What is printed comes from a database or a query, both untrusted: an escape sequence
    in a speaker's name or a manifest would drive the user's terminal (retitle it, set its
    clipboard, hide lines), a newline would forge a line.
    """
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def _shorten(value) -> str:
    if isinstance(value, list):
        head = ", ".join(f"{v:.3g}" if isinstance(v, float) else str(v) for v in value[:3])
        return f"[{head}{', ...' if len(value) > 3 else ''}] ({len(value)})"
    if isinstance(value, bytes):
        return f"<{len(value)} bytes>"
    if isinstance(value, float):
        return f"{value:.6g}"
    return "NULL" if value is None else str(value)


#: The format an output file's name asks for (``sql -o hits.csv``).
FORMAT_BY_SUFFIX = {".csv": "csv", ".json": "json", ".jsonl": "jsonl", ".parquet": "parquet"}


def format_for(fmt: str | None, output: Path | None) -> str:
    """The format to write: ``fmt`` if given, else the one ``output``'s suffix names, else
    the readable table."""
    if fmt is not None:
        return fmt
    return FORMAT_BY_SUFFIX.get(output.suffix.lower(), "table") if output else "table"


def format_table(table: pa.Table, fmt: str, *, max_rows: int = 50,
                 output: Path | None = None, truncated: bool = False) -> str | None:
    """Render ``table`` as ``fmt``: table, csv, json (one array of row objects: a JSON
    document, which ``json.load`` and ``pandas.read_json`` open), jsonl (JSON Lines, an
    object a line) or parquet.

    ``truncated``: ``table`` is the first rows of a longer result (a row cap stopped the
    rest), so the table's last line does not call its rows all.

    Returns the text, or None when it was written to ``output``.
    """
    if fmt == "parquet":
        with atomic_write(output) as handle:
            pq.write_table(table, handle)
        return None
    if fmt == "csv":
        buffer = io.BytesIO()
        # By position: a join may repeat a column name (SELECT a.x, b.x ...).
        flat = pa.Table.from_arrays([_csv_safe(table.column(i))
                                     for i in range(table.num_columns)],
                                    names=table.column_names)
        pacsv.write_csv(flat, buffer)
        text = buffer.getvalue().decode()
    elif fmt in ("json", "jsonl"):
        import json

        rows = [json.dumps(_strict(row), default=_json, allow_nan=False)
                for row in table.to_pylist()]
        text = ("".join(f"{row}\n" for row in rows) if fmt == "jsonl"
                else "[" + ",\n ".join(rows) + "]\n")
    else:
        text = _pretty(table, max_rows, truncated)
    if output is not None:
        with atomic_write(output) as handle:
            handle.write(text.encode())
        return None
    return text


def _csv_safe(column: pa.ChunkedArray) -> pa.ChunkedArray:
    # CSV has no lists: write them as space-separated numbers.
    if pa.types.is_list(column.type) or pa.types.is_large_list(column.type):
        return pa.chunked_array([pa.array(
            [None if v is None else " ".join(str(x) for x in v) for v in column.to_pylist()],
            pa.string())])
    if pa.types.is_binary(column.type):
        return pa.chunked_array([pa.array([None if v is None else v.hex()
                                           for v in column.to_pylist()], pa.string())])
    return column


def _strict(value):
    """JSON has no NaN or infinity (Python writes them, strict readers refuse the file):
    null, as SQL's missing value."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, list):
        return [_strict(v) for v in value]
    if isinstance(value, dict):
        return {k: _strict(v) for k, v in value.items()}
    return value


def _json(value):
    if isinstance(value, bytes):
        return value.hex()
    return str(value)


def _pretty(table: pa.Table, max_rows: int, truncated: bool = False) -> str:
    names = table.column_names
    shown = table.slice(0, max_rows)
    columns = [shown.column(i).to_pylist() for i in range(shown.num_columns)]
    names = [visible(name) for name in names]
    cells = [[visible(_shorten(c[r])) for c in columns] for r in range(shown.num_rows)]
    widths = [max([len(n)] + [len(c[i]) for c in cells]) for i, n in enumerate(names)]
    widths = [min(w, 60) for w in widths]

    def cut(value: str, width: int) -> str:
        return value if len(value) <= width else value[:width - 1] + "…"

    def line(values):
        return "  ".join(cut(v, w).ljust(w) for v, w in zip(values, widths, strict=True)
                         ).rstrip()

    out = [line(names), line(["-" * w for w in widths])]
    out += [line(c) for c in cells]
    n = table.num_rows
    rows = f"{n} row{'s' * (n != 1)}"
    whole = f"{rows} read; --limit stopped the rest" if truncated else None
    if n > max_rows:
        more = n - max_rows
        out.append(f"... {more} more row{'s' * (more != 1)} ({whole or f'{n} in all'})")
    else:
        out.append(f"({whole or rows})")
    return "\n".join(out) + "\n"
