"""The motion database: versioned Parquet datasets behind an atomic ``CURRENT`` pointer.

A database is a folder::

    DB/CURRENT                      name of the live version, e.g. "v000003"
    DB/v000003/manifest.json        schema version, database version, summary, tables
    DB/v000003/clips/emotion=<e>/part-0.parquet   one row per utterance
    DB/v000003/animes/emotion=<e>/part-0.parquet  one row per phoneme instance (anime)
    DB/v000003/frames/emotion=<e>/part-0.parquet  full-rate motion, one row per frame
    DB/v000003/audio/part-0.parquet               each clip's speech (16-bit PCM)
    DB/v000003/channels.parquet                   what each motion channel is
    DB/v000003/model_arrays.parquet               PCA/ICA means, components, mixing ...
    DB/v000003/components.parquet                 one row per independent component
    DB/reports/                                   ingest reports

Every table is plain Parquet with hive partitioning, readable by any Parquet engine
(DuckDB, Spark, pandas). A write builds a complete new version in a hidden staging
folder, renames it into place and only then replaces ``CURRENT`` (one atomic rename),
so a failed or killed write leaves the previous version live and unchanged. The
version before the live one is kept for readers that still have it open; older ones
are removed.

The manifest holds the SHA-256 of the model arrays' file as written (``checksums``):
reading the arrays checks it, so an accidental change of the file (a bad copy, a tool
that rewrote it) is refused in one line. It is no protection against a deliberate edit
(the editor can update the manifest too): :mod:`ingest.invariants` checks what the arrays
must satisfy by construction. Databases written before it have no checksum and open.
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import os
import re
import secrets
import shutil
import stat
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from db.arrow import numbers
from db.atomic import atomic_write, write_error
from db.errors import DataError
from db.footers import decoded_bytes
from db.layout import CURRENT, is_database  # noqa: F401 - is_database: callers' import
from db.lock import pid_alive, writer_lock
from db.memo import Memo, identities
from db.parts import read_batches
from db.parts import read_parts as _read_parts
from db.validate import (
    READ_OPTIONS,
    WRITE_OPTIONS,
    check_channels,
    check_confined,
    check_manifest,
    check_statistics,
    check_text,
    check_values,
)

logger = logging.getLogger(__name__)

#: Version of the table layout; readers refuse other versions.
SCHEMA_VERSION = 1
#: Tables partitioned by emotion (a column they all carry).
PARTITIONED = ("clips", "animes", "frames")
#: Tables stored as one folder of part files (unpartitioned) or one file.
FOLDER_TABLES = ("audio",)
FILE_TABLES = ("channels", "model_arrays", "components")
TABLES = PARTITIONED + FOLDER_TABLES + FILE_TABLES

#: Largest manifest read, bytes, and its deepest nesting.
MAX_MANIFEST_BYTES = 16 << 20
MAX_MANIFEST_DEPTH = 32
#: Most dimensions of a model array.
MAX_ARRAY_DIMS = 8
#: Most rows a Parquet file's footer may declare per byte of the file. A row of any
#: table this version writes takes far more (at most 0.06 rows a byte were measured, on
#: a 1,411-row ``channels`` file); a crafted footer declaring millions of rows of one
#: dictionary-encoded value in a small file would be decoded into gigabytes.
MAX_ROWS_PER_BYTE = 1
#: Most bytes a Parquet file may take once read, per byte of the file: its pages
#: uncompressed plus its columns decoded (:meth:`Database.check_rows`). The files this
#: version writes took 0.6 to 24.5 (FaceGood's frames, many of whose 116 channels are
#: constant), and Snappy, which they are written with, compresses at most 21-fold (at
#: most 43 counted twice); a dictionary of one long string that every row repeats, or
#: pages that compress a thousandfold, take thousands: a small crafted file decoded into
#: gigabytes.
MAX_DECODED_PER_BYTE = 64
#: Uncompressed bytes aimed at in one Parquet row group (row groups of 64-128 MB are
#: what the Parquet documentation recommends for large sequential reads; 64 MB keeps a
#: reader's buffers small on a wide table such as 1,400 motion channels).
ROW_GROUP_BYTES = 64 << 20
#: Fewest and most rows in a row group.
MIN_GROUP_ROWS = 1024
MAX_GROUP_ROWS = 64 * 1024
#: Seconds a writer waits for another one to finish (``animegraph ingest --wait``).
WRITE_WAIT_S = 600.0
#: ``based_on`` default of :func:`write_version`: do not check the live version.
ANY_VERSION = object()

_VERSION = re.compile(r"^v(\d{6})$")
_STAGING = re.compile(r"^\.v\d{6}\.partial-(?:(\d+)-)?[0-9a-f]+$")
_CURRENT = CURRENT
#: Largest CURRENT read: a version's name and a newline fit many times over.
_CURRENT_MAX_BYTES = 64
#: Tables whose file's SHA-256 the manifest holds (``checksums``), checked when read.
CHECKSUMMED = ("model_arrays",)
#: Checks of tables' footers (:meth:`Database.check_rows`) and model arrays read
#: (:meth:`Database.arrays`) this process remembers, by the identity of their files.
_CHECKED = Memo(256)
_ARRAYS = Memo(8)


def is_staging(name: str) -> bool:
    """True if ``name`` is a writer's staging folder (a version being written)."""
    return _STAGING.match(name) is not None


def write_version(path: str | os.PathLike, tables: dict[str, pa.Table], manifest: dict, *,
                  based_on: str | None | object = ANY_VERSION, wait: float = WRITE_WAIT_S,
                  ) -> Path:
    """Write a new version of the database at ``path`` and make it the live one.

    The database's writer lock (:func:`db.lock.writer_lock`) is held throughout (a
    caller may hold it already), and the switch of ``CURRENT`` checks that the live
    version is still ``based_on``: a version built from an older state is refused
    rather than silently dropping what another writer added.

    Parameters
    ----------
    path : path
        Database folder (created if absent).
    tables : dict of str to pyarrow.Table
        Every name in :data:`TABLES`. Partitioned tables need an ``emotion`` column.
    manifest : dict
        Summary to store (JSON-serialisable); the schema and database versions and
        the table list are added here.
    based_on : str or None, optional
        The live version (None: no database yet) the tables were built from; checked
        under the lock before anything is written. By default not checked.
    wait : float
        Seconds to wait for another writer.

    Returns
    -------
    Path
        The new version's folder.

    Raises
    ------
    DataError
        If another writer holds the database longer than ``wait``, or the live version
        moved away from ``based_on``.
    """
    with writer_lock(path, wait=wait, what="database"):
        return _write_version(Path(path), tables, manifest, based_on)


def _write_version(root: Path, tables: dict[str, pa.Table], manifest: dict,
                   based_on) -> Path:
    missing = set(TABLES) - set(tables)
    if missing:
        raise ValueError(f"missing tables: {sorted(missing)}")
    for name in PARTITIONED:
        if "emotion" not in tables[name].column_names:
            raise ValueError(f"table {name} needs an emotion column to be partitioned by")
        _check_partition_names(tables[name].column("emotion"))
    previous = current_version(root) if is_database(root) else None
    if based_on is not ANY_VERSION and previous != based_on:
        raise DataError(f"database {root} changed while this write was prepared (it is now "
                        f"{previous or 'empty'}, was {based_on or 'empty'}); nothing written")

    def fill(staging: Path) -> dict:
        for table_name, table in tables.items():
            _write_table(staging, table_name, table)
        return {**manifest, "schema_version": SCHEMA_VERSION,
                "tables": {t: int(tables[t].num_rows) for t in TABLES}}

    return _new_version(root, previous, fill)


def write_model_arrays(path: str | os.PathLike, arrays: dict[str, np.ndarray], manifest: dict,
                       *, based_on: str, wait: float = WRITE_WAIT_S) -> Path:
    """A new version of the database at ``path`` equal to its live version ``based_on`` but
    for the model arrays and the manifest (e.g. a classifier trained apart and stored in it).

    The other tables' files are hard-linked from the live version (copied where the file
    system has no links): they are never changed once written. Atomic, under the writer
    lock, refused if the live version moved away from ``based_on`` (as
    :func:`write_version`).

    ``arrays`` (every model array of the new version) and ``manifest`` (the live one's,
    changed; its version number and checksums are set here) were built from ``based_on``;
    ``wait``: seconds to wait for another writer.
    """
    root = Path(path)
    with writer_lock(root, wait=wait, what="database"):
        previous = current_version(root)
        if previous != based_on:
            raise DataError(f"database {root} changed while this write was prepared (it is "
                            f"now {previous}, was {based_on}); nothing written")

        def fill(staging: Path) -> dict:
            source = root / previous
            for child in source.iterdir():
                if child.name in ("manifest.json", "model_arrays.parquet"):
                    continue
                if child.is_dir():
                    shutil.copytree(child, staging / child.name, copy_function=_link_or_copy)
                else:
                    _link_or_copy(child, staging / child.name)
            _write_table(staging, "model_arrays", arrays_to_table(arrays))
            return dict(manifest)

        return _new_version(root, previous, fill)


def _link_or_copy(src, dst) -> None:
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


def _new_version(root: Path, previous: str | None, fill) -> Path:
    """Build the next version in a staging folder (``fill(staging)`` writes its tables and
    returns its manifest), then make it the live one (see the module docstring)."""
    number = 1 + max([_number(p.name) for p in root.iterdir() if _VERSION.match(p.name)],
                     default=0)
    name = f"v{number:06d}"
    staging = root / f".{name}.partial-{os.getpid()}-{secrets.token_hex(4)}"
    try:
        staging.mkdir()
        info = {
            **fill(staging),
            "db_version": number,
            "checksums": {t: file_sha256(staging / f"{t}.parquet") for t in CHECKSUMMED},
        }
        (staging / "manifest.json").write_text(json.dumps(info, indent=1, default=_json))
        _fsync_tree(staging)
        staging.rename(root / name)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    with atomic_write(root / _CURRENT) as handle:
        handle.write(name.encode())
    _prune(root, keep={name, previous} - {None})
    return root / name


def _check_partition_names(emotions: pa.ChunkedArray) -> None:
    """DataError if two emotion labels differ only in case: they name partition folders,
    which a case-insensitive file system (macOS, Windows) would make one, the second
    label's part files overwriting the first's."""
    seen: dict[str, str] = {}
    for name in pc.unique(emotions).to_pylist():
        key = str(name).casefold()
        if key in seen:
            raise DataError(f"emotion labels {seen[key]!r} and {name!r} differ only in case: "
                            "a database keeps one of them (ingest lowercases emotion labels)")
        seen[key] = str(name)


def rows_per_group(table: pa.Table) -> int:
    """Rows of ``table`` in one row group: about :data:`ROW_GROUP_BYTES` of data.

    A table built clip by clip is made of one small chunk a clip; written as it is, each
    chunk became its own row group (the 800 GRID clips: 799 row groups of 75 rows x
    1,416 columns), which readers pay for in per-column-chunk buffers and metadata.
    """
    per_row = table.nbytes / max(table.num_rows, 1)
    rows = int(ROW_GROUP_BYTES // max(per_row, 1.0))
    return max(MIN_GROUP_ROWS, min(MAX_GROUP_ROWS, rows))


def dictionary_columns(table: pa.Table) -> list[str]:
    """The columns worth dictionary-encoding in Parquet: all but floating-point ones,
    lists (motion, prosody and posteriors, whose values hardly repeat) and binary ones (a
    clip's speech). A dictionary tried on them is given up page by page, after the work:
    the 800 GRID clips' frames took 7.3 s to write as 461 MB with it, 2.1 s as 325 MB
    without (``docs/results/speed.md``, "Ingest"). The speech of every clip in one dictionary
    page made a reader read all of it to bound its size (:meth:`Database.check_rows`)."""
    return [f.name for f in table.schema
            if not (pa.types.is_floating(f.type) or pa.types.is_list(f.type)
                    or pa.types.is_large_list(f.type)
                    or pa.types.is_fixed_size_list(f.type) or pa.types.is_binary(f.type)
                    or pa.types.is_large_binary(f.type))]


def _write_table(folder: Path, name: str, table: pa.Table) -> None:
    try:
        _write_table_files(folder, name, table)
    except OSError as exc:  # pyarrow's own error names no file ("Error writing bytes ...")
        raise write_error(folder / name, exc) from None


def _write_table_files(folder: Path, name: str, table: pa.Table) -> None:
    import pyarrow.dataset as ds  # deferred: it imports pandas, which reading does not need

    rows = rows_per_group(table)
    dictionary = dictionary_columns(table)
    if name in PARTITIONED:
        # min_rows_per_group gathers the many small chunks of a table built clip by clip
        # into row groups of ``rows`` (the last one of a partition may be smaller).
        ds.write_dataset(
            table, folder / name, format="parquet",
            partitioning=ds.partitioning(pa.schema([("emotion", pa.string())]), flavor="hive"),
            basename_template="part-{i}.parquet", min_rows_per_group=rows,
            max_rows_per_group=rows, preserve_order=True, existing_data_behavior="error",
            file_options=ds.ParquetFileFormat().make_write_options(
                use_dictionary=dictionary, **WRITE_OPTIONS),
        )
    elif name in FOLDER_TABLES:
        (folder / name).mkdir()
        pq.write_table(table, folder / name / "part-0.parquet", row_group_size=rows,
                       use_dictionary=dictionary, **WRITE_OPTIONS)
    else:
        pq.write_table(table, folder / f"{name}.parquet", row_group_size=rows,
                       use_dictionary=dictionary, **WRITE_OPTIONS)


def _fsync_tree(folder: Path) -> None:
    # Data must be on disk before CURRENT points at it, or a crash could expose
    # a version whose files are empty.
    for path in folder.rglob("*"):
        if path.is_file():
            with open(path, "rb") as handle:
                os.fsync(handle.fileno())


def _prune(root: Path, keep: set[str]) -> None:
    for child in root.iterdir():
        stale_version = _VERSION.match(child.name) and child.name not in keep
        staging = _STAGING.match(child.name)
        # A staging folder is removed only once its writer is gone (a killed ingest);
        # one of a live writer (e.g. an older animegraph ignoring the lock) is left alone.
        stale_staging = staging is not None and not (
            staging.group(1) and pid_alive(int(staging.group(1))))
        if child.is_dir() and (stale_version or stale_staging):
            shutil.rmtree(child, ignore_errors=True)


def _number(name: str) -> int:
    return int(_VERSION.match(name).group(1))


def _json(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON-serialisable: {type(value).__name__}")


def own_folder(root: Path, *parts: str) -> Path:
    """``root / parts...``, a folder the database keeps beside its versions (reports,
    stored models); DataError if one of them is a symbolic link: a database from
    someone else would otherwise have the user's writes land where the link points."""
    path = Path(root)
    for part in parts:
        path = path / part
        if path.is_symlink():
            raise DataError(f"database {root} is damaged: {path} is a symbolic link "
                            f"(to {path.resolve()}); refused")
    return path


def current_version(path: str | os.PathLike) -> str:
    """Name of the live version of the database at ``path``."""
    root = Path(path)
    # CURRENT must be the database's own small regular file: opened without following a
    # symbolic link (one to /etc/passwd had its first bytes printed in the error), nor
    # waiting on a FIFO; what it holds is said only if it is a version's name.
    damaged = f"database {root} is damaged: {_CURRENT} "
    try:
        fd = os.open(root / _CURRENT, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0)
                     | getattr(os, "O_NONBLOCK", 0))
    except FileNotFoundError:
        raise DataError(f"{root} is not an animegraph database (no {_CURRENT} file)") from None
    except OSError as exc:
        what = "is a symbolic link" if os.path.islink(root / _CURRENT) else \
            f"cannot be read ({exc.strerror or exc})"
        raise DataError(damaged + what) from None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode) or info.st_size > _CURRENT_MAX_BYTES:
            raise DataError(damaged + "is not the small text file naming a version")
        raw = os.read(fd, _CURRENT_MAX_BYTES + 1)
    except OSError as exc:
        raise DataError(damaged + f"cannot be read ({exc.strerror or exc})") from None
    finally:
        os.close(fd)
    name = raw.decode("ascii", errors="replace").strip()
    if not _VERSION.match(name):
        raise DataError(damaged + "does not name a version")
    if not (root / name).is_dir():
        raise DataError(damaged + f"names {name}, which is not there")
    return name


@dataclass(frozen=True)
class Database:
    """A read-only view of the live version of a database.

    Attributes
    ----------
    root : Path
        The database folder.
    version_dir : Path
        Folder of the version that was live when the database was opened.
    manifest : dict
        That version's manifest.
    """

    root: Path
    version_dir: Path
    manifest: dict

    @classmethod
    def open(cls, path: str | os.PathLike) -> Database:
        """Open the database at ``path``.

        Its names, its links, its files' statistics and its channels are checked
        (:mod:`db.validate`): every command sees the same damage.

        Raises
        ------
        DataError
            If ``path`` is not a database, is damaged, or has another schema version.
        """
        root = Path(path)
        if not root.exists():
            raise DataError(f"database {root} does not exist")
        version_dir = root / current_version(root)
        manifest = _read_manifest(version_dir / "manifest.json")
        if manifest.get("schema_version") != SCHEMA_VERSION:
            raise DataError(
                f"database {root} has schema version {manifest.get('schema_version')}, "
                f"this animegraph reads version {SCHEMA_VERSION}"
            )
        check_manifest(manifest, TABLES, lambda problem: DataError(
            f"database {root} is damaged: {version_dir / 'manifest.json'}: {problem}"))
        check_confined(root, version_dir, lambda problem: DataError(
            f"database {root} is damaged: {problem}"))
        db = cls(root=root, version_dir=version_dir, manifest=manifest)
        check_statistics(db)
        check_channels(db)
        return db

    def damaged(self, name: str, problem: str) -> DataError:
        """The error for a table (or file) of this version that does not hold up."""
        where = self.table_path(name) if name in TABLES else self.version_dir / name
        return DataError(f"database {self.root} is damaged: {where}: {problem}")

    def table_path(self, name: str) -> Path:
        """Where the table ``name`` lives (a folder, or one file)."""
        if name in FILE_TABLES:
            return self.version_dir / f"{name}.parquet"
        return self.version_dir / name

    def columns(self, name: str) -> tuple[str, ...]:
        """The column names of table ``name`` (an empty tuple if it cannot be read)."""
        if name not in TABLES:
            raise DataError(f"no table {name!r}; tables are {', '.join(TABLES)}")
        path = self.table_path(name)
        try:  # one file's schema: pyarrow.dataset would import pandas (synth's start-up)
            files = [path] if path.is_file() else sorted(path.rglob("*.parquet"))
            names = tuple(pq.read_schema(files[0]).names) if files else ()
        except (OSError, pa.ArrowException):
            return ()
        if name in PARTITIONED and names and "emotion" not in names:
            names += ("emotion",)  # the partition key, a column of the table as read
        return names

    def files(self, name: str) -> list[Path]:
        """The Parquet files of table ``name``, the ones ``pyarrow.dataset`` reads (every
        file below the table's folder but hidden and ``_`` ones); none if it is missing."""
        path = self.table_path(name)
        if path.is_file():
            return [path]
        if not path.is_dir():
            return []
        return sorted(f for f in path.rglob("*") if f.is_file() and not any(
            part.startswith((".", "_")) for part in f.relative_to(path).parts))

    def check_rows(self, name: str) -> None:
        """DataError unless the footers of table ``name``'s files declare the rows the
        manifest counts for it (``tables``), no more than :data:`MAX_ROWS_PER_BYTE` a
        byte of their file, and no more than :data:`MAX_DECODED_PER_BYTE` bytes once
        read (:func:`db.footers.decoded_bytes`).

        A small file from someone else whose footer declares a hundred million rows, or
        whose one dictionary string every row repeats, is refused before a reader decodes
        it into gigabytes. Only the footers are read, and dictionary-encoded strings a few
        rows at a time when the footer cannot bound them. The sizes a footer
        declares are trusted: a Parquet writer's are the pages' own (a forged footer that
        understates them is beyond this check). The files are the ones
        ``pyarrow.dataset`` reads (every file below the table's folder but hidden and
        ``_`` ones).

        Remembered for the process while the files stay as they were
        (:mod:`db.memo`): a version's files are written once.
        """
        files = self.files(name)
        if not files:
            return  # the read says the table is missing
        ids = identities(files)
        counts = self.manifest.get("tables")
        key = ("rows", name, repr(counts.get(name) if isinstance(counts, dict) else None), ids)
        if ids is not None and _CHECKED.get(key):
            return
        self._check_footers(name, files)
        if ids is not None:
            _CHECKED.put(key, True, ids)

    def _check_footers(self, name: str, files: list[Path]) -> None:
        """:meth:`check_rows` itself, every time."""
        path = self.table_path(name)
        try:
            footers = [(f, pq.read_metadata(f), f.stat().st_size) for f in files]
        except (OSError, pa.ArrowException) as exc:
            raise self.damaged(name, f"cannot be read: {_first_line(exc)}") from None
        total = sum(meta.num_rows for _, meta, _ in footers)
        counts = self.manifest.get("tables")
        expected = counts.get(name) if isinstance(counts, dict) else None
        if (isinstance(expected, int) and not isinstance(expected, bool)
                and total != expected):
            raise self.damaged(name, f"its files' footers declare {total} rows, the manifest "
                               f"{expected} (not read)")
        for f, meta, size in footers:
            where = f.name if f == path else f.relative_to(path)
            if meta.num_rows > MAX_ROWS_PER_BYTE * size:
                raise self.damaged(name, f"{where} declares {meta.num_rows} rows in {size} "
                                   f"bytes, more than {MAX_ROWS_PER_BYTE} a byte: a crafted "
                                   f"footer (not read)")
            # A partition folder's value (emotion=...) is a column of every row as read.
            row_bytes = sum(len(part.partition("=")[2].encode())
                            for part in where.parts[:-1]) if f != path else 0
            try:
                decoded = decoded_bytes(f, meta, row_bytes, MAX_DECODED_PER_BYTE * size)
            except (OSError, pa.ArrowException) as exc:
                raise self.damaged(name, f"cannot be read: {_first_line(exc)}") from None
            if decoded > MAX_DECODED_PER_BYTE * size:
                raise self.damaged(name, f"{where} decodes to up to {decoded} bytes from "
                                   f"{size}, more than {MAX_DECODED_PER_BYTE} times its "
                                   f"size: a crafted file (not read)")
            check_text(self, name, f, where, meta)

    def table(self, name: str, columns: list[str] | None = None, filter=None) -> pa.Table:
        """Read a table (optionally some columns, rows matching a pyarrow ``filter``).

        The files' footers are checked first (:meth:`check_rows`), the values read after
        (:func:`db.validate.check_values`), and the pages' checksums as they are read."""
        if name not in TABLES:
            raise DataError(f"no table {name!r}; tables are {', '.join(TABLES)}")
        self.check_rows(name)
        try:
            table = None
            if filter is None:
                table = _read_parts(self.table_path(name), columns, name in PARTITIONED)
            if table is None:
                table = self.dataset(name).to_table(columns=columns, filter=filter)
        except (OSError, pa.ArrowException) as exc:
            raise self.damaged(name, f"cannot be read: {_first_line(exc)}") from None
        check_values(self, name, table)
        return table

    def batches(self, name: str, columns: list[str], rows: int = MAX_GROUP_ROWS):
        """Table ``name`` (``columns`` of it) read ``rows`` at a time, as tables, in the
        order of :meth:`table`, checked as :meth:`table` checks what it reads: the
        footers first, the pages' checksums and each piece's values as they are read.
        A reader that keeps a few columns of a large table (the anime graph's arrays)
        never holds the whole of it."""
        if name not in TABLES:
            raise DataError(f"no table {name!r}; tables are {', '.join(TABLES)}")
        self.check_rows(name)
        try:
            for part in read_batches(self.table_path(name), columns, name in PARTITIONED,
                                     rows):
                check_values(self, name, part)
                yield part
                del part
                # Arrow's allocator keeps freed pages for reuse: without this the pieces
                # of a whole large table stayed resident until the read was over.
                pa.default_memory_pool().release_unused()
        except (OSError, ValueError, pa.ArrowException) as exc:
            raise self.damaged(name, f"cannot be read: {_first_line(exc)}") from None

    def dataset(self, name: str, schema: pa.Schema | None = None):
        """Table ``name`` as a ``pyarrow.dataset.Dataset`` whose reads verify the pages'
        checksums (hive-partitioned by emotion if it is), unchecked otherwise: read it
        after :meth:`check_rows`."""
        import pyarrow.dataset as ds  # deferred: it imports pandas (a third of a second)

        form = ds.ParquetFileFormat(default_fragment_scan_options=ds.ParquetFragmentScanOptions(
            **READ_OPTIONS))
        return ds.dataset(self.table_path(name), format=form, schema=schema,
                          partitioning="hive" if name in PARTITIONED else None)

    def _check_sum(self, name: str) -> None:
        """DataError if the manifest holds a checksum of table ``name`` it does not match
        (none is held by a database written before checksums: nothing to check)."""
        sums = self.manifest.get("checksums", {})
        expected = sums.get(name) if isinstance(sums, dict) else sums
        if expected is None:
            return
        path = self.table_path(name)
        if not path.is_file():  # not a device or a pipe, which could be read forever
            raise self.damaged(name, "is not a file")
        try:
            actual = file_sha256(path)
        except OSError as exc:
            raise self.damaged(name, f"cannot be read: {exc.strerror or exc}") from None
        if actual != expected:
            raise self.damaged(name, "its SHA-256 differs from the manifest's: the file "
                               "was changed after the database was written")

    def arrays(self) -> dict[str, np.ndarray]:
        """The model arrays (PCA/ICA means, components, mixing matrices, cutoffs ...),
        read-only: checked and read once per process while the file stays as it was
        (:mod:`db.memo`), and shared by every call.

        Raises
        ------
        DataError
            If the file differs from the checksum in the manifest, or the table is not
            (name, shape, values) rows whose shapes fit their values, or a value is not
            finite.
        """
        path = self.table_path("model_arrays")
        ids = identities([path])
        sums = self.manifest.get("checksums")
        key = ("arrays", repr(sums.get("model_arrays") if isinstance(sums, dict) else sums),
               ids)
        cached = _ARRAYS.get(key) if ids is not None else None
        if cached is None:
            self._check_sum("model_arrays")
            try:
                cached = arrays_from_table(self.table("model_arrays"))
            except (KeyError, ValueError, TypeError, pa.ArrowException) as exc:
                raise self.damaged("model_arrays", f"unreadable model arrays ({exc})") from None
            for array in cached.values():
                array.flags.writeable = False  # shared by every later call
            if ids is not None and ids == identities([path]):  # unchanged while read
                _ARRAYS.put(key, cached, ids)
        return {name: array.view() for name, array in cached.items()}


def _first_line(exc: Exception) -> str:
    return str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__


def file_sha256(path: Path) -> str:
    """Hex SHA-256 of the file at ``path``."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def arrays_to_table(arrays: dict[str, np.ndarray]) -> pa.Table:
    """Store named float arrays as rows (name, shape, values) — no pickles."""
    names = sorted(arrays)
    return pa.table({
        "name": pa.array(names, pa.string()),
        "shape": pa.array([list(np.shape(arrays[n])) for n in names], pa.list_(pa.int64())),
        "values": pa.array([np.asarray(arrays[n], dtype=np.float64).ravel() for n in names],
                           pa.list_(pa.float64())),
    })


def arrays_from_table(table: pa.Table) -> dict[str, np.ndarray]:
    """Inverse of :func:`arrays_to_table`; checks every row (ValueError if one is bad)."""
    out = {}
    names = table.column("name").to_pylist()
    shapes = table.column("shape").to_pylist()
    values = table.column("values")
    if not (pa.types.is_list(values.type) or pa.types.is_large_list(values.type)) or not (
            pa.types.is_floating(values.type.value_type)
            or pa.types.is_integer(values.type.value_type)):
        raise ValueError(f"values must be lists of numbers, not {values.type}")
    for i, (name, shape) in enumerate(zip(names, shapes, strict=True)):
        if not isinstance(name, str) or name in out:
            raise ValueError(f"row {i}: missing or repeated name {name!r}")
        if (not isinstance(shape, list) or len(shape) > MAX_ARRAY_DIMS
                or not all(isinstance(d, int) and 0 <= d for d in shape)):
            raise ValueError(f"{name}: bad shape {shape!r}")
        if values[i].values is None:
            raise ValueError(f"{name}: no values")
        flat = numbers(values[i].values).astype(np.float64)
        if flat.size != math.prod(shape):
            raise ValueError(f"{name}: {flat.size} values for shape {tuple(shape)}")
        if not np.isfinite(flat).all():
            raise ValueError(f"{name}: values not finite")
        out[name] = flat.reshape(shape)
    return out


def _read_manifest(path: Path) -> dict:
    """A version's manifest: a JSON object of bounded size and depth, or DataError."""
    try:
        if path.stat().st_size > MAX_MANIFEST_BYTES:
            raise DataError(f"database {path.parent.parent} is damaged: {path} is larger "
                            f"than {MAX_MANIFEST_BYTES} bytes")
        manifest = json.loads(path.read_bytes().decode("utf-8"))
    except (OSError, ValueError, RecursionError) as exc:
        problem = "nested too deeply" if isinstance(exc, RecursionError) else "unreadable"
        raise DataError(f"database {path.parent.parent} is damaged: {path} is "
                        f"{problem}") from None
    if not isinstance(manifest, dict):
        raise DataError(f"database {path.parent.parent} is damaged: {path} is not a JSON "
                        f"object")
    stack, depth_of = [(manifest, 1)], 0
    while stack:
        item, depth = stack.pop()
        if isinstance(item, dict | list):
            depth_of = max(depth_of, depth)
            if depth_of > MAX_MANIFEST_DEPTH:
                raise DataError(f"database {path.parent.parent} is damaged: {path} is nested "
                                f"deeper than {MAX_MANIFEST_DEPTH} levels")
            stack.extend((v, depth + 1) for v in (item.values() if isinstance(item, dict)
                                                   else item))
    for key in ("fps",):
        value = manifest.get(key)
        if (isinstance(value, bool) or not isinstance(value, int | float)
                                  or not math.isfinite(value) or value <= 0):
            raise DataError(f"database {path.parent.parent} is damaged: {path}: {key} is "
                            f"{value!r}")
    for key in ("n_channels", "n_pcs", "n_clips", "n_animes", "n_frames"):
        value = manifest.get(key)
        if value is not None and (isinstance(value, bool) or not isinstance(value, int)
                                  or value < 0):
            raise DataError(f"database {path.parent.parent} is damaged: {path}: {key} is "
                            f"{value!r}")
    return manifest
