"""Time the serial emotion step of an ingest, part by part
(docs/results/emotion.md, "Cost").

Usage::

    python scripts/bench_emotion_model.py --corpus DIR --save INPUTS.npz [--workers 2]
    python scripts/bench_emotion_model.py --inputs INPUTS.npz [--repeat 3] [--profile]
                                          [--n-codebooks K]

``--save``: ingest ``DIR`` into a temporary database once, keeping what
:func:`ingest.emotion.model.fit_emotion_model` received (plain arrays, ``np.savez``).
``--inputs``: run :func:`fit_emotion_model` on them ``--repeat`` times in this process and
print, for each part (the speech / emotion split of the components, the emotion mappings,
the classifier), its wall and CPU seconds (the median over the repeats), the machine's
load average, and a digest of the fitted model's arrays (equal digests: equal results).
``--profile``: also the top of a cProfile of one run, by cumulative time.
``--n-codebooks K``: the database's classifier with K codebook pairs instead of the
default's (:func:`ingest.emotion.model.database_classifier` replaced for the run: the
ensemble of codebooks against one pair).
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import ingest.emotion.model as emotion_model
import ingest.pipeline as pipeline

_LISTS = ("sources", "motions", "audio")


def save_inputs(corpus: Path, out: Path, workers: int) -> int:
    captured = {}
    real = pipeline.fit_emotion_model

    def capture(sources, motions, emotions, sentence_ids, audio, loadings, groups, fps,
                **kw):
        captured.update(sources=sources, motions=motions, emotions=emotions,
                        sentence_ids=sentence_ids, audio=audio, loadings=loadings,
                        groups=groups, fps=fps, **kw)
        return real(sources, motions, emotions, sentence_ids, audio, loadings, groups, fps,
                    **kw)

    pipeline.fit_emotion_model = capture
    with tempfile.TemporaryDirectory() as tmp:
        pipeline.ingest([corpus], Path(tmp) / "db", workers=workers)
    arrays = {"n": np.array(len(captured["sources"])), "fps": np.array(captured["fps"]),
              "loadings": captured["loadings"], "groups": np.array(captured["groups"]),
              "emotions": np.array(captured["emotions"]),
              "sentence_ids": np.array([s or "" for s in captured["sentence_ids"]]),
              "speakers": np.array([s or "" for s in captured["speakers"]]),
              "random_state": np.array(captured["random_state"])}
    for k in range(len(captured["sources"])):
        arrays[f"sources/{k}"] = captured["sources"][k]
        arrays[f"motions/{k}"] = captured["motions"][k]
        audio, rate = captured["audio"][k]
        arrays[f"audio/{k}"] = audio
        arrays[f"rate/{k}"] = np.array(rate)
        row = captured["classifier_rows"][k]  # SpeechFeatures, a reason (str) or None
        if row is None or isinstance(row, str):
            arrays[f"row/{k}"] = np.array(row or "")
        else:
            arrays[f"row/{k}"] = row.functionals
            if row.frames is not None:
                arrays[f"frames/{k}"] = row.frames[0]
    np.savez(out, **arrays)
    print(f"saved the inputs of {len(captured['sources'])} clips to {out}")
    return 0


def load_inputs(path: Path) -> tuple[tuple, dict]:
    from ingest.emotion.classifier import SpeechFeatures

    z = np.load(path, allow_pickle=False)
    n = int(z["n"])
    rows = []
    for k in range(n):
        r = z[f"row/{k}"]
        frames = [z[f"frames/{k}"]] if f"frames/{k}" in z else None
        rows.append((str(r) or None) if r.dtype.kind == "U" else SpeechFeatures(r, frames))
    args = ([z[f"sources/{k}"] for k in range(n)], [z[f"motions/{k}"] for k in range(n)],
            [str(e) for e in z["emotions"]], [str(s) or None for s in z["sentence_ids"]],
            [(z[f"audio/{k}"], int(z[f"rate/{k}"])) for k in range(n)], z["loadings"],
            [str(g) for g in z["groups"]], float(z["fps"]))
    kw = dict(random_state=int(z["random_state"]),
              speakers=[str(s) or None for s in z["speakers"]], classifier_rows=rows)
    return args, kw


def digest(model) -> str:
    arrays, manifest, columns = model.to_database()
    h = hashlib.sha1()
    for key in sorted(arrays):
        h.update(key.encode())
        h.update(np.ascontiguousarray(arrays[key], dtype=np.float64).tobytes())
    h.update(repr(sorted(manifest.items())).encode())
    h.update(repr(sorted(columns.items())).encode())
    return h.hexdigest()[:12]


#: Functions of :mod:`ingest.emotion.model` timed by :func:`timed_parts`.
PARTS = ("split_components", "fit_mapping", "_fit_classifier")


@contextlib.contextmanager
def timed_parts():
    """Wall and CPU seconds spent in :data:`PARTS` while the block runs: yields
    ``{"wall": {name: s}, "cpu": {name: s}}``."""
    out: dict = {"wall": {}, "cpu": {}}
    saved = {name: getattr(emotion_model, name) for name in PARTS}

    def wrap(name, real):
        def timed(*a, **kw):
            w, c = time.perf_counter(), time.process_time()
            try:
                return real(*a, **kw)
            finally:
                out["wall"][name] = out["wall"].get(name, 0.0) + time.perf_counter() - w
                out["cpu"][name] = out["cpu"].get(name, 0.0) + time.process_time() - c
        return timed

    for name, real in saved.items():
        setattr(emotion_model, name, wrap(name, real))
    try:
        yield out
    finally:
        for name, real in saved.items():
            setattr(emotion_model, name, real)


def time_inputs(path: Path, repeat: int, profile: bool, n_codebooks: int | None = None) -> int:
    args, kw = load_inputs(path)
    if n_codebooks is not None:
        default = emotion_model.database_classifier
        emotion_model.database_classifier = lambda: default().set_params(
            n_codebooks=n_codebooks)
    runs = []
    for _ in range(repeat):
        w, c = time.perf_counter(), time.process_time()
        with timed_parts() as parts:
            model = emotion_model.fit_emotion_model(*args, **kw)
        runs.append((time.perf_counter() - w, time.process_time() - c, parts, digest(model)))
    print(f"fit_emotion_model on {len(args[0])} clips, {repeat} run(s), load average "
          f"{os.getloadavg()[0]:.1f}; classifier n_codebooks="
          f"{emotion_model.database_classifier().n_codebooks}; children's CPU is not in "
          "'CPU (this process)'")
    print(f"  {'part':<22}{'wall (s)':>10}{'CPU, this process (s)':>24}")
    for name in PARTS:
        if name in runs[0][2]["wall"]:
            print(f"  {name:<22}{np.median([r[2]['wall'][name] for r in runs]):10.2f}"
                  f"{np.median([r[2]['cpu'][name] for r in runs]):24.2f}")
    print(f"  {'total':<22}{np.median([r[0] for r in runs]):10.2f}"
          f"{np.median([r[1] for r in runs]):24.2f}")
    print(f"  children's CPU so far: {os.times().children_user:.2f} s; model digest(s): "
          + ", ".join(sorted({r[3] for r in runs})))
    if profile:
        import cProfile
        import pstats

        prof = cProfile.Profile()
        prof.runcall(emotion_model.fit_emotion_model, *args, **kw)
        pstats.Stats(prof, stream=sys.stdout).sort_stats("cumulative").print_stats(25)
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--corpus", type=Path)
    parser.add_argument("--save", type=Path)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--inputs", type=Path)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--profile", action="store_true")
    parser.add_argument("--n-codebooks", type=int, help="codebook pairs of the classifier")
    args = parser.parse_args()
    if args.corpus and args.save:
        return save_inputs(args.corpus, args.save, args.workers)
    if args.inputs:
        return time_inputs(args.inputs, args.repeat, args.profile, args.n_codebooks)
    parser.error("give --corpus DIR --save FILE, or --inputs FILE")
    return 2


if __name__ == "__main__":
    sys.exit(main())
