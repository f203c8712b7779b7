"""How the emotion classifier's speech check (``ingest.emotion.audio.speech_problem``)
judges real speech and generated non-speech: false refusals and what passes.

Usage::

    python scripts/measure_speech_check.py [--shared ../shared/data] [--per-corpus 200]

Reads up to ``--per-corpus`` recordings of each of EmoDB (``emodb/wav``), RAVDESS
(``ravdess/Actor_*``) and GRID (``grid/s1``, the sound of its videos), every one real
speech, and generates noise (white, pink, brown), tones (sine at 110-880 Hz, a chord, a
sweep) and music (notes with harmonics under an attack-decay envelope, with and without
rests) at several levels, and speech at -70 dBFS peak (an EmoDB recording scaled down).
Prints the measures' ranges per kind and the share refused: a real recording refused is
a false refusal; a generated one passed is a miss.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from db.errors import DataError
from ingest.emotion.audio import (
    FEATURE_SAMPLE_RATE,
    prepare_audio,
    speech_measures,
    speech_problem,
)
from ingest.formats.media import read_audio

SR = FEATURE_SAMPLE_RATE


def _real(shared: Path, n: int):
    rng = np.random.default_rng(0)
    corpora = {"emodb": sorted((shared / "emodb" / "wav").glob("*.wav")),
               "ravdess": sorted((shared / "ravdess").glob("Actor_*/*.flac")),
               "grid": sorted((shared / "grid" / "s1").glob("*.mp4"))}
    for name, files in corpora.items():
        if len(files) > n:
            files = [files[i] for i in sorted(rng.choice(len(files), n, replace=False))]
        for path in files:
            audio, rate = read_audio(path)
            yield name, path.name, audio, rate
    quiet = corpora["emodb"][:20]
    for path in quiet:  # real speech whose peak is at -70 dBFS
        audio, rate = read_audio(path)
        audio = np.asarray(audio, dtype=np.float64)
        yield "speech at -70 dBFS", path.name, audio / np.abs(audio).max() * 10 ** (-70 / 20), rate


def _note(f0, seconds, rng):
    t = np.arange(int(seconds * SR)) / SR
    tone = sum(np.sin(2 * np.pi * f0 * k * t + rng.uniform(0, 6)) / k for k in range(1, 6))
    envelope = np.minimum(1.0, t / 0.02) * np.exp(-t / max(seconds, 0.1))
    return tone * envelope


def _generated(seed: int):
    rng = np.random.default_rng(seed)
    n = 3 * SR
    t = np.arange(n) / SR
    white = rng.standard_normal(n)
    spectrum = np.fft.rfft(rng.standard_normal(n))
    f = np.maximum(np.fft.rfftfreq(n, 1 / SR), 1.0)
    pink = np.fft.irfft(spectrum / np.sqrt(f), n)
    brown = np.cumsum(rng.standard_normal(n))
    brown -= np.convolve(brown, np.ones(400) / 400, "same")
    out = {"noise: white": white, "noise: pink": pink, "noise: brown": brown,
           "noise: white, bursts": white * (np.sin(2 * np.pi * 3 * t) > 0)}
    for f0 in (110, 220, 440, 880):
        out[f"tone: {f0} Hz"] = np.sin(2 * np.pi * f0 * t)
    out["tone: chord"] = sum(np.sin(2 * np.pi * f * t) for f in (261.6, 329.6, 392.0))
    out["tone: sweep 100-1000 Hz"] = np.sin(2 * np.pi * (100 * t + 150 * t * t))
    scale = [261.6, 293.7, 329.6, 349.2, 392.0, 440.0, 493.9, 523.3]
    legato = np.concatenate([_note(rng.choice(scale), 0.25, rng) for _ in range(12)])
    out["music: notes"] = legato
    rests = np.concatenate([np.concatenate([_note(rng.choice(scale), 0.2, rng),
                                            np.zeros(int(0.05 * SR))]) for _ in range(12)])
    out["music: notes with rests"] = rests
    for name, x in list(out.items()):
        x = x / np.abs(x).max()
        out[name] = x
        out[f"{name} at -40 dBFS"] = x * 0.01
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shared", type=Path,
                        default=Path(__file__).resolve().parents[2] / "shared" / "data")
    parser.add_argument("--per-corpus", type=int, default=200)
    args = parser.parse_args(argv)
    real: dict[str, list] = {}
    refused: dict[str, list[str]] = {}
    for corpus, name, audio, rate in _real(args.shared, args.per_corpus):
        try:
            x = prepare_audio(audio, rate)
        except DataError as exc:
            refused.setdefault(corpus, []).append(f"{name}: {exc}")
            real.setdefault(corpus, [])
            continue
        m = speech_measures(x)
        real.setdefault(corpus, []).append(m)
        problem = speech_problem(x)
        if problem:
            refused.setdefault(corpus, []).append(f"{name}: {problem}")
    print("real speech (every one should pass):")
    total = wrong = 0
    for corpus, rows in real.items():
        n = len(rows) + sum(1 for r in refused.get(corpus, []) if "silence" in r)
        bad = len(refused.get(corpus, []))
        total, wrong = total + n, wrong + bad
        voiced = np.array([r["voiced"] for r in rows])
        spread = np.array([r["spread"] for r in rows])
        print(f"  {corpus}: {n} recordings, {bad} refused; voiced share "
              f"{voiced.min():.2f}-{voiced.max():.2f} (median {np.median(voiced):.2f}), "
              f"level spread {spread.min():.1f}-{spread.max():.1f} dB")
        for line in refused.get(corpus, [])[:5]:
            print(f"    refused {line}")
    print(f"false refusals: {wrong} of {total} ({100 * wrong / max(total, 1):.2f} %)")
    print("generated (none should pass):")
    missed = count = 0
    for seed in (1, 2):
        for name, x in _generated(seed).items():
            count += 1
            try:
                y = prepare_audio(x, SR)
            except DataError as exc:
                print(f"  {name}: refused: {exc}")
                continue
            m = speech_measures(y)
            problem = speech_problem(y)
            missed += not problem
            print(f"  {name}: voiced {m['voiced']:.2f}, spread {m['spread']:.1f} dB: "
                  f"{'refused: ' + problem if problem else 'PASSED AS SPEECH'}")
    print(f"generated passed as speech: {missed} of {count}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
