"""How well hama's transcript check tells a clip's own transcript from another.

Usage::

    python scripts/eval_transcript_check.py [--clips 100] [--shared ../shared/data]

For every eighth GRID s1 clip (up to ``--clips``; real English speech) and for eSpeak NG
speech of the synthetic corpus' sentences, prints the distribution of
:func:`ingest.speech.ctc.transcript_loss` (nats per frame below free recognition) with
(a) the clip's own transcript, (b) an unrelated sentence, (c) another clip's transcript
(for GRID: a sentence of the same grammar and length), and how many of each the check
(:data:`ingest.speech.ctc.MAX_ALIGN_LOSS`) rejects. The default phone engine runs this
check before PocketSphinx aligns a transcript (:func:`ingest.speech.engines.align_auto`).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import numpy as np

from db.errors import DataError
from ingest.speech import ctc

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
UNRELATED = "The quick brown fox jumps over the lazy dog near the river bank."
ESPEAK = ("Please move the boxes off the porch.",
          "The young boy took a brown bag of fresh cheese to the village market.",
          "Joy, the cheerful cook, enjoyed boiling oysters for lunch.",
          "She sells sea shells by the sea shore every single morning.",
          "Bring the green cups to the kitchen before dinner.",
          "I never said she stole my money, he said quietly.")


def _loss(audio: np.ndarray, rate: int, text: str) -> float:
    try:
        return ctc.transcript_loss(audio, rate, text)
    except DataError:  # more phones than the audio has frames: no alignment at all
        return float("inf")


def _mp4_audio(path: Path) -> np.ndarray:
    import imageio_ffmpeg

    out = subprocess.run(
        [imageio_ffmpeg.get_ffmpeg_exe(), "-v", "quiet", "-i", str(path), "-f", "s16le",
         "-ac", "1", "-ar", "16000", "-"], capture_output=True, check=True).stdout
    return np.frombuffer(out, "<i2").astype(np.float32) / 32768.0


def _row(name: str, values: list[float]) -> str:
    v = np.asarray(values)
    finite = v[np.isfinite(v)]
    rejected = int(np.sum(v > ctc.MAX_ALIGN_LOSS))
    return (f"{name:<34} {len(v):>5} {np.min(v):>7.2f} {np.median(v):>7.2f} "
            f"{np.max(finite) if finite.size else np.inf:>7.2f} {rejected:>5}/{len(v)}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clips", type=int, default=100)
    parser.add_argument("--shared", type=Path, default=SHARED)
    args = parser.parse_args()
    from ingest.speech.espeak import speak

    rows = {}
    spoken = [speak(text) for text in ESPEAK]
    rows["eSpeak, own transcript"] = [_loss(u.audio, u.sample_rate, u.text) for u in spoken]
    rows["eSpeak, unrelated sentence"] = [_loss(u.audio, u.sample_rate, UNRELATED)
                                          for u in spoken]
    rows["eSpeak, the next sentence's"] = [
        _loss(u.audio, u.sample_rate, spoken[(k + 1) % len(spoken)].text)
        for k, u in enumerate(spoken)]
    folder = args.shared / "grid" / "s1"
    if folder.is_dir():
        videos = sorted(folder.glob("*.mp4"))[::8][: args.clips]
        texts = [v.with_suffix(".txt").read_text().strip() for v in videos]
        audio = [_mp4_audio(v) for v in videos]
        rows["GRID, own transcript"] = [_loss(a, 16000, t) for a, t in zip(audio, texts,
                                                                          strict=True)]
        rows["GRID, unrelated sentence"] = [_loss(a, 16000, UNRELATED) for a in audio]
        rows["GRID, the next clip's (same grammar)"] = [
            _loss(a, 16000, texts[(k + 1) % len(texts)]) for k, a in enumerate(audio)]
    else:
        print(f"skipping GRID: {folder} not found", file=sys.stderr)
    print(f"{'transcript':<34} {'clips':>5} {'min':>7} {'median':>7} {'max':>7} rejected"
          f"  (loss in nats/frame; rejected above {ctc.MAX_ALIGN_LOSS})")
    for name, values in rows.items():
        print(_row(name, values))
    return 0


if __name__ == "__main__":
    sys.exit(main())
