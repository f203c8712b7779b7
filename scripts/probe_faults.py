"""The probe's sections on damage no command checked, inputs that were lost or mis-said,
output paths, limits and Ctrl-C (``scripts/probe_security.py`` runs them; see its
docstring)."""

from __future__ import annotations

import os
import shutil
import stat
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from crafted import UNCHECKED_DAMAGE, crafted_database  # noqa: E402
from probe_common import CLI, _held, _run  # noqa: E402


def probe_damage(corpus: Path, db: Path, work: Path) -> dict:
    """Damage no command checked (``tests/crafted.py: UNCHECKED_DAMAGE``) through info,
    sql, query, classify, synth and query --export, each a real process: a break is a
    command that exits 0 on damage it should refuse (all of it, but NaN, which no Parquet
    statistic holds: the commands that read those values), a traceback any traceback or
    more than one line."""
    clip = sorted((corpus / "clips").glob("*.wav"))[0]
    labels = clip.with_name(clip.name.replace(".wav", ".phones.csv"))
    folder = work / "damage"
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir()
    commands = {"info": ["info"], "sql": ["sql", "SELECT * FROM frames, clips LIMIT 1"],
                "query": ["query", "--limit", "3"], "classify": ["classify", str(clip)],
                "synth": ["synth", str(clip), "--labels", str(labels), "-o",
                          str(folder / "out.csv")],
                "export": ["query", "--clips", "--limit", "1", "--export",
                           str(folder / "export"), "--force"]}
    # Damage a footer shows is refused by every command when it opens the database; NaN,
    # in no footer, by the commands that read its values.
    # A flipped byte, by those that read its page (a page's CRC is checked as it is read).
    readers = {"frames_nan": ("export",), "components_cutoff_nan": ("info",),
               "frames_flipped_byte": ("sql", "export")}
    runs = breaks = tracebacks = 0
    for name in UNCHECKED_DAMAGE:
        path = crafted_database(db, folder / name, name)
        said = []
        for command, args in commands.items():
            proc = _run(args + ["--db", str(path)])
            runs += 1
            if not _held(proc):
                tracebacks += 1
                said.append(f"{command} NOT HELD ({proc.stderr.strip()[-200:]})")
                continue
            damaged = proc.returncode == 1 and "damaged" in proc.stderr
            if command in readers.get(name, commands) and not damaged:
                breaks += 1
                said.append(f"{command} PASSED")
            else:
                said.append(f"{command} {'refused' if damaged else 'ran'}")
        print(f"  {name}: {', '.join(said)}")
        shutil.rmtree(path, ignore_errors=True)
    for extra in folder.parent.glob(f"{folder.name}*-outside-*"):
        shutil.rmtree(extra, ignore_errors=True)
    return {"damage_cases": len(UNCHECKED_DAMAGE), "damage_runs": runs,
            "damage_breaks": breaks, "damage_tracebacks": tracebacks}


def probe_inputs(corpus: Path, db: Path, work: Path, shared: Path) -> dict:
    """Inputs that were lost or mis-said: a clip named ``..dots`` (ingest), a 2.2 GB SQL
    result, noise / a tone / speech at -70 dBFS / a long recording (classify), a capped
    paper search, ``synth --labels clip.align`` and the guide's path line (synth)."""
    folder = work / "inputs"
    shutil.rmtree(folder, ignore_errors=True)
    (folder / "clips").mkdir(parents=True)
    out = {}
    stem = sorted(p.stem for p in (corpus / "clips").glob("*.c3d"))[0]
    for path in (corpus / "clips").glob(f"{stem}.*"):
        shutil.copy(path, folder / "clips" / ("..dots" + path.name[len(stem):]))
    for name in ("corpus.json", "markers.csv"):
        shutil.copy(corpus / name, folder / name)
    proc = _run(["ingest", str(folder), "--db", str(folder / "db"), "--quiet"])
    out["dots_clip_added"] = _held(proc) and "1 added" in proc.stdout
    print(f"  ..dots clip: {proc.stdout.strip().splitlines()[:1]}")
    proc = _run(["sql", "--db", str(db), "SELECT repeat('x', 300000) AS s FROM range(8192)",
                 "-o", str(folder / "big.csv")])
    last = (proc.stderr.strip().splitlines() or [""])[-1]
    out["sql_2gb_result_held"] = (proc.returncode == 1 and _held(proc) and "too large" in last
                                  and "database" not in last)
    print(f"  2.4 GB SQL result: exit {proc.returncode}: {last}")
    # classify needs a database with a classifier: 34 clips of five emotions (built once).
    db = work / "emotion-db"
    if not db.exists():
        subprocess.run(CLI + ["corpus", "synth", "--out", str(work / "emotion-corpus"),
                              "--sentences", "5", "--parallel", "3", "--variations", "2",
                              "--seed", "7", "--quiet"], check=True)
        subprocess.run(CLI + ["ingest", str(work / "emotion-corpus"), "--db", str(db),
                              "--quiet"], check=True, capture_output=True)
    corpus = work / "emotion-corpus"
    rng = np.random.default_rng(10)
    wav = sorted((corpus / "clips").glob("*_happy_1.wav"))[0]
    from ingest.formats.wav import read_wav, write_wav

    speech, rate = read_wav(wav)
    speech = np.asarray(speech, dtype=np.float64)
    t = np.arange(3 * rate) / rate
    cases = {"white noise": (0.1 * rng.standard_normal(t.size), 1),
             "tone 220 Hz": (0.3 * np.sin(2 * np.pi * 220 * t), 1),
             "speech at -70 dBFS": (speech / np.abs(speech).max() * 10 ** (-70 / 20), 0)}
    held = 0
    for name, (x, code) in cases.items():
        path = folder / f"{name.replace(' ', '_')}.wav"
        write_wav(path, x.astype(np.float32), rate)
        proc = _run(["classify", str(path), "--db", str(db)])
        ok = proc.returncode == code and _held(proc)
        held += ok
        print(f"  classify {name}: exit {proc.returncode} "
              f"{(proc.stderr.strip() or proc.stdout.strip()).splitlines()[:1]}"
              f"{'' if ok else ' -- NOT HELD'}")
    out["classify_inputs"], out["classify_inputs_held"] = len(cases), held
    long = np.tile(speech, int(np.ceil(600 * rate / len(speech))))[:600 * rate]
    write_wav(folder / "long.wav", long.astype(np.float32), rate)
    t0 = time.perf_counter()
    proc = subprocess.run(["/usr/bin/time", "-f", "%M", *CLI, "classify", str(folder / "long.wav"),
                           "--db", str(db), "--timeline"], capture_output=True, text=True)
    rows = proc.stdout.strip().splitlines()
    out["classify_10min_s"] = round(time.perf_counter() - t0, 1)
    out["classify_10min_peak_mb"] = int(proc.stderr.strip().splitlines()[-1]) // 1024 \
        if proc.stderr.strip().splitlines()[-1].isdigit() else None
    out["classify_10min_windows"] = max(0, len(rows) - 1)
    print(f"  classify --timeline of 10 min: exit {proc.returncode}, {len(rows) - 1} windows, "
          f"{out['classify_10min_s']} s, {out['classify_10min_peak_mb']} MB; {rows[-1:]}")
    # A capped paper search says so, always (a warning through the search's logger).
    import logging

    from animegraph.search import candidates, search
    from animegraph.synthesis.model import Model

    model = Model.load(db)
    phones = ["AA", "B", "S", "IY", "T", "AH"] * 3
    cands = candidates(model.graph, phones)
    audio = [rng.random(len(c)) * 50.0 for c in cands.nodes]  # audio costs of a sort
    records = []
    handler = logging.Handler()
    handler.emit = records.append
    logging.getLogger("animegraph.search").addHandler(handler)
    try:
        result = search(model.graph, cands, audio, method="paper", max_expansions=3)
    except Exception as exc:  # noqa: BLE001 - reported, not hidden
        result = None
        print(f"  capped paper search: {type(exc).__name__}: {exc}")
    finally:
        logging.getLogger("animegraph.search").removeHandler(handler)
    warned = [r.getMessage() for r in records if r.levelno >= logging.WARNING]
    out["paper_cap_warned"] = bool(result is not None and result.capped and warned)
    print(f"  capped paper search: {warned[:1]}")
    align = shared / "grid" / "s1" / "bbaf2n.align"
    if align.exists():
        proc = _run(["synth", str(align.with_suffix(".mp4")), "--labels", str(align), "--db",
                     str(db), "-o", str(folder / "grid.csv")])
        out["synth_align_labels"] = proc.returncode == 0
        print(f"  synth --labels .align: exit {proc.returncode} "
              f"{[line for line in proc.stderr.splitlines() if 'path:' in line][:1]}")
    return out
def _case(name: str, proc: subprocess.CompletedProcess, ok: bool, counts: dict) -> None:
    """Count one case: held = ``ok`` and no traceback; print its last line."""
    traceback = "Traceback" in proc.stderr
    counts["tried"] += 1
    counts["held"] += ok and not traceback
    counts["tracebacks"] += traceback
    last = (proc.stderr.strip().splitlines() or [""])[-1]
    print(f"  {name}: {'held' if ok and not traceback else 'BROKEN'}: exit "
          f"{proc.returncode}: {last[:150]}")


def probe_outputs(corpus: Path, db: Path, work: Path) -> dict:
    """Every output option aimed at what no output may replace (issue 39): a device, a
    FIFO, a symbolic link, a database's CURRENT, a place inside a database, a database.
    Held = exit 2 with one line, and the target as it was."""
    folder = work / "outputs"
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir()
    (folder / "kept.txt").write_text("kept")
    os.mkfifo(folder / "fifo")
    (folder / "link").symlink_to(folder / "kept.txt")
    victim = folder / "db"
    shutil.copytree(db, victim)
    current = (victim / "CURRENT").read_bytes()
    wav = sorted((corpus / "clips").glob("*.wav"))[0]
    c3d = wav.with_suffix(".c3d")
    targets = {"/dev/null (a device)": Path("/dev/null"), "a FIFO": folder / "fifo",
               "a symbolic link": folder / "link", "DB/CURRENT": victim / "CURRENT",
               "inside DB": victim / "v000001" / "out.csv", "DB itself": victim}
    files = {"sql -o": ["sql", "SELECT 1", "--db", str(db), "-o"],
             "synth -o": ["synth", str(wav), "--db", str(db), "-o"],
             "render -o": ["render", str(c3d), "-o"], "plot -o": ["plot", str(c3d), "-o"],
             "map-emotion -o": ["map-emotion", str(c3d), "--db", str(db), "--to", "happy",
                                "-o"]}
    folders = {"query --export": ["query", "--db", str(db), "--force", "--export"],
               "batch --out": ["batch", str(wav), "--db", str(db), "--out"]}
    counts = {"tried": 0, "held": 0, "tracebacks": 0}
    for option, argv in {**files, **folders}.items():
        for what, target in targets.items():
            if option in folders and what in ("DB/CURRENT", "a symbolic link"):
                continue
            proc = _run(argv + [str(target)], timeout=120)
            lines = proc.stderr.strip().splitlines()
            _case(f"{option} {what}", proc, proc.returncode == 2 and len(lines) == 1, counts)
    intact = (stat.S_ISCHR(os.lstat("/dev/null").st_mode)
              and stat.S_ISFIFO(os.lstat(folder / "fifo").st_mode)
              and (folder / "link").is_symlink() and (folder / "kept.txt").read_text() == "kept"
              and (victim / "CURRENT").read_bytes() == current
              and not (victim / "v000001" / "out.csv").exists())
    print(f"  every target as it was: {intact}")
    return {"output_cases_tried": counts["tried"], "output_cases_held": counts["held"],
            "output_tracebacks": counts["tracebacks"], "output_targets_intact": intact}


def probe_limits(corpus: Path, db: Path, work: Path) -> dict:
    """Numbers beyond their range (``sql --timeout inf``, an emotion weight of 1e999), a
    CURRENT that is a symbolic link or a FIFO, a C3D cut short, a full disk, and the
    words of ``info`` and ``query --help``. Held = one line (exit 1 or 2) that says it."""
    from crafted import SECRET, crafted_database

    counts = {"tried": 0, "held": 0, "tracebacks": 0}
    for value in ("inf", "nan", "1e12", "-1", "0"):
        proc = _run(["sql", "--db", str(db), "--timeout", value, "SELECT 1"], timeout=60)
        _case(f"sql --timeout {value}", proc, proc.returncode == 2
              and len(proc.stderr.strip().splitlines()) == 1, counts)
    wav = sorted((corpus / "clips").glob("*.wav"))[0]
    proc = _run(["synth", str(wav), "--db", str(db), "-o", str(work / "w.c3d"), "--emotion",
                 "happy=1e999,sad=1"], timeout=300)
    _case("synth --emotion happy=1e999,sad=1", proc,
          proc.returncode in (1, 2) and "not a finite number" in proc.stderr, counts)
    for kind in ("current_symlink", "current_fifo"):
        path = crafted_database(db, work / kind, kind)
        for command in (["info"], ["sql", "SELECT 1"]):
            proc = _run(command + ["--db", str(path)], timeout=60)
            _case(f"{kind} {command[0]}", proc, proc.returncode == 1 and _held(proc)
                  and SECRET not in proc.stderr and "damaged" in proc.stderr, counts)
        shutil.rmtree(path, ignore_errors=True)
        (work / f"{kind}-secret.txt").unlink(missing_ok=True)
    c3d = sorted((corpus / "clips").glob("*.c3d"))[0]
    for cut in (100, 600, 700):
        short = work / f"cut{cut}.c3d"
        short.write_bytes(c3d.read_bytes()[:cut])
        proc = _run(["plot", str(short), "-o", str(work / "cut.png")], timeout=120)
        _case(f"C3D cut at {cut} bytes", proc, proc.returncode == 1 and _held(proc)
              and str(short) in proc.stderr and "struct" not in proc.stderr, counts)
    full = work / "full"
    full.mkdir(exist_ok=True)
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(full)],
                             capture_output=True).returncode == 0
    if mounted:
        try:
            (full / "pad").write_bytes(b"\0" * (250 * 1024))
            cases = {"sql -o on a full disk": ["sql", "--db", str(db), "SELECT * FROM frames",
                                               "-o", str(full / "x.parquet")],
                     "ingest on a full disk": ["ingest", str(corpus), "--db", str(full / "db"),
                                               "--quiet"]}
            for name, argv in cases.items():
                proc = _run(argv, timeout=300)
                _case(name, proc, proc.returncode == 1 and _held(proc)
                      and "the disk is full" in proc.stderr and str(full) in proc.stderr,
                      counts)
        finally:
            subprocess.run(["umount", str(full)], check=False)
    else:
        print("  full disk: skipped (mounting a small tmpfs needs root)")
    proc = _run(["info", "--db", str(db)], timeout=60)
    _case("info names where its database came from", proc, proc.returncode == 0
          and "named by --db" in proc.stdout, counts)
    proc = _run(["query", "--help"], timeout=60)
    _case("query --help lists .livelink.csv", proc, proc.returncode == 0
          and ".livelink.csv" in proc.stdout, counts)
    return {"limit_cases_tried": counts["tried"], "limit_cases_held": counts["held"],
            "limit_tracebacks": counts["tracebacks"]}


def probe_interrupts(work: Path) -> dict:
    """Ctrl-C mid-work on each command (scripts/bench_interrupt.py): held = exit 130 and
    no traceback; the latency from the signal to the exit, printed."""
    from bench_interrupt import DELAY_S, commands, interrupt_once

    corpus, db = work / "corpus", work / "db"
    runs = commands(corpus, db, work)
    held = tracebacks = 0
    worst = 0.0
    for name, argv in runs.items():
        if name == "fit":
            shutil.rmtree(work / "fit.db", ignore_errors=True)
            shutil.copytree(db, work / "fit.db")
        code, latency, traceback, last = interrupt_once(argv, DELAY_S[name],
                                                        work / f"{name}.err")
        held += code == 130 and not traceback
        tracebacks += traceback
        worst = max(worst, latency)
        print(f"  {name}: exit {code}, {latency:.2f} s after SIGINT, traceback: "
              f"{'YES' if traceback else 'no'}")
        for leftover in ("interrupt.db", "batch-out"):
            shutil.rmtree(work / leftover, ignore_errors=True)
    return {"interrupts_tried": len(runs), "interrupts_held": held,
            "interrupt_tracebacks": tracebacks, "interrupt_worst_latency_s": round(worst, 2)}
