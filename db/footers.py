"""Bounds of what a Parquet file takes once read, from its footer alone
(:meth:`db.store.Database.check_rows` refuses a small crafted file that would decode into
gigabytes before a reader decodes it)."""

from __future__ import annotations

from pathlib import Path

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

#: Bytes a value of a Parquet physical type takes once read (BYTE_ARRAY: its offset).
_WIDTH = {"BOOLEAN": 1, "INT32": 4, "INT64": 8, "INT96": 12, "FLOAT": 4, "DOUBLE": 8,
          "BYTE_ARRAY": 4}
_DICTIONARY = {"PLAIN_DICTIONARY", "RLE_DICTIONARY"}


def decoded_bytes(path: Path, meta: pq.FileMetaData, row_bytes: int, limit: int) -> int:
    """Bytes the Parquet file at ``path`` takes once read, at most: every column chunk's
    pages uncompressed plus its values decoded, and ``row_bytes`` more a row.

    A value takes its type's width; a string also its bytes, which are in its pages
    unless the pages share them: a dictionary-encoded string (or one delta-encoded
    against the one before) can be as long as its chunk's pages, in every row. When that
    bound passes ``limit``, the dictionary-encoded (top-level) columns are read a row
    group at a time as dictionaries (each string held once) to count their bytes, until
    the count passes ``limit``.

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
    # Read as dictionaries (page by page): a string repeated by a dictionary is held
    # once and counted for each row from its index, never decoded into each row (a few
    # rows at a time, that took seconds a 100k clips).
    reader = pq.ParquetFile(path, pre_buffer=False, buffer_size=1 << 20,
                            read_dictionary=countable)
    for column in countable:
        for g in range(meta.num_row_groups):
            for chunk in reader.read_row_group(g, columns=[column]).column(0).chunks:
                if pa.types.is_dictionary(chunk.type):
                    lengths = pc.binary_length(chunk.dictionary)
                    total += pc.sum(pc.take(lengths, chunk.indices)).as_py() or 0
                else:
                    total += pc.sum(pc.binary_length(chunk)).as_py() or 0
                if total > limit:
                    return total
    return total
