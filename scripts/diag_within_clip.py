"""How much of each clip's mouth opening its own audio explains: a reference for the
lip-sync tables that is given more than any system.

Usage::

    python scripts/diag_within_clip.py {talkingface,facegood,livelink}

For every clip of ``../shared/data/<DATA>``: a ridge regression from the clip's log-mel
frames (40 bands, +-200 ms of context, at the motion's frame rate) to its mouth opening
(:func:`animegraph.motion.measures.mouth_opening`), fitted on four of five contiguous
blocks of **the same clip** and tested on the fifth (ridge penalty by ``RidgeCV`` inside
the training blocks); prints each clip's Pearson R of the predictions against the truth
and the mean. A system that never heard the speaker being below this is no surprise; a
target above it asks for more than a linear map of the clip's own audio supports.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import librosa
import numpy as np
from sklearn.linear_model import RidgeCV

from animegraph.motion.measures import mouth_opening, pearson
from ingest.pipeline import IngestConfig, prepare_sources
from ingest.readers import discover

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"
N_MELS = 40
CONTEXT_S = 0.2
N_BLOCKS = 5


def context_frames(mel: np.ndarray, fps: float) -> np.ndarray:
    """Log-mel frames (n, N_MELS) with their neighbours within CONTEXT_S (7 offsets)."""
    ctx = int(round(CONTEXT_S * fps))
    step = max(1, ctx // 3)
    return np.concatenate([np.roll(mel, s, axis=0) for s in range(-ctx, ctx + 1, step)],
                          axis=1)


def within_clip_r(clip) -> float:
    audio = clip.audio.astype(np.float32) / 32767.0
    hop = int(round(clip.sample_rate / clip.fps))
    mel = np.log(librosa.feature.melspectrogram(y=audio, sr=clip.sample_rate, n_fft=2 * hop,
                                                hop_length=hop, n_mels=N_MELS) + 1e-8).T
    y = mouth_opening(clip.motion.astype(np.float64), clip.schema.names, clip.schema.kind)
    n = min(len(y), len(mel))
    x, y = context_frames(mel[:n], clip.fps), y[:n]
    pred = np.zeros(n)
    for block in np.array_split(np.arange(n), N_BLOCKS):
        train = np.setdiff1d(np.arange(n), block)
        model = RidgeCV(alphas=np.logspace(-1, 4, 11)).fit(x[train], y[train])
        pred[block] = model.predict(x[block])
    return pearson(pred, y)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("data", choices=("talkingface", "facegood", "livelink"))
    args = parser.parse_args()
    if not (SHARED / args.data).is_dir():
        print(f"diag_within_clip: {SHARED / args.data} is not there", file=sys.stderr)
        return 1
    clips, _ = prepare_sources(discover([SHARED / args.data]), IngestConfig(), workers=1)
    rs = []
    for clip in clips:
        rs.append(within_clip_r(clip))
        print(f"{clip.clip_id:40s} {clip.duration:6.1f} s  within-clip R {rs[-1]:.3f}",
              flush=True)
    print(f"mean over {len(rs)} clips: {np.mean(rs):.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
