"""Live synthesis measured: latency, CPU, drift, and quality against the offline default.

Usage::

    python scripts/bench_live.py [--quality synthetic facegood talkingface
                                            talkingface-across grid]
                                 [--grid-db DB] [--text]
                                 [--joined] [--guide-share S]
                                 [--phones-engine hama|auto [hama|auto]]
                                 [--lookaheads 40 80 120 200 300]
                                 [--latency-seconds 20] [--drift-seconds 120] [--json OUT]
    python scripts/bench_live.py --quality --db DB [--sentences 3] [--unpaced] ...

* **Quality** (``--quality``): a database is built from a split's training clips (as
  ``scripts/eval_lipsync.py`` builds a fold's) with its guides (mu-mlp and ppg-ridge, the
  audio-only default's, fitted on the same clips; one that cannot be fitted is left out
  and said). Each held-out clip is synthesized offline by the audio-only default
  (:func:`animegraph.synthesis.synthesize`: phones by the default engine, k-best 20, the
  guide blended) and live (:class:`animegraph.live.Stream`, pushed in 20 ms chunks, at
  each look-ahead); the mouth R of each against the recording (Pearson r of the mouth
  opening over the observed frames, :mod:`animegraph.motion.measures`, in the database's
  stored space) is averaged over the clips, beside the loudness reference
  (:class:`animegraph.baselines.reference.Loudness`). ``synthetic``: the last parallel
  sentence and the last two single-emotion ones held out of a generated corpus;
  ``facegood``: its last clip held out (the first ``--facegood-seconds`` of it scored);
  ``talkingface``: ``scripts/eval_lipsync.py``'s within-speaker split, two folds, each a
  database of the first 70 % of one of the two long single-speaker clips (its guides
  fitted on it) and that clip's last 30 % held out (the mean over the two);
  ``talkingface-across``: its across-speaker split, each of the 11 other clips held out
  of a database of the 12 others (11 folds);
  ``grid``: :func:`animegraph.apps.evaluate.grid_split` of the clips of ``--grid-db`` (an
  ``animegraph ingest`` of grid/s1), the database built from its 640 database clips or
  given (``--grid-train-db``, its guides stored). With ``--text``, also the offline
  default with each clip's transcript (k-best, context ranking, no guide: what ``synth``
  runs) and the live stream given it (``Stream(text=...)``, the guide blended); the
  transcripts given up while the stream ran, and those its end test reported. With
  ``--joined``, also the held-out clips played back to back as one stream (each clip's
  frames scored: the steady state, where the stream has a past; each clip starting on a
  frame of the stream, :func:`join_clips`), and each clip scored after its first second
  (offline and live). ``--phones-engine`` sets who places the
  stream's phones (``Stream(phones_engine=...)``); a second engine also streams each clip
  with it, paired in the same run (rows ``live-LA-ENGINE``).
* **Latency and CPU** (``--latency-seconds``): held-out speech played at real-time pace
  (:class:`animegraph.live.sources.FileSource`) through :func:`animegraph.live.run.run`
  at each look-ahead: for every frame, the wall time from the arrival of the chunk that
  holds the audio it shows to its sending (look-ahead, waiting for the update, compute);
  median, 95th percentile, max. CPU: the stream's updates' process CPU time (all threads)
  over the audio's duration (1.0 = one core), and their wall time likewise.
* **CPU alone** (``--unpaced``): the same speech pushed in 20 ms chunks as fast as the
  stream takes it (a second pass, after a warm-up one; at ``--lookaheads``' first
  look-ahead, else the default 120 ms): CPU per second of audio and
  each update's CPU and wall time (median, p95), without the pacing's waits. With
  ``--profile``, that pass runs under cProfile (slower: its times are not the figures)
  and each part's share of the updates' time is printed (hama's call, the guide, the
  DTW of new phones, recognition, the phones' features, search, k-best blend).
* **Drift** (``--drift-seconds``): one long paced stream (held-out speech repeated; at
  ``--lookaheads``' first look-ahead, else the default 120 ms, as ``--unpaced``):
  frames sent against the audio heard times the frame rate, the latency over its first
  and last tenth, and the updates that had to catch up.

The machine's load is printed (``os.getloadavg``): on a shared machine wall times rise
with it, CPU times much less; and the commit of the code measured (``# code``).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from animegraph.baselines import make_estimator
from animegraph.baselines.reference import Loudness
from animegraph.live import Stream
from animegraph.live.run import run
from animegraph.live.sources import FileSource
from animegraph.live.stream import DEFAULT_LOOKAHEAD_MS, default_guide_share
from animegraph.motion.measures import mouth_opening, pearson
from animegraph.synthesis import Model, synthesize
from animegraph.synthesis.path import AUDIO_ONLY_GUIDE, AUDIO_ONLY_K_BEST, TRANSCRIPT_K_BEST
from db.errors import AnimeGraphError
from ingest.corpus.synthetic import CorpusConfig, generate_corpus
from ingest.formats.wav import write_wav
from ingest.pipeline import IngestConfig, build_database, prepare_sources
from ingest.prepare import slice_clip
from ingest.readers import discover

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"
CHUNK_S = 0.02
#: The stream's hop and context (``--hop``, ``--context``; the defaults if not given).
WINDOW: dict = {}
#: The database ingested from grid/s1 (``--grid-db``), read for the grid split's clips.
GRID_DB: list = []
#: ... and a database already built from its 640 database clips (``--grid-train-db``, e.g.
#: an ``animegraph ingest`` of their videos, its guides stored), instead of building one.
GRID_TRAIN_DB: list = []
#: Also score the live stream and the offline default given each clip's transcript
#: (``--text``; clips that have one).
TEXT: list = []
#: Also score the held-out clips played back to back as one stream, and each clip's
#: frames after its first second (``--joined``).
JOINED: list = []
#: Phone engines the quality runs also stream each clip with (``--phones-engine``'s second
#: and later): rows ``live-LA-ENGINE``, paired with the first engine's ``live-LA``.
OTHER_ENGINES: list = []
#: Speech for latency and drift with --db (eSpeak NG).
SENTENCES = ("Please bring the blue box to the table.",
             "We were away a year ago when the rain came down on the hills.",
             "Seven wizards quietly hex a jolly box of frozen fish.")


#: The talkingface split's two long single-speaker clips: the first 70 % of each the
#: database, the last 30 % held out (``scripts/eval_lipsync.py``'s within-speaker split).
TALKINGFACE_LONG = ("dfrf_cnn2", "edtalk_pose_source2")
TALKINGFACE_CUT = 0.7


def synthetic_split(corpus: Path) -> tuple[list, list, object]:
    """The synthetic split: the default eSpeak NG corpus (generated in ``corpus`` unless it
    is there), its last parallel sentence and last two single ones held out: (database
    clips, held-out clips, head reference)."""
    if not (corpus / "corpus.json").is_file():
        generate_corpus(corpus, CorpusConfig(sentences=14, parallel=4, variations=3, seed=3),
                        workers=2)
    meta = json.loads((corpus / "corpus.json").read_text())
    clips, reference = prepare_sources(discover([corpus]), IngestConfig(), workers=2)
    singles = sorted({c.sentence_id for c in clips} - set(meta["parallel_sentences"]))
    held = {meta["parallel_sentences"][-1], *singles[-2:]}
    train = [c for c in clips if c.sentence_id not in held]
    test = [c for c in clips if c.sentence_id in held]
    return train, test, reference


def split(name: str, tmp: Path, facegood_seconds: float) -> list[tuple]:
    """The folds of a split: (fold name, train clips, held-out clips, head reference) each
    (one fold but for talkingface's two)."""
    if name == "synthetic":
        return [(name, *synthetic_split(tmp / "corpus"))]
    if name == "facegood":
        clips, reference = prepare_sources(discover([SHARED / "facegood"]), IngestConfig(),
                                           workers=2)
        held = clips[-1]
        seconds = min(facegood_seconds, held.duration)
        return [(name, clips[:-1], [slice_clip(held, 0.0, seconds, suffix="-head")],
                 reference)]
    if name in ("talkingface", "talkingface-across"):
        if not (SHARED / "talkingface").is_dir():
            raise SystemExit(f"the talkingface split needs {SHARED / 'talkingface'}")
        # All 13 clips prepared, as eval_lipsync.py prepares them: the head reference and
        # the lip-audio lags are decided over them all, so the offline default here is
        # the one of lipsync.md's within-speaker row.
        clips, reference = prepare_sources(discover([SHARED / "talkingface"]),
                                           IngestConfig(), workers=2)
        if name == "talkingface-across":  # leave one of the other 11 clips out
            return [(f"{name}-{held.clip_id}", [c for c in clips if c is not held], [held],
                     reference) for held in clips if held.clip_id not in TALKINGFACE_LONG]
        folds = []
        for clip in (c for c in clips if c.clip_id in TALKINGFACE_LONG):
            cut = TALKINGFACE_CUT * clip.duration
            folds.append((f"{name}-{clip.clip_id}",
                          [slice_clip(clip, 0.0, cut, suffix="_first70")],
                          [slice_clip(clip, cut, clip.duration, suffix="_last30")], reference))
        return folds
    if name == "grid":
        if not GRID_DB:
            raise SystemExit("the grid split needs --grid-db, a database ingested from grid/s1")
        from animegraph.apps.evaluate import grid_split
        from db.store import Database
        from ingest.tables import prepared_from_database

        clips = prepared_from_database(Database.open(GRID_DB[0]))
        reference = Database.open(GRID_DB[0]).arrays().get("head_reference")
        train, test = grid_split(clips)
        return [(name, train, test, reference)]
    raise SystemExit(f"unknown split {name!r}")


def guides(train) -> tuple[object, list[str]]:
    """The audio-only default's guide fitted on ``train``, and what could not be fitted."""
    got, missing = [], []
    for method in AUDIO_ONLY_GUIDE.split("+"):
        try:
            got.append(make_estimator(method).fit(train))
        except AnimeGraphError as exc:
            missing.append(f"{method}: {exc}")
    return (None if not got else got[0] if len(got) == 1 else tuple(got)), missing


def live_motion(model, audio, sr, lookahead_ms, guide, text=None, phones_engine=None
                ) -> tuple[np.ndarray, Stream]:
    window = {**WINDOW, **({"phones_engine": phones_engine} if phones_engine else {})}
    stream = Stream(model, sample_rate=sr, lookahead_ms=lookahead_ms, guide=guide,
                    backlog_ms=None, text=text, **window)
    return play(stream, audio), stream


def play(stream: Stream, audio: np.ndarray) -> np.ndarray:
    """``audio`` (float, ``(n_samples,)``) pushed into ``stream`` in :data:`CHUNK_S` chunks
    and closed: every frame it sends, ``(n_frames, n_channels)``."""
    step = int(CHUNK_S * stream.sample_rate)
    parts = [stream.push(audio[k:k + step]).motion for k in range(0, len(audio), step)]
    parts.append(stream.close().motion)
    return np.concatenate(parts)


def settled_posteriors(stream: Stream, audio: np.ndarray) -> np.ndarray:
    """Every 20 ms frame's hama posteriors as ``stream``'s track leaves them (settled, or
    the last computed), ``audio`` played through it: ``(n_frames, n_phones)``. For the
    diagnoses that give a stream posteriors it could not have (``diag_live_*.py``)."""
    rows: dict[int, np.ndarray] = {}
    track, update = stream._track, stream._track.update

    def keep(*a, **k):
        update(*a, **k)
        for f in range(track._first, track.frames):
            rows[f] = track._rows[f - track._first].copy()

    track.update = keep
    play(stream, audio)
    return np.stack([rows.get(f, rows[min(rows)]) for f in range(max(rows) + 1)])


def mouth_r(model, pred, clip, skip_s: float = 0.0) -> float:
    """Mouth R of ``pred`` against ``clip``'s recording over its observed frames (from
    ``skip_s`` on: the frames after a stream's start-up)."""
    truth = clip.motion.astype(np.float64)
    n = min(len(pred), len(truth))
    keep = ~np.asarray(clip.missing, dtype=bool)[:n].any(axis=1)
    keep[: int(round(skip_s * model.graph.fps))] = False
    local = model.to_local(pred[:n])[keep]
    return pearson(mouth_opening(local, model.names, model.kind),
                   mouth_opening(truth[:n][keep], model.names, model.kind))


def quality(name: str, tmp: Path, lookaheads, facegood_seconds: float,
            max_clips: int) -> dict:
    """Mouth R of the offline default, loudness and the live stream at each look-ahead on
    a split's held-out clips (the mean over the clips of all its folds)."""
    t0 = time.perf_counter()
    rows = {"offline": [], "offline-hama": [], "loudness": [],
            **{f"live-{la:g}": [] for la in lookaheads}}
    cpu = {f"live-{la:g}": [] for la in lookaheads}
    for engine in OTHER_ENGINES:
        rows.update({f"live-{la:g}-{engine}": [] for la in lookaheads})
        cpu.update({f"live-{la:g}-{engine}": [] for la in lookaheads})
    if JOINED:  # the clips back to back as one stream, and every clip after its first s
        rows.update({f"joined-{la:g}": [] for la in lookaheads})
        rows.update({f"{k}-after1s": [] for k in ("offline", *(f"live-{la:g}"
                                                                for la in lookaheads))})
    if TEXT:
        rows.update({"offline-text": [], **{f"live-text-{la:g}": [] for la in lookaheads}})
        cpu.update({f"live-text-{la:g}": [] for la in lookaheads})
    misfit = [0, 0]  # transcripts given up while running, found wrong at the end
    first: dict = {}
    n_clips = 0
    for fold, train, test, reference in split(name, tmp, facegood_seconds):
        test = test[::max(1, -(-len(test) // max_clips))]  # evenly, at most max_clips
        loud = Loudness().fit(train)
        if name == "grid" and GRID_TRAIN_DB:  # built already from the database clips
            from animegraph.live import stored_guide

            db = GRID_TRAIN_DB[0]
            guide, missing = stored_guide(db)
            missing = [f"{m}: not stored" for m in missing]
        else:
            db = tmp / f"db-{fold}"
            build_database(db, train, reference=reference)
            guide, missing = guides(train)
        n_train = len(train)
        del train  # the clips (the grid split's are 2 GB)
        model = Model.load(db)
        print(f"# {fold}: {n_train} clips in the database, {len(test)} held out; guide "
              f"{AUDIO_ONLY_GUIDE}"
              f"{' (not fitted: ' + '; '.join(missing) + ')' if missing else ''}"
              f"; guide share {WINDOW.get('guide_share', default_guide_share(model)):g}"
              f"; ready in {time.perf_counter() - t0:.0f} s", flush=True)
        score(model, guide, loud, test, lookaheads, rows, cpu, misfit)
        n_clips += len(test)
        if not first:  # the latency and drift runs' database and speech
            first = {"model": model, "guide": guide,
                     "speech": [(c.audio.astype(np.float32) / 32768.0, c.sample_rate)
                                for c in test]}
    out = {"clips": n_clips, "fps": first["model"].graph.fps,
           "transcripts_given_up": misfit[0], "transcripts_misfit_at_end": misfit[1],
           "mouth_r": {k: float(np.nanmean(v)) for k, v in rows.items()},
           "cpu_share": {k: float(np.mean(v)) for k, v in cpu.items()}}
    return {**out, **first}


def score(model, guide, loud, test, lookaheads, rows: dict, cpu: dict,
          misfit: list[int]) -> None:
    """Score one fold's held-out clips ``test``: append each clip's mouth R to ``rows``,
    its streams' CPU share to ``cpu``, and count the transcripts given up in ``misfit``."""
    for clip in test:
        audio = clip.audio.astype(np.float32) / 32768.0
        sr = clip.sample_rate
        off = synthesize(model, audio, sr, k_best=AUDIO_ONLY_K_BEST, guide=guide).motion
        rows["offline"].append(mouth_r(model, off, clip))
        if JOINED:
            rows["offline-after1s"].append(mouth_r(model, off, clip, 1.0))
        # The engine the live windows use: how much of the gap is PocketSphinx's placing.
        off = synthesize(model, audio, sr, k_best=AUDIO_ONLY_K_BEST, guide=guide,
                         phones_engine="hama").motion
        rows["offline-hama"].append(mouth_r(model, off, clip))
        pred = loud.predict(clip.audio, sr, n_frames=len(clip.motion))
        rows["loudness"].append(pearson(mouth_opening(pred, model.names, model.kind),
                                        mouth_opening(clip.motion, model.names, model.kind)))
        for la in lookaheads:
            motion, stream = live_motion(model, audio, sr, la, guide)
            rows[f"live-{la:g}"].append(mouth_r(model, motion, clip))
            cpu[f"live-{la:g}"].append(stream.stats.cpu_s / (len(audio) / sr))
            if JOINED:
                rows[f"live-{la:g}-after1s"].append(mouth_r(model, motion, clip, 1.0))
            for engine in OTHER_ENGINES:
                motion, stream = live_motion(model, audio, sr, la, guide,
                                             phones_engine=engine)
                rows[f"live-{la:g}-{engine}"].append(mouth_r(model, motion, clip))
                cpu[f"live-{la:g}-{engine}"].append(stream.stats.cpu_s / (len(audio) / sr))
        if JOINED:  # scored below, once the fold's clips are joined
            for la in lookaheads:
                rows[f"joined-{la:g}"].append(np.nan)
        text = getattr(clip, "text", None) if TEXT else None
        if TEXT and text:  # as synth with a transcript: k-best, context ranking, no guide
            off = synthesize(model, audio, sr, text=text, k_best=TRANSCRIPT_K_BEST,
                             recognized_guide=guide).motion
            rows["offline-text"].append(mouth_r(model, off, clip))
            for la in lookaheads:
                motion, stream = live_motion(model, audio, sr, la, guide, text=text)
                rows[f"live-text-{la:g}"].append(mouth_r(model, motion, clip))
                cpu[f"live-text-{la:g}"].append(stream.stats.cpu_s / (len(audio) / sr))
                said = [k for k in stream.stats.warnings
                        if k.startswith("the transcript does not fit")]
                misfit[0] += any("at its end" not in k for k in said)
                misfit[1] += any("at its end" in k for k in said)
        print(f"#   {clip.clip_id}: " + ", ".join(f"{k} {v[-1]:.3f}" for k, v in rows.items()
                                                  if v), flush=True)
    if JOINED:
        for la in lookaheads:
            rows[f"joined-{la:g}"][-len(test):] = joined(model, test, la, guide)
            got = rows[f"joined-{la:g}"][-len(test):]
            print(f"#   joined {la:g} ms: " + " ".join(f"{r:.3f}" for r in got), flush=True)


def joined(model, test, lookahead_ms: float, guide) -> list[float]:
    """Each clip's mouth R in one stream of the held-out clips played back to back (the
    steady state: a live stream is long, its start-up happens once), over the frames a
    stream of the clip alone sends; clips at another rate than the first are left out
    (NaN)."""
    audio, sr, firsts = join_clips(test, model.graph.fps)
    motion, _ = live_motion(model, audio, sr, lookahead_ms, guide)
    fps = model.graph.fps
    return [np.nan if k is None else
            mouth_r(model, motion[k: k + int(round(len(clip.audio) / sr * fps))], clip)
            for clip, k in zip(test, firsts, strict=True)]


def join_clips(test, fps: float) -> tuple[np.ndarray, int, list]:
    """The clips' audio back to back (float32, at the first clip's rate) with each clip
    starting on a frame of the stream (the index of its first frame; None for a clip at
    another rate, left out) and of hama's 20 ms frames, as a clip streamed alone does:
    a clip is padded to the next such start with its own last samples mirrored (its
    room's noise: less than 40 ms at 16 kHz and 25 fps).

    Joined end to end, a clip started between two frames: its frames were the stream's
    at up to half a frame from the clip's own (20 ms at 25 fps) and GRID's clips lost
    0.009 of mouth R as one stream for that alone (docs/results/live.md, "The clips as
    one stream")."""
    from math import gcd, lcm

    from animegraph.live.frontend import FRAME_RATE

    sr = test[0].sample_rate
    if float(fps).is_integer():  # the least step on both frame grids, in samples
        step = lcm(sr // gcd(sr, int(fps)), sr // gcd(sr, FRAME_RATE))
    else:
        step = sr / fps  # only the frames: no whole number of samples is on both
    parts, firsts, at = [], [], 0
    for clip in test:
        if clip.sample_rate != sr:
            firsts.append(None)
            continue
        start = int(round(np.ceil(at / step - 1e-9) * step))
        if start > at:  # the clip before padded with its own end, mirrored
            parts[-1] = np.pad(parts[-1], (0, start - at), mode="symmetric")
        firsts.append(int(round(start / sr * fps)))
        parts.append(clip.audio.astype(np.float32) / 32768.0)
        at = start + len(parts[-1])
    return np.concatenate(parts), sr, firsts


def paced(model, guide, wav: Path, lookahead_ms: float) -> dict:
    warm = Stream(model, sample_rate=FileSource(wav).sample_rate, guide=guide, backlog_ms=None)
    warm.push(FileSource(wav).audio[: warm.sample_rate])  # loads hama, compiles the DTW
    warm.close()
    stream = Stream(model, sample_rate=FileSource(wav).sample_rate, lookahead_ms=lookahead_ms,
                    guide=guide, **WINDOW)
    source = FileSource(wav)
    cpu0, wall0 = time.process_time(), time.perf_counter()
    take = run(stream, source)
    wall = time.perf_counter() - wall0
    lag = (np.asarray(take.sent_at) - np.asarray(take.arrived_at)) * 1000
    tenth = max(1, len(lag) // 10)
    return {"lookahead_ms": lookahead_ms, "seconds": take.heard_s, "frames": take.frames,
            "expected_frames": int(round(take.heard_s * stream.fps)),
            "latency_ms": {"median": float(np.median(lag)),
                           "p95": float(np.percentile(lag, 95)), "max": float(lag.max())},
            "latency_first_tenth_ms": float(np.median(lag[:tenth])),
            "latency_last_tenth_ms": float(np.median(lag[-tenth:])),
            "cpu_share": stream.stats.cpu_s / take.heard_s,
            # On a machine of its own an update takes its CPU time: a frame then waits
            # its look-ahead, up to a hop for the update, and the update.
            "update_cpu_ms": {"median": 1000 * float(np.median(stream.stats.update_cpu)),
                              "p95": 1000 * float(np.percentile(stream.stats.update_cpu, 95)),
                              "max": 1000 * float(np.max(stream.stats.update_cpu))},
            "update_wall_ms": {"median": 1000 * float(np.median(stream.stats.update_wall)),
                               "p95": 1000 * float(np.percentile(stream.stats.update_wall,
                                                                 95))},
            "latency_bound_cpu_ms": {
                "median": lookahead_ms + stream.hop_s * 500
                + 1000 * float(np.median(stream.stats.update_cpu)),
                "p95": lookahead_ms + stream.hop_s * 950
                + 1000 * float(np.percentile(stream.stats.update_cpu, 95))},
            "update_wall_share": stream.stats.wall_s / take.heard_s,
            "process_cpu_share": (time.process_time() - cpu0) / wall,
            "updates": stream.stats.updates, "caught_up": stream.stats.caught_up,
            "load": os.getloadavg()}


#: The parts of an update that ``--profile`` reports: (name, function as cProfile names it).
#: (name, the function's file and name as cProfile gives them)
PARTS = (("hama's call", "ingest/speech/ctc.py", "phone_probs"),
         ("the guide", "animegraph/synthesis/guide.py", "guide_trajectory"),
         ("DTW of new phones", "animegraph/synthesis/audio.py", "candidate_costs"),
         ("phones recognised", "ingest/speech/ctc.py", "recognize"),
         ("phones placed by PocketSphinx", "ingest/speech/sphinx.py", "align_phones"),
         ("phones' features", "animegraph/synthesis/pipeline.py", "query_phones"),
         ("search", "animegraph/search/solve.py", "search"),
         ("k-best blend", "animegraph/synthesis/assemble.py", "blend_k_best"))


def unpaced(model, guide, speech, lookahead_ms: float = 120.0,
            profile: bool = False) -> dict:
    """CPU of the stream alone: ``speech`` pushed in 20 ms chunks as fast as it is taken
    (after one warm-up pass), per second of audio and per update; with ``profile``, the
    measured pass under cProfile (its times then include the profiler's) and each of
    :data:`PARTS`' share of the updates' time."""
    import cProfile
    import pstats

    runs = []
    for measured in (False, True):  # the first pass warms hama and the kernels
        profiler = cProfile.Profile() if profile and measured else None
        if profiler is not None:
            profiler.enable()
        cpu = seconds = 0.0
        updates: list[float] = []
        walls: list[float] = []
        for audio, sr in speech:
            stream = Stream(model, sample_rate=sr, lookahead_ms=lookahead_ms, guide=guide,
                            backlog_ms=None, **WINDOW)
            step = int(CHUNK_S * sr)
            t = time.process_time()
            for k in range(0, len(audio), step):
                stream.push(audio[k:k + step])
            stream.close()
            cpu += time.process_time() - t
            seconds += len(audio) / sr
            updates += stream.stats.update_cpu
            walls += stream.stats.update_wall
        if profiler is not None:
            profiler.disable()
            runs.append({"profile": _shares(pstats.Stats(profiler))})
        runs.append({"seconds": seconds, "cpu_share": cpu / seconds,
                     "update_cpu_ms": {"median": 1000 * float(np.median(updates)),
                                       "p95": 1000 * float(np.percentile(updates, 95))},
                     "update_wall_ms": {"median": 1000 * float(np.median(walls)),
                                        "p95": 1000 * float(np.percentile(walls, 95))},
                     "updates": len(updates), "lookahead_ms": lookahead_ms,
                     "load": os.getloadavg()})
    if profile:
        runs[-1]["profile"] = runs[-2]["profile"]
    return runs[-1]


def _shares(stats) -> dict:
    """Each of :data:`PARTS`' cumulative time as a share of the updates' (``_update``)."""
    def cumulative(path: str, name: str) -> float:  # recursive calls counted once
        return sum(row[3] for (file, _, fn), row in stats.stats.items()
                   if fn == name and Path(file).as_posix().endswith(path))

    total = cumulative("animegraph/live/stream.py", "_update")
    return {"updates_s": round(total, 3), **{part: round(cumulative(path, fn) / total, 3)
                                             for part, path, fn in PARTS if total > 0}}


def speech_file(speech, seconds: float, path: Path) -> Path:
    """Held-out speech joined (and repeated) to ``seconds``, as a WAV."""
    sr = speech[0][1]
    parts, total = [], 0
    while total < seconds * sr:
        for audio, rate in speech:
            if rate == sr:
                parts.append(audio)
                total += len(audio)
    write_wav(path, np.concatenate(parts)[: int(seconds * sr)], sr)
    return path


def code_version() -> str:
    """The commit of the animegraph imported (its checkout's short hash, ``+`` if it has
    changes not committed), or where it was imported from when that is not a checkout:
    the figures' results pages name the commit measured."""
    import subprocess

    import animegraph

    root = Path(animegraph.__file__).resolve().parents[1]
    try:
        head = subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"],
                              capture_output=True, text=True, timeout=10, check=True)
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain",
                                "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10, check=True)
    except (OSError, subprocess.SubprocessError):
        return f"not a git checkout: {root}"
    return head.stdout.strip() + ("+" if dirty.stdout.strip() else "") + f" ({root})"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quality", nargs="*", default=["synthetic"])
    parser.add_argument("--lookaheads", nargs="+", type=float, default=None,
                        help="look-aheads (ms) of the quality and latency curves (40 80 "
                        "120 200 300); --unpaced and --drift-seconds run at the first "
                        "given (else the default look-ahead, 120)")
    parser.add_argument("--latency-seconds", type=float, default=20.0)
    parser.add_argument("--drift-seconds", type=float, default=120.0)
    parser.add_argument("--facegood-seconds", type=float, default=30.0)
    parser.add_argument("--max-clips", type=int, default=8,
                        help="held-out clips scored at most (every k-th)")
    parser.add_argument("--db", type=Path, default=None,
                        help="with --quality and nothing after it: time this database")
    parser.add_argument("--sentences", type=int, default=len(SENTENCES),
                        choices=tuple(range(1, len(SENTENCES) + 1)),
                        help="with --db: the eSpeak NG sentences spoken (the first n; a "
                        "short input for a quick check)")
    parser.add_argument("--unpaced", action="store_true",
                        help="also the stream's CPU with the speech pushed as fast as taken")
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--profile", action="store_true",
                        help="with --unpaced: the measured pass under cProfile, and the "
                        "share of an update's time each part takes")
    parser.add_argument("--grid-db", type=Path, default=None,
                        help="the grid split's clips: a database ingested from grid/s1 (read)")
    parser.add_argument("--grid-train-db", type=Path, default=None,
                        help="the grid split's database, built already from its 640 "
                        "database clips (e.g. animegraph ingest of their videos)")
    parser.add_argument("--text", action="store_true",
                        help="also live and offline with each held-out clip's transcript")
    parser.add_argument("--joined", action="store_true",
                        help="also the held-out clips back to back as one stream, and "
                        "each clip scored after its first second")
    parser.add_argument("--hop", type=float, default=None, help="the stream's hop (ms)")
    parser.add_argument("--context", type=float, default=None,
                        help="the stream's context (ms)")
    parser.add_argument("--posterior-context", type=float, default=None,
                        help="hama's left context before the first unsettled frame (ms)")
    parser.add_argument("--settle", type=float, default=None,
                        help="audio after a frame before its posteriors are settled (ms)")
    parser.add_argument("--threads", type=int, default=None,
                        help="threads an update may run at once (the stream's default if "
                        "not given; 0: no cap)")
    parser.add_argument("--guide-share", type=float, default=None,
                        help="the guide's share of each window's motion (if not given "
                        "the stream's default, by the database: default_guide_share)")
    parser.add_argument("--phones-engine", choices=("hama", "auto"), nargs="+", default=None,
                        help="how the stream's windows recognise their phones (the stream's "
                        "default if not given; auto: hama names them, PocketSphinx places "
                        "them, as offline); a second engine: also the quality of live at "
                        "each look-ahead with it, paired (rows live-LA-ENGINE)")
    args = parser.parse_args()
    # --unpaced and the drift stream run at one look-ahead: the first the user names.
    first_lookahead = args.lookaheads[0] if args.lookaheads else DEFAULT_LOOKAHEAD_MS
    args.lookaheads = args.lookaheads or [40, 80, 120, 200, 300]
    GRID_DB.extend([args.grid_db] if args.grid_db else [])
    GRID_TRAIN_DB.extend([args.grid_train_db] if args.grid_train_db else [])
    TEXT.extend([True] if args.text else [])
    JOINED.extend([True] if args.joined else [])
    WINDOW.update({k: v for k, v in (("hop_ms", args.hop), ("context_ms", args.context),
                                     ("posterior_context_ms", args.posterior_context),
                                     ("settle_ms", args.settle), ("threads", args.threads),
                                     ("guide_share", args.guide_share),
                                     ("phones_engine", (args.phones_engine or [None])[0]))
                   if v is not None})
    OTHER_ENGINES.extend((args.phones_engine or [])[1:])
    if WINDOW.get("threads") == 0:
        WINDOW["threads"] = None  # no cap
    print(f"# stream window {WINDOW or 'defaults'}", flush=True)
    print(f"# load average {os.getloadavg()} on {os.cpu_count()} cores", flush=True)
    print(f"# code {code_version()}", flush=True)
    results: dict = {"quality": {}, "latency": [], "drift": None}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        first = None
        for name in args.quality:
            q = quality(name, tmp, args.lookaheads, args.facegood_seconds, args.max_clips)
            first = first or q
            results["quality"][name] = {k: v for k, v in q.items()
                                        if k not in ("model", "guide", "speech")}
            print(json.dumps({name: results["quality"][name]}), flush=True)
        if first is None:  # latency and drift only: a database given, eSpeak NG's speech
            if args.db is None:
                return 0
            from animegraph.live import stored_guide
            from ingest.speech.espeak import speak

            model, (guide, _) = Model.load(args.db), stored_guide(args.db)
            said = [speak(t) for t in SENTENCES[:args.sentences]]
            first = {"speech": [(u.audio.astype(np.float32), u.sample_rate) for u in said]}
        else:
            model, guide = first["model"], first["guide"]
        if args.unpaced:
            results["unpaced"] = unpaced(model, guide, first["speech"], first_lookahead,
                                         profile=args.profile)
            print(json.dumps({"unpaced": results["unpaced"]}), flush=True)
        if args.latency_seconds > 0:
            wav = speech_file(first["speech"], args.latency_seconds, tmp / "latency.wav")
            for la in args.lookaheads:
                row = paced(model, guide, wav, la)
                results["latency"].append(row)
                print(json.dumps(row), flush=True)
        if args.drift_seconds > 0:
            wav = speech_file(first["speech"], args.drift_seconds, tmp / "drift.wav")
            results["drift"] = paced(model, guide, wav, first_lookahead)
            print(json.dumps({"drift": results["drift"]}), flush=True)
    if args.json:
        args.json.write_text(json.dumps(results, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
