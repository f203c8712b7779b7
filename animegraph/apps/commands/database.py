"""The database commands: ``ingest`` (clips into a database), ``sql`` and ``query``
(reading it), ``fit`` (a baseline stored in it) and ``info`` (what it holds)."""

from __future__ import annotations

import argparse
import sys
from contextlib import contextmanager
from types import SimpleNamespace

from animegraph.apps.commands.common import UsageError, progress, say


def cmd_ingest(args: argparse.Namespace) -> int:
    from db.errors import ParameterError
    from ingest.pipeline import IngestConfig, ingest
    from ingest.plausible import MAX_SPEED_CEILING_MM_S, Limits

    try:  # Limits bounds it (above 0, at most its ceiling): said as the option
        limits = None if args.max_speed is None else Limits(max_speed_mm_s=args.max_speed)
    except ParameterError:
        raise UsageError(f"animegraph ingest: --max-speed must be above 0 and at most "
                         f"{MAX_SPEED_CEILING_MM_S:g} mm/s (no part of a face moves faster), "
                         f"got {args.max_speed:g}") from None
    config = IngestConfig(variance=args.variance, fps=args.fps,
                          correct_lag=not args.no_lag_correction,
                          phones_engine=args.phones_engine, limits=limits,
                          posteriorgrams=args.posteriorgrams)
    wait = {} if args.wait is None else {"wait": args.wait}

    cluster = None
    if args.scheduler is not None:
        from animegraph.apps.batch_cluster import CONNECT_TIMEOUT_S, dask_client

        options = SimpleNamespace(scheduler=args.scheduler, workers=args.workers,
                                  connect_timeout=CONNECT_TIMEOUT_S)

        @contextmanager
        def cluster():  # entered for the clips only: the database is written without it
            with dask_client(options) as (client, n_workers):
                if not args.quiet:
                    say(f"ingest: preparing the clips on {n_workers} Dask worker"
                        f"{'s' * (n_workers != 1)} at {args.scheduler}")
                yield client

    report = ingest(args.sources, args.db, config, workers=args.workers, cluster=cluster,
                    progress=lambda total: progress(total, args.quiet, "clip",
                                                    "ingest: reading clips"),
                    say=None if args.quiet else say, **wait)
    for line in report.lines():
        print(line)
    if not args.no_prepare:
        _prepare(args.db, args.quiet, args.wait, "ingest: ")
    return 1 if report.count("rejected") else 0


def _prepare(db, quiet: bool, wait: float | None, step: str = "") -> None:
    """The database ready for its first synth (:mod:`animegraph.apps.prepare`), under its
    writer lock: the guides are fitted on the version they are stored with."""
    from animegraph.apps.prepare import prepare
    from db.lock import writer_lock
    from db.store import is_database

    if not is_database(db):  # nothing went in (every clip rejected)
        return
    with writer_lock(db, wait=600.0 if wait is None else wait, what="database"):
        try:
            prepare(db, (lambda line: None) if quiet else (lambda line: say(f"{step}{line}")))
        except KeyboardInterrupt:  # what is written stays: say what is not done
            say(f"{db} is written; what was not fitted or compiled is left to the first "
                "synth (or 'animegraph warmup')")
            raise


#: The columns of DuckDB's EXPLAIN (and EXPLAIN ANALYZE) result.
EXPLAIN_COLUMNS = ["explain_key", "explain_value"]


def cmd_sql(args: argparse.Namespace) -> int:
    from animegraph.apps.tabular import format_for, format_table, visible
    from db.sql import MAX_TIMEOUT_S, ROW_LIMIT, TIMEOUT_S, run
    from db.store import Database

    # -o hits.csv writes CSV: an aligned text table under that name (cut at --max-rows)
    # would be no CSV at all.
    fmt = format_for(args.format, args.output)
    if fmt == "parquet" and args.output is None:
        raise UsageError("animegraph sql: --format parquet needs --output FILE")
    if args.limit is not None and args.limit < 1:
        raise UsageError(f"animegraph sql: --limit must be at least 1, got {args.limit}")
    if args.timeout is not None and not 0 < args.timeout <= MAX_TIMEOUT_S:
        raise UsageError(f"animegraph sql: --timeout must be more than 0 and at most "
                         f"{MAX_TIMEOUT_S:g} seconds, got {args.timeout:g}")
    limit = ROW_LIMIT if args.limit is None else args.limit
    results = run(Database.open(args.db), args.query, row_limit=limit,
                  timeout=TIMEOUT_S if args.timeout is None else args.timeout)
    if args.output is not None and len(results) > 1:
        raise UsageError(f"animegraph sql: --output takes one statement, got {len(results)}")
    for i, result in enumerate(results):
        if i and fmt == "table":
            sys.stdout.write("\n")
        if fmt == "table" and result.table.column_names == EXPLAIN_COLUMNS:
            # A plan is a drawing over many lines: a table cell would show its first.
            text = "".join(f"{visible(line)}\n" for value in result.table.column(1).to_pylist()
                           for line in value.splitlines())
        else:
            text = format_table(result.table, fmt, max_rows=args.max_rows,
                                output=args.output, truncated=result.truncated)
        if text is not None:
            sys.stdout.write(text)
        if result.truncated:
            print(f"animegraph sql: only the first {limit} row{'s' * (limit != 1)} "
                  f"{'were' if limit != 1 else 'was'} read (raise --limit)",
                  file=sys.stderr)
    return 0


def cmd_query(args: argparse.Namespace) -> int:
    from animegraph.apps.query import (
        QuerySpec,
        build_sql,
        check_export,
        export_hits,
        in_database,
        run_query,
    )
    from animegraph.apps.tabular import format_table
    from db.store import Database

    spec = QuerySpec(phoneme=args.phoneme, emotion=args.emotion, text=args.text,
                     speaker=args.speaker, min_dur=args.min_dur, order_by=args.order_by,
                     descending=args.desc, limit=args.limit, clips=args.clips)
    if args.show_sql:
        # The database's spelling of the emotion and speaker: the SQL finds what the
        # query finds.
        needs_db = spec.emotion is not None or spec.speaker is not None
        print(build_sql(in_database(Database.open(args.db), spec) if needs_db else spec))
        return 0
    if args.export is not None:
        check_export(args.export, context=args.context, force=args.force)
    db = Database.open(args.db)
    hits = run_query(db, spec)
    shown = hits.drop_columns([c for c in ("corpus",) if c in hits.column_names]) \
        if args.format == "table" else hits
    sys.stdout.write(format_table(shown, args.format, max_rows=max(1, hits.num_rows)))
    if args.export is not None:
        rows = export_hits(db, hits, args.export, context=args.context, force=args.force,
                           progress=lambda total: progress(total, args.quiet, "hit",
                                                           "exporting"))
        print(f"animegraph: exported {len(rows)} hit{'s' * (len(rows) != 1)} to "
              f"{args.export} (index.csv)",
              file=sys.stderr)
    return 0


def cmd_fit(args: argparse.Namespace) -> int:
    import time

    from animegraph.baselines.base import fitted_model, model_path

    t0 = time.perf_counter()
    fitted_model(args.db, args.method, refit=True)
    print(f"fitted {args.method} on {args.db} in {time.perf_counter() - t0:.1f} s; stored "
          f"{model_path(args.db, args.method)}")
    return 0


def cmd_warmup(args: argparse.Namespace) -> int:
    import time

    from db.errors import DataError
    from db.store import is_database

    if not is_database(args.db):
        raise DataError(f"no database at {args.db}")
    t0 = time.perf_counter()
    _prepare(args.db, False, 0.0)
    print(f"{args.db} is ready for synth ({time.perf_counter() - t0:.1f} s)")
    return 0


def cmd_info(args: argparse.Namespace) -> int:
    import json

    from animegraph.apps.info import database_info, info_lines
    from animegraph.apps.tabular import visible
    from db.store import Database

    info = database_info(Database.open(args.db))
    info["chosen_by"] = args.db_source
    if args.json:
        print(json.dumps(info, indent=1))
    else:
        for line in info_lines(info):
            print(visible(line))
    return 0
