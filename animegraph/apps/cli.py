"""The ``animegraph`` command-line tool.

Every user error (a bad option, a missing file, an impossible size) ends as one line
on stderr and a non-zero exit; tracebacks are kept for bugs.

Here: :func:`main` (the entry point), the exit statuses, Ctrl-C and logging. The options
and their help are :mod:`animegraph.apps.cli_parser`'s; what each command does, the
modules of :mod:`animegraph.apps.commands`.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import signal
import sys
import threading
from collections.abc import Sequence

from animegraph.apps.cli_parser import (
    HELPER_CHOICES,
    SYNTH_AUDIO_COSTS,
    SYNTH_GUIDES,
    build_parser,
)
from animegraph.apps.commands.common import UsageError
from db.errors import AnimeGraphError

#: What scripts and tests import from here (the parser's and the commands' own names
#: are in :mod:`animegraph.apps.cli_parser` and :mod:`animegraph.apps.commands`).
__all__ = ["HELPER_CHOICES", "SYNTH_AUDIO_COSTS", "SYNTH_GUIDES", "UsageError", "build_parser",
           "main"]


def _resolve_db(args: argparse.Namespace) -> None:
    """Fill in a left-out ``--db``; say how to make one if it does not exist yet."""
    from animegraph.apps.cache import default_database
    from db.errors import DataError
    from db.store import is_database

    args.db_source = "--db"
    if args.db is not None:
        return
    args.db, args.db_source = default_database()
    if not is_database(args.db):
        how = ("run 'animegraph demo' to build it" if args.db_source.startswith("the demo")
               else f"run 'animegraph ingest SRC --db {args.db}' to build it")
        raise DataError(f"no --db given, and {args.db_source} ({args.db}) does not exist "
                        f"yet: {how}, or give --db DB")


class _LogFormatter(logging.Formatter):
    """``animegraph: warning: ...``: the style of the lines the commands print."""

    def formatMessage(self, record: logging.LogRecord) -> str:  # noqa: N802 (logging's name)
        return f"animegraph: {record.levelname.lower()}: {record.getMessage()}"


def _configure_logging(verbosity: int) -> None:
    level = logging.WARNING if verbosity == 0 else logging.INFO if verbosity == 1 else logging.DEBUG
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(_LogFormatter())
    logging.basicConfig(level=level, handlers=[handler])


def _on_interrupt(signum, frame) -> None:
    # The first Ctrl-C stops the work; later ones must not cut short the cleanup that
    # follows (ending worker processes, removing a half-built folder): they are ignored
    # until main() returns.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    raise KeyboardInterrupt


def _error_line(message: str) -> str:
    """The one error style: ``animegraph: error: [COMMAND: ]MESSAGE``."""
    if message.startswith("animegraph: "):
        message = message[len("animegraph: "):]
    elif message.startswith("animegraph "):
        message = message[len("animegraph "):]
    return f"animegraph: error: {message}"


def main(argv: Sequence[str] | None = None) -> int:
    """Run the tool; return the exit status (0, 1 bad input or data, 2 usage, 130 Ctrl-C)."""
    in_main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, _on_interrupt) if in_main else None
    try:
        status = _main(argv)
    except KeyboardInterrupt:
        # SIGINT stays ignored: the process is on its way out, and a Ctrl-C now would
        # turn the exit into a death by signal.
        return _interrupted()
    except BaseException:  # a bug: the caller (a test, a notebook) gets its handler back
        if previous is not None:
            signal.signal(signal.SIGINT, previous)
        raise
    if previous is not None:
        signal.signal(signal.SIGINT, previous)
    return status


def entry() -> None:
    """The ``animegraph`` program (and ``python -m animegraph``): :func:`main`, its status
    the process' exit status.

    After a Ctrl-C the process ends at once (``os._exit``) once the output is flushed:
    the work's own cleanup (workers ended, half-built folders removed, the batch's report
    written) ran while the interrupt unwound, and what was left was the interpreter's
    teardown of the loaded libraries, 2.5 s after a Dask batch, which a user who pressed
    Ctrl-C should not wait for. :func:`main` itself returns, for a caller in-process.
    """
    # main() hands back the handler it found: ignoring, so that a Ctrl-C just as the
    # command ends (an ingest that had written its database) is not a death by signal.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    status = main()
    if status == 130:
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(OSError, ValueError):
                stream.flush()
        logging.shutdown()
        os._exit(status)
    sys.exit(status)


def _interrupted() -> int:
    with contextlib.suppress(OSError):
        print("animegraph: interrupted", file=sys.stderr)
    return 130


def _main(argv: Sequence[str] | None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        _configure_logging(args.verbose)
        if args.command is None:
            raise UsageError("animegraph: choose a command: corpus, demo, ingest, synth, "
                             "batch, live, fit, warmup, sql, query, render, plot, classify, "
                             "map-emotion, emotion, info, studio "
                             "(see 'animegraph --help')")
        if not hasattr(args, "func"):
            raise UsageError(f"animegraph {args.command}: choose an action "
                             f"(see 'animegraph {args.command} --help')")
        # classify --model reads no database.
        if getattr(args, "default_db", False) and getattr(args, "model", None) is None:
            _resolve_db(args)
        return int(args.func(args) or 0)
    except UsageError as exc:
        print(_error_line(str(exc)), file=sys.stderr)
        return 2
    except AnimeGraphError as exc:
        print(_error_line(str(exc)), file=sys.stderr)
        return 1
    except BrokenPipeError:
        # The reader went away (``animegraph sql ... | head``): not an error.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except OSError as exc:
        # Disk full, permission denied, a folder vanished: the environment, not a bug.
        where = f" {exc.filename}:" if exc.filename else ""
        print(f"animegraph: error:{where} {exc.strerror or exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    entry()
