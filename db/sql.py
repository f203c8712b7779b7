"""SQL over the motion database: DuckDB views on the live version's Parquet files.

Each table of :mod:`db.store` is a view of the same name (``clips``, ``animes``,
``frames``, ``audio``, ``channels``, ``model_arrays``, ``components``). The SQL is
untrusted input (a database is shared, a query is pasted), so two fences hold it:

1. **DuckDB's own sandbox**: each query runs on a fresh in-memory connection with
   ``enable_external_access = false`` and ``lock_configuration = true`` (no ``SET`` can
   undo it). The tables are the live version's Parquet files opened by pyarrow
   (``pyarrow.dataset``) and registered as Arrow scans, so DuckDB itself needs no file
   at all: its only allowed directory (``allowed_directories``) is a private spill
   folder, deleted after the query. Any other file, URL, ``ATTACH``, extension
   (``INSTALL``/``LOAD``), ``COPY``/``EXPORT`` is refused by DuckDB, also into the
   database's own folder.
2. **Only reading statements**: ``SELECT`` (with ``WITH``, ``FROM``, ``VALUES``,
   ``DESCRIBE``, ``SHOW``, ``SUMMARIZE``) and ``EXPLAIN [ANALYZE]`` of one of those;
   anything else (``COPY`` into the version's own folder, ``CREATE``, ``SET`` ...) is
   refused before it is executed.

Results are streamed in Arrow batches and stop at a row cap (:data:`ROW_LIMIT`), and a
timer interrupts a query still running after :data:`TIMEOUT_S` seconds; both can be
raised. DuckDB's memory and spill space are capped (:data:`MEMORY_LIMIT`,
:data:`SPILL_LIMIT`; a query beyond them fails in one line). Several statements
separated by ``;`` each run, in order.
"""

from __future__ import annotations

import difflib
import os
import re
import tempfile
from dataclasses import dataclass

import duckdb
import pyarrow as pa
import pyarrow.dataset as ds

from db.errors import DataError, ParameterError
from db.store import TABLES, Database
from db.system import StillRunning, in_worker_thread

#: Rows a statement may return before the rest is dropped (``animegraph sql --limit``).
ROW_LIMIT = 100_000
#: Seconds a query may run before it is interrupted (``animegraph sql --timeout``), and
#: the most it may be given (a bounded wait; ``inf`` overflowed the timer's clock).
TIMEOUT_S = 60.0
MAX_TIMEOUT_S = 86400.0
#: Seconds between two looks of the waiting thread at the clock (and at Ctrl-C).
POLL_S = 0.05
#: Seconds an interrupted query gets to stop before its thread is left to the exit.
STOP_GRACE_S = 2.0
#: Rows per streamed Arrow batch: few enough that one batch of long values stays far
#: below Arrow's 2 GB string buffer (8,192 rows of 300 KB strings overflowed it, after
#: 19 s and 2.2 GB, in DuckDB's advice to ``SET arrow_large_buffer_size``).
BATCH_ROWS = 1024
#: Bytes of a statement's result kept (it is held whole to be printed or written): a
#: larger one is refused, with how to narrow it, when it passes this.
RESULT_BYTES = 256 << 20
#: Memory DuckDB may hold for a query, and disk it may spill to: its defaults are 80 %
#: of the machine's memory and 90 % of the free disk, which one pasted query (a
#: ``string_agg`` of 2 GB, a ``GROUP BY`` of 10^9 groups) took on a shared machine.
MEMORY_LIMIT = "4GB"
SPILL_LIMIT = "8GB"

_ALLOWED = {duckdb.StatementType.SELECT}
#: DuckDB's words for a table, and for a column, that a query names and no table has.
_NO_TABLE = re.compile(r"Table with name (\S+) does not exist")
_NO_COLUMN = re.compile(r'(?:Referenced column|does not have a column named|Column) "([^"]+)"')
#: DuckDB's words when the Arrow scan of a table failed (pyarrow could not read a file).
_SCAN_FAILED = re.compile(r"reading the stream registered as '(\w+)' failed: (.*)")
#: DuckDB's and Arrow's words when a batch of the result passed Arrow's 2 GB buffers.
_OVERFLOW = re.compile(r"arrow_large_buffer_size|maximum total string size|capacity "
                       r"overflow|offset overflow", re.IGNORECASE)
_EXPLAIN = re.compile(r"^\s*EXPLAIN\s+(?:ANALY[SZ]E\s+|\([^)]*\)\s*)?", re.IGNORECASE)


@dataclass(frozen=True)
class Result:
    """One statement's result.

    Attributes
    ----------
    sql : str
        The statement.
    table : pyarrow.Table
        Its rows, at most the row cap.
    truncated : bool
        True if the statement had more rows than the cap (they were not fetched).
    """

    sql: str
    table: pa.Table
    truncated: bool


def connect(db: Database, spill_dir: str | os.PathLike | None = None) -> duckdb.DuckDBPyConnection:
    """An in-memory, sandboxed DuckDB connection with a view per table of ``db``.

    The tables are Arrow scans of ``db``'s live version (opened by pyarrow); DuckDB may
    open no file but in ``spill_dir`` (its temporary files), and its configuration is
    locked.
    """
    con = duckdb.connect(":memory:", config={
        "autoinstall_known_extensions": False, "autoload_known_extensions": False,
    })
    try:
        allowed = []
        if spill_dir is not None:
            allowed.append(str(spill_dir) + os.sep)
            con.execute("SET temp_directory = ?", [str(spill_dir)])
        con.execute("SET allowed_directories = ?", [allowed])
        con.execute("SET memory_limit = ?", [MEMORY_LIMIT])
        con.execute("SET max_temp_directory_size = ?", [SPILL_LIMIT])
        con.execute("SET enable_external_access = false")
        con.execute("SET lock_configuration = true")
        for name in TABLES:
            con.register(name, _dataset(db, name))
    except BaseException:
        con.close()
        raise
    return con


def _dataset(db: Database, name: str) -> ds.Dataset:
    db.check_rows(name)  # a crafted file is refused before DuckDB scans it
    try:
        dataset = db.dataset(name)  # its pages' checksums verified as DuckDB scans them
        wide = _without_float16(dataset.schema)
        if wide is not dataset.schema:  # DuckDB reads no half floats: scanned as float32
            dataset = db.dataset(name, schema=wide)
        return dataset
    except (OSError, pa.ArrowException) as exc:
        raise db.damaged(name, f"cannot be read: {_first_line(exc)}") from None


def _without_float16(schema: pa.Schema) -> pa.Schema:
    """``schema`` with float16 columns (and lists of float16, e.g. ``animes.posteriors``)
    widened to float32; the same object if it has none."""
    fields, changed = [], False
    for field in schema:
        kind = field.type
        if pa.types.is_float16(kind):
            kind = pa.float32()
        elif pa.types.is_list(kind) and pa.types.is_float16(kind.value_type):
            kind = pa.list_(pa.float32())
        changed |= kind != field.type
        fields.append(field.with_type(kind))
    return pa.schema(fields, metadata=schema.metadata) if changed else schema


def check_read_only(sql: str) -> list[str]:
    """The statements of ``sql``; ParameterError unless every one only reads.

    ``EXPLAIN ANALYZE`` executes its statement, so an ``EXPLAIN`` is allowed only
    around a statement that is allowed itself.
    """
    statements = _parse(sql)
    if not statements:
        raise ParameterError("SQL is empty")
    for statement in statements:
        kind = statement.type
        if kind == duckdb.StatementType.EXPLAIN:
            inner = _EXPLAIN.sub("", statement.query, count=1)
            try:
                inner_statements = _parse(inner)
            except ParameterError:
                inner_statements = []
            if len(inner_statements) == 1 and inner_statements[0].type in _ALLOWED:
                continue
            kind = inner_statements[0].type if len(inner_statements) == 1 else kind
            raise ParameterError(f"only SELECT queries run here (the database is read-only); "
                                 f"got EXPLAIN {kind.name}")
        if kind.name == "MULTI":  # DuckDB's PIVOT without IN: it creates a type first
            raise ParameterError("a PIVOT without IN (...) runs more than one statement "
                                 "(DuckDB first creates a type of the values), which this "
                                 "read-only sandbox does not: name the values, e.g. PIVOT "
                                 "animes ON emotion IN ('happy', 'sad') USING count(*) "
                                 "GROUP BY phoneme")
        if kind not in _ALLOWED:
            raise ParameterError(f"only SELECT queries run here (the database is read-only); "
                                 f"got {kind.name}")
    return [s.query for s in statements]


def _parse(sql: str) -> list:
    try:
        return duckdb.extract_statements(sql)
    except duckdb.Error as exc:
        raise ParameterError(f"SQL does not parse: {_first_line(exc)}") from None


def run(db: Database, sql: str, *, row_limit: int = ROW_LIMIT,
        timeout: float = TIMEOUT_S) -> list[Result]:
    """Run read-only SQL (one or more statements); one :class:`Result` per statement.

    Parameters
    ----------
    db : Database
    sql : str
        One or more statements separated by ``;``.
    row_limit : int
        Rows kept per statement; the rest is never fetched (``Result.truncated``).
    timeout : float
        Seconds the whole run may take before DuckDB is interrupted.

    Raises
    ------
    ParameterError
        If the SQL writes, reaches outside the database, fails (unknown column, type
        error ...) or runs out of time: DuckDB's first line.
    """
    if row_limit < 1:
        raise ParameterError(f"the row limit must be >= 1, got {row_limit}")
    if not 0 < timeout <= MAX_TIMEOUT_S:
        raise ParameterError(f"the time limit must be more than 0 and at most "
                             f"{MAX_TIMEOUT_S:g} s, got {timeout}")
    statements = check_read_only(sql)
    with tempfile.TemporaryDirectory(prefix="animegraph-sql-") as spill:
        try:
            con = connect(db, spill)
        except duckdb.Error as exc:
            raise DataError(f"database {db.root} could not be opened: {_first_line(exc)}") from None
        stopped = False
        try:
            # The caller waits, not DuckDB: a Ctrl-C inside DuckDB's execution became its
            # "Query interrupted" only when the query ended on its own.
            return in_worker_thread(
                lambda: [_fetch(con, statement, row_limit) for statement in statements],
                timeout=timeout, on_timeout=con.interrupt, on_interrupt=con.interrupt,
                grace=STOP_GRACE_S, poll=POLL_S)
        except duckdb.InterruptException:
            raise ParameterError(f"query stopped after {timeout:g} s (raise the limit with "
                                 f"--timeout)") from None
        except duckdb.Error as exc:
            scan = _SCAN_FAILED.search(_first_line(exc))
            if scan is not None and scan.group(1) in TABLES:  # the files, not the query
                raise db.damaged(scan.group(1), f"cannot be read: {scan.group(2)}") from None
            raise ParameterError(f"query failed: {_failure(con, exc)}") from None
        except OSError as exc:
            raise DataError(f"database {db.root} could not be read: {exc}") from exc
        except StillRunning:
            stopped = True  # the query's thread still holds the connection
            raise KeyboardInterrupt from None
        finally:
            if not stopped:
                con.close()


def _fetch(con: duckdb.DuckDBPyConnection, statement: str, row_limit: int) -> Result:
    byte_limit = RESULT_BYTES
    relation = con.sql(statement)
    if relation is None:  # pragma: no cover - only reading statements get here
        return Result(statement, pa.table({}), False)
    reader = relation.to_arrow_reader(BATCH_ROWS)
    batches, rows, size, truncated = [], 0, 0, False
    try:
        for batch in _batches(reader):
            size += batch.nbytes
            if size > byte_limit:
                raise _too_large(byte_limit, rows + batch.num_rows)
            if rows + batch.num_rows > row_limit:
                batches.append(batch.slice(0, row_limit - rows))
                truncated = True
                break
            batches.append(batch)
            rows += batch.num_rows
    except _Overflow:
        raise _too_large(byte_limit, rows + BATCH_ROWS) from None
    finally:
        reader.close()
    table = pa.Table.from_batches(batches, schema=reader.schema)
    return Result(statement, table.rename_columns(unique_names(table.column_names)), truncated)


class _Overflow(Exception):
    """A batch of the result passed Arrow's 2 GB buffers."""


def _batches(reader):
    """The reader's batches; :class:`_Overflow` for a batch DuckDB cannot make because its
    values pass Arrow's 2 GB buffer: the result is too large (DuckDB advises a setting the
    sandbox locks), the database is not unreadable."""
    while True:
        try:
            yield reader.read_next_batch()
        except StopIteration:
            return
        except (OSError, pa.ArrowException, duckdb.Error) as exc:
            if _OVERFLOW.search(str(exc)):
                raise _Overflow from None
            raise


def _too_large(byte_limit: int, rows: int) -> ParameterError:
    return ParameterError(
        f"the result is too large: more than {byte_limit >> 20} MB in its first {rows} "
        f"rows (a result is held whole); narrow it: fewer or shorter columns, a WHERE, a LIMIT, "
        f"or an aggregate (count, avg, string_agg of a few)")


def unique_names(names: list[str]) -> list[str]:
    """``names`` made unique as DuckDB's ``df()`` does: a repeated name (``SELECT a.x,
    b.x``) gets the first free suffix ``_1``, ``_2`` ... (``x``, ``x_1``). JSON rows
    and DataFrames keep one column a name, so the second ``x`` was dropped. Names are
    compared whatever their case, as SQL compares them.

    Parameters
    ----------
    names : list of str
        Column names, in order.

    Returns
    -------
    list of str
        As many names, no two equal ignoring case; a name already unique is kept.
    """
    seen: set[str] = set()
    unique = []
    for name in names:
        new, k = name, 0
        while new.lower() in seen:
            k += 1
            new = f"{name}_{k}"
        seen.add(new.lower())
        unique.append(new)
    return unique


def query(db: Database, sql: str, *, row_limit: int = ROW_LIMIT,
          timeout: float = TIMEOUT_S) -> pa.Table:
    """Run read-only SQL; the result of its last statement as an Arrow table.

    Raises
    ------
    ParameterError
        As :func:`run`, and if the result has more than ``row_limit`` rows.
    """
    last = run(db, sql, row_limit=row_limit, timeout=timeout)[-1]
    if last.truncated:
        raise ParameterError(f"the query returns more than {row_limit} rows; narrow it or "
                             f"raise the limit")
    return last.table


def _failure(con: duckdb.DuckDBPyConnection, exc: duckdb.Error) -> str:
    """DuckDB's error on one line, saying what exists when a name is misspelt.

    DuckDB's first line names the error; its own suggestion ("Did you mean "avg"?") is on
    a later line, and for a column it offers only the tables in the query, not the one
    that has it: a misspelt table gets the list of tables, a misspelt column the columns
    of every table that are close to it.
    """
    lines = [line.strip() for line in str(exc).strip().splitlines() if line.strip()]
    if not lines:
        return type(exc).__name__
    # DuckDB calls an Arrow scan (each table here) a "values list".
    first = lines[0].replace("Values list ", "Table ")
    first += "" if first.endswith(("!", ".", "?")) else "."
    if _NO_TABLE.search(first):
        return f"{first} The tables: {', '.join(TABLES)}."
    column = _NO_COLUMN.search(first)
    if column is not None:
        close = _close_columns(con, column.group(1))
        where = f"Close to it: {'; '.join(close)}" if close else "No column is close to it"
        return f"{first} {where} (DESCRIBE <table> lists a table's columns)."
    hint = next((line for line in lines[1:] if line.startswith("Did you mean")), None)
    return f"{first} {hint}" if hint else first


def _close_columns(con: duckdb.DuckDBPyConnection, name: str, n: int = 5) -> list[str]:
    """Up to ``n`` columns of the database's tables spelt like ``name`` (case is ignored,
    as DuckDB does), closest first, each with the tables that have it:
    ``emotion (clips, animes)``, ``"lid_low_r.y" (frames)``."""
    tables: dict[str, list[str]] = {}
    for table in TABLES:
        for column in con.sql(f"SELECT * FROM {table} LIMIT 0").columns:
            tables.setdefault(column, []).append(table)
    by_key = {column.lower(): column for column in tables}
    close = difflib.get_close_matches(name.lower(), by_key, n=n, cutoff=0.7)
    # Named as SQL takes them: a channel such as lid_low_r.y needs double quotes.
    return [f"{_identifier(by_key[key])} ({', '.join(tables[by_key[key]])})" for key in close]


def _identifier(name: str) -> str:
    return name if name.isidentifier() else '"' + name.replace('"', '""') + '"'


def _first_line(exc: Exception) -> str:
    return str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
