"""Worker processes share the cores out: each one's native thread pools are limited."""

from __future__ import annotations

import os

from ingest.workers import map_in_processes, threads_per_worker


def _thread_pools(_job) -> tuple[list[int], str | None]:
    import numpy  # noqa: F401  (loads the BLAS if the worker has not yet)
    from threadpoolctl import threadpool_info

    blas = [pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"]
    return blas, os.environ.get("OMP_NUM_THREADS")


def test_each_worker_gets_its_share_of_the_cores():
    from threadpoolctl import threadpool_info

    own = [pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"]
    share = threads_per_worker(2)
    for blas, omp in map_in_processes(_thread_pools, [0, 1, 2, 3], workers=2):
        assert blas, "numpy's BLAS was not found in the worker"
        # Never more than the share; the BLAS may be built for fewer threads than that.
        assert all(n == min(share, max(own)) for n in blas), (blas, share, own)
        assert omp == str(share)


def test_pools_loaded_before_the_limit_are_limited_too():
    """numba and the BLAS already loaded (a worker's main module may import them) obey
    the limit; run apart, so that this test process keeps its own threads."""
    import subprocess
    import sys

    code = ("import numba, numpy\n"
            "from threadpoolctl import threadpool_info\n"
            "from ingest.workers import limit_threads\n"
            "limit_threads(1)\n"
            "print(numba.get_num_threads(), "
            "max(p['num_threads'] for p in threadpool_info()))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split()
    assert out == ["1", "1"], out


def test_thread_budget_follows_omp_num_threads(monkeypatch):
    from db.system import thread_budget, usable_cpus

    for given, expected in (("3", 3), ("0", 1), (" 2 ", 2), ("lots", usable_cpus()),
                            ("", usable_cpus())):
        monkeypatch.setenv("OMP_NUM_THREADS", given)
        assert thread_budget() == expected, given
    monkeypatch.delenv("OMP_NUM_THREADS")
    assert thread_budget() == usable_cpus()


def test_what_ended_workers_left_is_not_reported_after_the_program_ends(tmp_path):
    """Workers ended at a Ctrl-C leave named semaphores, which multiprocessing's resource
    tracker unlinks once the program is gone; it also warned of each on the terminal,
    after 'animegraph: interrupted' (seen in a fresh environment). A pool started by
    map_in_processes quiets that report, and only that."""
    import subprocess
    import sys

    code = ("import os, multiprocessing as mp\n"
            "from ingest.workers import map_in_processes\n"
            "map_in_processes(abs, [-1, 2], workers=1)\n"
            "leaked = mp.get_context('spawn').Semaphore(1)\n"  # a worker killed mid-job's
            "os._exit(0)\n")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONWARNINGS"}
    err = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=env, cwd=tmp_path, check=True).stderr
    assert "resource_tracker" not in err, err
