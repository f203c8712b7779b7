"""End-to-end real-time factor of lip-sync synthesis in one resident process.

Usage::

    python scripts/bench_e2e.py [--db DB] [--repeats 3] [--segmentation recognized|aligned|labels]
                                [--phones-engine auto|hama|pocketsphinx] [--k-best K]
                                [--guide mu-mlp|av-hmm|ppg-ridge|mu-mlp+ppg-ridge [--guide-blend W]]
                                [--audio RECORDING] [--profile N]

Speaks a 9 s sentence with eSpeak NG, then runs :func:`animegraph.synthesis.synthesize` on it
``--repeats`` times in this process (the first run pays numba's cache load), with the
phones recognised (default), force-aligned to the text, or taken from eSpeak's events.
Prints each run's phase timings and real-time factor (synthesis time / audio duration), and
the process's CPU time (less sensitive to the machine's load than the wall time). With
``--guide`` the database's stored guide (fitted and stored first if absent, reported
apart) guides the animes' choice, as ``synth --guide``. Last, hama's model call alone on
the same audio: the floor under the ``segment`` phase when phones are recognised or a
transcript is checked (hama hears a recording of ``ingest.speech.ctc.SPLIT_SECONDS`` or
more in pieces, on every core).
``--audio`` times a recording instead (a WAV or a video's sound track; phones recognised).
``--profile N`` then runs ``N`` more syntheses under :mod:`cProfile` timed by the process's
CPU clock (all threads: hama's pieces and the DTW threads count where they are waited
for) and prints the functions of most CPU per run: where the time goes on a machine whose
wall clock other processes share.
DB defaults to the default database (built on first use, as by ``animegraph demo``).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from animegraph.apps.cli import SYNTH_GUIDES

TEXT = ("The quick brown fox jumps over the lazy dog while the children watch from the "
        "garden, and everybody laughs when the old farmer finally catches it near the river.")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--db", type=Path, default=None)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--segmentation", choices=("recognized", "aligned", "labels"),
                        default="recognized")
    parser.add_argument("--audio", type=Path, default=None,
                        help="a recording to time instead of the eSpeak sentence (phones "
                             "recognised)")
    parser.add_argument("--phones-engine", default=None,
                        help="phone engine (ingest.speech.engines.ENGINES; default auto)")
    parser.add_argument("--k-best", type=int, default=None,
                        help="k-best blending (synth's default on audio only: 20)")
    parser.add_argument("--audio-cost", default=None,
                        help="synthesize's audio_cost (default plp; posteriorgram, "
                             "plp+posteriorgram)")
    parser.add_argument("--guide", choices=SYNTH_GUIDES, default=None,
                        help="trajectory-guided selection by this stored baseline")
    parser.add_argument("--guide-blend", type=float, default=0.5,
                        help="with --guide: the guide's share of the output (0.5)")
    parser.add_argument("--profile", type=int, default=0, metavar="N",
                        help="then N runs under cProfile (CPU clock): the costliest "
                             "functions per run")
    args = parser.parse_args()

    from animegraph.synthesis import Model, synthesize
    from ingest.formats.phones_csv import Segment
    from ingest.speech import ctc
    from ingest.speech.espeak import speak

    if args.db is None:
        from animegraph.apps.demo import ensure_default_corpus, ensure_default_db

        corpus, _, _ = ensure_default_corpus()
        args.db, _ = ensure_default_db(corpus)
    if args.audio is not None and args.segmentation != "recognized":
        parser.error("--audio has no transcript or labels: --segmentation recognized")
    utt = speak(TEXT)
    if args.audio is not None:
        from types import SimpleNamespace

        from ingest.formats.media import read_audio

        audio, rate = read_audio(args.audio)
        utt = SimpleNamespace(audio=audio, sample_rate=rate)
    seconds = len(utt.audio) / utt.sample_rate
    model = Model.load(args.db)
    kwargs = {"phones_engine": args.phones_engine, "k_best": args.k_best}
    if args.audio_cost is not None:
        kwargs["audio_cost"] = args.audio_cost
    if args.guide is not None:
        from animegraph.baselines.stored import load_forward

        guides = []
        for name in args.guide.split("+"):  # a mean of several: each stored apart
            t = time.perf_counter()
            guides.append(load_forward(args.db, name))
            if guides[-1] is None:
                from animegraph.baselines.base import fitted_model

                guides[-1] = fitted_model(args.db, name)
                print(f"# {name} fitted and stored in {time.perf_counter() - t:.1f} s")
        guide = guides[0] if len(guides) == 1 else tuple(guides)
        kwargs |= {"guide": guide, "guide_blend": args.guide_blend}
    if args.segmentation == "aligned":
        kwargs["text"] = TEXT
    elif args.segmentation == "labels":
        kwargs["labels"] = [Segment(p.phone, p.start, p.end) for p in utt.phones]
    print(f"# {seconds:.2f} s of speech, {model.graph.n_nodes} animes, phones "
          f"{args.segmentation} ({args.phones_engine or 'auto'}), k-best {args.k_best}"
          + (f", guide {args.guide} ({args.guide_blend:g})" if args.guide else ""))
    for k in range(args.repeats):
        if hasattr(ctc, "forget"):  # every run hears the audio afresh (hama remembers its
            ctc.forget()            # last outputs; older checkouts have no such memory)
        t, cpu = time.perf_counter(), time.process_time()
        out = synthesize(model, utt.audio, utt.sample_rate, **kwargs)
        total = time.perf_counter() - t
        cpu = time.process_time() - cpu
        phases = " ".join(f"{name[:-2]} {v:.2f}" for name, v in out.timings.items()
                          if name != "total_s")
        print(f"run {k + 1}: {total:.2f} s, real-time factor {total / seconds:.3f}, CPU "
              f"{cpu:.2f} s ({cpu / seconds:.3f} x real time) "
              f"({phases}; {len(out.phones)} phones, {out.result.n_jumps} jumps)")
    if args.profile > 0:
        profile_runs(args.profile, lambda: synthesize(model, utt.audio, utt.sample_rate,
                                                      **kwargs), ctc)
    if hasattr(ctc, "forget") and args.segmentation != "labels":
        # The floor under "segment": hama's call (its pieces on every core), same audio.
        ctc.forget()
        t = time.perf_counter()
        ctc.posteriors(utt.audio, utt.sample_rate)
        alone = time.perf_counter() - t
        print(f"hama's call alone: {alone:.2f} s ({alone / seconds:.3f} x real time)")
    return 0


def profile_runs(n: int, run, ctc, top: int = 30) -> None:
    """``n`` runs of ``run()`` under cProfile with the process's CPU clock; prints the
    ``top`` functions by cumulative and by own CPU seconds per run."""
    import cProfile
    import io
    import pstats

    profiler = cProfile.Profile(time.process_time)
    for _ in range(n):
        if hasattr(ctc, "forget"):
            ctc.forget()
        profiler.enable()
        run()
        profiler.disable()
    stats = pstats.Stats(profiler, stream=(out := io.StringIO()))
    print(f"# cProfile, CPU seconds summed over {n} runs (divide by {n} for one run)")
    for order in ("cumulative", "tottime"):
        stats.sort_stats(order).print_stats(top)
    print("\n".join(line for line in out.getvalue().splitlines() if line.strip()))


if __name__ == "__main__":
    sys.exit(main())
