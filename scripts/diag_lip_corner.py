"""Why the demo's synthesized lip-corner curve spikes: each post-processing step on/off.

Usage::

    python scripts/diag_lip_corner.py [--db PATH] [--emotion happy]

Synthesizes the demo's held-out sentence (its eSpeak speech and exact phones, as
``animegraph demo`` does) from the database (default: the demo's) with every
combination of time-warping, blending and smoothing (and with the helper pair blended as
the paper does or anchored, every ``PostOptions.helper``), and prints the lip-corner-to-eye
distance (the demo plot's second measure) of the synthesized motion: its maximum and its
99th percentile over the speech, against the reference motion of the same sentence in
that emotion and in neutral, and the number of jump matches.
"""

from __future__ import annotations

import argparse
import itertools
import sys
from pathlib import Path

import numpy as np

from animegraph.apps.cache import default_database
from animegraph.apps.demo import DEMO_SENTENCE
from animegraph.synthesis import HELPER_MODES, Model, PostOptions, synthesize
from db.store import is_database
from ingest.corpus import face
from ingest.corpus.emotions import EMOTIONS
from ingest.corpus.synthetic import ClipSpec, CorpusConfig, synthesize_clip
from ingest.formats.phones_csv import Segment

A, B = "lip_corner_r", "eye_out_r"


def _summary(markers: np.ndarray, fps: float, start: float, end: float) -> str:
    d = face.marker_distance(markers, A, B)[int(start * fps):int(end * fps)]
    return f"max {np.nanmax(d):6.2f} mm, 99th percentile {np.nanpercentile(d, 99):6.2f} mm"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--db", type=Path, default=None)
    parser.add_argument("--emotion", default="happy")
    args = parser.parse_args()
    db = args.db or default_database()[0]
    if not is_database(db):
        sys.exit(f"diag_lip_corner: no database at {db}: run 'animegraph demo' first")
    config = CorpusConfig()
    clips = {}
    for emo in dict.fromkeys([args.emotion, "neutral"]):
        spec = ClipSpec(clip_id=f"demo_{emo}", sentence_id="demo", text=DEMO_SENTENCE,
                        emotion=emo, variation=1, speaker=config.speaker,
                        seed=EMOTIONS.index(emo) + 1)
        clips[emo] = synthesize_clip(spec, config)
    clip = clips[args.emotion]
    speech = [p for p in clip.utterance.phones if p.phone != "SIL"]
    start, end = speech[0].start, speech[-1].end
    print(f"{A} to {B}, {start:.2f}-{end:.2f} s of '{DEMO_SENTENCE}'")
    for emo, c in clips.items():
        print(f"  reference {emo:<8s}: {_summary(c.markers, c.fps, start, end)}")
    model = Model.load(db)
    labels = [Segment(p.phone, p.start, p.end) for p in clip.utterance.phones]
    runs = [(warp, blend, smooth, "paper")
            for warp, blend, smooth in itertools.product((True, False), repeat=3)]
    runs += [(warp, True, smooth, helper) for helper in HELPER_MODES[1:]
             for warp, smooth in itertools.product((True, False), repeat=2)]
    for warp, blend, smooth, helper in runs:
        out = synthesize(model, clip.utterance.audio, clip.utterance.sample_rate,
                         labels=labels, emotion=args.emotion,
                         options=PostOptions(time_warp=warp, blend=blend, smooth=smooth,
                                             helper=helper))
        markers = out.motion.reshape(len(out.motion), -1, 3)
        helpers = sum(1 for j in out.joins if j.get("blend") == "helper")
        print(f"  synthesized warp={warp!s:<5} blend={blend!s:<5} smooth={smooth!s:<5} "
              f"helper={helper if blend else '-':<18}: {_summary(markers, out.fps, start, end)}; "
              f"{out.result.n_jumps} jumps, {helpers} blended with a helper pair")


if __name__ == "__main__":
    main()
