"""``animegraph corpus synth`` (the synthetic corpus) and ``animegraph demo``."""

from __future__ import annotations

import argparse

from animegraph.apps.commands.common import UsageError, progress, say


def cmd_corpus_synth(args: argparse.Namespace) -> int:
    from ingest.corpus.synthetic import CorpusConfig, generate_corpus, plan_corpus

    if args.scale == "paper" and (args.sentences is not None or args.parallel is not None):
        raise UsageError("animegraph corpus synth: --scale paper fixes --sentences and "
                         "--parallel; leave them out")
    config = CorpusConfig(
        sentences=40 if args.sentences is None else args.sentences,
        parallel=_default_parallel(args),
        variations=args.variations, fps=args.fps, seed=args.seed, scale=args.scale,
    )
    n = len(plan_corpus(config))
    summary = generate_corpus(args.out, config, workers=args.workers, force=args.force,
                              progress=progress(n, args.quiet, "clip",
                                                "generating the corpus"),
                              say=None if args.quiet else say)
    print(f"wrote {summary.n_clips} clip{'s' * (summary.n_clips != 1)} of "
          f"{summary.n_sentences} sentence{'s' * (summary.n_sentences != 1)}, "
          f"{summary.duration_s / 60:.1f} min of speech, to {summary.path}")
    return 0


def _default_parallel(args: argparse.Namespace) -> int:
    if args.parallel is not None:
        return args.parallel
    sentences = 40 if args.sentences is None else args.sentences
    return min(10, sentences)


def cmd_demo(args: argparse.Namespace) -> int:
    from animegraph.apps.demo import run_demo

    def demo_progress(total: int, step: str = "clips"):
        return progress(total, args.quiet, "clip", step)

    result = run_demo(args.out, emotion=args.emotion, text=args.text, workers=args.workers,
                      progress=demo_progress, say=print, prepare=not args.no_prepare)
    for line in result.report():  # the answer first, then the wait for the guides
        print(line)
    result.finish(say=print)
    from animegraph.apps.prepare import unfitted_note

    # what is still missing (--no-prepare, or a fit that failed): said, with how
    note = unfitted_note(result.db) if result.db is not None else None
    if note:
        print(note)
    return 0
