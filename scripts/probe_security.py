"""Probe what comes in as an attacker or a careless user would, and count
(docs/results/robustness.md).

Usage::

    python scripts/probe_security.py --work DIR [--trials 20] [--flips 200] [--kills 5]
                                     [--seed 18]

Builds a small synthetic corpus (6 clips) and its database under ``DIR`` (reused when
present), then prints, section by section:

1. **SQL escapes** (``tests/crafted.py: sql_escapes``: COPY/EXPORT/ATTACH/INSTALL/LOAD,
   ``EXPLAIN ANALYZE`` around them, ``read_text``/``read_csv``/``read_blob``/``glob``
   outside the version, URLs, ``SET``/``RESET`` of the sandbox, several statements):
   tried, refused by ``animegraph sql`` in one line, refused by DuckDB's own sandbox
   alone (the bare connection, without the statement filter), and whether any file in
   or outside the database changed.
2. **Crafted databases** (``tests/crafted.py: DATABASE_MUTATIONS``, a manifest's
   ``limits`` beyond their ceilings among them) x ``info``, ``sql``
   (the command line's ``main`` in this process: held = no exception escapes it) and
   ``synth`` (a real process: held = exit 0, or exit 1 with one line on stderr; a
   traceback or a signal such as a segfault is a failure).
3. **Crafted clips**: ``--flips`` seeded single-bit flips in copies of a C3D, plus the
   named poisons (a marker at 4.4e6 mm, 3e38, an all-zero marker, a long run of
   impossible values, a pickled ``.npy`` payload, labels that break the store, absurd
   phones, a 100,000-deep JSON side file): held = rejected with one line, or accepted
   with every coordinate within range and no impossible speed; the pickle payload must
   not run.
4. **Concurrent writers**: ``--trials`` times, two ``animegraph ingest`` processes of
   different clips into one new database at once: clips lost = clips reported added but
   missing from the final database.
6. **Real data** (``--shared``, default ``../shared/data``): the synthetic corpus, the
   FACEGOOD, talking-face and Live Link clips through the plausibility checks: passed,
   passed with samples filled, rejected, and the fastest point.
7. **Crafted media** (``tests/crafted.py``: ``disguised_playlists``, ``flac_declaring``,
   ``gltf_reaching``): playlists named ``speech.mp4`` (DASH, HLS, ffconcat) that name a
   private recording elsewhere, and a FLAC named ``.wav`` declaring 2**36 samples, each
   the speech of ``animegraph synth`` (a real process: held = exit 1 with one line, and
   the private recording not read); glTFs whose buffer is outside their folder, and
   glTFs drawing a quad from 5,000 nodes (nested, flat: ``gltf_drawing``), through
   ``load_mesh`` (held = refused in one line).
8. **Outputs** (issue 39): every output option (``sql -o``, ``synth -o``, ``render -o``,
   ``plot -o``, ``map-emotion -o``, ``query --export``, ``batch --out``) aimed at a device
   (``/dev/null``), a FIFO, a symbolic link, a database's ``CURRENT``, a place inside a
   database and a database: held = exit 2 in one line, and every target as it was.
9. **Limits and messages**: ``sql --timeout`` of inf, nan, 1e12, -1, 0; an emotion weight
   of 1e999; a ``CURRENT`` that is a symbolic link (to a file whose content must not be
   printed) or a FIFO; a C3D cut short; a full disk (a 256 KB tmpfs, as root only);
   ``info``'s and ``query --help``'s words: held = one line that says it, no traceback.
10. **Interrupts** (``scripts/bench_interrupt.py``): Ctrl-C mid-work on ``sql``, ``batch``,
   ``ingest``, ``synth``, ``render`` and ``fit``: held = exit 130 and no traceback; the
   worst latency from the signal to the exit.
5. **Kills**: ``--kills`` times, an ingest into the database killed with SIGKILL at a
   seeded moment: survived = the database still opens at a complete version and the next
   writer gets the lock at once.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from crafted import (  # noqa: E402
    DATABASE_MUTATIONS,
    PicklePayload,
    crafted_database,
    disguised_playlists,
    flac_declaring,
    gltf_drawing,
    gltf_reaching,
    sql_bombs,
    sql_escapes,
)

from db.errors import AnimeGraphError  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from probe_common import CLI, _held, _run, _snapshot, setup  # noqa: E402
from probe_faults import (  # noqa: E402
    probe_damage,
    probe_inputs,
    probe_interrupts,
    probe_limits,
    probe_outputs,
)


def probe_sql(db: Path, work: Path) -> dict:
    from db.sql import connect, run
    from db.store import Database

    outside = work / "outside"
    shutil.rmtree(outside, ignore_errors=True)
    outside.mkdir()
    (outside / "outside.txt").write_text("secret")
    database = Database.open(db)
    before = _snapshot(db)
    escapes = sql_escapes(database.version_dir, db, outside)
    refused = refused_by_duckdb = 0
    for sql in escapes:
        proc = _run(["sql", "--db", str(db), sql])
        if proc.returncode != 0 and _held(proc):
            refused += 1
        else:
            print(f"  NOT refused: {sql}")
        con = connect(database)
        try:
            for statement in __import__("duckdb").extract_statements(sql):
                con.execute(statement.query)
        except Exception:  # noqa: BLE001 - any refusal by DuckDB counts
            refused_by_duckdb += 1
        finally:
            con.close()
    try:
        run(database, "SELECT 1")
    except AnimeGraphError:
        pass
    changed = _snapshot(db) != before or sorted(p.name for p in outside.iterdir()) != [
        "outside.txt"]
    bombs_held = 0
    for name, sql in sql_bombs().items():
        proc = _run(["sql", "--db", str(db), "--timeout", "10", sql])
        bombs_held += proc.returncode == 1 and _held(proc)
        print(f"  {name}: exit {proc.returncode}: "
              f"{(proc.stderr.strip().splitlines() or [''])[-1][:120]}")
    import resource

    return {"sql_escapes_tried": len(escapes), "sql_escapes_refused": refused,
            "sql_escapes_refused_by_duckdb_alone": refused_by_duckdb,
            "files_changed": changed, "sql_bombs_tried": len(sql_bombs()),
            "sql_bombs_held": bombs_held,
            "sql_peak_child_mb": resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss // 1024}


def probe_databases(corpus: Path, db: Path, work: Path) -> dict:
    clip = sorted((corpus / "clips").glob("*.wav"))[0]
    labels = clip.with_name(clip.name.replace(".wav", ".phones.csv"))
    folder = work / "crafted"
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir()
    from animegraph.apps.cli import main as cli

    tried = held = 0
    failures = []
    for name in sorted(DATABASE_MUTATIONS):
        path = crafted_database(db, folder / name, name)
        # info and sql in this process (the CLI's own main: a traceback propagates here);
        # synth, whose compiled kernels could crash, as a real process.
        for command in (["info"], ["sql", "SELECT count(*), max(next_node) FROM animes"]):
            tried += 1
            try:
                with open(os.devnull, "w") as sink, redirect_stdout(sink), \
                        redirect_stderr(sink):
                    cli(command + ["--db", str(path)])
                held += 1
            except Exception as exc:  # noqa: BLE001 - a traceback: not held
                failures.append(f"{name} {command[0]}: {type(exc).__name__}: {exc}")
        proc = _run(["synth", str(clip), "--labels", str(labels), "-o",
                     str(folder / f"{name}.c3d"), "--db", str(path)])
        tried += 1
        if _held(proc):
            held += 1
        else:
            failures.append(f"{name} synth: exit {proc.returncode}: "
                            f"{proc.stderr.strip().splitlines()[-1:]}")
        shutil.rmtree(path, ignore_errors=True)
    for line in failures:
        print(f"  FAILED {line}")
    return {"crafted_databases": len(DATABASE_MUTATIONS), "database_runs_tried": tried,
            "database_runs_held": held}


def _clip_copy(corpus: Path, stem: str, dest: Path, new: str) -> Path:
    dest.mkdir(parents=True, exist_ok=True)
    for suffix in (".c3d", ".wav", ".phones.csv", ".json"):
        shutil.copy(corpus / "clips" / f"{stem}{suffix}", dest / f"{new}{suffix}")
    return dest / f"{new}.c3d"


def _points(path: Path, change) -> None:
    from ingest.formats.c3d import MarkerData, read_c3d, write_c3d

    data = read_c3d(path)
    points = data.points.copy()
    change(points)
    write_c3d(path, MarkerData(points, data.labels, data.rate, data.units))


def _named_poisons(corpus: Path, stem: str, work: Path) -> dict[str, Path]:
    """name -> folder holding one poisoned clip."""
    out = {}

    def make(name, edit):
        folder = work / "poison" / name
        shutil.rmtree(folder, ignore_errors=True)
        c3d = _clip_copy(corpus, stem, folder, name)
        edit(c3d, folder)
        out[name] = folder

    def set_points(change):
        return lambda c3d, _: _points(c3d, change)

    def meta(**fields):
        def edit(c3d, folder):
            path = c3d.with_suffix(".json")
            path.write_text(json.dumps({**json.loads(path.read_text()), **fields}))
        return edit

    make("marker_4e6", set_points(lambda p: p.__setitem__((40, 30, 1), 4.4e6)))
    make("coordinate_3e38", set_points(lambda p: p.__setitem__((70, 10, 0), 3e38)))
    make("all_zero_marker", set_points(lambda p: p.__setitem__((slice(None), 5), 0.0)))
    make("long_bad_run", set_points(lambda p: p.__setitem__((slice(10, 200), 3, 1), 3e38)))
    make("step_jump", set_points(lambda p: p.__setitem__(
        (slice(100, None), 7, 2), p[100:, 7, 2] + 80.0)))
    make("emotion_hive_default", meta(emotion="__HIVE_DEFAULT_PARTITION__"))
    make("emotion_null", meta(emotion="NULL"))
    make("emotion_300_chars", meta(emotion="x" * 300))
    make("emotion_1mb", meta(emotion="x" * 1_000_000))
    make("emotion_nul", meta(emotion="hap\x00py"))
    make("emotion_path", meta(emotion="../../etc"))
    make("speaker_newline", meta(speaker="a\nb"))

    def phones(n, step):
        def edit(c3d, folder):
            rows = ["start,end,phone"] + [f"{i * step:.6f},{(i + 1) * step:.6f},AA"
                                          for i in range(n)]
            c3d.with_name(c3d.name.replace(".c3d", ".phones.csv")).write_text(
                "\n".join(rows) + "\n")
        return edit

    make("phones_4us", phones(100_000, 4e-6))
    make("phones_too_many", phones(200, 0.011))

    def deep(c3d, folder):
        c3d.with_suffix(".json").write_text("[" * 100_000 + "]" * 100_000)
    make("json_deep", deep)
    return out


def probe_clips(corpus: Path, work: Path, flips: int, seed: int) -> dict:
    from ingest.plausible import Limits, check_clip
    from ingest.readers import discover, load

    limits = Limits()
    stem = sorted(p.stem for p in (corpus / "clips").glob("*.c3d"))[0]
    tried = held = accepted = 0

    def judge(folder: Path) -> tuple[bool, bool]:
        try:
            [source] = discover([folder])
            clip, _ = check_clip(load(source), limits)
        except AnimeGraphError as exc:
            return "\n" not in str(exc), False
        except Exception as exc:  # noqa: BLE001 - a traceback: not held
            print(f"  traceback on {folder.name}: {type(exc).__name__}: {exc}")
            return False, False
        pts = clip.motion.reshape(len(clip.motion), -1, 3)
        steps = np.linalg.norm(np.diff(pts, axis=0), axis=2) * clip.fps
        ok = (np.nanmax(np.abs(pts)) <= limits.max_coordinate_mm
              and not (steps > limits.max_speed_mm_s).any())
        return ok, True

    rng = np.random.default_rng(seed)
    folder = work / "flip"
    shutil.rmtree(folder, ignore_errors=True)
    c3d = _clip_copy(corpus, stem, folder, stem)
    original = c3d.read_bytes()
    for _ in range(flips):
        data = bytearray(original)
        data[int(rng.integers(len(data)))] ^= 1 << int(rng.integers(8))
        c3d.write_bytes(bytes(data))
        ok, kept = judge(folder)
        tried, held, accepted = tried + 1, held + ok, accepted + kept
    named = _named_poisons(corpus, stem, work)
    named_held = 0
    for name, poison in named.items():
        ok, kept = judge(poison)
        named_held += ok
        print(f"  {name}: {'accepted (filled as dropouts)' if kept else 'rejected'}"
              f"{'' if ok else ' -- NOT HELD'}")
    # A pickled payload in a FACEGOOD layout must be refused, and must not run.
    fg = work / "facegood"
    shutil.rmtree(fg, ignore_errors=True)
    (fg / "bs_value").mkdir(parents=True)
    (fg / "wav").mkdir()
    shutil.copy(corpus / "clips" / f"{stem}.wav", fg / "wav" / "c1.wav")
    (fg / "bsname.txt").write_text("2\njaw\nbrow\n")
    marker = work / "payload-ran"
    marker.unlink(missing_ok=True)
    np.save(fg / "bs_value" / "bs_value_c1.npy", np.array([PicklePayload(marker)], dtype=object),
            allow_pickle=True)
    ok, _ = judge(fg)
    pickle_held = ok and not marker.exists()
    print(f"  pickled .npy payload: {'refused, did not run' if pickle_held else 'RAN'}")
    return {"clip_inputs_tried": tried + len(named) + 1,
            "clip_inputs_held": held + named_held + int(pickle_held),
            "bit_flips_tried": tried, "bit_flips_held": held,
            "bit_flips_accepted_plausible": accepted, "named_poisons": len(named),
            "named_poisons_held": named_held, "pickle_payload_ran": marker.exists()}


def probe_writers(corpus: Path, work: Path, trials: int) -> dict:
    stems = sorted(p.stem for p in (corpus / "clips").glob("*.c3d"))[:2]
    lost = failed = 0
    for trial in range(trials):
        base = work / "writers" / f"t{trial}"
        shutil.rmtree(base, ignore_errors=True)
        sources = []
        for k, stem in enumerate(stems):
            src = base / f"src{k}"
            (src / "clips").mkdir(parents=True)
            for name in ("corpus.json", "markers.csv"):
                shutil.copy(corpus / name, src / name)
            _clip_copy(corpus, stem, src / "clips", stem)
            sources.append(src)
        db = base / "db"
        procs = [subprocess.Popen(CLI + ["ingest", str(s), "--db", str(db), "--quiet"],
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
                 for s in sources]
        outs = [p.communicate(timeout=900) for p in procs]
        codes = [p.returncode for p in procs]
        from db.store import Database

        added = sum(1 for code in codes if code == 0)
        try:
            stored = Database.open(db).table("clips", columns=["clip_id"]).num_rows
        except AnimeGraphError:
            stored = 0
        lost += max(0, added - stored)
        failed += sum(1 for code in codes if code != 0)
        if codes != [0, 0]:
            print(f"  trial {trial}: exits {codes}: {[o[1].strip()[-200:] for o in outs]}")
        shutil.rmtree(base, ignore_errors=True)
    return {"concurrent_writer_trials": trials, "clips_lost": lost,
            "writers_failed": failed}


def probe_kills(corpus: Path, db: Path, work: Path, kills: int, seed: int) -> dict:
    from db.lock import writer_lock
    from db.store import Database

    rng = np.random.default_rng(seed)
    target = work / "killed.db"
    shutil.rmtree(target, ignore_errors=True)
    shutil.copytree(db, target)
    versions = []
    survived = 0
    for k in range(kills):
        # New clips (renamed copies) each time, so that every ingest rewrites the database.
        src = work / "kills" / f"src{k}"
        shutil.rmtree(src, ignore_errors=True)
        (src / "clips").mkdir(parents=True)
        for name in ("corpus.json", "markers.csv"):
            shutil.copy(corpus / name, src / name)
        for stem in sorted(p.stem for p in (corpus / "clips").glob("*.c3d")):
            _clip_copy(corpus, stem, src / "clips", f"k{k}_{stem}")
        proc = subprocess.Popen(CLI + ["ingest", str(src), "--db", str(target), "--quiet"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(float(rng.uniform(2.0, 12.0)))
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        try:
            opened = Database.open(target)
            opened.table("animes", columns=["node_id"])
            with writer_lock(target, wait=0):
                pass
            survived += 1
            versions.append(opened.version_dir.name)
        except AnimeGraphError as exc:
            print(f"  kill not survived: {exc}")
    print(f"  versions after each kill: {' '.join(versions)}")
    return {"kills": kills, "kills_survived": survived}


def probe_real(shared: Path, corpus: Path) -> dict:
    """The plausibility checks on real data: how many good clips they would touch."""
    from ingest.plausible import check_clip
    from ingest.readers import discover, load

    out = {}
    # livelink: its rotations must still read as radians (head yaw/roll within pi, pitch
    # and the eyes within pi/2)
    for name, folder in (("synthetic", corpus), ("facegood", shared / "facegood"),
                         ("talkingface", shared / "talkingface"),
                         ("livelink", shared / "livelink")):
        if not folder.exists():
            print(f"  {folder} absent: skipped")
            continue
        found = discover([folder])
        passed = filled = rejected = 0
        fastest = 0.0
        for source in found:
            try:
                raw = load(source)
                clip, note = check_clip(raw)
            except AnimeGraphError as exc:
                rejected += 1
                print(f"  {name} {source.clip_id}: rejected: {exc}")
                continue
            passed += 1
            filled += bool(note)
            names = list(raw.schema.names)
            cols = [i for i, n in enumerate(names) if n.endswith(".x")
                    and names[i + 1:i + 3] == [n[:-2] + ".y", n[:-2] + ".z"]]
            if cols:
                idx = np.concatenate([np.arange(i, i + 3) for i in cols])
                pts = raw.motion[:, idx].reshape(len(raw.motion), -1, 3)
                speed = np.linalg.norm(np.diff(pts, axis=0), axis=2) * raw.fps
                fastest = max(fastest, float(np.nanmax(speed)))
        out[f"{name}_clips"] = len(found)
        out[f"{name}_passed"] = passed
        out[f"{name}_filled"] = filled
        out[f"{name}_rejected"] = rejected
        out[f"{name}_fastest_point_mm_s"] = round(fastest)
    return out


def probe_media(corpus: Path, db: Path, work: Path) -> dict:
    """Crafted speech through ``synth`` and crafted glTFs through ``load_mesh``."""
    from animegraph.face.mesh import load_mesh

    folder = work / "media"
    shutil.rmtree(folder, ignore_errors=True)
    (folder / "private").mkdir(parents=True)
    private = folder / "private" / "private.mp4"
    wav = next((corpus / "clips").glob("*.wav"))
    subprocess.run(CLI[:1] + ["-c", "import imageio_ffmpeg, subprocess, sys; subprocess.run("
                              "[imageio_ffmpeg.get_ffmpeg_exe(), '-v', 'error', '-y', "
                              "'-f', 'lavfi', '-i', 'color=s=64x48:d=4', '-i', sys.argv[1], "
                              "'-shortest', '-c:v', 'libx264', '-c:a', 'aac', sys.argv[2]], "
                              "check=True)", str(wav), str(private)], check=True)
    (folder / "private.mp4").symlink_to(private)  # a neighbour, for the relative concat
    speech = {f"playlist:{kind}": text for kind, text in disguised_playlists(private).items()}
    tried = held = 0
    for name, text in speech.items():
        path = folder / f"speech_{name.split(':')[1]}.mp4"
        path.write_text(text)
        speech[name] = path
    speech["flac declaring 2**36 samples"] = flac_declaring(folder / "declared.wav", 2**36 - 1)
    for name, path in speech.items():
        proc = _run(["synth", str(path), "--db", str(db), "-o", str(folder / "out.csv")])
        tried += 1
        ok = _held(proc) and proc.returncode == 1
        held += ok
        last = (proc.stderr.strip().splitlines() or [""])[-1]
        print(f"  {name}: {'held' if ok else 'NOT HELD'}: exit {proc.returncode}: {last}")
    quad = (np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 1]], np.float32).tobytes()
            + np.array([0, 1, 2, 0, 2, 3], np.uint32).tobytes())
    secret = folder / "private" / "secret.bin"
    secret.write_bytes(quad)
    (folder / "mesh").mkdir()
    (folder / "mesh" / "link.bin").symlink_to(secret)
    for uri in ("../private/secret.bin", str(secret), secret.as_uri(), "link.bin"):
        path = folder / "mesh" / "bad.gltf"
        path.write_text(json.dumps(gltf_reaching(uri)))
        tried += 1
        try:
            load_mesh(path)
            print(f"  glTF buffer {uri}: NOT HELD: read")
        except AnimeGraphError as exc:
            held += "\n" not in str(exc)
            print(f"  glTF buffer {uri}: held: {exc}")
    (folder / "mesh" / "quad.bin").write_bytes(quad)
    for nested in (True, False):  # minutes of trimesh's walk; vertices by the thousand
        path = folder / "mesh" / f"drawn_{'nested' if nested else 'flat'}.gltf"
        path.write_text(json.dumps(gltf_drawing("quad.bin", 5000, nested=nested)))
        tried += 1
        t0 = time.perf_counter()
        try:
            load_mesh(path)
            print(f"  glTF of 5,000 {path.stem} nodes: NOT HELD: read")
        except AnimeGraphError as exc:
            held += "\n" not in str(exc)
            print(f"  glTF of 5,000 {path.stem} nodes: held in "
                  f"{time.perf_counter() - t0:.1f} s: {exc}")
    return {"media_cases_tried": tried, "media_cases_held": held}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", type=Path, default=None)
    parser.add_argument("--trials", type=int, default=20)
    parser.add_argument("--flips", type=int, default=200)
    parser.add_argument("--kills", type=int, default=5)
    parser.add_argument("--seed", type=int, default=18)
    parser.add_argument("--shared", type=Path,
                        default=Path(__file__).resolve().parents[2] / "shared" / "data")
    parser.add_argument("--skip", nargs="*", default=[],
                        choices=["sql", "databases", "clips", "writers", "kills", "real",
                                 "media", "damage", "inputs", "outputs", "limits",
                                 "interrupts"])
    args = parser.parse_args(argv)
    work = args.work or Path(tempfile.mkdtemp(prefix="probe-security-"))
    work.mkdir(parents=True, exist_ok=True)
    corpus, db = setup(work)
    results = {}
    steps = [("sql", lambda: probe_sql(db, work)),
             ("clips", lambda: probe_clips(corpus, work, args.flips, args.seed)),
             ("writers", lambda: probe_writers(corpus, work, args.trials)),
             ("kills", lambda: probe_kills(corpus, db, work, args.kills, args.seed)),
             ("databases", lambda: probe_databases(corpus, db, work)),
             ("real", lambda: probe_real(args.shared, corpus)),
             ("media", lambda: probe_media(corpus, db, work)),
             ("damage", lambda: probe_damage(corpus, db, work)),
             ("inputs", lambda: probe_inputs(corpus, db, work, args.shared)),
             ("outputs", lambda: probe_outputs(corpus, db, work)),
             ("limits", lambda: probe_limits(corpus, db, work)),
             ("interrupts", lambda: probe_interrupts(work))]
    for name, step in steps:
        if name in args.skip:
            continue
        t0 = time.perf_counter()
        print(f"== {name}", flush=True)
        out = step()
        results.update(out)
        for key, value in out.items():
            print(f"{key}: {value}", flush=True)
        print(f"({time.perf_counter() - t0:.0f} s)", flush=True)
    print(json.dumps(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
