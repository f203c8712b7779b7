"""How well hama's transcript check tells a clip's own transcript from another.

Usage::

    python scripts/eval_transcript_check.py [--clips 100] [--shared ../shared/data]

For every eighth GRID s1 clip (up to ``--clips``; real English speech) and for eSpeak NG
speech of the synthetic corpus' sentences, prints the distributions of
:func:`ingest.speech.ctc.transcript_loss` (nats per frame below free recognition) and
:func:`ingest.speech.ctc.phone_share` (phones named per phone heard) with (a) the clip's
own transcript, also with white noise at 10 and 0 dB SNR, through a telephone band and
with room echo (RT60 0.5 and 1 s), (b) an unrelated sentence, (c)
another clip's transcript (for GRID: a sentence of the same grammar and length), (d) the
transcript's first three words, (e) its last word alone, and how many of each
:func:`ingest.speech.ctc.check_transcript` rejects (loss above
:data:`~ingest.speech.ctc.MAX_ALIGN_LOSS`, or share below
:data:`~ingest.speech.ctc.MIN_PHONE_SHARE`) and how many it passes with a warning (loss
above :data:`~ingest.speech.ctc.DOUBT_ALIGN_LOSS`). The default phone engine runs this check
before PocketSphinx aligns a transcript (:func:`ingest.speech.engines.align_auto`), and
ingest before it aligns inside a word alignment's words.
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


def _case(audio: np.ndarray, rate: int, text: str) -> tuple[float, float, bool, bool]:
    """(loss, share, rejected, aligned with a warning) of ``text`` as the transcript of
    ``audio``."""
    try:
        loss = ctc.transcript_loss(audio, rate, text)
    except DataError:  # more phones than the audio has frames: no alignment at all
        return float("inf"), ctc.phone_share(audio, rate, text), True, False
    try:
        with ctc.doubts() as doubted:
            ctc.check_transcript(audio, rate, text)
    except DataError:
        return loss, ctc.phone_share(audio, rate, text), True, False
    return loss, ctc.phone_share(audio, rate, text), False, bool(doubted)


def _noisy(audio: np.ndarray, snr_db: float, seed: int) -> np.ndarray:
    noise = np.random.default_rng(seed).normal(size=len(audio))
    noise *= np.sqrt(np.mean(audio ** 2) / np.mean(noise ** 2)) * 10 ** (-snr_db / 20)
    return np.clip(audio + noise, -1, 1).astype(np.float32)


def _echo(audio: np.ndarray, rate: int, rt60: float, seed: int) -> np.ndarray:
    """``audio`` in a room whose echo decays 60 dB in ``rt60`` s, at its own peak level."""
    from eval_music import room_impulse  # scripts/ is sys.path[0]
    from scipy.signal import fftconvolve, resample_poly

    h = room_impulse(np.random.default_rng(seed), rt60)  # at 16 kHz
    h = resample_poly(h, rate, 16000) if rate != 16000 else h
    wet = fftconvolve(audio, h)[: audio.size]
    return (wet * np.max(np.abs(audio)) / max(np.max(np.abs(wet)), 1e-9)).astype(np.float32)


def _telephone(audio: np.ndarray, rate: int) -> np.ndarray:
    """``audio`` through an 8 kHz channel (nothing above 4 kHz), back at ``rate``."""
    from scipy.signal import resample_poly

    return resample_poly(resample_poly(audio, 8000, rate), rate, 8000)[: audio.size].astype(
        np.float32)


def _cases(audio: list[np.ndarray], rate: int, texts: list[str], name: str) -> dict:
    """The rows of one data set: (audio, text) pairs per case."""
    def words(t: str, part: slice) -> str:
        return " ".join(t.split()[part])

    n = len(texts)
    pairs = list(zip(audio, texts, strict=True))
    return {
        f"{name}, own transcript": pairs,
        f"{name}, own, noise 10 dB SNR": [(_noisy(a, 10, k), t) for k, (a, t) in
                                           enumerate(pairs)],
        f"{name}, own, noise 0 dB SNR": [(_noisy(a, 0, k), t) for k, (a, t) in
                                          enumerate(pairs)],
        f"{name}, own, telephone band (8 kHz)": [(_telephone(a, rate), t) for a, t in pairs],
        f"{name}, own, room echo RT60 0.5 s": [(_echo(a, rate, 0.5, k), t) for k, (a, t) in
                                               enumerate(pairs)],
        f"{name}, own, room echo RT60 1 s": [(_echo(a, rate, 1.0, k), t) for k, (a, t) in
                                             enumerate(pairs)],
        f"{name}, unrelated sentence": [(a, UNRELATED) for a in audio],
        f"{name}, the next one's": [(a, texts[(k + 1) % n]) for k, a in enumerate(audio)],
        f"{name}, its first three words": [(a, words(t, slice(3))) for a, t in
                                           zip(audio, texts, strict=True)],
        f"{name}, its last word": [(a, words(t, slice(-1, None))) for a, t in
                                   zip(audio, texts, strict=True)],
    }


def _mp4_audio(path: Path) -> np.ndarray:
    import imageio_ffmpeg

    out = subprocess.run(
        [imageio_ffmpeg.get_ffmpeg_exe(), "-v", "quiet", "-i", str(path), "-f", "s16le",
         "-ac", "1", "-ar", "16000", "-"], capture_output=True, check=True).stdout
    return np.frombuffer(out, "<i2").astype(np.float32) / 32768.0


def _row(name: str, results: list[tuple[float, float, bool, bool]]) -> str:
    loss, share, rejected, doubted = (np.asarray(v) for v in zip(*results, strict=True))
    finite = loss[np.isfinite(loss)]
    return (f"{name:<36} {len(loss):>5} {np.min(loss):>6.2f} {np.median(loss):>6.2f} "
            f"{np.max(finite) if finite.size else np.inf:>6.2f} {np.min(share):>6.2f} "
            f"{np.median(share):>6.2f} {np.max(share):>6.2f} "
            f"{int(rejected.sum()):>5}/{len(loss)} {int(doubted.sum()):>5}/{len(loss)}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clips", type=int, default=100)
    parser.add_argument("--shared", type=Path, default=SHARED)
    args = parser.parse_args()
    from ingest.speech.espeak import speak

    spoken = [speak(text) for text in ESPEAK]
    cases = _cases([u.audio for u in spoken], spoken[0].sample_rate,
                   [u.text for u in spoken], "eSpeak")
    folder = args.shared / "grid" / "s1"
    if folder.is_dir():
        videos = sorted(folder.glob("*.mp4"))[::8][: args.clips]
        texts = [v.with_suffix(".txt").read_text().strip() for v in videos]
        cases |= _cases([_mp4_audio(v) for v in videos], 16000, texts, "GRID")
    else:
        print(f"skipping GRID: {folder} not found", file=sys.stderr)
    print(f"{'transcript':<36} {'clips':>5} {'loss: min':>6} {'median':>6} {'max':>6} "
          f"{'share: min':>6} {'median':>6} {'max':>6} rejected  warned   (loss in "
          f"nats/frame, rejected above {ctc.MAX_ALIGN_LOSS}, aligned with a warning above "
          f"{ctc.DOUBT_ALIGN_LOSS}; share: phones named per phone heard, rejected below "
          f"{ctc.MIN_PHONE_SHARE})")
    for name, pairs in cases.items():
        rate = 16000 if name.startswith("GRID") else spoken[0].sample_rate
        print(_row(name, [_case(a, rate, t) for a, t in pairs]), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
