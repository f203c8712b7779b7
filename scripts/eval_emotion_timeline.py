"""The emotion timeline's window and hop, measured on long recordings of known emotions.

The default classifier (with probabilities, as ``emotion fit`` trains it) is fitted on some
RAVDESS actors; each held-out actor's utterances are joined into one long recording, runs of
``--run`` utterances of one emotion in a random order, so that the emotion changes every
10 s or so and the truth is known at every instant. For each window length and hop the
recording is classified window by window (:func:`ingest.emotion.timeline.classify_windows`)
and the emotion at every 0.1 s is the most probable of the probabilities interpolated between
window centres (:func:`ingest.emotion.timeline.weights_over_time`, what ``synth --emotion
auto`` follows). Printed: that accuracy, the mean windows per second (the cost), and one
label for the whole recording (the windows' mean) as the baseline.

    python scripts/eval_emotion_timeline.py --json timeline.json
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data" / "ravdess"


def _read(paths):
    from ingest.emotion.labelled import preset_label
    from ingest.formats.wav import read_wav

    out = []
    for p in paths:
        audio, rate = read_wav(p)
        emotion, actor = preset_label("ravdess", p)
        out.append((audio, rate, emotion, actor))
    return out


def _long_recording(items, run: int, rng) -> tuple[np.ndarray, int, np.ndarray, np.ndarray]:
    """Runs of ``run`` utterances of one emotion, in random order: audio, rate, and the
    truth as (ends in s, emotions)."""
    by = {}
    for it in items:
        by.setdefault(it[2], []).append(it)
    runs = []
    for group in by.values():
        order = rng.permutation(len(group))
        runs += [[group[k] for k in order[i:i + run]] for i in range(0, len(group), run)]
    rng.shuffle(runs)
    pieces, ends, labels, t = [], [], [], 0
    rate = items[0][1]
    for r in runs:
        for audio, *_ in r:
            pieces.append(audio)
            t += len(audio)
        ends.append(t / rate)
        labels.append(r[0][2])
    return np.concatenate(pieces), rate, np.array(ends), np.array(labels)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--train", default="01-08", help="training actors, a range (01-08)")
    ap.add_argument("--test", default="09-12", help="held-out actors, a range (09-12)")
    ap.add_argument("--emotions", default="neutral,happy,sad,angry")
    ap.add_argument("--windows", default="2,3,4", help="window lengths, seconds")
    ap.add_argument("--hops", default="0.5,1,2", help="hops, seconds")
    ap.add_argument("--run", type=int, default=3, help="utterances per run of one emotion")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--single", action="store_true",
                    help="one recording per actor and emotion (no change of emotion)")
    ap.add_argument("--one-speaker", action="store_true",
                    help="normalise each recording's windows together (one speaker)")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    from ingest.emotion.model import database_classifier
    from ingest.emotion.timeline import classify_windows, mean_probabilities, weights_over_time

    wanted = set(args.emotions.split(","))

    def actors(text):
        a, b = (int(x) for x in text.split("-"))
        return [f"{k:02d}" for k in range(a, b + 1)]

    def files(names):
        return [p for a in names for p in sorted((SHARED / f"Actor_{a}").glob("03-01-*.flac"))]

    train = [it for it in _read(files(actors(args.train))) if it[2] in wanted]
    test = [it for it in _read(files(actors(args.test))) if it[2] in wanted]
    t0 = time.perf_counter()
    clf = database_classifier().fit([(a, r) for a, r, _, _ in train],
                                    np.array([e for _, _, e, _ in train]),
                                    speakers=np.array([s for *_, s in train]))
    print(f"fitted on {len(train)} utterances of actors {args.train} in "
          f"{time.perf_counter() - t0:.0f} s")
    rng = np.random.default_rng(args.seed)
    recordings = []
    for actor in actors(args.test):
        items = [it for it in test if it[3] == actor]
        if args.single:
            for emotion in sorted(wanted):
                same = [it for it in items if it[2] == emotion]
                recordings.append(_long_recording(same, len(same), rng))
        else:
            recordings.append(_long_recording(items, args.run, rng))
    total_s = sum(len(a) / r for a, r, _, _ in recordings)
    print(f"{len(recordings)} held-out recordings, {total_s:.0f} s, runs of {args.run} "
          f"utterances (mean run {total_s / sum(len(e) for *_, e, _ in recordings):.1f} s)")
    rows = []
    for window in [float(x) for x in args.windows.split(",")]:
        for hop in [float(x) for x in args.hops.split(",")]:
            if hop > window:
                continue
            right = n = one_right = n_windows = 0
            t1 = time.perf_counter()
            for audio, rate, ends, labels in recordings:
                windows = classify_windows(clf, audio, rate, window=window, hop=hop,
                                           one_speaker=args.one_speaker)
                n_windows += len(windows)
                times = np.arange(0.05, len(audio) / rate, 0.1)
                truth = labels[np.minimum(np.searchsorted(ends, times), len(labels) - 1)]
                names, w = weights_over_time(windows, times)
                guess = np.array(names)[np.argmax(w, axis=1)]
                right += int(np.sum(guess == truth))
                one_right += int(np.sum(truth == next(iter(mean_probabilities(windows)))))
                n += len(times)
            rows.append({"window_s": window, "hop_s": hop, "accuracy": right / n,
                         "one_label_accuracy": one_right / n,
                         "windows_per_s": n_windows / total_s,
                         "seconds": time.perf_counter() - t1})
            r = rows[-1]
            print(f"window {window:g} s hop {hop:g} s: {100 * r['accuracy']:.1f} % of 0.1 s "
                  f"steps right (one label for all: {100 * r['one_label_accuracy']:.1f} %), "
                  f"{r['windows_per_s']:.2f} windows/s, {r['seconds']:.0f} s", flush=True)
    if args.json:
        args.json.write_text(json.dumps({"args": vars(args) | {"json": str(args.json)},
                                         "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
