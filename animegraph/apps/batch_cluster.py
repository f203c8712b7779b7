"""The Dask cluster ``animegraph batch`` (:mod:`animegraph.apps.batch`) runs its lines on
(a new local one, or an existing one at a scheduler's address), and ``animegraph ingest
--scheduler`` prepares its clips on (:mod:`ingest.on_dask`)."""

from __future__ import annotations

import logging
import multiprocessing
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager

from db.errors import DataError
from ingest.workers import sigint_ignored_by_children

logger = logging.getLogger(__name__)

#: Longest wait for a local cluster's workers to start (a bound against a hang).
WORKER_START_TIMEOUT_S = 300.0
#: Seconds to wait for an existing scheduler (and for it to have a worker).
CONNECT_TIMEOUT_S = 5.0
#: The loggers a local cluster speaks through while it is stopped (tornado's "Exception
#: in callback" among them; Dask's configuration sets tornado.application's own level).
_DASK_LOGGERS = ("distributed", "tornado", "tornado.application", "asyncio")
#: Dask's settings for a local cluster (its scheduler and nannies live in this process,
#: its workers are given this process' settings). At Dask's defaults every server's event
#: loop wakes 50 times a second to time itself, each worker samples its threads' stacks
#: 100 times a second for a profile only a dashboard shows (there is none), the memory
#: monitors look 10 times a second and the scheduler moves tasks between workers: all
#: CPU spent for as long as the cluster is up, busy or not (``docs/results/speed.md``,
#: "Ingest on Dask"). The clips' tasks are alike and independent, and a worker's memory
#: is checked often enough every second.
LOCAL_CLUSTER_CONFIG = {
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "2s",
    "distributed.admin.system-monitor.disk": False,
    "distributed.admin.system-monitor.gil.enabled": False,
    "distributed.worker.profile.enabled": False,
    "distributed.worker.memory.monitor-interval": "1s",
    "distributed.scheduler.work-stealing": False,
    "distributed.scheduler.active-memory-manager.start": False,
    # Dask's default also sets MALLOC_TRIM_THRESHOLD_=65536 in its workers: glibc then
    # gives freed memory back to the system at once and takes it again for the next
    # frame's arrays (page faults, system time); a clip cost its worker 76 ms of CPU
    # against 57.6 in a pool worker. The native thread pools keep one thread each.
    "distributed.nanny.pre-spawn-environ": {
        "OMP_NUM_THREADS": 1, "MKL_NUM_THREADS": 1, "OPENBLAS_NUM_THREADS": 1},
}


@contextmanager
def dask_client(options, *, prepare: Callable[[], object] | None = None
                ) -> Iterator[tuple[object, int]]:
    """A Dask client: of a new local cluster of ``options.workers`` processes (one thread
    each, numba single-threaded), or of the cluster at ``options.scheduler``.

    ``prepare()`` runs once the scheduler is known to be reachable and before a local
    cluster's workers start. Yields (client, number of workers).

    Raises
    ------
    DataError
        The scheduler cannot be reached within ``options.connect_timeout`` seconds, or
        has no worker.
    """
    import distributed  # noqa: F401  (first: importing it sets its loggers' levels)

    quiet = logging.getLogger("distributed")
    level = quiet.level
    if not logger.isEnabledFor(logging.DEBUG):
        quiet.setLevel(logging.ERROR)  # Dask's news of its own start and stop
    try:
        with _client(options, prepare) as client:
            yield client, len(client.scheduler_info()["workers"])
    finally:
        quiet.setLevel(level)


@contextmanager
def _client(options, prepare: Callable[[], object] | None):
    import dask
    from distributed import Client, LocalCluster

    cluster = client = None
    before = set(multiprocessing.active_children())
    quiet: dict[str, int] = {}
    # Left last (after the cluster is closed): its settings are the cluster's while it is up.
    settings = ExitStack()
    try:
        if options.scheduler:
            address = options.scheduler
            # Made in two steps so that a Client that fails to connect can be closed here:
            # left to the garbage collector, it waits 10 s for its stopped event loop
            # and prints a traceback ("Exception ignored in: Client.__del__").
            client = Client.__new__(Client)
            try:
                client.__init__(address, timeout=options.connect_timeout,
                                set_as_default=False)
            except (OSError, TimeoutError, ValueError) as exc:
                _close_unconnected(client)
                client = None
                raise DataError(f"cannot reach the Dask scheduler at {address}: {exc}; give "
                                "the address of a running one, e.g. tcp://127.0.0.1:8786"
                                ) from None
            try:
                client.wait_for_workers(1, timeout=options.connect_timeout)
            except (OSError, TimeoutError) as exc:
                raise DataError(f"the Dask scheduler at {options.scheduler} has no workers "
                                f"({type(exc).__name__})") from None
            if prepare is not None:
                prepare()
        else:
            if prepare is not None:
                prepare()
            from ingest.workers import compile_shared_kernels

            compile_shared_kernels()  # the local workers share this installation's caches
            settings.enter_context(dask.config.set(LOCAL_CLUSTER_CONFIG))
            cluster = LocalCluster(
                n_workers=0, threads_per_worker=1, processes=True,
                # CRITICAL: a worker busy in a line when a Ctrl-C closes the scheduler
                # logs its failed heartbeat as an ERROR with a traceback; a line's own
                # errors come back through its future, not through the workers' logs.
                dashboard_address=None, silence_logs=logging.CRITICAL,
                # No dashboard, and the scheduler's own HTTP server (which it starts even
                # so, on 8787 by default) on a free local port: a second cluster said
                # "Port 8787 is already in use".
                scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"},
                # One core per worker: numba's own threads would compete with the others.
                env={"NUMBA_NUM_THREADS": "1"},
            )
            client = Client(cluster, set_as_default=False)
            # The worker processes are born ignoring SIGINT (a terminal's Ctrl-C reaches
            # the whole process group): a Ctrl-C ends the batch here, and the batch ends
            # the workers. Ignored only until they exist, so no Ctrl-C goes unseen for long.
            with sigint_ignored_by_children():
                started = set(multiprocessing.active_children())
                cluster.scale(options.workers)
                deadline = time.monotonic() + options.connect_timeout
                while (len(set(multiprocessing.active_children()) - started) < options.workers
                       and time.monotonic() < deadline):
                    time.sleep(0.01)
            try:
                client.wait_for_workers(options.workers, timeout=WORKER_START_TIMEOUT_S)
            except TimeoutError:
                raise DataError(f"the {options.workers} local Dask workers did not start "
                                f"within {WORKER_START_TIMEOUT_S:.0f} s") from None
        yield client
    except KeyboardInterrupt:
        if cluster is not None:
            # Quiet until the cluster is closed: a nanny whose worker is ended while it
            # starts says so with a traceback (through tornado's logger), and nothing is
            # wrong: the batch is being stopped.
            quiet = {name: logging.getLogger(name).level for name in _DASK_LOGGERS}
            for name in quiet:
                logging.getLogger(name).setLevel(logging.CRITICAL + 1)
            _end_workers_now(cluster, set(multiprocessing.active_children()) - before)
        raise
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
        settings.close()
        for name, level in quiet.items():
            logging.getLogger(name).setLevel(level)


def _end_workers_now(cluster, processes) -> None:
    """Ctrl-C: end a local cluster's worker processes at once. Closed gracefully, the
    cluster waited for each worker to finish and say so (6 s of a 2-worker batch after
    the Ctrl-C, and a closing worker's comm could raise CommClosedError); its nannies are
    told first that a worker's end is no reason to start another."""
    from ingest.workers import end_workers

    for nanny in list(getattr(cluster, "workers", {}).values()):
        close_gracefully = getattr(nanny, "close_gracefully", None)
        if close_gracefully is not None:  # a Nanny (a Worker in threads has none)
            close_gracefully(reason="animegraph batch interrupted")
    end_workers(processes)


def _close_unconnected(client) -> None:
    """Close a Client whose constructor failed, quietly."""
    try:
        client.close(timeout=1)
    except Exception:  # half made: whatever it lacks, it is no longer used
        logger.debug("closing an unconnected Dask client", exc_info=True)
