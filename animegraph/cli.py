"""The ``animegraph`` command-line tool.

Every user error (a bad option, a missing file, an impossible size) ends as one line
on stderr and a non-zero exit; tracebacks are kept for bugs.
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence
from pathlib import Path

from animegraph import __version__
from db.errors import AnimeGraphError


class UsageError(Exception):
    """The command line itself is wrong (exit status 2)."""


class _Parser(argparse.ArgumentParser):
    # argparse prints the whole usage block and exits; one line says it better.
    def error(self, message: str) -> None:  # type: ignore[override]
        raise UsageError(f"{self.prog}: {message} (see '{self.prog} --help')")


def _whole_number(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    return value


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every sub-command."""
    parser = _Parser(
        prog="animegraph",
        description="Expressive speech-driven facial animation (after Cao et al. 2005).",
    )
    parser.add_argument("--version", action="version", version=f"animegraph {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0,
                        help="more log output (-vv for debug)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)

    corpus = sub.add_parser("corpus", help="corpus tools")
    corpus_sub = corpus.add_subparsers(dest="corpus_command", metavar="ACTION",
                                       parser_class=_Parser)
    synth = corpus_sub.add_parser(
        "synth", help="generate a synthetic expressive speech + facial mocap corpus",
        description="Generate a synthetic expressive speech + facial motion-capture corpus "
        "(eSpeak NG speech with exact phone timing, five emotions, 3D markers on the "
        "canonical face mesh).",
    )
    synth.add_argument("--out", required=True, type=Path, help="folder to create")
    synth.add_argument("--sentences", type=_whole_number, default=None,
                       help="distinct sentences (default 40)")
    synth.add_argument("--parallel", type=_whole_number, default=None,
                       help="sentences spoken in all five emotions (default 10)")
    synth.add_argument("--variations", type=_whole_number, default=3,
                       help="takes of every (sentence, emotion) pair (default 3)")
    synth.add_argument("--fps", type=_number, default=120.0, help="marker frame rate (120)")
    synth.add_argument("--seed", type=_whole_number, default=0, help="random seed (0)")
    synth.add_argument("--scale", choices=("default", "paper"), default="default",
                       help="'paper': Cao et al.'s size, 1,326 utterances")
    synth.add_argument("--workers", type=_whole_number, default=None,
                       help="worker processes (default: all cores)")
    synth.add_argument("--force", action="store_true", help="replace a non-empty --out")
    synth.add_argument("--quiet", action="store_true", help="no progress bar")
    synth.set_defaults(func=_cmd_corpus_synth)

    demo = sub.add_parser(
        "demo", help="run the pipeline on the embedded default data",
        description="Create the default corpus in the cache folder (once), then run the "
        "pipeline on a sentence that is not in it and write the outputs and a plot.",
    )
    demo.add_argument("--out", type=Path, default=Path("animegraph-demo"),
                      help="output folder (default ./animegraph-demo)")
    demo.add_argument("--emotion", default="happy", help="emotion of the demo sentence")
    demo.add_argument("--text", default=None, help="the sentence to say")
    demo.add_argument("--workers", type=_whole_number, default=None,
                      help="worker processes for the corpus (default: all cores)")
    demo.add_argument("--quiet", action="store_true", help="no progress bar")
    demo.set_defaults(func=_cmd_demo)
    return parser


def _progress(total: int, quiet: bool, unit: str):
    from functools import partial

    from tqdm import tqdm

    return partial(tqdm, total=total, unit=unit, disable=quiet, file=sys.stderr,
                   dynamic_ncols=True)


def _cmd_corpus_synth(args: argparse.Namespace) -> int:
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
                              progress=_progress(n, args.quiet, "clip"))
    print(f"wrote {summary.n_clips} clips of {summary.n_sentences} sentences, "
          f"{summary.duration_s / 60:.1f} min of speech, to {summary.path}")
    return 0


def _default_parallel(args: argparse.Namespace) -> int:
    if args.parallel is not None:
        return args.parallel
    sentences = 40 if args.sentences is None else args.sentences
    return min(10, sentences)


def _cmd_demo(args: argparse.Namespace) -> int:
    from animegraph.demo import run_demo

    def progress(total: int):
        return _progress(total, args.quiet, "clip")

    result = run_demo(args.out, emotion=args.emotion, text=args.text, workers=args.workers,
                      progress=progress, say=print)
    for line in result.report():
        print(line)
    return 0


def _configure_logging(verbosity: int) -> None:
    level = logging.WARNING if verbosity == 0 else logging.INFO if verbosity == 1 else logging.DEBUG
    logging.basicConfig(level=level, format="animegraph: %(levelname)s: %(message)s",
                        stream=sys.stderr)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the tool; return the exit status."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        _configure_logging(args.verbose)
        if args.command is None:
            raise UsageError("animegraph: choose a command: corpus, demo "
                             "(see 'animegraph --help')")
        if not hasattr(args, "func"):
            raise UsageError(f"animegraph {args.command}: choose an action "
                             f"(see 'animegraph {args.command} --help')")
        return int(args.func(args) or 0)
    except UsageError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except AnimeGraphError as exc:
        print(f"animegraph: error: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:
        # Disk full, permission denied, a folder vanished: the environment, not a bug.
        where = f" {exc.filename}" if exc.filename else ""
        print(f"animegraph: error:{where}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("animegraph: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
