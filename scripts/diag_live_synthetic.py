"""Where live synthesis loses to the offline default on the synthetic split: the guide or
the animes, and which step of them.

Usage::

    python scripts/diag_live_synthetic.py [--work DIR] [--lookahead 120]
                                          [--variants base fade ...]
    python scripts/diag_live_synthetic.py --agreement WAV [WAV ...]

The split is ``scripts/bench_live.py --quality synthetic``'s (its generated corpus, held-out
clips and database; with ``--work`` the corpus and database are kept there and reused).
Each held-out clip is synthesized offline and live with the guide's share at 0 (the
animes alone) and at 1 (the guide alone): both blends are linear, so the stream's output
is ``(1 - s) * animes + s * guide`` and each half can be swapped for the offline one.
Printed per clip and as the mean: mouth R (the bench's ``mouth_r``) over the whole clip
and after its first second of

* ``live`` and ``offline`` (the default blends: 0.65 live, 0.5 offline), and offline at
  live's share;
* ``live, offline's guide`` / ``live, offline's animes``: one half swapped;
* the halves alone (``animes`` and ``guide``, live and offline);

and, for each ``--variant`` other than ``base``, the live stream with one of its steps
changed (a diagnosis reaching into the stream; not a way to run it):

* ``offpost``: hama's posteriors of the whole clip (offline's: the model hearing all of
  it, scaled to its peak) for the windows;
* ``level``: the stream's level (hama's scale, the pauses' threshold) the clip's peak from
  its first sample;
* ``longctx``: hama hearing 10 s before the first unsettled frame (all the clip so far;
  at the stream's start the track has it hear silence before the first sample, up to
  the context's worth);
* ``settled``: every frame's posteriors as the track settles them (the window's newest
  rows not tentative);
* ``future``: every frame's posteriors heard with :data:`FUTURE_MS` of audio after it;
* ``wide``: and with all the clip before it (10 s of context);
* ``fade``: the cross-fade between two windows :data:`FADE_S` long, whatever the frame rate;
* ``nosmooth``: the k-best blend not low-passed, offline nor live (on both sides).

``--agreement``: for recordings (any split's), hama's posteriors as a stream's track
settles them (after 120, 300, 600 ms) against the whole clip's, after the first second,
and the phones recognised from them against the whole clip's phones and (a synthetic
clip's ``.phones.csv`` beside it) the true ones: :func:`agreement`.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_live  # noqa: E402  (the bench's split, stream and scoring)

#: ``fade``: the windows' cross-fade in seconds (FADE_FRAMES at 25 fps).
FADE_S = 0.12
#: ``future``: each frame's posteriors heard with this much audio after it (ms).
FUTURE_MS = 600.0
VARIANTS = ("base", "offpost", "fade", "nosmooth", "level", "longctx", "settled",
            "future", "wide")


def the_split(work: Path):
    """The synthetic split's database (built once in ``work``), guide and held-out clips."""
    from animegraph.baselines.base import save_model
    from animegraph.live import stored_guide
    from ingest.pipeline import build_database

    db = work / "db"
    train, test, reference = bench_live.synthetic_split(work / "corpus")
    test = test[::max(1, -(-len(test) // 8))]  # as the bench's --max-clips 8
    if not db.is_dir():
        build_database(db, train, reference=reference)
        fitted, missing = bench_live.guides(train)
        for m in fitted if isinstance(fitted, tuple) else (fitted,):
            save_model(m, db)
        print(f"# guides not fitted: {missing}" if missing else "# guides stored", flush=True)
    guide, _ = stored_guide(db)
    return db, guide, test


def settled_rows(model, audio, sr, lookahead, settle_ms: float | None = None,
                 context_ms: float | None = None) -> np.ndarray:
    """Every frame's posteriors as the stream's track leaves them once settled (after
    ``settle_ms``, hearing ``context_ms`` before; the track's defaults if None)."""
    from animegraph.live import Stream

    extra = {k: v for k, v in (("settle_ms", settle_ms), ("posterior_context_ms", context_ms))
             if v is not None}
    stream = Stream(model, sample_rate=sr, lookahead_ms=lookahead, backlog_ms=None, **extra)
    return bench_live.settled_posteriors(stream, audio)


def track_rows(audio: np.ndarray, sr: int, settle_s: float, hop_s: float = 0.08
               ) -> np.ndarray:
    """hama's posteriors of ``audio`` as a stream's track settles them (the default
    context; each frame's row once it is settled, the last ones as the track ends)."""
    from animegraph.live.frontend import PosteriorTrack

    track, rows, peak = PosteriorTrack(sr, settle_s=settle_s), {}, 0.0
    hop = int(hop_s * sr)
    for end in [*range(hop, len(audio), hop), len(audio)]:
        peak = max(peak, float(np.abs(audio[:end]).max()))
        track.update(audio[:end], 0, end, peak)
        for f in range(track._first, track.settled):
            rows.setdefault(f, track._rows[f - track._first].copy())
    for f in range(track._first, track.frames):
        rows.setdefault(f, track._rows[f - track._first].copy())
    return np.stack([rows[f] for f in range(max(rows) + 1)])


def edit_rate(said: list[str], truth: list[str]) -> float:
    """Phone error rate: the edit distance of ``said`` to ``truth`` over ``len(truth)``."""
    d = np.arange(len(truth) + 1)
    for i, x in enumerate(said, 1):
        prev, d[0] = d.copy(), i
        for j, y in enumerate(truth, 1):
            d[j] = min(prev[j] + 1, d[j - 1] + 1, prev[j - 1] + (x != y))
    return float(d[-1]) / max(1, len(truth))


def agreement(paths, settles=(0.12, 0.3, 0.6)) -> None:
    """For each WAV: the track's posteriors (settled after each of ``settles`` s) against
    the whole clip's, after its first second (mean total variation per 20 ms frame); the
    phones recognised from each (CTC, :func:`ingest.speech.ctc.recognize`) against those
    of the whole clip's and, where the corpus gives them (``<clip>.phones.csv``), against
    the true ones (phone error rate, silences left out)."""
    from animegraph.live.frontend import to_model_rate
    from ingest.formats.phones_csv import read_phones_csv
    from ingest.formats.wav import read_wav
    from ingest.speech import ctc

    def said(audio, sr, rows):
        ctc.remember(audio, sr, rows)
        return [p.phone for p in ctc.recognize(audio, sr) if p.phone != "SIL"]

    for path in paths:
        audio, sr = read_wav(path)
        x = to_model_rate(audio, sr)
        whole = ctc.phone_probs((x * (0.9 / max(1e-9, np.abs(x).max()))).astype(np.float32))
        labels = Path(path).with_suffix(".phones.csv")
        truth = ([p.phone for p in read_phones_csv(labels) if p.phone != "SIL"]
                 if labels.is_file() else None)
        heard = said(audio, sr, whole)
        out = [] if truth is None else [f"whole clip: error {edit_rate(heard, truth):.2f}"]
        for settle in settles:
            rows = track_rows(audio, sr, settle)
            n = min(len(rows), len(whole))
            tv = 0.5 * np.abs(rows[:n] - whole[:n]).sum(axis=1)
            live_said = said(audio, sr, rows[:n])
            line = (f"settled {settle * 1000:g} ms: variation {tv[50:].mean():.3f}, "
                    f"phones against the whole clip's {edit_rate(live_said, heard):.2f}")
            if truth is not None:
                line += f", error {edit_rate(live_said, truth):.2f}"
            out.append(line)
        print(f"{Path(path).name}: " + "; ".join(out), flush=True)


def live(model, audio, sr, lookahead, guide, share, variant, whole_probs):
    """The stream's output with the guide's share ``share``, one step changed."""
    from animegraph.live import Stream
    from animegraph.live import stream as stream_module

    extra = {"posterior_context_ms": 10000.0} if variant == "longctx" else {}
    stream = Stream(model, sample_rate=sr, lookahead_ms=lookahead, guide=guide,
                    backlog_ms=None, guide_share=share, **extra)
    if variant in ("offpost", "settled", "future", "wide"):
        rows = (whole_probs if variant == "offpost"
                else settled_rows(model, audio, sr, lookahead,
                                  FUTURE_MS if variant in ("future", "wide") else None,
                                  10000.0 if variant == "wide" else None))
        stream._track.posteriors = lambda first, count: rows[
            np.clip(np.arange(first, first + count), 0, len(rows) - 1)]
    if variant == "level":  # the clip's peak known from its first sample
        peak = float(np.abs(audio).max())
        stream.level = lambda: peak
    fade = stream_module.FADE_FRAMES
    if variant == "fade":
        stream_module.FADE_FRAMES = max(1, int(round(FADE_S * model.graph.fps)))
    try:
        return bench_live.play(stream, audio)
    finally:
        stream_module.FADE_FRAMES = fade


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--work", type=Path, default=None,
                        help="keep the corpus and database here (reused when present)")
    parser.add_argument("--lookahead", type=float, default=120.0)
    parser.add_argument("--variants", nargs="+", default=["base"], choices=VARIANTS)
    parser.add_argument("--agreement", nargs="+", type=Path, default=None, metavar="WAV",
                        help="only: the track's posteriors against the whole clip's, for "
                        "these recordings")
    args = parser.parse_args()
    if args.agreement:
        agreement(args.agreement)
        return 0
    if args.work is not None:
        args.work.mkdir(parents=True, exist_ok=True)
        return run(args, args.work)
    import tempfile

    with tempfile.TemporaryDirectory(prefix="diag-synth-") as tmp:
        return run(args, Path(tmp))


def run(args, work: Path) -> int:
    """Score the variants on the split kept in (or built into) ``work``; print them."""
    from animegraph.live.frontend import to_model_rate
    from animegraph.live.stream import LIVE_GUIDE_SHARE
    from animegraph.synthesis import Model, assemble, synthesize
    from animegraph.synthesis.path import AUDIO_ONLY_K_BEST
    from ingest.speech import ctc

    db, guide, test = the_split(work)
    model = Model.load(db)
    s = LIVE_GUIDE_SHARE
    print(f"# {len(test)} clips, {model.graph.fps:g} fps, look-ahead {args.lookahead:g} ms, "
          f"load {os.getloadavg()}", flush=True)
    rows: dict[str, list[float]] = {}

    def put(name, motion, clip):
        for suffix, skip in (("", 0.0), (" >1s", 1.0)):
            rows.setdefault(name + suffix, []).append(
                bench_live.mouth_r(model, motion, clip, skip))

    smooth = assemble.smooth
    for clip in test:
        audio = clip.audio.astype(np.float32) / 32768.0
        sr = clip.sample_rate
        x = to_model_rate(audio, sr)
        whole = ctc.phone_probs((x * (0.9 / max(1e-9, np.abs(x).max()))).astype(np.float32))
        for variant in args.variants:
            tag = "" if variant == "base" else f" [{variant}]"
            if variant == "nosmooth":
                assemble.smooth = lambda motion, *a, **k: motion
            try:
                if variant in ("base", "nosmooth") or variant == args.variants[0]:
                    oa = synthesize(model, audio, sr, k_best=AUDIO_ONLY_K_BEST).motion
                    og = synthesize(model, audio, sr, k_best=AUDIO_ONLY_K_BEST, guide=guide,
                                    guide_blend=1.0).motion
                la = live(model, audio, sr, args.lookahead, None, 0.0, variant, whole)
                lg = live(model, audio, sr, args.lookahead, guide, 1.0, variant, whole)
            finally:
                assemble.smooth = smooth
            n = min(len(oa), len(og), len(la), len(lg))
            oa, og, la, lg = oa[:n], og[:n], la[:n], lg[:n]
            if variant in ("base", "nosmooth"):
                put("offline" + tag, 0.5 * oa + 0.5 * og, clip)
                put("offline at live's share" + tag, (1 - s) * oa + s * og, clip)
                put("live, offline's guide" + tag, (1 - s) * la + s * og, clip)
                put("live, offline's animes" + tag, (1 - s) * oa + s * lg, clip)
                put("animes offline" + tag, oa, clip)
                put("guide offline" + tag, og, clip)
            put("live" + tag, (1 - s) * la + s * lg, clip)
            put("animes live" + tag, la, clip)
            put("guide live" + tag, lg, clip)
        print(f"# {clip.clip_id}: " + ", ".join(f"{k} {v[-1]:.3f}" for k, v in rows.items()),
              flush=True)
    width = max(map(len, rows))
    for k, v in rows.items():
        print(f"{k:<{width}}  {np.mean(v):.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
