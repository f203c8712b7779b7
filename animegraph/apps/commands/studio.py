"""``animegraph studio``: the local web app over a database (:mod:`animegraph.apps.studio`)."""

from __future__ import annotations

import argparse
import errno
import signal

from animegraph.apps.commands.common import UsageError


def cmd_studio(args: argparse.Namespace) -> int:
    try:
        from animegraph.apps.studio.server import serve
    except ImportError as exc:  # aiohttp is a dependency; a broken install says so
        raise UsageError(f"animegraph studio: {exc} (pip install aiohttp)") from None

    if not 0 <= args.port <= 65535:
        raise UsageError(f"animegraph studio: --port must be 0 to 65535, got {args.port}")

    def stop(signum, frame):
        raise KeyboardInterrupt

    # SIGTERM (a service manager, a test) stops it as Ctrl-C does: the temporary folder
    # of uploads and outputs is removed on the way out.
    previous = signal.signal(signal.SIGTERM, stop)
    try:
        serve(args.db, port=args.port, open_browser=not args.no_browser,
              say=lambda line: print(line, flush=True))
    except KeyboardInterrupt:
        print("animegraph: studio stopped", flush=True)
    except OSError as exc:
        if exc.errno not in (errno.EADDRINUSE, errno.EACCES):
            raise
        why = "is in use" if exc.errno == errno.EADDRINUSE else "may not be used by you"
        raise UsageError(f"animegraph studio: port {args.port} {why}: choose another "
                         "--port, or --port 0 for any free one") from None
    finally:
        signal.signal(signal.SIGTERM, previous)
    return 0
