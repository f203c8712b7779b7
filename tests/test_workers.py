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


def test_a_forked_child_computes_with_this_process_state():
    from ingest.workers import in_forked_child

    state = {"words": ["a", "b"]}  # what the child sees is a copy of this process
    value = in_forked_child(lambda: [(w, os.getpid()) for w in state["words"]])
    assert [w for w, _ in value] == ["a", "b"]
    assert all(pid != os.getpid() for _, pid in value)  # computed in another process


def test_a_forked_childs_errors_come_back():
    import pytest

    from db.errors import DataError
    from ingest.workers import ChildFailed, in_forked_child

    def runtime():
        raise RuntimeError("Final result does not match the grammar")

    with pytest.raises(ChildFailed, match="does not match the grammar") as caught:
        in_forked_child(runtime)
    assert isinstance(caught.value, RuntimeError)  # callers catching that keep working
    with pytest.raises(DataError, match="ValueError: bad"):
        in_forked_child(lambda: (_ for _ in ()).throw(ValueError("bad")))
    # A child killed (a Ctrl-C reaches the whole process group) leaves a readable error.
    import signal

    with pytest.raises(DataError, match=f"killed by signal {int(signal.SIGINT)}"):
        in_forked_child(lambda: os.kill(os.getpid(), signal.SIGINT))


def test_interrupt_awaited_only_in_work_run_in_a_worker_thread():
    from db.system import in_worker_thread, interrupt_awaited

    assert not interrupt_awaited()
    assert in_worker_thread(interrupt_awaited)
    assert not interrupt_awaited()  # the caller's context is left as it was


def test_librosa_s_gufuncs_are_compiled_into_the_cache_before_workers_start(tmp_path):
    # numba/numba#10128: workers compiling the same gufunc at once can leave a cache that
    # crashes every later call; the parent compiles them first, the workers only read.
    import subprocess
    import sys

    cache = tmp_path / "numba"
    code = "from ingest.workers import compile_shared_kernels; compile_shared_kernels()"
    subprocess.run([sys.executable, "-c", code], check=True, timeout=600,
                   env={**os.environ, "NUMBA_CACHE_DIR": str(cache)})
    names = {p.name for p in cache.rglob("*.nbi")}
    assert any("_pi_wrapper" in n for n in names), names  # yin's parabolic interpolation
    assert any("_zc_wrapper" in n for n in names), names  # zero crossings
    assert any("_localmin" in n for n in names), names  # yin's troughs


def test_clips_prepared_in_this_process_use_one_blas_thread_meanwhile():
    """``--workers 1``: the clips are prepared here with one BLAS thread, as a pool worker
    has; the writer's part after them gets the cores back."""
    import pytest
    from threadpoolctl import threadpool_limits

    from ingest.per_clip import _map

    with threadpool_limits(limits=2):
        before, _ = _thread_pools(None)
        if max(before, default=1) < 2:
            pytest.skip("numpy's BLAS here runs one thread: nothing to limit")
        seen = _map(_thread_pools, [0, 1], 1, None)
        after, _ = _thread_pools(None)
    assert [blas for blas, _ in seen] == [[1] * len(before)] * 2
    assert after == before
