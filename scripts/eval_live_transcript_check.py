"""How well the live stream's end-of-speech transcript test tells right transcripts from
wrong ones: the data :data:`animegraph.live.transcript.MAX_LIVE_ALIGN_LOSS` and
:data:`~animegraph.live.transcript.MIN_LIVE_PHONE_SHARE` are chosen on.

Usage::

    python scripts/eval_live_transcript_check.py --grid-db DB640 [--every 8]
        [--offset 0] [--synthetic] [--take 1] [--held-out S1DB] [--json out.json]
    python scripts/eval_live_transcript_check.py --summarize out.json

Each clip is streamed live (:class:`animegraph.live.Stream`, 20 ms chunks, as
``bench_live.py`` plays them) at the default setting and at ``--low-latency``, given its
own transcript, and the posteriors the transcript's path is fed (every update's, and the
stream's last) are kept. The same posteriors are then fed to a
:class:`~animegraph.live.transcript.TranscriptTrack` of each transcript tried — the
clip's own, another clip's sentence, and the sentence with one word changed — as the
stream would feed it: the posteriors are the audio's alone (the transcript only places
the window's phones), and the frames the path fixes depend only on how many there are.
Printed per setting and kind: the alignment loss at the end (nats/frame below free
recognition; its percentiles) and how many the test reports at offline's threshold
(:data:`ingest.speech.ctc.MAX_ALIGN_LOSS`) and at the live one.

Clips: GRID's database clips (``--grid-db``, e.g. /work/grid2/db640: the 640 clips of
``animegraph.apps.evaluate.grid_split``'s database part; every ``--every``-th), none of
the held-out clips the results are scored on; with ``--synthetic``, eSpeak NG speech of
the synthetic corpus' sentences that ``bench_live.py --quality synthetic`` keeps in its
database (one take per sentence and emotion). GRID's one-word changes are made in each
of its six slots (command, colour, preposition, letter, digit, adverb: another word of
the same slot), so the table says which the test can hear. ``--held-out S1DB``: the 20
held-out clips ``bench_live.py --quality grid --max-clips 20`` scores instead (measure
there, never choose there).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from animegraph.live import Stream
from animegraph.live.frontend import FRAME_RATE
from animegraph.live.stream import DEFAULT_SETTING, LOW_LATENCY
from animegraph.live.transcript import MAX_LIVE_ALIGN_LOSS, MIN_LIVE_PHONE_SHARE, TranscriptTrack
from animegraph.synthesis import Model
from ingest.speech.ctc import MAX_ALIGN_LOSS, MIN_PHONE_SHARE

CHUNK_S = 0.02
SETTINGS = {"default": DEFAULT_SETTING, "low-latency": LOW_LATENCY}
#: GRID's grammar: each sentence is one word of each slot, in this order.
GRID_SLOTS = (("bin", "lay", "place", "set"), ("blue", "green", "red", "white"),
              ("at", "by", "in", "with"), tuple("abcdefghijklmnopqrstuvxyz"),
              ("zero", "one", "two", "three", "four", "five", "six", "seven", "eight",
               "nine"), ("again", "now", "please", "soon"))
SLOT_NAMES = ("command", "colour", "preposition", "letter", "digit", "adverb")


def fed_posteriors(model, audio: np.ndarray, sr: int, text: str, setting: dict):
    """The posteriors a live stream of ``audio`` feeds its transcript's path: every
    update's ``(log_probs, first)``, and the last (the stream's end). Its track keeps
    them and never gives up (its tests off), so that the stream feeds it to the end."""
    track = TranscriptTrack(text, FRAME_RATE, test=False, fed=[])
    stream = Stream(model, sample_rate=sr, backlog_ms=None, text=track, **setting)
    step = int(CHUNK_S * sr)
    for k in range(0, len(audio), step):
        stream.push(audio[k:k + step])
    stream.close()
    fed = [(lp, first) for lp, first, at_end in track.fed if not at_end]
    last = next((lp, first) for lp, first, at_end in track.fed if at_end)
    return fed, last


def replay(text: str, fed, last) -> dict:
    """``text``'s track fed the posteriors a stream fed its own, as the stream feeds them.

    Returns ``loss`` and ``share`` (the alignment loss, nats/frame below free recognition,
    and the phones said per phone heard, of the test that failed, else of the test at the
    end; inf and 0 if the path could not be closed), ``failed`` (why the track gave the
    transcript up, at its own thresholds, or None) and, from a track with its tests off
    (the same path, followed to the end), ``worst_loss`` and ``worst_share`` (the largest
    loss and the smallest share of all its tests): a threshold pair reports the
    transcript if and only if one of the two crosses it, so the data choose thresholds
    without streaming again."""
    track = TranscriptTrack(text, FRAME_RATE)
    untested = TranscriptTrack(text, FRAME_RATE, test=False)
    worst_loss, worst_share = -np.inf, np.inf

    def measure():
        nonlocal worst_loss, worst_share
        if untested.fit is not None:
            loss, said, heard = untested.fit
            worst_loss, worst_share = max(worst_loss, loss), min(worst_share,
                                                                 said / max(heard, 1))

    for lp, first in fed:
        if track.failed is None:
            track.update(lp, first)
        untested.update(lp, first)
        measure()
    if track.failed is None:
        track.finish(*last)
    untested.finish(*last)
    if untested.failed is not None:  # the path could not be closed
        worst_loss, worst_share = np.inf, 0.0
    else:
        measure()
    loss, said, heard = (np.inf, 0, 1) if track.fit is None else track.fit
    return {"loss": loss, "share": said / max(heard, 1), "failed": track.failed,
            "worst_loss": worst_loss, "worst_share": worst_share,
            "thresholds": [MAX_LIVE_ALIGN_LOSS, MIN_LIVE_PHONE_SHARE]}


def one_word_changes(text: str, rng: np.random.Generator) -> dict[str, str]:
    """GRID: the sentence with one slot's word changed to another of that slot."""
    words = text.split()
    if len(words) != len(GRID_SLOTS) or any(
            w not in s for w, s in zip(words, GRID_SLOTS, strict=True)):
        return {}
    out = {}
    for i, (name, slot) in enumerate(zip(SLOT_NAMES, GRID_SLOTS, strict=True)):
        other = [w for w in slot if w != words[i]]
        changed = list(words)
        changed[i] = other[int(rng.integers(len(other)))]
        out[f"one word: {name}"] = " ".join(changed)
    return out


def swapped_word(text: str, others: list[str], rng: np.random.Generator) -> str:
    """Free text: one word of three letters or more replaced by one of another
    sentence's."""
    words = text.rstrip(".").split()
    long = [i for i, w in enumerate(words) if len(w.strip(",")) >= 3]
    i = long[int(rng.integers(len(long)))]
    pool = sorted({w.strip(",.").lower() for s in others for w in s.split()
                   if len(w.strip(",.")) >= 3} - {words[i].strip(",").lower()})
    words[i] = pool[int(rng.integers(len(pool)))]
    return " ".join(words) + "."


def grid_clips(db: Path, every: int, held_out: bool, offset: int = 0):
    """(id, audio float32, rate, text) of every ``every``-th clip of a GRID database from
    the ``offset``-th on (``held_out``: its held-out part by ``grid_split``, as
    bench_live picks 20)."""
    from animegraph.apps.evaluate import grid_split
    from db.store import Database
    from ingest.tables import prepared_from_database

    clips = prepared_from_database(Database.open(db))
    if held_out:
        _, test = grid_split(clips)
        clips = test[::max(1, -(-len(test) // 20))]
    else:
        clips = clips[offset::every]
    return [(c.clip_id, c.audio.astype(np.float32) / 32768.0, c.sample_rate, c.text)
            for c in clips if c.text]


def synthetic_clips(take: int = 1):
    """eSpeak NG speech of the synthetic split's database sentences (bench_live's
    corpus; its held-out sentences left out), one take per sentence and emotion (the
    ``take``-th variation of the three)."""
    from ingest.corpus.synthetic import CorpusConfig, plan_corpus, synthesize_clip

    config = CorpusConfig(sentences=14, parallel=4, variations=3, seed=3)
    specs = plan_corpus(config)
    parallel = sorted({s.sentence_id for s in specs[: 4 * 5 * 3]})
    singles = sorted({s.sentence_id for s in specs} - set(parallel))
    held = {parallel[-1], *singles[-2:]}  # as bench_live.split holds them out
    out = []
    for spec in specs:
        if spec.sentence_id in held or spec.variation != take:
            continue
        utt = synthesize_clip(spec, config).utterance
        out.append((spec.clip_id, utt.audio.astype(np.float32), utt.sample_rate, spec.text))
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--summarize", type=Path, default=None, metavar="JSON",
                        help="only print the table of the rows a run wrote (--json), "
                        "at today's thresholds")
    parser.add_argument("--grid-db", type=Path, default=None,
                        help="GRID database (its model streams; its clips are tried)")
    parser.add_argument("--every", type=int, default=8, help="every n-th GRID clip")
    parser.add_argument("--offset", type=int, default=0,
                        help="the first GRID clip tried (another offset: other clips)")
    parser.add_argument("--take", type=int, default=1, choices=(1, 2, 3),
                        help="the synthetic corpus' take tried (another take: other speech)")
    parser.add_argument("--synthetic", action="store_true",
                        help="also eSpeak NG speech of the synthetic corpus' sentences")
    parser.add_argument("--held-out", type=Path, default=None,
                        help="GRID s1 database: try its 20 held-out clips instead")
    parser.add_argument("--settings", nargs="+", default=list(SETTINGS),
                        choices=list(SETTINGS))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
    if args.summarize is not None:
        summarize(json.loads(args.summarize.read_text()))
        return 0
    if args.grid_db is None:
        parser.error("--grid-db is required (or --summarize JSON)")
    rng = np.random.default_rng(args.seed)
    model = Model.load(args.grid_db)
    corpora = {"grid": grid_clips(args.held_out or args.grid_db, args.every,
                                  args.held_out is not None, args.offset)}
    if args.synthetic:
        corpora["synthetic"] = synthetic_clips(args.take)
    rows = []
    for corpus, clips in corpora.items():
        texts = [c[3] for c in clips]
        print(f"# {corpus}: {len(clips)} clips", flush=True)
        for i, (cid, audio, sr, text) in enumerate(clips):
            other = next(t for t in texts[i + len(texts) // 2:] + texts if t != text)
            tried = {"right": text, "another clip's": other}
            if corpus == "grid":
                tried.update(one_word_changes(text, rng))
            else:
                tried["one word"] = swapped_word(text, [t for t in texts if t != text], rng)
            for name, setting in SETTINGS.items():
                if name not in args.settings:
                    continue
                fed, last = fed_posteriors(model, audio, sr, text, setting)
                for kind, t in tried.items():
                    rows.append({"corpus": corpus, "clip": cid, "setting": name,
                                 "kind": kind, "text": t, **replay(t, fed, last)})
                right = rows[-len(tried)]
                print(f"{corpus} {cid} {name}: right {right['loss']:.2f}, " + ", ".join(
                    f"{r['kind']} {r['loss']:.2f}" for r in rows[-len(tried) + 1:]),
                    flush=True)
            if args.json:  # after every clip: a long run stopped keeps what it measured
                args.json.write_text(json.dumps(rows, indent=1, default=float))
    summarize(rows)
    return 0


def summarize(rows: list[dict]) -> None:
    """Per corpus, setting and kind: the percentiles of the loss where the track stopped
    and of the worst share of its tests, and how many are reported at offline's
    thresholds and at the live ones (the live track's verdict)."""
    keys = sorted({(r["corpus"], r["setting"], r["kind"]) for r in rows},
                  key=lambda k: (k[0], k[1], k[2] != "right", k[2]))
    print(f"\n| corpus | setting | transcript | n | loss p1 / p50 / p99 / max | "
          f"worst share min / p1 / p5 / p50 | reported at {MAX_ALIGN_LOSS}, "
          f"{MIN_PHONE_SHARE} | reported live ({MAX_LIVE_ALIGN_LOSS}, "
          f"{MIN_LIVE_PHONE_SHARE}) |")
    print("|---|---|---|---|---|---|---|---|")
    for key in keys:
        got = [r for r in rows if (r["corpus"], r["setting"], r["kind"]) == key]
        loss = np.array([r["loss"] for r in got])
        p = np.percentile(loss, [1, 50, 99])
        worst_loss = np.array([r["worst_loss"] for r in got])
        worst_share = np.array([r["worst_share"] for r in got])
        q = np.percentile(worst_share, [0, 1, 5, 50])
        offline = int(np.sum((worst_loss > MAX_ALIGN_LOSS) | (worst_share < MIN_PHONE_SHARE)))
        live = int(np.sum((worst_loss > MAX_LIVE_ALIGN_LOSS)
                          | (worst_share < MIN_LIVE_PHONE_SHARE)))
        for r in got:  # the track's verdict is its worst test's against its thresholds
            if "thresholds" in r:
                max_loss, min_share = r["thresholds"]
                assert (r["failed"] is not None) == (
                    r["worst_loss"] > max_loss or r["worst_share"] < min_share), r
        print(f"| {key[0]} | {key[1]} | {key[2]} | {len(got)} | {p[0]:.2f} / {p[1]:.2f} / "
              f"{p[2]:.2f} / {loss.max():.2f} | {q[0]:.2f} / {q[1]:.2f} / {q[2]:.2f} / "
              f"{q[3]:.2f} | {offline} | {live} |")


if __name__ == "__main__":
    sys.exit(main())
