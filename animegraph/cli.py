"""The ``animegraph`` command-line tool.

Every user error (a bad option, a missing file, an impossible size) ends as one line
on stderr and a non-zero exit; tracebacks are kept for bugs.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
from collections.abc import Sequence
from pathlib import Path

from animegraph import __version__
from animegraph.baselines import METHODS
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

    ing = sub.add_parser(
        "ingest", help="add mocap clips + speech to a motion database",
        description="Read clips (markers: C3D/TRC/CSV; animation curves: NPY/CSV; landmarks "
        "tracked from video) with their speech, segment them into phonemes and store them as "
        "anime nodes in a Parquet database (created if absent). Unchanged clips are skipped; "
        "a bad clip is rejected with its reason while the others go in.",
    )
    ing.add_argument("sources", nargs="+", type=Path, metavar="SRC",
                     help="clip files or folders")
    ing.add_argument("--db", required=True, type=Path, help="database folder")
    ing.add_argument("--workers", type=_whole_number, default=1,
                     help="worker processes (default 1)")
    ing.add_argument("--variance", type=_number, default=0.95,
                     help="share of motion variance PCA keeps (paper: 0.95-0.98)")
    ing.add_argument("--fps", type=_number, default=None,
                     help="database frame rate (default: the highest of the clips)")
    ing.add_argument("--no-lag-correction", action="store_true",
                     help="keep landmark motion where it is instead of shifting it by the "
                     "estimated lip-audio lag")
    ing.add_argument("--quiet", action="store_true", help="no progress bar")
    ing.set_defaults(func=_cmd_ingest)

    sql = sub.add_parser(
        "sql", help="run a read-only SQL query on a database",
        description="Run SQL (DuckDB) over the database's tables: clips, animes, frames, "
        "audio, channels, model_arrays, components. Only SELECT queries run.",
    )
    sql.add_argument("query", help="the SQL, e.g. \"SELECT phoneme, count(*) FROM animes "
                     "GROUP BY 1\"")
    sql.add_argument("--db", required=True, type=Path, help="database folder")
    sql.add_argument("--format", choices=("table", "csv", "json", "parquet"), default="table")
    sql.add_argument("-o", "--output", type=Path, default=None,
                     help="write here instead of standard output (required for parquet)")
    sql.add_argument("--max-rows", type=_whole_number, default=50,
                     help="rows shown in table format (default 50)")
    sql.set_defaults(func=_cmd_sql)

    syn = sub.add_parser(
        "synth", help="facial motion for speech, from a motion database",
        description="Segment the speech into phones, search the Anime Graph for the best "
        "matching anime sequence (Cao et al. 2005, Eq. 2: jump matches, jump cost, DTW "
        "audio cost with weights 100, 1, 0.01), then time-warp, blend and smooth it.",
    )
    syn.add_argument("audio", type=Path, metavar="AUDIO", help="speech (WAV, any rate)")
    syn.add_argument("--db", required=True, type=Path, help="database folder")
    given = syn.add_mutually_exclusive_group()
    given.add_argument("--text", default=None, help="transcript (forced alignment)")
    given.add_argument("--labels", type=Path, default=None,
                       help="phone labels (.phones.csv, .TextGrid or HTK .lab)")
    syn.add_argument("--emotion", default=None, help="prefer animes of this emotion")
    syn.add_argument("--method", choices=METHODS, default="anime-graph",
                     help="synthesis system: anime-graph (default, Cao et al.), or a baseline "
                     "fitted on the database on first use and stored in it: mu-mlp (Hong et "
                     "al. 2002), hier-pca (Cosker et al.), av-hmm (Terissi et al. 2013)")
    syn.add_argument("--refit", action="store_true",
                     help="refit a baseline even if the database has it stored")
    mode = syn.add_mutually_exclusive_group()
    mode.add_argument("--exact", action="store_true",
                      help="the global optimum (default)")
    mode.add_argument("--window", type=_whole_number, default=None, metavar="K",
                      help="the paper's bounded look-ahead of K phonemes (3-6)")
    mode.add_argument("--search", choices=("exact", "paper", "window", "dp"), default=None,
                      help="Anime Graph search algorithm (paper: the published priority "
                      "queue)")
    syn.add_argument("-o", "--output", required=True, type=Path,
                     help="motion file: .c3d (marker databases), .csv or .npz")
    syn.add_argument("--explain", action="store_true",
                     help="print where every phone's motion came from and its costs")
    syn.add_argument("--explain-json", type=Path, default=None,
                     help="write the explanation as JSON here")
    syn.add_argument("--no-time-warp", action="store_true", help="skip DTW time-warping")
    syn.add_argument("--no-blend", action="store_true", help="skip blending at jumps")
    syn.add_argument("--no-smooth", action="store_true", help="skip low-pass smoothing")
    syn.set_defaults(func=_cmd_synth)

    fit = sub.add_parser(
        "fit", help="fit a baseline method on a database and store it there",
        description="Fit a baseline (issue #8) on every clip of a database and store the "
        "trained model as arrays in DB/baselines/<version>/<method>.parquet; 'synth "
        "--method' uses it (and fits it on first use if absent).",
    )
    fit.add_argument("--db", required=True, type=Path, help="database folder")
    fit.add_argument("--method", required=True, choices=METHODS[1:], help="baseline method")
    fit.set_defaults(func=_cmd_fit)

    info = sub.add_parser("info", help="summarise a database")
    info.add_argument("--db", required=True, type=Path, help="database folder")
    info.add_argument("--json", action="store_true", help="the summary as JSON")
    info.set_defaults(func=_cmd_info)
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


def _cmd_ingest(args: argparse.Namespace) -> int:
    from ingest.pipeline import IngestConfig, ingest

    config = IngestConfig(variance=args.variance, fps=args.fps,
                          correct_lag=not args.no_lag_correction)
    report = ingest(args.sources, args.db, config, workers=args.workers,
                    progress=lambda total: _progress(total, args.quiet, "clip"))
    for line in report.lines():
        print(line)
    return 1 if report.count("rejected") else 0


def _cmd_sql(args: argparse.Namespace) -> int:
    from animegraph.tabular import format_table
    from db.sql import query
    from db.store import Database

    if args.format == "parquet" and args.output is None:
        raise UsageError("animegraph sql: --format parquet needs --output FILE")
    result = query(Database.open(args.db), args.query)
    text = format_table(result, args.format, max_rows=args.max_rows, output=args.output)
    if text is not None:
        sys.stdout.write(text)
    return 0


def _cmd_synth(args: argparse.Namespace) -> int:
    import json
    import time

    from animegraph.synth import Model, synthesize, write_motion
    from animegraph.synthesis import PostOptions
    from ingest.formats.wav import read_wav
    from ingest.readers.common import read_labels

    if args.output.suffix.lower() not in (".c3d", ".csv", ".npz"):
        raise UsageError(f"animegraph synth: -o must end in .c3d, .csv or .npz, got "
                         f"{args.output.name!r}")
    if args.method != "anime-graph":
        return _synth_baseline(args)
    method = args.search or ("window" if args.window is not None else "exact")
    if method == "window" and args.window is None:
        raise UsageError("animegraph synth: --search window needs --window K")
    t0 = time.perf_counter()
    model = Model.load(args.db)
    if args.emotion is not None and args.emotion not in model.graph.emotions:
        raise UsageError(f"animegraph synth: emotion {args.emotion!r} is not in the database "
                         f"(it has {', '.join(model.graph.emotions)})")
    audio, sample_rate = read_wav(args.audio)
    labels = read_labels(args.labels) if args.labels else None
    print(f"animegraph: loaded {model.graph.n_nodes} animes in "
          f"{time.perf_counter() - t0:.2f} s; synthesizing {len(audio) / sample_rate:.1f} s "
          f"of speech ...", file=sys.stderr)
    options = PostOptions(time_warp=not args.no_time_warp, blend=not args.no_blend,
                          smooth=not args.no_smooth)
    out = synthesize(model, audio, sample_rate, text=args.text, labels=labels,
                     emotion=args.emotion, method=method, window=args.window,
                     options=options)
    write_motion(out, model, args.output)
    r = out.result
    t = out.timings
    print(f"animegraph: {len(out.phones)} phones ({out.segmentation}), {r.n_jumps} jump "
          f"matches, cost {r.cost:.3f} ({r.method}, {r.n_expanded} expansions); "
          f"{t['total_s']:.2f} s = segment {t['segment_s']:.2f} + audio cost "
          f"{t['audio_cost_s']:.2f} + search {t['search_s']:.3f} + post {t['post_s']:.2f}; "
          f"wrote {args.output}", file=sys.stderr)
    backoffs = sorted({f"{e['phone']}->{e['anime_phone']}" for e in out.explain
                       if e["backoff"]})
    if backoffs:
        print(f"animegraph: phones missing from the database, backed off: "
              f"{', '.join(backoffs)}", file=sys.stderr)
    if args.explain:
        import pyarrow as pa

        from animegraph.tabular import format_table

        print(format_table(pa.Table.from_pylist(out.explain), "table",
                           max_rows=len(out.explain)), end="")
    if args.explain_json:
        from db.atomic import atomic_write

        record = {"phones": out.explain, "joins": out.joins, "cost": r.cost,
                  "n_jumps": r.n_jumps, "method": r.method, "timings": t}
        with atomic_write(args.explain_json) as handle:
            handle.write(json.dumps(record, indent=1, default=_jsonable).encode())
    return 0


def _synth_baseline(args: argparse.Namespace) -> int:
    """``synth --method <baseline>``: motion from the audio alone by a fitted baseline."""
    import time

    import numpy as np

    from animegraph.baselines.base import fitted_model
    from animegraph.synth import to_world, write_channels
    from db.store import Database
    from ingest.formats.wav import read_wav

    search_only = [flag for flag, on in (
        ("--text", args.text is not None), ("--labels", args.labels is not None),
        ("--exact", args.exact), ("--window", args.window is not None),
        ("--search", args.search is not None), ("--explain", args.explain),
        ("--explain-json", args.explain_json is not None),
        ("--no-time-warp", args.no_time_warp), ("--no-blend", args.no_blend),
        ("--no-smooth", args.no_smooth)) if on]
    if search_only:
        raise UsageError(f"animegraph synth: {', '.join(search_only)} only apply to "
                         f"--method anime-graph, not {args.method}")
    db = Database.open(args.db)
    emotions = sorted(set(db.table("clips", columns=["emotion"]).column("emotion").to_pylist()))
    if args.emotion is not None and args.emotion not in emotions:
        raise UsageError(f"animegraph synth: emotion {args.emotion!r} is not in the database "
                         f"(it has {', '.join(emotions)})")
    audio, sample_rate = read_wav(args.audio)
    t0 = time.perf_counter()
    model = fitted_model(args.db, args.method, refit=args.refit)
    t1 = time.perf_counter()
    motion = model.predict(audio, sample_rate, emotion=args.emotion)
    t2 = time.perf_counter()
    head = db.arrays().get("head_reference")
    write_channels(to_world(motion, model.groups_, head), model.fps_, model.channels_,
                   model.kind_, args.output, extra={"method": np.array(args.method)})
    print(f"animegraph: {args.method} model ready in {t1 - t0:.2f} s; synthesized "
          f"{len(audio) / sample_rate:.1f} s of speech in {t2 - t1:.2f} s; wrote "
          f"{args.output}", file=sys.stderr)
    return 0


def _cmd_fit(args: argparse.Namespace) -> int:
    import time

    from animegraph.baselines.base import fitted_model, model_path

    t0 = time.perf_counter()
    fitted_model(args.db, args.method, refit=True)
    print(f"fitted {args.method} on {args.db} in {time.perf_counter() - t0:.1f} s; stored "
          f"{model_path(args.db, args.method)}")
    return 0


def _jsonable(value):
    import numpy as np

    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, tuple):
        return list(value)
    return str(value)


def _cmd_info(args: argparse.Namespace) -> int:
    import json

    from animegraph.info import database_info, info_lines
    from db.store import Database

    info = database_info(Database.open(args.db))
    if args.json:
        print(json.dumps(info, indent=1))
    else:
        for line in info_lines(info):
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
            raise UsageError("animegraph: choose a command: corpus, demo, ingest, synth, fit, "
                             "sql, info "
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
    except BrokenPipeError:
        # The reader went away (``animegraph sql ... | head``): not an error.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
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
