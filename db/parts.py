"""A table's Parquet files read with :mod:`pyarrow.parquet`, whole or a batch at a time,
as ``pyarrow.dataset`` reads them, without importing it (it imports pandas, a third of a
second of every command's start-up). The callers check the files first
(:meth:`db.store.Database.check_rows`)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from urllib.parse import unquote

import pyarrow as pa
import pyarrow.parquet as pq

from db.arrow import repeat_string
from db.validate import READ_OPTIONS


def read_parts(path: Path, columns: list[str] | None, partitioned: bool) -> pa.Table | None:
    """A table read file by file with :mod:`pyarrow.parquet`, as ``pyarrow.dataset`` reads it.

    The same rows in the same order (files in sorted path order), and for a table
    partitioned by emotion its ``emotion`` column (a string, last unless ``columns``
    orders it), without importing :mod:`pyarrow.dataset`, which imports pandas. None when
    the layout is not the one this version writes (no files, another partition key):
    the caller then asks ``pyarrow.dataset``.
    """
    if path.is_file():
        return read_file(path, columns)
    if not partitioned:
        files = sorted(path.glob("*.parquet"))
        parts = [read_file(f, columns) for f in files]
    else:
        files = sorted(path.glob("*=*/*.parquet"))
        parts = []
        for f in files:
            key, _, value = f.parent.name.partition("=")
            if key != "emotion" or "%" in value:
                return None
            want = None if columns is None else [c for c in columns if c != key]
            part = read_file(f, want)
            if part is None:
                return None
            part = part.append_column(key, repeat_string(value, part.num_rows))
            parts.append(part if columns is None else part.select(columns))
    if not parts or any(part is None for part in parts):
        return None
    return pa.concat_tables(parts)


def read_file(path: Path, columns: list[str] | None) -> pa.Table | None:
    """One Parquet file, or None if it lacks a column asked for (``pyarrow.dataset`` then
    says so)."""
    file = pq.ParquetFile(path, **READ_OPTIONS)
    if columns is not None and not set(columns) <= set(file.schema_arrow.names):
        return None
    return file.read(columns=columns)


def read_batches(path: Path, columns: list[str], partitioned: bool,
                 rows: int) -> Iterator[pa.Table]:
    """The rows of the table at ``path`` (a file, or a folder of them as
    :func:`read_parts` reads it), ``columns`` only, at most ``rows`` at a time, each
    piece a table; the pages' checksums are checked as they are read.

    Raises
    ------
    ValueError
        If the layout is not the one this version writes or a file lacks a column.
    """
    if path.is_file():
        files = [(path, None)]
    elif partitioned:
        files = []
        for f in sorted(path.glob("*=*/*.parquet")):
            key, _, value = f.parent.name.partition("=")
            if key != "emotion":
                raise ValueError(f"{f.parent.name}: not an emotion partition")
            files.append((f, unquote(value)))  # as pyarrow's hive partitioning decodes it
    else:
        files = [(f, None) for f in sorted(path.glob("*.parquet"))]
    for f, emotion in files:
        # Without pre-buffering: with it the reader kept every row group's column chunks
        # read so far until the file's last batch (the whole file's bytes at the end).
        file = pq.ParquetFile(f, pre_buffer=False, **READ_OPTIONS)
        want = [c for c in columns if not (emotion is not None and c == "emotion")]
        missing = set(want) - set(file.schema_arrow.names)
        if missing:
            raise ValueError(f"{f.name} has no column {sorted(missing)[0]!r}")
        for batch in file.iter_batches(batch_size=rows, columns=want):
            part = pa.Table.from_batches([batch])
            if emotion is not None and "emotion" in columns:
                part = part.append_column("emotion", repeat_string(emotion, part.num_rows))
            yield part.select(columns)
