"""How long each command takes to end after Ctrl-C, and how it ends.

Usage::

    python scripts/bench_interrupt.py --work DIR [--repeat 3] [--commands sql batch ...]

Builds (or reuses) the small synthetic corpus and database of
``scripts/probe_security.py`` under ``DIR``, then, for each command, starts it as a
terminal's foreground job would be (its own process group), waits until it is at work
(``--delay`` seconds after the start, past the imports), sends SIGINT to the whole group
(what Ctrl-C does) and times how long the process takes to end. ``synth`` is pressed
inside its slowest stage for Ctrl-C, PocketSphinx placing the phones of a long recording
(``--synth-at placement``: half a second after ``-vv``'s line "PocketSphinx places", with
a fresh phone cache each run, or the phones are read from the cache and PocketSphinx never
runs), or at a fixed delay, while hama hears the speech (``--synth-at delay``). Prints, a
line per run:
the command, its exit status (130 is the one expected), the seconds from the signal to the
exit, and whether stderr held a traceback; then the median and the worst latency of each
command. tests/test_interrupt.py checks the status and the absent traceback; the latency
is measured here only (a unit test asserts no wall-clock limit).
"""

from __future__ import annotations

import argparse
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from probe_common import CLI, setup  # noqa: E402

from ingest.cache import CACHE_ENV  # noqa: E402

#: Seconds after the start at which Ctrl-C is pressed: past the imports, inside the work.
DELAY_S = {"sql": 4.0, "batch": 12.0, "ingest": 6.0, "synth": 8.0, "render": 5.0,
           "fit": 2.5}
#: ``synth``'s line (with ``-vv``) as PocketSphinx starts placing the phones, and the
#: seconds after it at which Ctrl-C is pressed (inside the decoding).
PLACEMENT_LINE, PLACEMENT_DELAY_S = "PocketSphinx places", 0.5
#: Longest wait for that line (a bound: the load of a shared machine varies).
MARKER_BOUND_S = 600.0


def commands(corpus: Path, db: Path, work: Path) -> dict[str, list[str]]:
    """command name -> its arguments, each a run of several seconds at least."""
    import numpy as np

    from ingest.formats.wav import read_wav, write_wav

    wavs = sorted((corpus / "clips").glob("*.wav"))
    c3d = wavs[0].with_suffix(".c3d")
    # synth and render of one clip end within the delay: the corpus' speech end to end, 6
    # times, and a clip's motion 8 times
    from ingest.formats.c3d import MarkerData, read_c3d, write_c3d

    clip = read_c3d(c3d)
    c3d = work / "interrupt-motion.c3d"
    write_c3d(c3d, MarkerData(np.concatenate([clip.points] * 8), clip.labels, clip.rate))
    speech = [read_wav(path) for path in wavs]
    long = work / "interrupt-speech.wav"
    write_wav(long, np.concatenate([samples for samples, _ in speech] * 6), speech[0][1])
    script = work / "interrupt-script.csv"
    script.write_text("id,text\n" + "".join(
        f"l{i},This is line number {i} of a long dialogue.\n" for i in range(60)))
    return {
        "sql": ["sql", "--db", str(db), "SELECT count(*) FROM range(1000000000000)"],
        "batch": ["batch", str(script), "--db", str(db), "--out", str(work / "batch-out"),
                  "--workers", "2"],
        "ingest": ["ingest", str(corpus), "--db", str(work / "interrupt.db"), "--workers",
                   "2"],
        "synth": ["synth", str(long), "--db", str(db), "-o", str(work / "interrupt.c3d")],
        "render": ["render", str(c3d), "-o", str(work / "interrupt.mp4")],
        "fit": ["fit", "--db", str(work / "fit.db"), "--method", "hier-pca"],
    }


def interrupt_once(args: list[str], delay: float, err_path: Path, marker: str | None = None,
                   env: dict | None = None) -> tuple[int, float, bool, str]:
    """(exit status, seconds from SIGINT to exit, traceback printed, last stderr line).

    Ctrl-C is pressed ``delay`` seconds after the start, or, with ``marker``, ``delay``
    seconds after that text appears on stderr."""
    with err_path.open("w") as err:
        proc = subprocess.Popen(CLI + args, stdout=subprocess.DEVNULL, stderr=err,
                                start_new_session=True,
                                env={**os.environ, "PYTHONUNBUFFERED": "1", **(env or {})})
        deadline = time.monotonic() + MARKER_BOUND_S
        while (marker is not None and proc.poll() is None and time.monotonic() < deadline
               and marker not in err_path.read_text()):
            time.sleep(0.05)
        time.sleep(delay)
        if proc.poll() is not None:
            text = err_path.read_text()
            return proc.returncode, float("nan"), "Traceback" in text, "ended before Ctrl-C"
        t0 = time.monotonic()
        os.killpg(proc.pid, signal.SIGINT)
        try:
            code = proc.wait(300)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            code = proc.wait()
        latency = time.monotonic() - t0
    text = err_path.read_text()
    last = (text.strip().splitlines() or [""])[-1]
    if marker is not None and marker not in text:
        last = f"pressed without {marker!r} seen; {last}"
    return code, latency, "Traceback" in text, last


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", type=Path, default=None)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--commands", nargs="*", default=list(DELAY_S), choices=list(DELAY_S))
    parser.add_argument("--synth-at", choices=["placement", "delay"], default="placement",
                        help="press Ctrl-C on synth while PocketSphinx places the phones "
                             "(default) or at its fixed delay, while hama hears the speech")
    args = parser.parse_args(argv)
    work = args.work or Path(tempfile.mkdtemp(prefix="bench-interrupt-"))
    work.mkdir(parents=True, exist_ok=True)
    corpus, db = setup(work)
    runs = commands(corpus, db, work)
    summary = {}
    for name in args.commands:
        latencies = []
        for k in range(args.repeat):
            if name == "fit":  # fit stores its model in the database: a copy each time
                subprocess.run(["rm", "-rf", str(work / "fit.db")], check=True)
                subprocess.run(["cp", "-r", str(db), str(work / "fit.db")], check=True)
            command, delay, marker, env = runs[name], DELAY_S[name], None, None
            if name == "synth" and args.synth_at == "placement":
                command = ["-vv", *command]
                delay, marker = PLACEMENT_DELAY_S, PLACEMENT_LINE
                env = {CACHE_ENV: str(work / f"cache-{k}")}
                subprocess.run(["rm", "-rf", env[CACHE_ENV]], check=True)
            code, latency, traceback, last = interrupt_once(command, delay,
                                                            work / f"{name}.err", marker, env)
            latencies.append(latency)
            print(f"{name} run {k + 1}: exit {code}, {latency:.2f} s after SIGINT, "
                  f"traceback: {'YES' if traceback else 'no'}; {last[:100]}", flush=True)
            for leftover in ("interrupt.db", "batch-out"):
                subprocess.run(["rm", "-rf", str(work / leftover)], check=True)
        summary[name] = (statistics.median(latencies), max(latencies))
    for name, (median, worst) in summary.items():
        print(f"{name}: median {median:.2f} s, worst {worst:.2f} s from SIGINT to exit")
    return 0


if __name__ == "__main__":
    sys.exit(main())
