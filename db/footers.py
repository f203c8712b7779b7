"""Bounds of what a Parquet file takes once read, from its footer alone
(:meth:`db.store.Database.check_rows` refuses a small crafted file that would decode into
gigabytes before a reader decodes it)."""

from __future__ import annotations

from pathlib import Path

import pyarrow.compute as pc
import pyarrow.parquet as pq

#: Most rows one batch of :func:`decoded_bytes`'s count decodes (a row group's most).
MAX_BATCH_ROWS = 64 * 1024

#: Bytes a value of a Parquet physical type takes once read (BYTE_ARRAY: its offset).
_WIDTH = {"BOOLEAN": 1, "INT32": 4, "INT64": 8, "INT96": 12, "FLOAT": 4, "DOUBLE": 8,
          "BYTE_ARRAY": 4}
_DICTIONARY = {"PLAIN_DICTIONARY", "RLE_DICTIONARY"}
#: Most bytes of strings :func:`decoded_bytes` decodes at once to count them.
_COUNT_BYTES = 16 << 20


def decoded_bytes(path: Path, meta: pq.FileMetaData, row_bytes: int, limit: int) -> int:
    """Bytes the Parquet file at ``path`` takes once read, at most: every column chunk's
    pages uncompressed plus its values decoded, and ``row_bytes`` more a row.

    A value takes its type's width; a string also its bytes, which are in its pages
    unless the pages share them: a dictionary-encoded string (or one delta-encoded
    against the one before) can be as long as its chunk's pages, in every row. When that
    bound passes ``limit``, the dictionary-encoded (top-level) columns are decoded a few
    rows at a time (at most :data:`_COUNT_BYTES` at once) to count their bytes, until the
    count passes ``limit``.

    Parameters
    ----------
    path : Path
    meta : pyarrow.parquet.FileMetaData
        Its footer.
    row_bytes : int
        Bytes a row takes beyond its columns (its partition values).
    limit : int
        Bytes beyond which the exact count may stop.
    """
    total = meta.num_rows * row_bytes
    shared: dict[str, int] = {}  # column -> bound of its strings whose pages share them
    longest: dict[str, int] = {}  # ... and the most bytes one of them can take
    uncountable = set()  # those delta-encoded or nested: not counted without decoding
    for g in range(meta.num_row_groups):
        group = meta.row_group(g)
        for c in range(meta.num_columns):
            chunk = group.column(c)
            kind, values = chunk.physical_type, chunk.num_values
            width = (meta.schema.column(c).length if kind == "FIXED_LEN_BYTE_ARRAY"
                     else _WIDTH.get(kind, 16))
            total += chunk.total_uncompressed_size + values * width
            encodings = set(chunk.encodings)
            if kind == "BYTE_ARRAY" and encodings & (_DICTIONARY | {"DELTA_BYTE_ARRAY"}):
                column, most = chunk.path_in_schema, chunk.total_uncompressed_size
                shared[column] = shared.get(column, 0) + values * most
                longest[column] = max(longest.get(column, 0), most)
                if "DELTA_BYTE_ARRAY" in encodings or "." in column:
                    uncountable.add(column)
    countable = [c for c in shared if c not in uncountable]
    if total + sum(shared.values()) <= limit or total > limit or not countable:
        return total + sum(shared.values())
    total += sum(shared[c] for c in uncountable)
    reader = pq.ParquetFile(path, pre_buffer=False, buffer_size=1 << 20)  # page by page
    for column in countable:
        # Decoded a few rows at a time, as few as their longest value allows, until the
        # count passes the limit: never more than _COUNT_BYTES of them at once.
        rows = max(1, min(MAX_BATCH_ROWS, _COUNT_BYTES // max(longest[column], 1)))
        for batch in reader.iter_batches(batch_size=rows, columns=[column]):
            total += pc.sum(pc.binary_length(batch.column(0))).as_py() or 0
            if total > limit:
                return total
    return total
