"""Synthesis against databases of up to 100 hours: load time, memory and latency.

Usage::

    python scripts/bench_scale.py [--db BASE] [--sizes 10000 100000 1000000 4000000]
                                  [--work DIR] [--keep] [--max-rss-gb 8] [--repeats 2]
                                  [--json OUT] [--after JSON] [--reuse]
                                  [--modes eager cold warm] [--load-only]
                                  [--kbest-all] [--no-exact]

For each size, a database is written on disk (``--work``, a temporary folder by default,
removed at the end unless ``--keep``) whose animes and clips replicate those of BASE (the
default database of ``animegraph demo`` when left out) as ``scripts/bench_search.py``
replicates its graphs: each copy's clips are new clips (``<clip>#r<k>``), every boundary
frame (a node's last frame and its successor's first, ``first_pcs``/``last_pcs``) moved
by Gaussian noise of 0.1 x the per-component spread, so no two copies coincide. The
``frames`` and ``audio`` tables are BASE's alone (``synth`` reads neither; replicated they
would take 38 GB at 4M animes). 100 hours of speech are about 4M animes (the default
database: 10,512 animes in 991 s).

Each size is built, then measured, in a fresh process: :meth:`animegraph.synthesis.Model.load` (what
``synth`` loads before it hears the speech), the resident memory after it and the peak of
the whole process, then :func:`animegraph.synthesis.synthesize` of a 10 s eSpeak NG line
given its own phone labels (the segmentation's cost does not depend on the database) with
``synth``'s default k-best blending (20 animes a phone, the search over each phone's
shortlist; with ``--kbest-all`` also over every candidate; the guide, a fitted model's
forward pass whose cost does not grow with the database, is left out) and the exact
search alone (one anime a phone, ``--exact``'s search), ``--repeats`` times each (the
first pays numba's cache load; the best is reported). Latency is wall time, CPU is every
thread's. Before a size is loaded its peak memory is projected from the size before it
(linear in animes): a size projected above ``--max-rss-gb`` is built but not loaded.

``--modes`` says how the graph is loaded (:mod:`animegraph.search.mapped`), each in its
own process: ``eager`` converts it from Parquet at every load (no cache), ``cold``
converts it and writes its cache (removed first), ``warm`` maps the cache written
before (``$ANIMEGRAPH_CACHE/graphs``, 0.3 to 2.1 kB an anime). ``--reuse`` measures a
database already at ``--work``/db-SIZE instead of writing it; ``--load-only`` leaves out
the synthesis.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

#: About 10 s of eSpeak NG speech (the sentence of ``scripts/bench_e2e.py``).
TEXT = ("The quick brown fox jumps over the lazy dog while the children watch from the "
        "garden, and everybody laughs when the old farmer finally catches it near the river.")


def _list_values(column: pa.ChunkedArray) -> tuple[np.ndarray, pa.Array]:
    """A list<float> column of equal-length rows: (values (n, k) float32, its offsets)."""
    flat = column.combine_chunks()
    values = flat.flatten().to_numpy(zero_copy_only=False).astype(np.float32)
    return values.reshape(len(flat), -1), flat.offsets


def replicate_tables(tables: dict[str, pa.Table], copies: int,
                     rng: np.random.Generator) -> dict[str, pa.Table]:
    """``copies`` replicas of the animes and clips of ``tables`` (the first unchanged)."""
    animes, clips = tables["animes"], tables["clips"]
    n = animes.num_rows
    node_id = animes.column("node_id").to_numpy()
    order = np.argsort(node_id)
    if not np.array_equal(node_id[order], np.arange(n)):
        raise SystemExit("bench_scale: the base's node ids are not 0..n-1")
    nxt = animes.column("next_node").to_numpy(zero_copy_only=False)
    nxt = np.where(np.isnan(nxt), -1, nxt).astype(np.int64) if nxt.dtype.kind == "f" else nxt
    first, offsets = _list_values(animes.column("first_pcs"))
    last, _ = _list_values(animes.column("last_pcs"))
    sigma = 0.1 * np.concatenate([first, last]).std(axis=0)
    row_of = np.empty(n, dtype=np.int64)  # table row of each node id
    row_of[node_id] = np.arange(n)
    has_next = nxt >= 0
    succ_row = row_of[nxt[has_next]]  # the row of each row's successor
    a_parts, c_parts = [], []
    for r in range(copies):
        a, c = animes, clips
        if r:
            shift = pa.scalar(r * n, pa.int64())
            suffix = f"#r{r}"
            noise_last = (rng.standard_normal(last.shape) * sigma).astype(np.float32)
            noise_first = (rng.standard_normal(first.shape) * sigma).astype(np.float32)
            noise_first[succ_row] = noise_last[has_next]
            a = a.set_column(a.schema.get_field_index("node_id"), "node_id",
                             pc.add(a.column("node_id"), shift))
            for name in ("prev_node", "next_node"):
                col = a.column(name)
                moved = pc.if_else(pc.greater_equal(col, 0), pc.add(col, shift), col)
                a = a.set_column(a.schema.get_field_index(name), name, moved)
            for name, base, noise in (("first_pcs", first, noise_first),
                                      ("last_pcs", last, noise_last)):
                values = pa.array((base + noise).ravel(), pa.float32())
                a = a.set_column(a.schema.get_field_index(name), name,
                                 pa.ListArray.from_arrays(offsets, values))
            for t_name in ("a", "c"):
                t = a if t_name == "a" else c
                col = pc.binary_join_element_wise(t.column("clip_id"), pa.scalar(suffix), "")
                t = t.set_column(t.schema.get_field_index("clip_id"), "clip_id", col)
                if t_name == "a":
                    a = t
                else:
                    c = t
        a_parts.append(a)
        c_parts.append(c)
    return {**tables, "animes": pa.concat_tables(a_parts), "clips": pa.concat_tables(c_parts)}


def build(base: Path, size: int, out: Path, rng: np.random.Generator) -> dict:
    """Write the replicated database of about ``size`` animes at ``out``."""
    from db.store import TABLES, Database, write_version

    db = Database.open(base)
    tables = {name: db.table(name) for name in TABLES}
    copies = max(1, round(size / tables["animes"].num_rows))
    t0 = time.perf_counter()
    big = replicate_tables(tables, copies, rng)
    manifest = {k: v for k, v in db.manifest.items()
                if k not in ("schema_version", "db_version", "tables", "checksums")}
    manifest |= {"n_animes": big["animes"].num_rows, "n_clips": big["clips"].num_rows,
                 "duration_s": float(db.manifest.get("duration_s", 0.0)) * copies}
    write_version(out, big, manifest)
    del big, tables
    disk = sum(f.stat().st_size for f in out.rglob("*") if f.is_file())
    return {"copies": copies, "animes": copies * db.manifest["n_animes"],
            "hours": float(db.manifest.get("duration_s", 0.0)) * copies / 3600,
            "build_s": time.perf_counter() - t0, "disk_gb": disk / 1e9}


def _rss_gb() -> float:
    """Resident memory of this process now (Linux /proc)."""
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1e9


def measure(db_path: Path, repeats: int, mode: str = "cold", load_only: bool = False,
            kbest_all: bool = False, exact: bool = True) -> dict:
    """Load the database and synthesize the line (run in a fresh process); ``mode`` as
    ``--modes`` says."""
    import hashlib

    from animegraph.search import mapped
    from animegraph.synthesis import Model, synthesize
    from ingest.cache import cache_dir
    from ingest.formats.phones_csv import Segment
    from ingest.speech.espeak import speak

    if mode == "eager":
        mapped.MIN_ANIMES = 2**62
    elif mode == "cold":  # the folder load_graph keeps this database's graph in
        shutil.rmtree(cache_dir() / "graphs" / hashlib.sha256(
            os.fsencode(db_path.resolve())).hexdigest()[:24], ignore_errors=True)

    utt = speak(TEXT)
    labels = [Segment(p.phone, p.start, p.end) for p in utt.phones]
    seconds = len(utt.audio) / utt.sample_rate
    rss0 = _rss_gb()
    t, c = time.perf_counter(), time.process_time()
    model = Model.load(db_path)
    row = {"load_s": time.perf_counter() - t, "load_cpu_s": time.process_time() - c,
           "rss_after_load_gb": _rss_gb(), "rss_before_load_gb": rss0,
           "peak_after_load_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9,
           "animes": model.graph.n_nodes, "graph_gb": model.graph.nbytes() / 1e9,
           "speech_s": seconds, "phones": len(labels), "mode": mode}
    runs = [("kbest", {"k_best": 20})]
    if kbest_all:  # the search over every candidate (synth --shortlist all)
        runs.append(("kbest_all", {"k_best": 20, "shortlist": None}))
    if exact:
        runs.append(("exact", {}))
    for name, kwargs in () if load_only else runs:
        best = None
        for _ in range(repeats):
            t, c = time.perf_counter(), time.process_time()
            out = synthesize(model, utt.audio, utt.sample_rate, labels=labels, **kwargs)
            took = (time.perf_counter() - t, time.process_time() - c)
            if best is None or took[0] < best[0]:
                best, timings = took, dict(out.timings)
        row[f"{name}_s"], row[f"{name}_cpu_s"] = best
        row[f"{name}_search_s"] = timings.get("search_s")
        row[f"{name}_timings"] = timings
        row[f"{name}_rtf"] = best[0] / seconds
    row["peak_rss_gb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9
    return row


def _build(base: Path, out: Path, size: int, seed: int) -> dict | None:
    """Write the database of ``size`` animes at ``out`` (in a child process: the build's
    tables, gigabytes at 4M animes, are not held while it is measured); None if it
    failed (said)."""
    shutil.rmtree(out, ignore_errors=True)
    built = subprocess.run(
        [sys.executable, __file__, "--build", str(base), str(out), "--sizes", str(size),
         "--seed", str(seed)], capture_output=True, text=True, check=False)
    if built.returncode:
        print(built.stderr.strip().splitlines()[-1] if built.stderr.strip() else
              f"build failed ({built.returncode})")
        return None
    return json.loads(built.stdout.strip().splitlines()[-1])


def _existing(out: Path) -> dict | None:
    """What :func:`build` says of the database already at ``out``; None if there is none
    (said)."""
    from db.errors import DataError
    from db.store import Database

    try:
        manifest = Database.open(out).manifest
    except DataError as exc:
        print(exc)
        return None
    disk = sum(f.stat().st_size for f in out.rglob("*") if f.is_file())
    return {"animes": manifest["n_animes"], "build_s": float("nan"),
            "hours": float(manifest.get("duration_s", 0.0)) / 3600, "disk_gb": disk / 1e9}


def _print(row: dict) -> None:
    """One line of the table for a measured row."""
    nan = float("nan")
    load = (f"{row['animes']:9d} {row['hours']:6.1f} {row['disk_gb']:7.2f} {row['mode']:>5s} "
            f"{row['load_s']:7.2f} {row['load_cpu_s']:8.2f} {row['rss_after_load_gb']:8.2f} "
            f"{row['peak_after_load_gb']:8.2f}")
    if "kbest_s" not in row:
        print(load)
    else:
        print(f"{load} {row['peak_rss_gb']:7.2f} {row['kbest_s']:7.2f} {row['kbest_cpu_s']:7.2f} "
              f"{row['kbest_rtf']:7.3f} {row.get('exact_s', nan):7.2f} "
              f"{row.get('exact_cpu_s', nan):9.2f}")
        for name in ("kbest", "kbest_all"):
            if f"{name}_timings" in row:
                print(f"          {name} {row[f'{name}_s']:.2f} s, CPU "
                      f"{row[f'{name}_cpu_s']:.2f} s; phases: " + ", ".join(
                          f"{k[:-2]} {v:.2f} s" for k, v in row[f"{name}_timings"].items()))
    sys.stdout.flush()


def _projected_peak(measured: list[dict], animes: int) -> float | None:
    """Peak memory at ``animes`` extrapolated linearly from the sizes measured: through
    the last two, or from the last one's growth over its memory before loading."""
    peaks = {}  # the highest peak measured at each size
    for r in measured:
        if r["peak_rss_gb"] >= peaks.get(r["animes"], {"peak_rss_gb": -1.0})["peak_rss_gb"]:
            peaks[r["animes"]] = r
    measured = [peaks[a] for a in sorted(peaks)]
    if not measured:
        return None
    b = measured[-1]
    if len(measured) >= 2:
        a = measured[-2]
        slope = (b["peak_rss_gb"] - a["peak_rss_gb"]) / max(b["animes"] - a["animes"], 1)
    else:
        slope = (b["peak_rss_gb"] - b["rss_before_load_gb"]) / b["animes"]
    return b["peak_rss_gb"] + max(slope, 0.0) * (animes - b["animes"])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--db", type=Path, help="base database (default: the demo's)")
    parser.add_argument("--sizes", type=int, nargs="+",
                        default=[10_000, 100_000, 1_000_000, 4_000_000])
    parser.add_argument("--work", type=Path, help="where the databases are written")
    parser.add_argument("--keep", action="store_true", help="keep the databases")
    parser.add_argument("--max-rss-gb", type=float, default=8.0)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--no-exact", action="store_true",
                        help="leave out the exact search alone (bench_search.py times it)")
    parser.add_argument("--kbest-all", action="store_true",
                        help="also k-best over every candidate (synth --shortlist all)")
    parser.add_argument("--json", type=Path)
    parser.add_argument("--after", type=Path,
                        help="the --json of an earlier run: its sizes project the peak "
                             "memory of these (to measure 4M alone, after the smaller ones)")
    parser.add_argument("--reuse", action="store_true",
                        help="measure the databases already at --work (db-SIZE)")
    parser.add_argument("--modes", nargs="+", choices=("eager", "cold", "warm"),
                        default=["eager", "cold", "warm"],
                        help="how the graph is loaded (each in its own process)")
    parser.add_argument("--load-only", action="store_true", help="no synthesis")
    parser.add_argument("--mode", default="cold", help=argparse.SUPPRESS)
    parser.add_argument("--measure", type=Path, help=argparse.SUPPRESS)  # the children's
    parser.add_argument("--build", type=Path, nargs=2, help=argparse.SUPPRESS)  # parts
    args = parser.parse_args()
    if args.measure:
        print(json.dumps(measure(args.measure, args.repeats, args.mode, args.load_only,
                                 args.kbest_all, not args.no_exact)))
        return 0
    if args.build:
        base, out = args.build
        print(json.dumps(build(base, args.sizes[0], out, np.random.default_rng(args.seed))))
        return 0
    if args.db is None and not args.reuse:
        from animegraph.apps.demo import ensure_default_corpus, ensure_default_db

        corpus, _, _ = ensure_default_corpus()
        args.db, _ = ensure_default_db(corpus)
    work = args.work or Path(tempfile.mkdtemp(prefix="bench-scale-"))
    work.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(args.seed)
    print(f"# {os.cpu_count()} cores; base {args.db}; line: {TEXT!r}")
    print(f"{'animes':>9s} {'hours':>6s} {'disk_GB':>7s} {'mode':>5s} {'load_s':>7s} "
          f"{'load_cpu':>8s} {'rss_load':>8s} {'pk_load':>8s} {'peak_GB':>7s} {'kbest_s':>7s} "
          f"{'kb_cpu':>7s} {'kbest_x':>7s} {'exact_s':>7s} {'exact_cpu':>9s}")
    rows = []
    measured = ([r for r in json.loads(args.after.read_text()) if "peak_rss_gb" in r]
                if args.after else [])
    try:
        for size in args.sizes:
            out = work / f"db-{size}"
            if args.reuse:
                base = _existing(out)
            else:
                base = _build(args.db, out, size, int(rng.integers(2**31)))
            if base is None:
                return 1
            for mode in args.modes:
                row = dict(base)
                # Converting (eager, cold) peaks as it always did: projected from those.
                projected = _projected_peak([r for r in measured if r.get("mode") != "warm"],
                                            row["animes"]) if mode != "warm" else None
                if projected is not None and projected > args.max_rss_gb:
                    row["skipped"] = f"projected peak {projected:.1f} GB > {args.max_rss_gb}"
                    print(f"{row['animes']:9d} {row['hours']:6.1f} {row['disk_gb']:7.2f} "
                          f"{mode:>5s} not loaded: {row['skipped']}")
                    rows.append(row)
                    continue
                command = [sys.executable, __file__, "--measure", str(out), "--repeats",
                           str(args.repeats), "--mode", mode]
                command += ["--load-only"] * args.load_only + ["--kbest-all"] * args.kbest_all
                command += ["--no-exact"] * args.no_exact
                child = subprocess.run(command,
                                       capture_output=True, text=True, check=False)
                if child.returncode:
                    print(child.stderr.strip().splitlines()[-1] if child.stderr.strip()
                          else f"measure failed ({child.returncode})")
                    return 1
                row |= json.loads(child.stdout.strip().splitlines()[-1])
                rows.append(row)
                measured.append(row)
                _print(row)
            if not args.keep and not args.reuse:
                shutil.rmtree(out, ignore_errors=True)
    finally:
        if not args.keep and args.work is None:
            shutil.rmtree(work, ignore_errors=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
