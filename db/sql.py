"""SQL over the motion database: DuckDB views on the live version's Parquet files.

Each table of :mod:`db.store` is a view of the same name (``clips``, ``animes``,
``frames``, ``audio``, ``channels``, ``model_arrays``, ``components``). Queries are
read-only: only ``SELECT`` (with ``WITH``, ``DESCRIBE``, ``SHOW``, ``SUMMARIZE``) and
``EXPLAIN`` statements run; anything that could write (``COPY``, ``CREATE``,
``INSERT``, ``ATTACH``, ``SET`` ...) is refused before it is executed.
"""

from __future__ import annotations

import os

import duckdb
import pyarrow as pa

from db.errors import DataError, ParameterError
from db.store import FILE_TABLES, PARTITIONED, TABLES, Database

_ALLOWED = {duckdb.StatementType.SELECT, duckdb.StatementType.EXPLAIN}


def connect(db: Database) -> duckdb.DuckDBPyConnection:
    """An in-memory DuckDB connection with a view per table of ``db``."""
    con = duckdb.connect(":memory:")
    for name in TABLES:
        path = db.table_path(name)
        if name in FILE_TABLES:
            source = f"read_parquet('{_quote(path)}')"
        else:
            hive = ", hive_partitioning = true" if name in PARTITIONED else ""
            source = f"read_parquet('{_quote(path)}/**/*.parquet'{hive})"
        con.execute(f'CREATE VIEW "{name}" AS SELECT * FROM {source}')
    return con


def _quote(path: os.PathLike) -> str:
    return str(path).replace("'", "''")


def check_read_only(sql: str) -> None:
    """Raise ParameterError unless every statement of ``sql`` only reads."""
    try:
        statements = duckdb.extract_statements(sql)
    except duckdb.Error as exc:
        raise ParameterError(f"SQL does not parse: {_first_line(exc)}") from None
    if not statements:
        raise ParameterError("SQL is empty")
    for statement in statements:
        if statement.type not in _ALLOWED:
            kind = statement.type.name
            raise ParameterError(f"only SELECT queries run here (the database is read-only); "
                                 f"got a {kind} statement")


def query(db: Database, sql: str) -> pa.Table:
    """Run a read-only query; the result of its last statement as an Arrow table.

    Raises
    ------
    ParameterError
        If the SQL writes, or fails (unknown column, type error ...): the message is
        DuckDB's first line.
    """
    check_read_only(sql)
    con = connect(db)
    try:
        statements = duckdb.extract_statements(sql)
        for statement in statements[:-1]:
            con.execute(statement.query)
        relation = con.sql(statements[-1].query)
        # DuckDB 2 renamed a relation's arrow() to to_arrow_table().
        fetch = getattr(relation, "to_arrow_table", None) or relation.arrow
        return fetch()
    except duckdb.Error as exc:
        raise ParameterError(f"query failed: {_first_line(exc)}") from None
    except OSError as exc:
        raise DataError(f"database {db.root} could not be read: {exc}") from exc
    finally:
        con.close()


def _first_line(exc: Exception) -> str:
    return str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
