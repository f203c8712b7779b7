"""The ``animegraph`` argument parser: every sub-command, its options and their help.

Each sub-command's function (``func``) is in :mod:`animegraph.apps.commands`; a
left-out ``--db`` (``default_db``) is filled in by :mod:`animegraph.apps.cli`. The emotion
commands' arguments are in :mod:`animegraph.apps.cli_parser_emotion`."""

from __future__ import annotations

import argparse
import difflib
import math
from pathlib import Path

from animegraph import __version__
from animegraph.apps.cli_parser_emotion import add_emotion_commands
from animegraph.apps.commands.common import UsageError
from animegraph.apps.commands.corpus import cmd_corpus_synth, cmd_demo
from animegraph.apps.commands.database import (
    cmd_fit,
    cmd_info,
    cmd_ingest,
    cmd_query,
    cmd_sql,
    cmd_warmup,
)
from animegraph.apps.commands.live import cmd_live
from animegraph.apps.commands.render import cmd_plot, cmd_render
from animegraph.apps.commands.studio import cmd_studio
from animegraph.apps.commands.synth import cmd_batch, cmd_synth
from animegraph.baselines import METHODS
from ingest.speech.engines import ENGINES

#: ``synth --helper``: animegraph.synthesis.HELPER_MODES, written out so that ``--help`` does
#: not import the synthesis (tests/test_synth.py checks that they are the same).
HELPER_CHOICES = ("paper", "anchored", "anchored-nonspeech")

#: ``synth --audio-cost`` (:data:`animegraph.synthesis.audio.AUDIO_COSTS`, spelled out here
#: so that the command line starts without importing synthesis).
SYNTH_AUDIO_COSTS = ("plp", "posteriorgram", "plp+posteriorgram")

#: ``synth --guide`` (:data:`animegraph.synthesis.guide.GUIDES`, spelled out here too).
SYNTH_GUIDES = ("mu-mlp", "av-hmm", "ppg-ridge", "mu-mlp+ppg-ridge")

#: ``sql --timeout``'s default and ceiling (:data:`db.sql.TIMEOUT_S`, :data:`db.sql.MAX_TIMEOUT_S`,
#: spelled out here so that ``--help`` does not import DuckDB; tests/test_sql_sandbox.py
#: checks that they are the same).
TIMEOUT_S, MAX_TIMEOUT_S = 60.0, 86400.0

#: ``sql --help``'s list of the tables and their main columns (tests/test_ingest.py checks
#: that each column is in a database).
SQL_TABLES_HELP = (
    "Each table, what a row is and its main columns. "
    "clips: utterance (clip_id, corpus, speaker, emotion, text, fps, duration, phones, ...); "
    "animes: phoneme instance, times in s (node_id, clip_id, position, phoneme, emotion, "
    "start_time, end_time, start_frame, end_frame, prosody, motion, ...; frames "
    "start_frame <= frame < end_frame, neighbours sharing the one astride their boundary); "
    "frames: motion frame (clip_id, frame, time, and a column per channel, "
    "e.g. \"lip_corner_r.x\" in double quotes); "
    "audio: utterance (clip_id, sample_rate, pcm16); "
    "channels: motion channel (name, group, kind, units, min, max); "
    "components: independent component (component, cutoff_hz, motion_share, label, ...); "
    "model_arrays: learned array (name, shape, values). "
    "'DESCRIBE animes' lists a table's columns and their types.")

#: What a speech argument accepts: anything libsndfile (through soundfile) decodes.
SPEECH_FORMATS = ("speech: WAV, FLAC, OGG/Vorbis or MP3 (anything libsndfile reads), or a "
                  "video's sound track (.mp4, .mov, .mkv ...), any sample rate, channels "
                  "averaged to mono")


class _Parser(argparse.ArgumentParser):
    # argparse prints the whole usage block and exits; one line says it better.
    def error(self, message: str) -> None:  # type: ignore[override]
        raise UsageError(f"{self.prog}: {message} (see '{self.prog} --help')")

    def parse_known_args(self, args=None, namespace=None):  # type: ignore[override]
        # A command's parser hands what it does not know up to the top parser, which
        # told it without the command's name and sent the user to the top-level help
        # (which lists no command's options): the command's parser says it, with the
        # option it may be a misspelling of.
        namespace, extras = super().parse_known_args(args, namespace)
        if extras and not self._has_commands:
            self.error(f"unrecognized arguments: {' '.join(extras)}{self._did_you_mean(extras)}")
        return namespace, extras

    # Whether this parser hands its words on to a command's parser (the top parser, and
    # ``corpus``): set here rather than read from argparse's private ``_subparsers``.
    _has_commands = False

    def add_subparsers(self, **kwargs):
        self._has_commands = True
        return super().add_subparsers(**kwargs)

    def _did_you_mean(self, extras: list[str]) -> str:
        known = [option for action in self._actions for option in action.option_strings]
        close = [match for extra in extras if extra.startswith("--")
                 for match in difflib.get_close_matches(extra.split("=")[0], known, n=1,
                                                         cutoff=0.75)]
        return f"; did you mean {' or '.join(dict.fromkeys(close))}?" if close else ""


def _shortlist(text: str) -> int | str:
    """``--shortlist``: ``all`` or a whole number >= 1."""
    if text == "all":
        return text
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1 or 'all', got {text!r}")
    return value


def _whole_number(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    return value


def _thread_cap(text: str) -> int | None:
    """``--threads``: a whole number >= 1, or 0 for no cap (None, as the Python API
    spells it)."""
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, or 0 for no cap, "
                                         f"got {text!r}")
    return value or None


def _output(folder: bool | None):
    """The type of an option naming an output: :func:`db.atomic.check_output_path` (a new path,
    or an existing regular file or folder as ``folder`` says; never a device, FIFO or
    symbolic link, never inside a database), said as the option's error."""
    from db.atomic import check_output_path
    from db.errors import DataError

    def output(text: str) -> Path:
        try:
            return check_output_path(text, folder=folder)
        except DataError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
    output.__name__ = "output path"  # argparse's word for it in "invalid output path value"
    return output


_output_file, _output_folder, _output_file_or_folder = _output(False), _output(True), _output(None)


def _formats(text: str) -> tuple[str, ...]:
    """``c3d,csv``: names, checked by the command (it knows the database's kind)."""
    names = tuple(name.strip().lower() for name in text.split(","))
    if not all(names):
        raise argparse.ArgumentTypeError(f"expected formats separated by commas, got {text!r}")
    return names


def _number(text: str) -> float:
    """A finite number: ``inf`` and ``nan`` parse as floats, and each option that took
    them went on without its limit (``sql --timeout inf`` ended in a thread's
    OverflowError and no time limit at all)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
    return value


def _phones_engine_option(parser, transcript: str) -> None:
    """``--phones-engine`` of ``ingest`` and ``synth`` (``transcript``: what they call one)."""
    parser.add_argument("--phones-engine", choices=ENGINES, default=None,
                        help=f"phone engine when there are no labels: auto (default: "
                        f"PocketSphinx aligns {transcript}; without one hama names the "
                        "phones and PocketSphinx places them: each measured best at it), "
                        "hama (CTC phone model shipped in "
                        "its wheel) or pocketsphinx")


def _db_option(parser: argparse.ArgumentParser) -> None:
    """``--db``, which may be left out: ``$ANIMEGRAPH_DB``, else the demo's database."""
    from animegraph.apps.cache import DB_ENV, default_db_dir

    parser.add_argument("--db", type=Path, default=None,
                        help=f"database folder (default: ${DB_ENV} if set, else the one "
                        f"'animegraph demo' builds, {default_db_dir()})")
    parser.set_defaults(default_db=True)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every sub-command."""
    from animegraph.apps.cache import DB_ENV, default_db_dir

    parser = _Parser(
        prog="animegraph",
        description="Expressive speech-driven facial animation (after Cao et al. 2005).",
        epilog=f"Commands that read a database take --db DB; left out, ${DB_ENV} is used if "
        f"set, else the default database that 'animegraph demo' builds: {default_db_dir()}. "
        "Exit status: 0 done, 1 bad input or data, 2 wrong command line, 130 interrupted.",
    )
    parser.add_argument("--version", action="version", version=f"animegraph {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0,
                        help="more log output (-vv for debug)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)

    _add_corpus(sub)
    _add_demo(sub)
    _add_ingest(sub)
    _add_sql(sub)
    _add_synth(sub)
    _add_batch(sub)
    _add_live(sub)
    _add_query(sub)
    _add_render(sub)
    _add_plot(sub)
    add_emotion_commands(sub, db_option=_db_option, output_file=_output_file,
                         number=_number, parser_class=_Parser, speech=SPEECH_FORMATS)
    _add_fit(sub)
    _add_warmup(sub)
    _add_info(sub)
    _add_studio(sub)
    return parser


def _add_corpus(sub) -> None:
    """``corpus`` and its one action, ``corpus synth``."""
    corpus = sub.add_parser("corpus", help="corpus tools",
                            description="Corpus tools: 'corpus synth' generates the "
                            "synthetic expressive speech + facial motion-capture corpus.")
    corpus_sub = corpus.add_subparsers(dest="corpus_command", metavar="ACTION",
                                       parser_class=_Parser)
    synth = corpus_sub.add_parser(
        "synth", help="generate a synthetic expressive speech + facial mocap corpus",
        description="Generate a synthetic expressive speech + facial motion-capture corpus "
        "(eSpeak NG speech with exact phone timing, five emotions, 3D markers on the "
        "canonical face mesh).",
    )
    synth.add_argument("--out", required=True, type=_output_folder, help="folder to create")
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
    synth.set_defaults(func=cmd_corpus_synth)


def _add_demo(sub) -> None:
    """``demo``: the pipeline on the embedded default data."""
    demo = sub.add_parser(
        "demo", help="run the pipeline on the embedded default data",
        description="Create the default corpus in the cache folder (once), then run the "
        "pipeline on a sentence that is not in it and write the outputs and a plot.",
    )
    # The default a string: argparse checks it through the type as it does a given one.
    demo.add_argument("--out", type=_output_folder, default="animegraph-demo",
                      help="output folder (default ./animegraph-demo)")
    demo.add_argument("--emotion", default="happy", help="emotion of the demo sentence")
    demo.add_argument("--text", default=None, help="the sentence to say")
    demo.add_argument("--workers", type=_whole_number, default=None,
                      help="worker processes for the corpus (default: all cores)")
    demo.add_argument("--quiet", action="store_true", help="no progress bar")
    demo.add_argument("--no-prepare", action="store_true",
                      help="do not fit the guides of synth from speech alone beside the demo "
                      "(the first such synth, or 'animegraph warmup', fits them)")
    demo.set_defaults(func=cmd_demo)


def _add_ingest(sub) -> None:
    """``ingest``: clips and their speech into a database."""
    ing = sub.add_parser(
        "ingest", help="add mocap clips + speech to a motion database",
        description="Read clips (markers: C3D/TRC/CSV; animation curves: NPY/CSV; iPhone "
        "captures: Live Link Face CSV; landmarks tracked from video: NPY, or the video "
        "itself) with their speech, segment them into phonemes and store them as "
        "anime nodes in a Parquet database (created if absent). Unchanged clips are skipped; "
        "a bad clip is rejected with its reason while the others go in; prepared clips "
        "are kept in the cache until they are in, so a killed ingest run again redoes "
        "only the clips it had not finished. Then the database "
        "is made ready for its first synth: the default guides of audio-only synth fitted "
        "and stored, the search kernels compiled once (see 'animegraph warmup').",
    )
    ing.add_argument("sources", nargs="+", type=Path, metavar="SRC",
                     help="clip files or folders")
    ing.add_argument("--db", required=True, type=Path, help="database folder")
    ing.add_argument("--workers", type=_whole_number, default=1,
                     help="worker processes (default 1; ignored with --scheduler)")
    ing.add_argument("--scheduler", default=None, metavar="ADDRESS",
                     help="prepare the clips on an existing Dask cluster, e.g. "
                     "tcp://host:8786: clips up to 64 MB travel as bytes; this process "
                     "alone writes the database")
    ing.add_argument("--variance", type=_number, default=0.95,
                     help="share of motion variance PCA keeps (paper: 0.95-0.98)")
    ing.add_argument("--fps", type=_number, default=None,
                     help="database frame rate (default: the highest of the clips)")
    ing.add_argument("--no-lag-correction", action="store_true",
                     help="keep landmark and iPhone (Live Link) motion where it is "
                     "instead of shifting it by the estimated lip-audio lag")
    ing.add_argument("--posteriorgrams", action="store_true",
                     help="also store each clip's phone posteriorgram (hama), for synth "
                     "--audio-cost posteriorgram (beyond the paper; kept once stored; "
                     "always kept for clips whose phones hama recognised)")
    _phones_engine_option(ing, "a transcript")
    ing.add_argument("--max-speed", type=_number, default=None, metavar="MM_S",
                     help="fastest plausible marker motion in mm/s (default: the "
                     "database's, else 5000); a faster jump is a dropout, or rejects the "
                     "clip if it lasts. The database keeps the largest its clips went in "
                     "with, and checks its stored clips with it")
    ing.add_argument("--wait", type=_number, default=None,
                     help="seconds to wait for another ingest into the same --db to finish "
                     "(default 600); one writer at a time")
    ing.add_argument("--no-prepare", action="store_true",
                     help="leave fitting the default guides and compiling the search "
                     "kernels to the first synth (or 'animegraph warmup')")
    ing.add_argument("--quiet", action="store_true", help="no progress bar")
    ing.set_defaults(func=cmd_ingest)


def _add_sql(sub) -> None:
    """``sql``: read-only SQL over a database."""
    sql = sub.add_parser(
        "sql", help="run a read-only SQL query on a database",
        description="Run SQL (DuckDB) over the database's tables: clips, animes, frames, "
        "audio, channels, model_arrays, components. Only SELECT queries run, in DuckDB's "
        "sandbox (no file outside the database, no network, no extensions); several "
        "statements separated by ';' each print their result.",
        epilog=SQL_TABLES_HELP,
    )
    sql.add_argument("query", help="the SQL, e.g. \"SELECT phoneme, count(*) FROM animes "
                     "GROUP BY 1\"")
    _db_option(sql)
    sql.add_argument("--format", choices=("table", "csv", "json", "jsonl", "parquet"),
                     default=None, help="json: one array of row objects; jsonl: JSON "
                     "Lines, an object a line (default: as -o's name says: .csv, .json, "
                     ".jsonl, .parquet; else table)")
    sql.add_argument("-o", "--output", type=_output_file, default=None,
                     help="write here instead of standard output (required for parquet)")
    sql.add_argument("--max-rows", type=_whole_number, default=50,
                     help="rows shown in table format (default 50)")
    sql.add_argument("--limit", type=_whole_number, default=None,
                     help="rows fetched per statement; the rest is never read "
                     "(default 100000)")
    sql.add_argument("--timeout", type=_number, default=None,
                     help=f"seconds before the query is interrupted: more than 0, at most "
                     f"{MAX_TIMEOUT_S:g} (a day; default {TIMEOUT_S:g})")
    sql.set_defaults(func=cmd_sql)


def _add_synth(sub) -> None:
    """``synth``: facial motion for speech (the Anime Graph, or a baseline)."""
    syn = sub.add_parser(
        "synth", help="facial motion for speech, from a motion database",
        description="Segment the speech into phones, search the Anime Graph for the best "
        "matching anime sequence (Cao et al. 2005, Eq. 2: jump matches, jump cost, DTW "
        "audio cost with weights 100, 1, 0.01), then time-warp, blend and smooth it.",
    )
    syn.add_argument("audio", type=Path, metavar="AUDIO", help=SPEECH_FORMATS)
    _db_option(syn)
    given = syn.add_mutually_exclusive_group()
    given.add_argument("--text", default=None, help="transcript (forced alignment)")
    given.add_argument("--labels", type=Path, default=None,
                       help="phone labels (.phones.csv, .TextGrid or HTK .lab; default: "
                       "AUDIO's <stem>.phones.csv, .TextGrid or .lab beside it, if any, "
                       "else the phones are recognized)")
    feel = syn.add_mutually_exclusive_group()
    feel.add_argument("--emotion", default=None, metavar="E|auto",
                      help="the face's emotion: prefer animes of E and map the others into "
                      "it (Cao et al. §5); 'auto': the emotion classified from the speech (§6)")
    feel.add_argument("--emotion-mix", default=None, metavar="E=W,...",
                      help="blend mapped emotions, e.g. happy=0.7,neutral=0.3")
    syn.add_argument("--method", choices=METHODS, default="anime-graph",
                     help="synthesis system: anime-graph (default, Cao et al.), or a baseline "
                     "fitted on the database on first use and stored in it: mu-mlp (Hong et "
                     "al. 2002), hier-pca (Cosker et al.), av-hmm (Terissi et al. 2013), "
                     "ppg-ridge (beyond the papers: phone posteriors, speaker-independent)")
    syn.add_argument("--refit", action="store_true",
                     help="refit a baseline even if the database has it stored")
    mode = syn.add_mutually_exclusive_group()
    mode.add_argument("--exact", action="store_true",
                      help="the paper's synthesis, one anime a phone: the global optimum "
                      "(the search the default k-best runs on, too)")
    mode.add_argument("--window", type=_whole_number, default=None, metavar="K",
                      help="the paper's bounded look-ahead of K phonemes (K >= 1; the "
                      "paper uses 3-6)")
    mode.add_argument("--search", choices=("exact", "paper", "window", "dp"), default=None,
                      help="Anime Graph search algorithm (paper: the published priority "
                      "queue)")
    syn.add_argument("--tolerance", type=_number, default=None, metavar="T",
                     help="exact search only: accept a sequence certified within (1 + T) of "
                     "the optimum's cost, e.g. 0.01 (much faster on huge databases)")
    syn.add_argument("-o", "--output", required=True, type=_output_file,
                     help="motion file: .c3d (marker databases), .csv or .npz; "
                     "NAME.livelink.csv writes Live Link Face CSV (ARKit databases)")
    syn.add_argument("--timecode", default=None, metavar="HH:MM:SS:FF",
                     help="first frame's timecode in a .livelink.csv (default 00:00:00:00)")
    syn.add_argument("--explain", action="store_true",
                     help="print where every phone's motion came from and its costs")
    syn.add_argument("--explain-json", type=_output_file, default=None,
                     help="write the explanation as JSON here")
    syn.add_argument("--no-time-warp", action="store_true", help="skip DTW time-warping")
    syn.add_argument("--no-blend", action="store_true",
                     help="skip blending at jumps (with --k-best: cut each phone's mean at "
                     "its boundaries instead of cross-fading it into its neighbours' "
                     "through the recorded transitions)")
    syn.add_argument("--helper", choices=HELPER_CHOICES, default=None,
                     help="the paper's search, with a helper pair's motion blended in at a "
                     "jump as recorded ('paper', §4.3, the default), moved onto the animes' "
                     "poses at the blend's ends ('anchored'), or that but for the speech "
                     "components ('anchored-nonspeech')")
    syn.add_argument("--no-smooth", action="store_true", help="skip low-pass smoothing")
    _phones_engine_option(syn, "a --text")
    _synth_beyond_paper_options(syn)
    syn.set_defaults(func=cmd_synth)


def _synth_beyond_paper_options(syn: argparse.ArgumentParser) -> None:
    """``synth``'s options beyond the paper: k-best, its ranking and recentring, the
    audio cost, the candidates and the guiding baseline."""
    syn.add_argument("--k-best", type=_whole_number, default=None, metavar="K",
                     help="beyond the paper: average the K best-matching animes of each "
                     "phone (default 20, which suits real data; --exact, --window or "
                     "--search alone: the paper's one anime a phone)")
    syn.add_argument("--shortlist", type=_shortlist, default=None, metavar="N|all",
                     help="beyond the paper: k-best's search and ranking see each phone's "
                     "first N candidates by the ranking's own order (default 100, so that "
                     "the time does not grow with the database; never fewer than K); all: "
                     "every candidate")
    syn.add_argument("--recentre", action=argparse.BooleanOptionalAction, default=None,
                     help="beyond the paper: k-best averages each anime relative to its "
                     "recording's mean pose, the utterance taking the mean pose of the "
                     "recordings drawn on (default: on when the database's clips come from "
                     "more than one speaker or corpus folder, whose rest poses differ; off "
                     "with one)")
    syn.add_argument("--context-ranking", action=argparse.BooleanOptionalAction, default=None,
                     help="beyond the paper: rank each phone's k-best animes by phonetic "
                     "context (their recorded neighbour phones against the input's) before "
                     "the audio cost (default: on with a transcript or labels, off without)")
    syn.add_argument("--audio-cost", choices=SYNTH_AUDIO_COSTS, default=None,
                     help="the audio cost of Eq. 5: plp (the paper's RASTA-PLP DTW, "
                     "default), or beyond the paper posteriorgram (DTW of hama phone "
                     "posteriors: a database ingested with --posteriorgrams, or whose "
                     "phones hama recognised) or both")
    syn.add_argument("--candidates", choices=("label", "likely"), default=None,
                     help="candidate animes of a phone: label (the paper: its own phone's, "
                     "default), or likely (beyond the paper: also those of the 3 phones its "
                     "posteriorgram makes likeliest)")
    syn.add_argument("--guide", choices=(*SYNTH_GUIDES, "none"), default=None,
                     help="beyond the paper: a baseline fitted on the database (on first use, "
                     "then stored) predicts the motion, and the output is the mean of it and "
                     "the animes' (default with audio only: mu-mlp+ppg-ridge, the mean of the "
                     "two; none: off)")
    syn.add_argument("--guide-blend", type=_number, default=None, metavar="W",
                     help="the guide's share of the output motion, in [0, 1] (default 0.5; "
                     "0 with --guide-rank: ranking only)")
    syn.add_argument("--guide-rank", action="store_true",
                     help="also rank each phone's animes by their distance to the guide's "
                     "motion beside the audio cost (trajectory-guided selection; it helped "
                     "within one speaker, not across speakers: off by default)")


def _add_batch(sub) -> None:
    """``batch``: every line of a dialogue script."""
    bat = sub.add_parser(
        "batch", help="animate every line of a dialogue script, in parallel (Dask)",
        description="Animate a dialogue script (CSV or JSON Lines: id, text, and optional "
        "audio, emotion, speaker, voice, window, exact). Lines without a recording are spoken "
        "by eSpeak NG with their emotion's prosody, phone timing from the synthesizer; lines "
        "with one are force-aligned to their text. Each line gets OUT/<id>/ (speech.wav, "
        "motion, phones.csv, explain.json[, preview.mp4]); OUT/report.csv lists them all. "
        "A re-run makes only the lines whose inputs changed (all with --force); a changed "
        "--render renders the stored motion, without synthesizing it again.",
    )
    bat.add_argument("script", type=Path, metavar="SCRIPT", help="dialogue script (.csv, .jsonl)")
    _db_option(bat)
    bat.add_argument("-o", "--out", required=True, type=_output_folder, help="output folder")
    bat.add_argument("--workers", type=_whole_number, default=2,
                     help="worker processes of the local Dask cluster (default 2; "
                     "ignored with --scheduler)")
    bat.add_argument("--scheduler", default=None, metavar="ADDRESS",
                     help="run on an existing Dask cluster, e.g. tcp://host:8786")
    bat.add_argument("--render", choices=("none", "mp4"), default="none",
                     help="also render an MP4 preview of each line (default none)")
    bat.add_argument("--motion-format", type=_formats, default=(), metavar="FORMATS",
                     help="motion files to write, comma-separated: c3d, csv, npz, livelink "
                     "(Live Link Face CSV), as synth -o writes them; default the "
                     "database's own (C3D of markers, CSV of landmarks with their head "
                     "pose, Live Link CSV of ARKit blendshapes)")
    bat.add_argument("--force", action="store_true", help="redo lines finished before")
    bat.add_argument("--quiet", action="store_true", help="no progress bar")
    bat.set_defaults(func=cmd_batch)


def _add_query(sub) -> None:
    """``query``: anime nodes or clips, exported for other tools."""
    from animegraph.apps.query_fields import ANIME_FIELDS, CLIP_FIELDS
    from animegraph.motion.suffixes import EXPORT_FORMATS

    qry = sub.add_parser(
        "query", help="find anime nodes or clips; export them for other tools",
        description="List the anime nodes (phoneme instances) or, with --clips, the "
        "utterances that match, as a table. The query is SQL over the database's views "
        "(--show-sql prints it; 'animegraph sql' runs it as it is). --export writes each hit "
        f"as motion ({'; '.join(f'{suffix}: {what}' for suffix, what in EXPORT_FORMATS.items())})"
        " with context, its speech (WAV), its phones (.phones.csv), a PNG preview, and "
        "index.csv.",
    )
    _db_option(qry)
    qry.add_argument("--phoneme", default=None, help="ARPAbet phone, e.g. AA")
    qry.add_argument("--emotion", default=None, help="emotion label, e.g. angry")
    qry.add_argument("--text", default=None, metavar="WORDS",
                     help="the utterance's transcript contains every one of these words")
    qry.add_argument("--speaker", default=None,
                     help="speaker, as in the clips table (any case) or a part of it")
    qry.add_argument("--min-dur", type=_number, default=None, metavar="SEC",
                     help="at least this long (the anime, or the clip with --clips)")
    qry.add_argument("--order-by", default=None, metavar="FIELD",
                     help=f"animes: {', '.join(ANIME_FIELDS)} (default node_id); clips: "
                     f"{', '.join(CLIP_FIELDS)} (default clip_id)")
    qry.add_argument("--desc", action="store_true", help="descending order")
    qry.add_argument("--limit", type=_whole_number, default=20, help="most hits (default 20)")
    qry.add_argument("--clips", action="store_true", help="whole utterances, not animes")
    qry.add_argument("--format", choices=("table", "csv", "json", "jsonl"), default="table",
                     help="json: one array of hit objects; jsonl: JSON Lines, an object a "
                     "line (default table)")
    qry.add_argument("--show-sql", action="store_true",
                     help="print the SQL instead of running it")
    qry.add_argument("--export", type=_output_folder, default=None, metavar="DIR",
                     help="write every hit into this new folder")
    qry.add_argument("--context", type=_number, default=0.25, metavar="SEC",
                     help="seconds of motion and speech kept around each anime (0.25)")
    qry.add_argument("--force", action="store_true", help="replace an existing --export folder")
    qry.add_argument("--quiet", action="store_true", help="no progress bar (--export)")
    qry.set_defaults(func=cmd_query)


def _add_render(sub) -> None:
    """``render``: motion onto a face mesh (video, glTF, OBJ frames)."""
    ren = sub.add_parser(
        "render", help="render motion: MP4/GIF of a shaded face, glTF, OBJ frames",
        description="Carry marker or landmark motion onto a face mesh by RBF scattered-data "
        "interpolation with independent face regions (Cao et al. 2005, section 7) and write "
        "an MP4 (speech muxed in with --audio), a GIF, a PNG still, a glTF 2.0 binary (.glb, "
        "morph targets + head motion) or a folder of OBJ frames (-o without extension). "
        "Curve motion (blendshape weights) is drawn as curves over time with the phones.",
    )
    ren.add_argument("motion", type=Path, metavar="MOTION", help="motion: .c3d, .csv or .npz")
    ren.add_argument("-o", "--output", required=True, type=_output_file_or_folder,
                     help=".mp4, .gif, .png, .glb, or a folder name for OBJ frames")
    ren.add_argument("--audio", type=Path, default=None,
                     help="speech to mux into an MP4 (a WAV, or a video: its audio track)")
    ren.add_argument("--beside", type=Path, default=None, metavar="VIDEO",
                     help="put this video (the actor) left of the face in the MP4")
    ren.add_argument("--db", type=Path, default=None,
                     help="database the motion came from (checks its channels match)")
    ren.add_argument("--mesh", type=Path, default=None,
                     help="another face mesh (any format trimesh reads; mm, x left, y up)")
    ren.add_argument("--marker-map", type=Path, default=None,
                     help="CSV label,vertex[,region][,group]: where each marker sits")
    ren.add_argument("--rest-frame", type=_whole_number, default=None,
                     help="frame of the motion that matches the mesh's expression (default: "
                     "the mesh's own marker vertices for the canonical mesh, frame 0 for "
                     "another mesh)")
    ren.add_argument("--labels", type=Path, default=None,
                     help="phone labels for captions (.phones.csv, .TextGrid, .lab; default "
                     "MOTION's <stem>.phones.csv when there is one)")
    ren.add_argument("--explain", type=Path, default=None,
                     help="'synth --explain-json' record, for phone captions")
    ren.add_argument("--fps", type=_number, default=None,
                     help="frame rate (video: 30, GIF: 20; glb/OBJ: the motion's)")
    ren.add_argument("--size", default=None,
                     help="frame size WxH of an MP4, GIF or PNG (default: a face 480x540, "
                     "240x270 in a GIF; curves 960x540, 640x360 in a GIF)")
    ren.add_argument("--force", action="store_true", help="replace an existing OBJ folder")
    ren.add_argument("--quiet", action="store_true", help="no progress bar")
    ren.set_defaults(func=cmd_render)


def _add_plot(sub) -> None:
    """``plot``: motion over the speech and its phones."""
    plo = sub.add_parser(
        "plot", help="plot motion against ground truth, with phones and jump matches",
        description="Plot facial measures (mouth opening, width, brow; or the busiest "
        "curves) of MOTION, against --truth when given, over the speech and the phone "
        "timeline; with --explain (from 'synth --explain-json') the jump matches are "
        "marked and each phone is coloured by its source recording.",
    )
    plo.add_argument("motion", type=Path, metavar="MOTION", help="motion: .c3d, .csv or .npz")
    plo.add_argument("-o", "--output", required=True, type=_output_file, help="PNG file")
    plo.add_argument("--truth", type=Path, default=None, help="ground-truth motion")
    plo.add_argument("--explain", type=Path, default=None, help="'synth --explain-json' file")
    plo.add_argument("--labels", type=Path, default=None,
                     help="phone labels instead (default MOTION's <stem>.phones.csv if any)")
    plo.add_argument("--audio", type=Path, default=None,
                     help="the speech (a WAV, or a video: its audio track)")
    plo.add_argument("--title", default="", help="title")
    plo.set_defaults(func=cmd_plot)


def _add_fit(sub) -> None:
    """``fit``: a baseline fitted and stored with a database."""
    fit = sub.add_parser(
        "fit", help="fit a baseline method on a database and store it there",
        description="Fit a baseline (mu-mlp: Hong et al. 2002; hier-pca: Cosker et al.; "
        "av-hmm: Terissi et al. 2013) on every clip of a database and store the "
        "trained model as arrays in DB/baselines/<version>/<method>.parquet; 'synth "
        "--method' uses it (and fits it on first use if absent).",
    )
    _db_option(fit)
    fit.add_argument("--method", required=True, choices=METHODS[1:], help="baseline method")
    fit.set_defaults(func=cmd_fit)


def _add_live(sub) -> None:
    """``live``: speech in as it is spoken, motion out in real time."""
    live = sub.add_parser(
        "live", help="facial motion in real time for speech as it is spoken",
        description="Hear speech as it arrives (a file at its pace, raw PCM on stdin, the "
        "microphone) and send the face frame by frame: hama's phone posteriors computed once "
        "per 20 ms frame, the synthesis' audio-only default re-run on a short sliding "
        "window, each frame sent once the look-ahead after it is heard.")
    _db_option(live)
    live.add_argument("--source", required=True, metavar="FILE|-|ws:PORT|mic",
                      help="a WAV or video played at real-time pace; - for raw 16-bit "
                      "little-endian mono PCM on stdin (with --rate); ws:PORT to take that "
                      "PCM as binary messages from a WebSocket client at ws://HOST:PORT/ "
                      "(with --rate; the stream ends when it closes); mic for the microphone "
                      "(pip install 'animegraph[live]' and the PortAudio library, "
                      "libportaudio2)")
    live.add_argument("--rate", type=_whole_number, default=None, metavar="HZ",
                      help="sample rate of --source - and ws:PORT (and of mic; default "
                      "16000)")
    live.add_argument("--fast", action="store_true",
                      help="play a file as fast as it is synthesized, not at its pace")
    live.add_argument("--lookahead", type=_number, default=None, metavar="MS",
                      help="audio heard after a frame before it is sent (120 ms; 40 with "
                      "--low-latency)")
    live.add_argument("--hop", type=_number, default=None, metavar="MS",
                      help="audio between two updates (80 ms; 40 with --low-latency)")
    live.add_argument("--low-latency", action="store_true",
                      help="frames sooner, following the offline output less closely: "
                      "look-ahead 40 ms, an update every 40 ms, hama hearing 300 ms of "
                      "context and settling a frame 80 ms after it (docs/results/live.md)")
    live.add_argument("--threads", type=_thread_cap, default=1, metavar="N",
                      help="threads an update may run at once (the DTW's, BLAS's; 1: the "
                      "stream within one core, docs/results/live.md; 0: no cap)")
    live.add_argument("--emotion", default=None, metavar="E|auto|E=W,...",
                      help="the face's emotion: a name, auto, or a mix")
    live.add_argument("--text", default=None, metavar="TRANSCRIPT",
                      help="what the speech says (a text-to-speech voice knows it): its "
                      "phones are aligned to the speech as it arrives instead of "
                      "recognised; a transcript that does not fit is said and dropped")
    live.add_argument("--guide", choices=("default", "none"), default="default",
                      help="the audio-only default's guide (mu-mlp and ppg-ridge), or none")
    live.add_argument("--guide-share", type=_number, default=None, metavar="S",
                      help="the guide's share of each window's motion, 0-1 (1: the guide "
                      "alone); by default 0.65 (chosen on a calibration split of one "
                      "speaker) for a database of one recording session, offline's 0.5 for "
                      "several (docs/results/live.md, \"The guide's share, live\")")
    live.add_argument("--phones-engine", choices=("hama", "auto"), default=None,
                      help="how each window's phones are recognised: auto (the default; hama "
                      "with --low-latency), as offline's default engine: hama names them and "
                      "PocketSphinx places them; or hama naming and placing them "
                      "(docs/results/live.md, \"Placing the phones\")")
    live.add_argument("--livelink", default=None, metavar="HOST:PORT",
                      help="send Live Link Face packets over UDP (Unreal listens on 11111); "
                      "ARKit databases")
    live.add_argument("--subject", default="animegraph", help="the Live Link subject name")
    live.add_argument("--websocket", type=_whole_number, default=None, metavar="PORT",
                      help="serve JSON frames at ws://HOST:PORT/ (0: a free port)")
    live.add_argument("--host", default="127.0.0.1",
                      help="address the WebSocket servers listen on (127.0.0.1)")
    live.add_argument("--record", type=Path, default=None, metavar="DIR",
                      help="keep what was sent in DIR: take.livelink.csv (or the database's "
                      "motion format) and take.wav")
    live.set_defaults(func=cmd_live)


def _add_warmup(sub) -> None:
    """``warmup``: a database ready for its first synth."""
    warm = sub.add_parser(
        "warmup", help="make a database ready for its first synth (ingest does this)",
        description="Fit and store the default guides of audio-only synth (mu-mlp and "
        "ppg-ridge) if the database lacks them, and compile the search kernels once for "
        "this installation (numba caches them on disk), saying each step and its time; "
        "nothing to do takes no time. 'animegraph ingest' does this after writing.",
    )
    _db_option(warm)
    warm.set_defaults(func=cmd_warmup)


def _add_info(sub) -> None:
    """``info``: what a database holds."""
    info = sub.add_parser(
        "info", help="summarise a database",
        description="Say which database is used (--db, $ANIMEGRAPH_DB or the demo's) and "
        "summarise it: clips, emotions, phones, motion components, emotion model and "
        "fitted baselines.",
    )
    _db_option(info)
    info.add_argument("--json", action="store_true", help="the summary as JSON")
    info.set_defaults(func=cmd_info)


def _add_studio(sub) -> None:
    """``studio``: the local web app over a database."""
    studio = sub.add_parser(
        "studio", help="browse a database in the browser: clips on a 3D face, SQL, synthesis",
        description="Start a local web app on the database: an overview (what 'info' "
        "shows, with plots), the clips ('query' filters) playing on a 3D face with their "
        "speech (two side by side), a SQL console (the 'sql' sandbox), synthesis of an "
        "uploaded recording beside its nearest recorded clip, and the face driven by "
        "'animegraph live --websocket'. "
        "It listens on 127.0.0.1 only and prints its URL, which carries a random token "
        "every request needs; Ctrl-C stops it.",
    )
    _db_option(studio)
    studio.add_argument("--port", type=_whole_number, default=8765,
                        help="port to listen on (default 8765; 0: any free port)")
    studio.add_argument("--no-browser", action="store_true",
                        help="do not open a browser (default: open one; $BROWSER chooses "
                        "it, as Python's webbrowser does)")
    studio.set_defaults(func=cmd_studio)
