"""Time the DTW audio cost (Eq. 5, ``animegraph.search.dtw``) against tslearn and librosa.

Usage::

    python scripts/bench_dtw.py [--sizes 10000 100000] [--input-frames 12]
                                [--ref-pairs 300] [--repeat 5] [--no-cold]

Prints microseconds per (input, anime) pair for ``audio_costs`` over random ragged
prosody curves (lengths 2-40, 9 coefficients, float32) against one input curve, serial
and parallel; the same per pair through Python (``audio_cost``, ``dtw``); tslearn's
``dtw`` and ``dtw_path`` (default backend dispatch, ``be="numpy"``, a ``Backend``
object) and ``librosa.sequence.dtw`` per pair; then the first ``audio_costs`` call in a
fresh process with numba's cache cold and warm. Best of ``--repeat`` runs; the load
average is printed since other processes on the machine skew every figure.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time

import numba
import numpy as np

from animegraph.search import dtw as dtw_module
from animegraph.search.dtw import audio_cost, audio_costs, dtw

_COLD_SNIPPET = """
import time
{preload}
t0 = time.perf_counter()
import numpy as np
from animegraph.search.dtw import audio_costs
t1 = time.perf_counter()
rng = np.random.default_rng(0)
lengths = rng.integers(2, 41, size={nodes})
offsets = np.zeros(len(lengths) + 1, np.int64)
np.cumsum(lengths, out=offsets[1:])
values = rng.standard_normal((offsets[-1], 9)).astype(np.float32)
x = rng.standard_normal((12, 9)).astype(np.float32)
t2 = time.perf_counter()
audio_costs(x, values, offsets, np.arange(len(lengths)))
t3 = time.perf_counter()
print(t1 - t0, t3 - t2)
"""


def _ragged(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    lengths = rng.integers(2, 41, size=n)
    offsets = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(lengths, out=offsets[1:])
    return rng.standard_normal((offsets[-1], 9)).astype(np.float32), offsets


def _best(func, repeat: int, *args) -> float:
    func(*args)  # compile / warm up
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        func(*args)
        best = min(best, time.perf_counter() - start)
    return best


def _per_pair(label: str, seconds: float, pairs: int) -> None:
    print(f"  {label:<46} {seconds / pairs * 1e6:10.2f} us/pair")


def _run(code: str, env: dict[str, str]) -> tuple[float, float]:
    out = subprocess.run([sys.executable, "-c", code], env=env, check=True,
                         capture_output=True, text=True)
    imp, first = map(float, out.stdout.split())
    return imp, first


def _cold_start(nodes: int) -> None:
    """First audio_costs call in fresh processes: empty numba cache, warm, in-tree cache."""
    code = _COLD_SNIPPET.format(nodes=nodes, preload="")
    kernel = "parallel" if nodes >= dtw_module._PARALLEL_MIN_NODES else "serial"
    print(f"first audio_costs call ({nodes} nodes, {kernel} kernel) in a fresh process")
    rows = []
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        rows.append(("cache cold (empty NUMBA_CACHE_DIR)", _run(code, env)))
        rows.append(("cache warm (same NUMBA_CACHE_DIR)", _run(code, env)))
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    _run(code, env)  # fills the in-tree cache if this source was never compiled here
    rows.append(("cache warm (in-tree __pycache__)", _run(code, env)))
    # numba's first use imports scipy.linalg (its BLAS check); a CLI that has already
    # imported scipy (librosa, scikit-learn) does not pay that again.
    preloaded = _COLD_SNIPPET.format(nodes=nodes, preload="import scipy.linalg")
    rows.append(("cache warm, scipy.linalg already imported", _run(preloaded, env)))
    for label, (imp, first) in rows:
        print(f"  {label:<46} import {imp:6.2f} s   first call {first:6.2f} s")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000])
    parser.add_argument("--input-frames", type=int, default=12)
    parser.add_argument("--ref-pairs", type=int, default=300,
                        help="pairs timed one by one for the per-pair figures")
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--no-cold", action="store_true", help="skip the cold-start runs")
    args = parser.parse_args()

    rng = np.random.default_rng(0)
    x = rng.standard_normal((args.input_frames, 9)).astype(np.float32)
    threads = numba.get_num_threads()
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cpus; numba "
          f"{numba.__version__}, {threads} threads; input {args.input_frames} frames, "
          "anime curves 2-40 frames x 9")

    for n in args.sizes:
        values, offsets = _ragged(rng, n)
        nodes = np.arange(n)
        print(f"audio_costs over {n} nodes")
        numba.set_num_threads(1)  # audio_costs goes serial on one thread
        serial = _best(audio_costs, args.repeat, x, values, offsets, nodes)
        numba.set_num_threads(threads)
        _per_pair("serial kernel", serial, n)
        parallel = _best(audio_costs, args.repeat, x, values, offsets, nodes)
        _per_pair(f"parallel kernel ({threads} threads)", parallel, n)
        print(f"  {'per call (parallel)':<46} {parallel * 1e3:10.2f} ms")

    values, offsets = _ragged(rng, args.ref_pairs)
    curves = [values[offsets[a]:offsets[a + 1]] for a in range(args.ref_pairs)]
    curves64 = [c.astype(np.float64) for c in curves]
    x64 = x.astype(np.float64)
    pairs = len(curves)
    print(f"one pair at a time ({pairs} pairs)")
    _per_pair("animegraph audio_cost (Eq. 5, Python call)",
              _best(lambda: [audio_cost(x, c) for c in curves], args.repeat), pairs)
    _per_pair("animegraph dtw (cost + path)",
              _best(lambda: [dtw(x, c) for c in curves], args.repeat), pairs)

    from tslearn.backend import Backend
    from tslearn.metrics import dtw as ts_dtw
    from tslearn.metrics import dtw_path as ts_dtw_path

    backend = Backend("numpy")
    _per_pair("tslearn dtw, be=None (backend from the arrays)",
              _best(lambda: [ts_dtw(x64, c) for c in curves64], 1), pairs)
    _per_pair('tslearn dtw, be="numpy"',
              _best(lambda: [ts_dtw(x64, c, be="numpy") for c in curves64], args.repeat), pairs)
    _per_pair("tslearn dtw, be=Backend('numpy')",
              _best(lambda: [ts_dtw(x64, c, be=backend) for c in curves64], args.repeat), pairs)
    _per_pair("tslearn dtw_path, be=Backend('numpy')",
              _best(lambda: [ts_dtw_path(x64, c, be=backend) for c in curves64], args.repeat),
              pairs)

    import librosa

    xt = np.ascontiguousarray(x64.T)
    cts = [np.ascontiguousarray(c.T) for c in curves64]
    _per_pair("librosa.sequence.dtw (cost + path)",
              _best(lambda: [librosa.sequence.dtw(xt, c) for c in cts], args.repeat), pairs)
    _per_pair("librosa.sequence.dtw, backtrack=False",
              _best(lambda: [librosa.sequence.dtw(xt, c, backtrack=False) for c in cts],
                    args.repeat), pairs)

    if not args.no_cold:
        _cold_start(10)
        _cold_start(1000)
        from animegraph.search.jit import cache_folder

        folder = cache_folder()
        print(f"numba cache files of animegraph/search/dtw.py: "
              f"{len(list(folder.rglob('dtw.*.nb*'))) if folder else 0} in {folder}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
