"""What hama's phone model costs a call, by the audio it hears; and a live stream's model.

Usage::

    python scripts/bench_hama.py [--lengths 40 80 ... 2000] [--repeats 15]
                                 [--settings 300/40/40 600/120/80 ...] [--json OUT]

* **Per call** (``--lengths``, ms): :func:`ingest.speech.ctc.phone_probs` (the native
  engine of the ``hama`` wheel and the fold onto the project's phones) on that much
  16 kHz audio (eSpeak NG speech, repeated to the longest length), ``--repeats`` times
  each after a warm-up call: the median wall and CPU time (the process's, all threads),
  and the process's threads after the calls, and before the model was loaded
  (``/proc/self/task``, where it exists). A straight line is fitted to the CPU
  medians of the calls up to 1 s (least squares): a fixed cost per call and a cost per
  second of audio heard, and each call's departure from it (the longer calls': the
  attention's quadratic part).
* **A live stream's model** (``--settings`` context/settled/hop, ms): the audio a
  :class:`animegraph.live.frontend.PosteriorTrack` hears per update
  (``context + settled + hop``) and its model's CPU per second of audio, measured on
  the same speech pushed hop by hop, beside what the fitted line predicts.

CPU times are the process's; on an idle machine a one-threaded call's wall time is its
CPU time, so a wall time well above it is the load. The load average is printed.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from animegraph.live.frontend import MODEL_RATE, PosteriorTrack
from ingest.speech import ctc
from ingest.speech.espeak import speak

SENTENCES = ("Please bring the blue box to the table.",
             "We were away a year ago when the rain came down on the hills.")
#: Calls up to this long (ms) make the line's fit.
FIT_UPTO_MS = 1000


def speech(seconds: float) -> np.ndarray:
    """eSpeak NG speech at hama's rate, peak 0.9, repeated to at least ``seconds``."""
    from scipy.signal import resample_poly

    parts = []
    for text in SENTENCES:
        said = speak(text)
        x = said.audio.astype(np.float64)
        if said.sample_rate != MODEL_RATE:
            g = np.gcd(MODEL_RATE, said.sample_rate)
            x = resample_poly(x, MODEL_RATE // g, said.sample_rate // g)
        parts.append(x)
    x = np.concatenate(parts)
    x = np.tile(x, int(np.ceil(seconds * MODEL_RATE / len(x))))
    return (0.9 * x / np.abs(x).max()).astype(np.float32)


def threads_now() -> int | None:
    task = Path("/proc/self/task")
    return len(list(task.iterdir())) if task.is_dir() else None


def per_call(x: np.ndarray, lengths_ms, repeats: int) -> list[dict]:
    before = threads_now()
    ctc.phone_probs(x[:MODEL_RATE])  # loads the model
    print(json.dumps({"threads_before_the_model": before, "after": threads_now()}), flush=True)
    rows = []
    for ms in lengths_ms:
        clip = x[: int(ms * MODEL_RATE / 1000)]
        walls, cpus = [], []
        for _ in range(repeats):
            wall, cpu = time.perf_counter(), time.process_time()
            ctc.phone_probs(clip)
            walls.append(time.perf_counter() - wall)
            cpus.append(time.process_time() - cpu)
        rows.append({"ms": ms, "wall_ms": 1000 * float(np.median(walls)),
                     "cpu_ms": 1000 * float(np.median(cpus)), "threads": threads_now()})
        print(json.dumps(rows[-1]), flush=True)
    return rows


def fit(rows: list[dict]) -> dict:
    """The CPU medians' straight line over calls up to :data:`FIT_UPTO_MS`."""
    ms = np.array([r["ms"] for r in rows], dtype=float)
    cpu = np.array([r["cpu_ms"] for r in rows])
    use = ms <= FIT_UPTO_MS
    slope, fixed = np.polyfit(ms[use], cpu[use], 1)
    off = cpu - (fixed + slope * ms)
    return {"fixed_ms": float(fixed), "ms_per_s_heard": float(1000 * slope),
            "largest_departure": {f"{m:g} ms": round(float(d), 2)
                                  for m, d in zip(ms, off, strict=True)}}


def stream_model(x: np.ndarray, settings, line: dict) -> list[dict]:
    """Each setting's model CPU per second of audio, pushed hop by hop."""
    rows = []
    for text in settings:
        ctx, settle, hop = (float(v) / 1000 for v in text.split("/"))
        track = PosteriorTrack(MODEL_RATE, context_s=ctx, settle_s=settle)
        step = int(round(hop * MODEL_RATE))
        cpu = time.process_time()
        updates = 0
        for end in range(step, len(x) + 1, step):
            track.update(x[:end], 0, end, 0.9)
            updates += 1
        cpu = time.process_time() - cpu
        heard = (ctx + settle + hop) * 1000
        seconds = updates * hop
        rows.append({"setting": text, "heard_per_update_ms": heard,
                     "model_cpu_per_s": cpu / seconds,
                     "update_cpu_ms": 1000 * cpu / updates,
                     "predicted_update_cpu_ms": line["fixed_ms"]
                     + line["ms_per_s_heard"] * heard / 1000,
                     "model_s_heard_per_s": track.model_s / seconds})
        print(json.dumps(rows[-1]), flush=True)
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--lengths", nargs="+", type=float,
                        default=[40, 80, 120, 200, 300, 380, 460, 560, 680, 800, 1000,
                                 1500, 2000], help="audio per call (ms)")
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument("--settings", nargs="*",
                        default=["300/40/40", "300/80/40", "450/80/40", "600/40/40",
                                 "600/80/40", "600/120/80"],
                        help="a stream's hama context/settled/hop (ms)")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    if args.repeats < 1 or min(args.lengths) <= 0:
        print("bench_hama: --repeats and --lengths must be positive", file=sys.stderr)
        return 2
    print(f"# load average {os.getloadavg()} on {os.cpu_count()} cores", flush=True)
    x = speech(max(max(args.lengths) / 1000, 12.0))
    calls = per_call(x, args.lengths, args.repeats)
    line = fit(calls)
    print(json.dumps({"fit": line}), flush=True)
    streams = stream_model(x[: 12 * MODEL_RATE], args.settings, line)
    print(f"# load average {os.getloadavg()}", flush=True)
    if args.json:
        args.json.write_text(json.dumps({"calls": calls, "fit": line, "streams": streams},
                                        indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
