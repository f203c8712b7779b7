"""The live guide's share chosen on a calibration split of the GRID database clips.

Usage::

    python scripts/calib_live_share.py --grid-db S1DB --work DIR [--clips 30]
                                       [--shares 0.5 0.65 0.8 1.0] [--json OUT]
                                       [--settings default low-latency]
    python scripts/calib_live_share.py --grid-db S1DB --held-out DB640 --clips 20 ...
    python scripts/calib_live_share.py --talkingface [--piece 6] --shares 0.5 0.65 ...

:func:`animegraph.apps.evaluate.grid_split`'s 640 database clips of ``--grid-db`` (an
``animegraph ingest`` of grid/s1) are split again: every 8th (80) is a calibration clip,
the other 560 are built into a database in ``--work`` (with the audio-only default's
guides, :func:`animegraph.apps.prepare.fit_guides`; kept and reused if there already).
The held-out clips of the GRID split are never read. ``--clips`` calibration clips (evenly
spaced) are streamed live (``scripts/bench_live.py``'s ``live_motion``: 20 ms chunks) at
the default setting and ``--low-latency``'s, the guide given each share of the window's
motion (``Stream(guide_share=...)``); each clip's mouth R against its recording is
printed, and per setting the mean for each share with the mean paired difference to the
first share (0.5, offline's) and its standard error (the differences' standard deviation
over the square root of the number of clips). With ``--held-out DB`` (a database of the
GRID split's 640 database clips, guides stored), the same on the split's held-out clips
(``--clips`` of them evenly, as ``scripts/bench_live.py --max-clips`` picks them): the
check after the choice, never the choice.

``--talkingface``: a calibration split of several speakers, none of it scored by
``scripts/bench_live.py``: the first 70 % of each of talkingface's two long clips (the
within-speaker split's database part; the across split holds them in its databases,
never scores them), cut into ``--piece``-second pieces, each streamed against a database
of the speakers it is not: the 11 other clips and the other long clip's first 70 % (its
guides fitted as ``bench_live.py``'s talkingface splits fit them). Those 11 clips are
the across split's scored clips, here only database material.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_live import (  # noqa: E402
    SHARED,
    TALKINGFACE_CUT,
    TALKINGFACE_LONG,
    WINDOW,
    guides,
    live_motion,
    mouth_r,
)

from animegraph.live import stored_guide  # noqa: E402
from animegraph.live.stream import DEFAULT_SETTING, LOW_LATENCY  # noqa: E402
from animegraph.synthesis import Model  # noqa: E402

#: Every STEP-th of the GRID split's database clips is a calibration clip.
STEP = 8
SETTINGS = {"default": DEFAULT_SETTING, "low-latency": LOW_LATENCY}


def calibration_split(grid_db: Path):
    """(calibration clips, the other database clips, head reference) of ``grid_db``."""
    from animegraph.apps.evaluate import grid_split
    from db.store import Database
    from ingest.tables import prepared_from_database

    clips = prepared_from_database(Database.open(grid_db))
    reference = Database.open(grid_db).arrays().get("head_reference")
    train, _ = grid_split(clips)  # the held-out part is left alone
    calib = train[::STEP]
    rest = [c for i, c in enumerate(train) if i % STEP]
    return calib, rest, reference


def held_out_clips(grid_db: Path):
    """The GRID split's held-out clips of ``grid_db``."""
    from animegraph.apps.evaluate import grid_split
    from db.store import Database
    from ingest.tables import prepared_from_database

    return grid_split(prepared_from_database(Database.open(grid_db)))[1]


def talkingface_folds(work: Path, piece_s: float):
    """(model, guide, clips streamed) per long talkingface clip: its first 70 % in pieces
    of ``piece_s`` seconds, and a database in ``work`` of the speakers it is not (built and
    its guides fitted once; the database reused if there already)."""
    from ingest.pipeline import IngestConfig, build_database, prepare_sources
    from ingest.prepare import slice_clip
    from ingest.readers import discover

    clips, reference = prepare_sources(discover([SHARED / "talkingface"]), IngestConfig(),
                                       workers=2)
    firsts = {c.clip_id: slice_clip(c, 0.0, TALKINGFACE_CUT * c.duration, suffix="_first70")
              for c in clips if c.clip_id in TALKINGFACE_LONG}
    short = [c for c in clips if c.clip_id not in TALKINGFACE_LONG]
    for name, first in firsts.items():
        train = short + [c for k, c in firsts.items() if k != name]
        db = work / f"db-not-{name}"
        if not db.exists():
            build_database(db, train, reference=reference)
        guide, missing = guides(train)
        if missing:
            raise SystemExit(f"the calibration guides could not be fitted: {missing}")
        n = int(first.duration // piece_s)
        pieces = [slice_clip(first, k * piece_s, (k + 1) * piece_s, suffix=f"_{k}")
                  for k in range(n)]
        yield Model.load(db), guide, pieces


def stream_shares(model, guide, clips, settings, shares, rows: dict) -> None:
    """Stream each of ``clips`` at each setting and share; append its mouth R to ``rows``."""
    for clip in clips:
        audio = clip.audio.astype(np.float32) / 32768.0
        for setting in settings:
            WINDOW.clear()
            WINDOW.update({k: v for k, v in SETTINGS[setting].items() if k != "lookahead_ms"})
            for share in shares:
                WINDOW["guide_share"] = share
                motion, _ = live_motion(model, audio, clip.sample_rate,
                                        SETTINGS[setting]["lookahead_ms"], guide)
                rows[(setting, share)].append(mouth_r(model, motion, clip))
        print(f"#   {clip.clip_id}: " + ", ".join(f"{s} {g:g} {v[-1]:.3f}"
                                                  for (s, g), v in rows.items()), flush=True)
    WINDOW.clear()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--grid-db", type=Path, default=None)
    parser.add_argument("--talkingface", action="store_true",
                        help="the talkingface calibration split (several speakers) instead")
    parser.add_argument("--piece", type=float, default=6.0,
                        help="with --talkingface: seconds of each streamed piece")
    parser.add_argument("--work", type=Path, default=None,
                        help="folder for the calibration database (db560), reused if built")
    parser.add_argument("--held-out", type=Path, default=None,
                        help="stream the GRID split's held-out clips against this database "
                        "of its 640 database clips instead")
    parser.add_argument("--clips", type=int, default=30)
    parser.add_argument("--shares", type=float, nargs="+", default=[0.5, 0.65, 0.8, 1.0])
    parser.add_argument("--settings", nargs="+", default=list(SETTINGS), choices=SETTINGS)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True, cwd=Path(__file__).parent).stdout.strip()
    rows = {(s, g): [] for s in args.settings for g in args.shares}
    if args.talkingface:
        work = args.work or Path("calib-talkingface")
        names = []
        for model, guide, clips in talkingface_folds(work, args.piece):
            print(f"# {len(clips)} pieces of {clips[0].clip_id.rsplit('_', 1)[0]}; code "
                  f"{commit}; load {os.getloadavg()}; ready in "
                  f"{time.perf_counter() - t0:.0f} s", flush=True)
            stream_shares(model, guide, clips, args.settings, args.shares, rows)
            names += [c.clip_id for c in clips]
        return report(args, rows, names, commit)
    if args.grid_db is None or (args.work is None) == (args.held_out is None):
        raise SystemExit("calib_live_share.py: give --grid-db and --work DIR or --held-out "
                         "DB, or --talkingface")
    if args.held_out:
        calib, rest, db = held_out_clips(args.grid_db), [], args.held_out
    else:
        calib, rest, reference = calibration_split(args.grid_db)
        db = args.work / "db560"
    print(f"# {len(calib)} {'held-out' if args.held_out else 'calibration'} clips, "
          f"database {db}", flush=True)
    if not args.held_out and not db.exists():
        from animegraph.apps.prepare import fit_guides
        from ingest.pipeline import build_database

        build_database(db, rest, reference=reference)
        print(fit_guides(db, print), flush=True)
    del rest
    calib = calib[::max(1, -(-len(calib) // args.clips))]
    model = Model.load(db)
    guide, missing = stored_guide(db)
    if missing:
        raise SystemExit(f"the calibration database lacks the guides {missing}")
    print(f"# {len(calib)} clips streamed; code {commit}; load {os.getloadavg()}; ready in "
          f"{time.perf_counter() - t0:.0f} s", flush=True)
    stream_shares(model, guide, calib, args.settings, args.shares, rows)
    return report(args, rows, [c.clip_id for c in calib], commit)


def report(args, rows: dict, names: list[str], commit: str) -> int:
    """Print (and with ``--json`` write) each setting's mean per share, paired against the
    first share."""
    out = {"clips": names, "commit": commit, "load": os.getloadavg(),
           "settings": {}}
    for setting in args.settings:
        base = np.asarray(rows[(setting, args.shares[0])])
        print(f"{setting}: share  mouth R  paired diff vs {args.shares[0]:g} (SE)")
        out["settings"][setting] = {}
        for share in args.shares:
            r = np.asarray(rows[(setting, share)])
            d = r - base
            se = float(d.std(ddof=1) / np.sqrt(len(d))) if len(d) > 1 else float("nan")
            print(f"  {share:5.2f}  {r.mean():.3f}  {d.mean():+.4f} ({se:.4f})")
            out["settings"][setting][f"{share:g}"] = {
                "mouth_r": float(r.mean()), "diff": float(d.mean()), "se": se,
                "per_clip": r.tolist()}
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
