"""Where each phone engine's recognised GRID phones differ from the aligned ones (issue 14).

Usage::

    python scripts/grid_phone_engines.py --grid-db DB [--clips 159] [--engines hama pocketsphinx]

Reads the clips of an ``animegraph ingest`` of ``grid/s1`` (phones aligned inside GRID's
word alignments), takes the held-out clips of ``scripts/eval_lipsync.py --datasets grid``
(every fifth in clip-id order; the first ``--clips`` of them), recognises their phones
from the audio alone with each engine and prints, means over the clips, on 10 ms frames
over the aligned span:

- ``acc``: same phone as the aligned one; ``speech_acc`` / ``speech_viseme``: same phone /
  viseme class on the aligned speech frames (not ``SIL``);
- ``sil_as_speech``: share of the aligned silence frames given a phone (the mouth then
  moves where the speaker is silent), split into ``edge_sil_as_speech`` (the silence
  before the first and after the last aligned phone) and ``pause_sil_as_speech`` (pauses
  between phones); ``speech_as_sil``: the reverse;
- ``vowels_mouth_r`` / ``ref_vowels_mouth_r``: how well a vowel indicator of the phones
  (recognised / aligned) follows the clip's mouth opening (:func:`vowels_follow`): what
  the phones' names and times say about the mouth before any synthesis;
- ``per``: phone error rate (``SIL`` left out); ``phones`` / ``ref_phones``: phones a clip;
  ``median_dur_s`` / ``ref_median_dur_s``: median phone duration; ``ref_silence_s`` /
  ``ref_seconds``: seconds of ``SIL`` in the aligned phones / of the clip.

With ``--scores RUN.json`` (an ``eval_lipsync.py --datasets grid --grid-engines ...`` run on
the same split) it also prints, per engine, the correlation over the clips between each
measure and the mouth R of ``--system`` synthesized from that engine's phones (part
``recognized-<engine>``): which of them goes with the motion's quality.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from animegraph.apps.evaluate import GRID_HOLDOUT, grid_split
from animegraph.motion.measures import mouth_opening
from db.store import Database
from ingest.speech.engines import ENGINES
from ingest.speech.phones import SILENCE, VISEME_OF, VOWELS
from ingest.speech.scoring import phone_error_rate
from ingest.speech.segment import segment
from ingest.tables import prepared_from_database

STEP_S = 0.01
#: Gaussian smoothing (s) of the vowel indicator of :func:`vowels_follow`.
VOWEL_SIGMA_S = 0.05


def frame_labels(segments, t: np.ndarray) -> np.ndarray:
    """The phone of each time in ``t`` (s), shape (len(t),)."""
    starts = np.array([s.start for s in segments])
    k = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(segments) - 1)
    return np.array([segments[j].phone for j in k])


def vowels_follow(segments, opening: np.ndarray, fps: float) -> float:
    """Pearson r of a mouth opening, shape (n_frames,) at ``fps``, with a vowel indicator
    of ``segments`` (1 in a vowel, else 0; Gaussian-smoothed, sigma
    :data:`VOWEL_SIGMA_S`)."""
    from scipy.ndimage import gaussian_filter1d

    labels = frame_labels(segments, np.arange(len(opening)) / fps)
    vowel = np.isin(labels, VOWELS).astype(np.float64)
    return float(np.corrcoef(gaussian_filter1d(vowel, VOWEL_SIGMA_S * fps), opening)[0, 1])


def agreement(reference, hypothesis, opening: np.ndarray, fps: float) -> dict[str, float]:
    """The measures of the module docstring for one clip (``opening``: its mouth
    opening, shape (n_frames,) at ``fps``)."""
    t = np.arange(reference[0].start, reference[-1].end, STEP_S) + STEP_S / 2
    a, b = frame_labels(reference, t), frame_labels(hypothesis, t)
    silent = a == SILENCE
    speech = ~silent
    said = np.flatnonzero(speech)
    edge = silent.copy()
    if said.size:
        edge[said[0]:said[-1] + 1] = False
    pause = silent & ~edge
    vis = np.array([VISEME_OF[x] == VISEME_OF[y] for x, y in zip(a, b, strict=True)])
    durs = [s.end - s.start for s in hypothesis if s.phone != SILENCE]
    ref_durs = [s.end - s.start for s in reference if s.phone != SILENCE]
    return {"acc": float(np.mean(a == b)),
            "speech_acc": float(np.mean(a[speech] == b[speech])),
            "speech_viseme": float(np.mean(vis[speech])),
            "sil_as_speech": float(np.mean(b[silent] != SILENCE)) if silent.any() else np.nan,
            "edge_sil_as_speech": float(np.mean(b[edge] != SILENCE)) if edge.any() else np.nan,
            "pause_sil_as_speech": (float(np.mean(b[pause] != SILENCE)) if pause.any()
                                    else np.nan),
            "speech_as_sil": float(np.mean(b[speech] == SILENCE)),
            "vowels_mouth_r": vowels_follow(hypothesis, opening, fps),
            "ref_vowels_mouth_r": vowels_follow(reference, opening, fps),
            "per": phone_error_rate(reference, hypothesis),
            "phones": float(len(durs)), "ref_phones": float(len(ref_durs)),
            "median_dur_s": float(np.median(durs)) if durs else np.nan,
            "ref_median_dur_s": float(np.median(ref_durs)),
            "ref_silence_s": float(sum(s.end - s.start for s in reference
                                       if s.phone == SILENCE)),
            "ref_seconds": float(reference[-1].end - reference[0].start)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grid-db", type=Path, required=True)
    parser.add_argument("--clips", type=int, default=None, help="held-out clips (default all)")
    parser.add_argument("--engines", nargs="+", choices=ENGINES,
                        default=["hama", "pocketsphinx"])
    parser.add_argument("--scores", type=Path, help="an eval_lipsync.py --json run (grid)")
    parser.add_argument("--system", default="kbest20")
    args = parser.parse_args()
    test = grid_split(prepared_from_database(Database.open(args.grid_db)))[1]
    test = test[:args.clips]
    rows: dict[str, list[dict]] = {e: [] for e in args.engines}
    for clip in test:
        audio = clip.audio.astype(np.float32) / 32767.0
        opening = mouth_opening(clip.motion, clip.schema.names, clip.schema.kind)
        for engine in args.engines:
            hyp = list(segment(audio, clip.sample_rate, engine=engine)[0])
            rows[engine].append(agreement(list(clip.phones), hyp, opening, clip.fps))
    print(f"# {len(test)} held-out GRID clips (every {GRID_HOLDOUT}th in clip-id order); "
          "means over clips")
    keys = list(next(iter(rows.values()))[0])
    print(f"{'engine':13s} " + " ".join(f"{k:>19s}" for k in keys))
    for engine, values in rows.items():
        print(f"{engine:13s} " + " ".join(f"{np.nanmean([v[k] for v in values]):19.3f}"
                                          for k in keys))
    if args.scores is None:
        return 0
    run = json.loads(args.scores.read_text())["grid"]
    print(f"# correlation over the clips with {args.system}'s mouth R from the engine's phones")
    for engine, values in rows.items():
        part = run.get(f"recognized-{engine}")
        if part is None:
            print(f"{engine:13s} (no part recognized-{engine} in {args.scores})")
            continue
        scores = {c["clip"]: c["methods"][args.system]["mouth_r"] for c in part["clips"]}
        r = np.array([scores[c.clip_id] for c in test])
        cells = []
        for k in keys:
            v = np.array([x[k] for x in values])
            ok = np.isfinite(v) & np.isfinite(r)
            cells.append(np.corrcoef(v[ok], r[ok])[0, 1] if ok.sum() > 2 else np.nan)
        print(f"{engine:13s} " + " ".join(f"{c:19.2f}" for c in cells))
    return 0


if __name__ == "__main__":
    sys.exit(main())
