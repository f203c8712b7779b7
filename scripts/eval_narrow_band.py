"""How well the narrow-band check tells real speech from speech that was 8 kHz.

Usage::

    python scripts/eval_narrow_band.py [--shared ../shared/data]

For real recordings (every third GRID s1 clip, every EmoDB clip, the talkingface clips;
all at 16 kHz) prints the distribution of :func:`ingest.speech.quality.assess`'s
``high_band_db`` (power density over :data:`~ingest.speech.quality.HIGH_BAND` against
:data:`~ingest.speech.quality.SPEECH_BAND`, dB) as recorded and brought to 8 kHz and back
(``scipy.signal.resample_poly``, its default Kaiser window, beta 5, and beta 2), and
how many each would call narrow-band (below
:data:`~ingest.speech.quality.NARROW_BAND_DB`); then the same for random cuts of 0.2 to
1.5 s, split by whether they hold :data:`~ingest.speech.quality.MIN_BAND_SOUND` s of sound.
"""

from __future__ import annotations

import argparse
import sys
from math import gcd
from pathlib import Path

import numpy as np
from scipy.signal import resample_poly

from ingest.formats.media import read_audio
from ingest.speech import quality

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
RATE = 16000


def _band_db(x: np.ndarray, sound: float | None = None) -> float | None:
    """``high_band_db`` of ``x`` at 16 kHz; ``sound``: judged over this least sound."""
    saved = quality.MIN_BAND_SOUND
    if sound is not None:
        quality.MIN_BAND_SOUND = sound
    try:
        return quality.assess(x, RATE).high_band_db
    finally:
        quality.MIN_BAND_SOUND = saved


def _at_16k(path: Path) -> np.ndarray:
    x, rate = read_audio(path, RATE) if path.suffix != ".wav" else read_audio(path)
    x = x.astype(np.float64)
    if rate != RATE:
        g = gcd(RATE, rate)
        x = resample_poly(x, RATE // g, rate // g)
    return x


def _telephone(x: np.ndarray, window=("kaiser", 5.0)) -> np.ndarray:
    return resample_poly(resample_poly(x, 1, 2, window=window), 2, 1, window=window)


def _row(name: str, values: list[float]) -> str:
    v = np.asarray([x for x in values if x is not None])
    below = int(np.sum(v < quality.NARROW_BAND_DB))
    return (f"{name:<44} {len(v):>5} {v.min():>7.1f} {np.percentile(v, 1):>7.1f} "
            f"{np.median(v):>7.1f} {v.max():>7.1f} {below:>5}/{len(v)}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shared", type=Path, default=SHARED)
    args = parser.parse_args()
    sets = {"GRID s1 (every third)": sorted((args.shared / "grid" / "s1").glob("*.mp4"))[1::3],
            "EmoDB": sorted((args.shared / "emodb" / "wav").glob("*.wav")),
            "talkingface": sorted((args.shared / "talkingface").glob("*/audio_16k.wav"))}
    if not any(sets.values()):
        print(f"no recordings under {args.shared}", file=sys.stderr)
        return 1
    rng = np.random.default_rng(0)
    print(f"{'audio':<44} {'clips':>5} {'min':>7} {'p1':>7} {'median':>7} {'max':>7} "
          f"narrow  (high band against speech band, dB; narrow below "
          f"{quality.NARROW_BAND_DB})")
    cuts: dict[str, list] = {}
    for name, files in sets.items():
        if not files:
            continue
        real, phone, poor = [], [], []
        for path in files:
            x = _at_16k(path)
            real.append(_band_db(x))
            phone.append(_band_db(_telephone(x)))
            poor.append(_band_db(_telephone(x, ("kaiser", 2.0))))
            for seconds in (0.2, 0.5, 1.0, 1.5):
                n = int(seconds * RATE)
                start = int(rng.integers(0, max(1, len(x) - n)))
                piece = x[start:start + n]
                if np.abs(piece).max() < 0.05:  # a pause: no sound to judge
                    continue
                judged = _band_db(piece) is not None
                key = (f"cuts of {seconds:g} s, {'>=' if judged else '<'} "
                       f"{quality.MIN_BAND_SOUND:g} s of sound")
                cuts.setdefault(key, []).append(_band_db(piece, sound=0.0))
        print(_row(f"{name}, as recorded", real))
        print(_row(f"{name}, 8 kHz and back", phone))
        print(_row(f"{name}, 8 kHz and back (Kaiser beta 2)", poor), flush=True)
    for key in sorted(cuts):
        print(_row(key, cuts[key]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
