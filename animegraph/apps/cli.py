"""The ``animegraph`` command-line tool.

Every user error (a bad option, a missing file, an impossible size) ends as one line
on stderr and a non-zero exit; tracebacks are kept for bugs.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import signal
import sys
import threading
from collections.abc import Sequence
from pathlib import Path

from animegraph import __version__
from animegraph.baselines import METHODS
from db.errors import AnimeGraphError
from ingest.speech.engines import ENGINES

#: ``synth --helper``: animegraph.synthesis.HELPER_MODES, written out so that ``--help`` does
#: not import the synthesis (tests/test_synth.py checks that they are the same).
HELPER_CHOICES = ("paper", "anchored", "anchored-nonspeech")
#: What a speech argument accepts: anything libsndfile (through soundfile) decodes.
SPEECH_FORMATS = ("speech: WAV, FLAC, OGG/Vorbis or MP3 (anything libsndfile reads), or a "
                  "video's sound track (.mp4, .mov, .mkv ...), any sample rate, channels "
                  "averaged to mono")


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



def _phones_engine_option(parser, transcript: str) -> None:
    """``--phones-engine`` of ``ingest`` and ``synth`` (``transcript``: what they call one)."""
    parser.add_argument("--phones-engine", choices=ENGINES, default=None,
                        help=f"phone engine when there are no labels: auto (default: "
                        f"PocketSphinx aligns {transcript}; without one hama names the "
                        "phones and PocketSphinx places them: each measured best at it), "
                        "hama (CTC phone model shipped in "
                        "its wheel) or pocketsphinx")

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
                     help="keep landmark and iPhone (Live Link) motion where it is "
                     "instead of shifting it by the estimated lip-audio lag")
    ing.add_argument("--posteriorgrams", action="store_true",
                     help="also store each clip's phone posteriorgram (hama), for synth "
                     "--audio-cost posteriorgram (beyond the paper; kept once stored; "
                     "always kept for clips whose phones hama recognised)")
    _phones_engine_option(ing, "a transcript")
    ing.add_argument("--max-speed", type=_number, default=None, metavar="MM_S",
                     help="fastest plausible marker motion in mm/s (default 5000); a faster "
                     "jump is a dropout, or rejects the clip if it lasts")
    ing.add_argument("--wait", type=_number, default=None,
                     help="seconds to wait for another ingest into the same --db to finish "
                     "(default 600); one writer at a time")
    ing.add_argument("--quiet", action="store_true", help="no progress bar")
    ing.set_defaults(func=_cmd_ingest)

    sql = sub.add_parser(
        "sql", help="run a read-only SQL query on a database",
        description="Run SQL (DuckDB) over the database's tables: clips, animes, frames, "
        "audio, channels, model_arrays, components. Only SELECT queries run, in DuckDB's "
        "sandbox (no file outside the database, no network, no extensions); several "
        "statements separated by ';' each print their result.",
    )
    sql.add_argument("query", help="the SQL, e.g. \"SELECT phoneme, count(*) FROM animes "
                     "GROUP BY 1\"")
    _db_option(sql)
    sql.add_argument("--format", choices=("table", "csv", "json", "parquet"), default="table")
    sql.add_argument("-o", "--output", type=Path, default=None,
                     help="write here instead of standard output (required for parquet)")
    sql.add_argument("--max-rows", type=_whole_number, default=50,
                     help="rows shown in table format (default 50)")
    sql.add_argument("--limit", type=_whole_number, default=None,
                     help="rows fetched per statement; the rest is never read "
                     "(default 100000)")
    sql.add_argument("--timeout", type=_number, default=None,
                     help="seconds before the query is interrupted (default 60)")
    sql.set_defaults(func=_cmd_sql)

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
                      help="the global optimum (default)")
    mode.add_argument("--window", type=_whole_number, default=None, metavar="K",
                      help="the paper's bounded look-ahead of K phonemes (K >= 1; the "
                      "paper uses 3-6)")
    mode.add_argument("--search", choices=("exact", "paper", "window", "dp"), default=None,
                      help="Anime Graph search algorithm (paper: the published priority "
                      "queue)")
    syn.add_argument("--tolerance", type=_number, default=None, metavar="T",
                     help="exact search only: accept a sequence certified within (1 + T) of "
                     "the optimum's cost, e.g. 0.01 (much faster on huge databases)")
    syn.add_argument("-o", "--output", required=True, type=Path,
                     help="motion file: .c3d (marker databases), .csv or .npz; "
                     "NAME.livelink.csv writes Live Link Face CSV (ARKit databases)")
    syn.add_argument("--timecode", default=None, metavar="HH:MM:SS:FF",
                     help="first frame's timecode in a .livelink.csv (default 00:00:00:00)")
    syn.add_argument("--explain", action="store_true",
                     help="print where every phone's motion came from and its costs")
    syn.add_argument("--explain-json", type=Path, default=None,
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
    syn.add_argument("--k-best", type=_whole_number, default=None, metavar="K",
                     help="beyond the paper: average the K best-matching animes of each "
                     "phone (20 suits real data with recognized phones)")
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
                     "posteriors; the database must have been ingested with hama) or both")
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
                     "motion beside the audio cost (trajectory-guided selection)")
    syn.set_defaults(func=_cmd_synth)

    bat = sub.add_parser(
        "batch", help="animate every line of a dialogue script, in parallel (Dask)",
        description="Animate a dialogue script (CSV or JSON Lines: id, text, and optional "
        "audio, emotion, speaker, voice, window, exact). Lines without a recording are spoken "
        "by eSpeak NG with their emotion's prosody, phone timing from the synthesizer; lines "
        "with one are force-aligned to their text. Each line gets OUT/<id>/ (speech.wav, "
        "motion, phones.csv, explain.json[, preview.mp4]); OUT/report.csv lists them all. "
        "Finished lines are skipped on a re-run unless --force.",
    )
    bat.add_argument("script", type=Path, metavar="SCRIPT", help="dialogue script (.csv, .jsonl)")
    _db_option(bat)
    bat.add_argument("--out", required=True, type=Path, help="output folder")
    bat.add_argument("--workers", type=_whole_number, default=2,
                     help="worker processes of the local Dask cluster (default 2; "
                     "ignored with --scheduler)")
    bat.add_argument("--scheduler", default=None, metavar="ADDRESS",
                     help="run on an existing Dask cluster, e.g. tcp://host:8786")
    bat.add_argument("--render", choices=("none", "mp4"), default="none",
                     help="also render an MP4 preview of each line (default none)")
    bat.add_argument("--force", action="store_true", help="redo lines finished before")
    bat.add_argument("--quiet", action="store_true", help="no progress bar")
    bat.set_defaults(func=_cmd_batch)
    _add_animator_commands(sub)
    cls = sub.add_parser(
        "classify", help="the emotion of speech, by the database's classifier",
        description="Print the probability of each of the database's emotions for the "
        "speech (any rate, mono or stereo), by the classifier trained on the database's "
        "clips at ingest: prosodic and spectral features with 50 frame-averaged cepstrum "
        "coefficients, normalised per speaker (an unknown speaker by the training "
        "population), and a linear SVM (Cao et al. 2005 §6 uses an SVM on the signal's "
        "mean, variance, RMS and first 500 real-cepstrum coefficients).",
    )
    cls.add_argument("audio", type=Path, metavar="AUDIO", help=SPEECH_FORMATS)
    _db_option(cls)
    cls.add_argument("--json", action="store_true", help="the probabilities as JSON")
    cls.set_defaults(func=_cmd_classify)

    mp = sub.add_parser(
        "map-emotion", help="change the emotion of a facial motion",
        description="Map the emotion components of a motion (as written by 'synth': .c3d, "
        ".csv or .npz, in the database's channels) from one emotion to another with the "
        "database's RBF mapping (Cao et al. 2005 §5.2); speech components are kept.",
    )
    mp.add_argument("motion", type=Path, metavar="IN", help="motion file (.c3d, .csv, .npz)")
    _db_option(mp)
    mp.add_argument("--to", required=True, metavar="E|E=W,...",
                    help="target emotion, or a mix such as happy=0.7,neutral=0.3")
    mp.add_argument("--from", dest="source", default="auto", metavar="E|auto",
                    help="emotion of IN; 'auto' (default): classify --audio if given, else "
                    "the emotion whose mean emotion components are nearest IN's")
    mp.add_argument("--audio", type=Path, default=None,
                    help="the speech of IN, for --from auto")
    mp.add_argument("-o", "--output", required=True, type=Path,
                    help="motion file to write (.c3d, .csv or .npz)")
    mp.set_defaults(func=_cmd_map_emotion)
    fit = sub.add_parser(
        "fit", help="fit a baseline method on a database and store it there",
        description="Fit a baseline (mu-mlp: Hong et al. 2002; hier-pca: Cosker et al.; "
        "av-hmm: Terissi et al. 2013) on every clip of a database and store the "
        "trained model as arrays in DB/baselines/<version>/<method>.parquet; 'synth "
        "--method' uses it (and fits it on first use if absent).",
    )
    _db_option(fit)
    fit.add_argument("--method", required=True, choices=METHODS[1:], help="baseline method")
    fit.set_defaults(func=_cmd_fit)

    info = sub.add_parser(
        "info", help="summarise a database",
        description="Say which database is used (--db, $ANIMEGRAPH_DB or the demo's) and "
        "summarise it: clips, emotions, phones, motion components, emotion model and "
        "fitted baselines.",
    )
    _db_option(info)
    info.add_argument("--json", action="store_true", help="the summary as JSON")
    info.set_defaults(func=_cmd_info)
    return parser


def _db_option(parser: argparse.ArgumentParser) -> None:
    """``--db``, which may be left out: ``$ANIMEGRAPH_DB``, else the demo's database."""
    from animegraph.apps.cache import DB_ENV, default_db_dir

    parser.add_argument("--db", type=Path, default=None,
                        help=f"database folder (default: ${DB_ENV} if set, else the one "
                        f"'animegraph demo' builds, {default_db_dir()})")
    parser.set_defaults(default_db=True)


def _resolve_db(args: argparse.Namespace) -> None:
    """Fill in a left-out ``--db``; say how to make one if it does not exist yet."""
    from animegraph.apps.cache import default_database
    from db.errors import DataError
    from db.store import is_database

    args.db_source = "--db"
    if args.db is not None:
        return
    args.db, args.db_source = default_database()
    if not is_database(args.db):
        how = ("run 'animegraph demo' to build it" if args.db_source.startswith("the demo")
               else f"run 'animegraph ingest SRC --db {args.db}' to build it")
        raise DataError(f"no --db given, and {args.db_source} ({args.db}) does not exist "
                        f"yet: {how}, or give --db DB")


def _add_animator_commands(sub) -> None:
    """``query``, ``render`` and ``plot``: the animator's commands."""
    from animegraph.apps.query_fields import ANIME_FIELDS, CLIP_FIELDS

    qry = sub.add_parser(
        "query", help="find anime nodes or clips; export them for other tools",
        description="List the anime nodes (phoneme instances) or, with --clips, the "
        "utterances that match, as a table. The query is SQL over the database's views "
        "(--show-sql prints it; 'animegraph sql' runs it as it is). --export writes each hit "
        "as motion (C3D for marker databases, CSV otherwise) with context, its speech "
        "(WAV), a PNG preview, and index.csv.",
    )
    _db_option(qry)
    qry.add_argument("--phoneme", default=None, help="ARPAbet phone, e.g. AA")
    qry.add_argument("--emotion", default=None, help="emotion label, e.g. angry")
    qry.add_argument("--text", default=None, metavar="WORDS",
                     help="the utterance's transcript contains every one of these words")
    qry.add_argument("--speaker", default=None, help="speaker id")
    qry.add_argument("--min-dur", type=_number, default=None, metavar="SEC",
                     help="at least this long (the anime, or the clip with --clips)")
    qry.add_argument("--order-by", default=None, metavar="FIELD",
                     help=f"animes: {', '.join(ANIME_FIELDS)} (default node_id); clips: "
                     f"{', '.join(CLIP_FIELDS)} (default clip_id)")
    qry.add_argument("--desc", action="store_true", help="descending order")
    qry.add_argument("--limit", type=_whole_number, default=20, help="most hits (default 20)")
    qry.add_argument("--clips", action="store_true", help="whole utterances, not animes")
    qry.add_argument("--format", choices=("table", "csv", "json"), default="table")
    qry.add_argument("--show-sql", action="store_true",
                     help="print the SQL instead of running it")
    qry.add_argument("--export", type=Path, default=None, metavar="DIR",
                     help="write every hit into this new folder")
    qry.add_argument("--context", type=_number, default=0.25, metavar="SEC",
                     help="seconds of motion and speech kept around each anime (0.25)")
    qry.add_argument("--force", action="store_true", help="replace an existing --export folder")
    qry.set_defaults(func=_cmd_query)

    ren = sub.add_parser(
        "render", help="render motion: MP4/GIF of a shaded face, glTF, OBJ frames",
        description="Carry marker or landmark motion onto a face mesh by RBF scattered-data "
        "interpolation with independent face regions (Cao et al. 2005, section 7) and write "
        "an MP4 (speech muxed in with --audio), a GIF, a PNG still, a glTF 2.0 binary (.glb, "
        "morph targets + head motion) or a folder of OBJ frames (-o without extension). "
        "Curve motion (blendshape weights) is drawn as curves over time with the phones.",
    )
    ren.add_argument("motion", type=Path, metavar="MOTION", help="motion: .c3d, .csv or .npz")
    ren.add_argument("-o", "--output", required=True, type=Path,
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
    ren.add_argument("--size", default="480x540", help="video frame size WxH (480x540)")
    ren.add_argument("--force", action="store_true", help="replace an existing OBJ folder")
    ren.add_argument("--quiet", action="store_true", help="no progress bar")
    ren.set_defaults(func=_cmd_render)

    plo = sub.add_parser(
        "plot", help="plot motion against ground truth, with phones and jump matches",
        description="Plot facial measures (mouth opening, width, brow; or the busiest "
        "curves) of MOTION, against --truth when given, over the speech and the phone "
        "timeline; with --explain (from 'synth --explain-json') the jump matches are "
        "marked and each phone is coloured by its source recording.",
    )
    plo.add_argument("motion", type=Path, metavar="MOTION", help="motion: .c3d, .csv or .npz")
    plo.add_argument("-o", "--output", required=True, type=Path, help="PNG file")
    plo.add_argument("--truth", type=Path, default=None, help="ground-truth motion")
    plo.add_argument("--explain", type=Path, default=None, help="'synth --explain-json' file")
    plo.add_argument("--labels", type=Path, default=None,
                     help="phone labels instead (default MOTION's <stem>.phones.csv if any)")
    plo.add_argument("--audio", type=Path, default=None, help="the speech (WAV)")
    plo.add_argument("--title", default="", help="title")
    plo.set_defaults(func=_cmd_plot)


def _cmd_query(args: argparse.Namespace) -> int:
    from animegraph.apps.query import QuerySpec, build_sql, export_hits, run_query
    from animegraph.apps.tabular import format_table
    from db.store import Database

    spec = QuerySpec(phoneme=args.phoneme, emotion=args.emotion, text=args.text,
                     speaker=args.speaker, min_dur=args.min_dur, order_by=args.order_by,
                     descending=args.desc, limit=args.limit, clips=args.clips)
    if args.show_sql:
        print(build_sql(spec))
        return 0
    if args.export is not None and args.export.exists() and not args.force:
        from db.errors import DataError

        raise DataError(f"export folder {args.export} exists (use --force to replace it)")
    db = Database.open(args.db)
    hits = run_query(db, spec)
    shown = hits.drop_columns([c for c in ("corpus",) if c in hits.column_names]) \
        if args.format == "table" else hits
    sys.stdout.write(format_table(shown, args.format, max_rows=max(1, hits.num_rows)))
    if args.export is not None:
        rows = export_hits(db, hits, args.export, context=args.context, force=args.force,
                           progress=lambda total: _progress(total, False, "hit",
                                                            "exporting"))
        print(f"animegraph: exported {len(rows)} hits to {args.export} (index.csv)",
              file=sys.stderr)
    return 0


def _size(text: str) -> tuple[int, int]:
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise UsageError(f"animegraph render: --size must be WxH, e.g. 480x540; got "
                         f"{text!r}") from None
    return width, height


def _phone_track(args: argparse.Namespace) -> list[dict]:
    from animegraph.motion.files import read_phone_track

    if args.explain is not None and args.labels is not None:
        raise UsageError(f"animegraph {args.command}: give --explain or --labels, not both")
    labels = args.labels
    if labels is None and args.explain is None:
        labels = _sidecar_labels(args.motion)  # what 'query --export' writes by each snippet
    return read_phone_track(labels=labels, explain=args.explain)


def _cmd_render(args: argparse.Namespace) -> int:
    import time

    from animegraph.face.render import deformer_for, render_motion
    from animegraph.motion.files import read_motion
    from ingest.formats.livelink import is_arkit

    size = _size(args.size)
    if args.fps is not None and not args.fps > 0:
        raise UsageError(f"animegraph render: --fps must be > 0, got {args.fps}")
    if args.audio is not None and not args.audio.is_file():
        raise UsageError(f"animegraph render: --audio {args.audio} does not exist")
    if args.beside is not None and not args.beside.is_file():
        raise UsageError(f"animegraph render: --beside {args.beside} does not exist")
    for option, given in (("--beside", args.beside), ("--audio", args.audio)):
        if given is not None and args.output.suffix.lower() != ".mp4":
            raise UsageError(f"animegraph render: {option} needs an .mp4 output (a GIF, PNG, "
                             "glTF or OBJ frames carry neither sound nor a second picture)")
    phones = _phone_track(args)
    t0 = time.perf_counter()
    motion = read_motion(args.motion)
    if args.db is not None:
        _check_db_channels(args.db, motion)
    deformer = deformer_for(motion.names, mesh_path=args.mesh, map_path=args.marker_map,
                            rest_frame=_rest(motion, args))
    out = render_motion(motion, args.output, deformer=deformer, audio=args.audio,
                        fps=args.fps, phones=phones, size=size, force=args.force,
                        progress=lambda total: _progress(total, args.quiet, "frame",
                                                              "rendering"),
                        beside=args.beside)
    what = "curves" if deformer is None else f"{deformer.mesh.name}, " \
        f"{deformer.markers.n_markers} markers"
    if deformer is None and is_arkit(motion.names):
        what = "ARKit blendshapes on the canonical face mesh"
    print(f"animegraph: rendered {motion.duration:.2f} s of motion ({what}) in "
          f"{time.perf_counter() - t0:.1f} s: {out}", file=sys.stderr)
    return 0


def _rest(motion, args: argparse.Namespace):
    """Rest-frame marker positions for the deformer, or None for the mesh's own."""
    from animegraph.face.mesh import default_marker_map, load_mesh, motion_points, read_marker_map

    if args.mesh is not None and args.marker_map is None:
        raise UsageError("animegraph render: --mesh needs --marker-map (which marker sits on "
                         "which vertex)")
    index = args.rest_frame
    if index is None and args.mesh is None:
        return None
    index = 0 if index is None else index
    if not 0 <= index < motion.n_frames:
        raise UsageError(f"animegraph render: --rest-frame must be in 0-{motion.n_frames - 1}, "
                         f"got {index}")
    from animegraph.face.mesh import canonical_mesh
    from animegraph.motion.files import point_labels

    mesh = load_mesh(args.mesh) if args.mesh is not None else canonical_mesh()
    markers = (read_marker_map(args.marker_map, mesh) if args.marker_map is not None
               else default_marker_map(point_labels(motion.names)))
    return motion_points(motion.names, motion.values[index:index + 1], markers.labels)[0]


def _check_db_channels(db_path: Path, motion) -> None:
    from db.errors import DataError
    from db.store import Database

    names = set(Database.open(db_path).table("channels").column("name").to_pylist())
    extra = [n for n in motion.names if n not in names]
    if extra:
        raise DataError(f"the motion's channels are not the database's: {len(extra)} of "
                        f"{len(motion.names)} are not in it ({', '.join(extra[:3])} ...)")


def _cmd_plot(args: argparse.Namespace) -> int:
    from animegraph.apps.plots import plot_motion
    from animegraph.motion.files import read_motion
    from ingest.formats.media import read_audio

    if args.output.suffix.lower() != ".png":
        raise UsageError(f"animegraph plot: -o must end in .png, got {args.output.name!r}")
    phones = _phone_track(args)
    motion = read_motion(args.motion)
    truth = read_motion(args.truth) if args.truth is not None else None
    audio = read_audio(args.audio) if args.audio is not None else None
    plot_motion(motion, args.output, truth=truth, phones=phones, audio=audio,
                title=args.title or args.motion.name)
    print(f"animegraph: wrote {args.output}", file=sys.stderr)
    return 0


def _progress(total: int, quiet: bool, unit: str, step: str):
    """A progress bar factory labelled with its step (every step over ~2 s has one)."""
    from functools import partial

    from tqdm import tqdm

    return partial(tqdm, total=total, unit=unit, desc=step, disable=quiet, file=sys.stderr,
                   dynamic_ncols=True)


def _say(line: str) -> None:
    print(f"animegraph: {line}", file=sys.stderr)


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
                              progress=_progress(n, args.quiet, "clip",
                                                  "generating the corpus"),
                              say=None if args.quiet else _say)
    print(f"wrote {summary.n_clips} clips of {summary.n_sentences} sentences, "
          f"{summary.duration_s / 60:.1f} min of speech, to {summary.path}")
    return 0


def _default_parallel(args: argparse.Namespace) -> int:
    if args.parallel is not None:
        return args.parallel
    sentences = 40 if args.sentences is None else args.sentences
    return min(10, sentences)


def _cmd_demo(args: argparse.Namespace) -> int:
    from animegraph.apps.demo import run_demo

    def progress(total: int, step: str = "clips"):
        return _progress(total, args.quiet, "clip", step)

    result = run_demo(args.out, emotion=args.emotion, text=args.text, workers=args.workers,
                      progress=progress, say=print)
    for line in result.report():
        print(line)
    return 0


def _cmd_ingest(args: argparse.Namespace) -> int:
    from ingest.pipeline import IngestConfig, ingest
    from ingest.plausible import Limits

    limits = Limits() if args.max_speed is None else Limits(max_speed_mm_s=args.max_speed)
    config = IngestConfig(variance=args.variance, fps=args.fps,
                          correct_lag=not args.no_lag_correction,
                          phones_engine=args.phones_engine, limits=limits,
                          posteriorgrams=args.posteriorgrams)
    wait = {} if args.wait is None else {"wait": args.wait}
    report = ingest(args.sources, args.db, config, workers=args.workers,
                    progress=lambda total: _progress(total, args.quiet, "clip",
                                                     "ingest: reading clips"),
                    say=None if args.quiet else _say, **wait)
    for line in report.lines():
        print(line)
    return 1 if report.count("rejected") else 0


def _cmd_sql(args: argparse.Namespace) -> int:
    from animegraph.apps.tabular import format_table
    from db.sql import ROW_LIMIT, TIMEOUT_S, run
    from db.store import Database

    if args.format == "parquet" and args.output is None:
        raise UsageError("animegraph sql: --format parquet needs --output FILE")
    limit = args.limit or ROW_LIMIT
    results = run(Database.open(args.db), args.query, row_limit=limit,
                  timeout=args.timeout or TIMEOUT_S)
    if args.output is not None and len(results) > 1:
        raise UsageError(f"animegraph sql: --output takes one statement, got {len(results)}")
    for i, result in enumerate(results):
        if i and args.format == "table":
            sys.stdout.write("\n")
        text = format_table(result.table, args.format, max_rows=args.max_rows,
                            output=args.output)
        if text is not None:
            sys.stdout.write(text)
        if result.truncated:
            print(f"animegraph sql: only the first {limit} rows were read (raise --limit)",
                  file=sys.stderr)
    return 0


def _cmd_synth(args: argparse.Namespace) -> int:
    import time

    import numpy as np

    from animegraph.emotion.control import check_names, parse_emotion, resolve_emotion
    from animegraph.synthesis import (
        Model,
        PostOptions,
        backoffs,
        check_not_silent,
        synthesize,
        write_explain,
        write_motion,
    )
    from animegraph.synthesis.guide import guide_names
    from ingest.formats.media import read_audio
    from ingest.readers.common import read_labels

    if args.output.suffix.lower() not in (".c3d", ".csv", ".npz"):
        raise UsageError(f"animegraph synth: -o must end in .c3d, .csv or .npz, got "
                         f"{args.output.name!r}")
    _check_timecode(args)
    if args.method != "anime-graph":
        return _synth_baseline(args)
    method = args.search or ("window" if args.window is not None else "exact")
    if args.window is not None and args.window < 1:
        raise UsageError(f"animegraph synth: --window must be at least 1, got {args.window}")
    if method == "window" and args.window is None:
        raise UsageError("animegraph synth: --search window needs --window K")
    if args.tolerance is not None:
        if not 0.0 <= args.tolerance < 1.0:
            raise UsageError(f"animegraph synth: --tolerance must be a number in [0, 1), got "
                             f"{args.tolerance}")
        if method != "exact":
            raise UsageError(f"animegraph synth: --tolerance is only used by method='exact' "
                             f"(the exact search), not {method}")
    if args.k_best is not None and args.k_best < 1:
        raise UsageError(f"animegraph synth: --k-best must be at least 1, got {args.k_best}")
    sidecar = _sidecar_labels(args.audio) if args.labels is None and args.text is None else None
    args.labels = sidecar or args.labels
    k_best, path = _synth_path(args)
    if args.context_ranking is not None and not k_best:
        raise UsageError("animegraph synth: --context-ranking ranks the animes k-best "
                         "averages; the paper's search (--exact, --window, --search) takes "
                         "one anime a phone")
    if args.helper is not None and k_best:
        raise UsageError("animegraph synth: --helper blends the paper's search (one anime a "
                         "phone) at its jumps; --k-best averages animes instead: give one")
    if args.recentre is not None and not k_best:
        raise UsageError("animegraph synth: --recentre changes how k-best averages "
                         "animes; the paper's search (--exact, --window, --search) takes one "
                         "anime a phone")
    audio_cost = args.audio_cost or "plp"
    path, guide_name, guide_blend, guide_rank = _synth_plan(args, path)
    t0 = time.perf_counter()
    model = Model.load(args.db)
    _check_livelink_channels(args, model.names)
    emotion = parse_emotion(args.emotion_mix if args.emotion_mix is not None else args.emotion)
    if args.emotion_mix is not None and not isinstance(emotion, dict) and "=" not in \
            args.emotion_mix:
        raise UsageError("animegraph synth: --emotion-mix takes name=weight pairs, e.g. "
                         "happy=0.7,neutral=0.3")
    emotion = check_names(emotion, model.emotion_model, model.graph.emotions)
    audio, sample_rate = read_audio(args.audio)  # a WAV, or a video's sound track
    # Silence is the error, not a transcript that does not fit it: checked first.
    check_not_silent(audio)
    t_check = time.perf_counter()
    mismatch = (_transcript_mismatch(args, audio, sample_rate) if args.text is not None
                else None)
    if mismatch is not None:
        args.text = None  # speech alone: its default path and guide, as said
        k_best, path = _synth_path(args)
        path, guide_name, guide_blend, guide_rank = _synth_plan(args, path)
    t0 += time.perf_counter() - t_check  # hearing the speech is not loading the database
    if sidecar is not None:
        print(f"animegraph: using the phone labels beside the speech, {sidecar} "
              "(--labels or --text to use others)", file=sys.stderr)
    labels = read_labels(args.labels) if args.labels else None
    # Classify ("auto") before any progress line, so that a failure is one line.
    choice = resolve_emotion(emotion, model.emotion_model, model.graph.emotions,
                             audio if np.ndim(audio) == 1 else np.mean(audio, axis=1),
                             sample_rate)
    t_guide = time.perf_counter()
    guide = _load_guide(args.db, guide_name, asked=args.guide is not None)
    t0 += time.perf_counter() - t_guide  # a first use's fit is not loading the database
    path += _guide_shortfall(guide_name, guide_names(guide))
    print(f"animegraph: loaded {model.graph.n_nodes} animes in "
          f"{time.perf_counter() - t0:.2f} s; synthesizing {len(audio) / sample_rate:.1f} s "
          f"of speech ...", file=sys.stderr)
    options = PostOptions(time_warp=not args.no_time_warp, blend=not args.no_blend,
                          smooth=not args.no_smooth, helper=args.helper or PostOptions.helper,
                          recentre=args.recentre)
    if choice.probabilities is not None:
        probs = ", ".join(f"{k} {v:.2f}" for k, v in choice.probabilities.items())
        print(f"animegraph: emotion auto: the speech sounds {choice.target} ({probs})",
              file=sys.stderr)
    from animegraph.search.kernels import compile_notice

    notice = compile_notice(method)
    if notice:
        print(f"animegraph: {notice}", file=sys.stderr)
    out = synthesize(model, audio, sample_rate, text=args.text, labels=labels,
                     emotion=choice.target, method=method, window=args.window,
                     tolerance=args.tolerance or 0.0, options=options, k_best=k_best,
                     phones_engine=args.phones_engine, audio_cost=audio_cost,
                     candidates_from=args.candidates or "label", guide=guide,
                     guide_blend=guide_blend, guide_rank=guide_rank,
                     context=args.context_ranking, recognized_guide=_recognized_guide(args))
    from animegraph.synthesis.path import CONTEXT_PHRASE

    if mismatch is not None:
        # Said only now that phones were found: on music or noise the one line is
        # synthesize's "no speech found", not a transcript nothing could have matched.
        print(f"animegraph: warning: {mismatch}: synthesizing from the speech alone",
              file=sys.stderr)
    if args.text is not None and out.segmentation == "recognized":
        # The check passed, the alignment failed: what ran is the speech-alone path.
        alone = argparse.Namespace(**{**vars(args), "text": None})
        path, name, _, _ = _synth_plan(alone, _synth_path(alone)[1])
        path += _guide_shortfall(name, out.guided)
        path += " (transcript alignment failed: synthesized from the speech alone)"
    if out.context_ranked and CONTEXT_PHRASE not in path:
        path += f"; k-best{CONTEXT_PHRASE}"
    elif not out.context_ranked:  # e.g. a transcript that failed to align: recognised
        path = path.replace(CONTEXT_PHRASE, "")
    if out.recentred:
        why = "as asked" if args.recentre else f"{len(model.sessions)} speakers or sessions"
        path += f"; each anime relative to its recording's mean pose ({why})"
    print(f"animegraph: path: {path}", file=sys.stderr)
    for warning in out.warnings:
        print(f"animegraph: warning: {warning}", file=sys.stderr)
    write_motion(out, model, args.output, timecode=args.timecode)
    if isinstance(out.emotion.target, dict):
        print(f"animegraph: emotion mix {out.emotion.describe()}: animes preferred from "
              f"{out.emotion.search}, emotion components blended from their mappings",
              file=sys.stderr)
    elif out.emotion.target is not None and out.emotion.search != out.emotion.target:
        print(f"animegraph: the database has no {out.emotion.target} animes: preferred "
              f"{out.emotion.search}, mapped into {out.emotion.target}", file=sys.stderr)
    for note in out.notes:
        print(f"animegraph: {note}", file=sys.stderr)
    r = out.result
    t = out.timings
    print(f"animegraph: {len(out.phones)} phones ({out.segmentation}), {r.n_jumps} jump "
          f"matches, cost {r.cost:.3f} ({r.method}, {r.n_expanded} expansions); "
          f"{t['total_s']:.2f} s = segment {t['segment_s']:.2f} + audio cost "
          f"{t['audio_cost_s']:.2f} + search {t['search_s']:.3f} + post {t['post_s']:.2f}"
          + (f" (k-best {k_best}: each phone the mean of up to {k_best} animes, "
             + ("cross-faded into its neighbours through the recorded transitions"
                if out.cross_faded else "cut at its boundaries") + ")"
             if k_best else "") + f"; wrote {args.output}", file=sys.stderr)
    missing = backoffs(out)
    if missing:
        print(f"animegraph: phones missing from the database, backed off: "
              f"{', '.join(missing)}", file=sys.stderr)
    if args.explain:
        import pyarrow as pa

        from animegraph.apps.tabular import format_table

        print(f"path: {path}")
        for warning in out.warnings:
            print(f"warning: {warning}")
        print(format_table(pa.Table.from_pylist(out.explain), "table",
                           max_rows=len(out.explain)), end="")
    if args.explain_json:
        write_explain(out, args.explain_json)
    return 0


def _check_timecode(args: argparse.Namespace) -> None:
    """``synth --timecode``: only with a ``.livelink.csv`` output, and a real timecode."""
    from animegraph.motion.files import LIVELINK_SUFFIX
    from ingest.formats.livelink import parse_timecode

    livelink = args.output.name.lower().endswith(LIVELINK_SUFFIX)
    if args.timecode is None:
        return
    if not livelink:
        raise UsageError(f"animegraph synth: --timecode needs -o NAME{LIVELINK_SUFFIX} "
                         f"(Live Link Face CSV), got {args.output.name!r}")
    try:
        parse_timecode(args.timecode)
    except ValueError as exc:
        raise UsageError(f"animegraph synth: --timecode: {exc}") from None


def _check_livelink_channels(args: argparse.Namespace, names) -> None:
    """A ``.livelink.csv`` output needs an ARKit database: say so before synthesizing."""
    from animegraph.motion.files import LIVELINK_SUFFIX
    from ingest.formats.livelink import is_arkit

    if args.output.name.lower().endswith(LIVELINK_SUFFIX) and not is_arkit(names):
        raise UsageError(f"animegraph synth: -o {args.output.name}: Live Link Face CSV needs "
                         f"a database of ARKit blendshapes (an iPhone capture); this one has "
                         f"other channels (write .csv or .npz)")


#: Phone-label files looked for beside a speech or motion file, in this order (what
#: 'corpus synth', 'demo', 'query --export' and 'batch' write; the formats ingest reads).
SIDECAR_LABELS = (".phones.csv", ".TextGrid", ".lab")


def _sidecar_labels(path: Path) -> Path | None:
    """``<stem>.phones.csv`` (or ``.TextGrid``, ``.lab``) beside ``path`` (speech for
    ``synth``, motion for ``render`` and ``plot``), if there is one."""
    for suffix in SIDECAR_LABELS:
        beside = path.with_name(path.stem + suffix)
        if beside.is_file():
            return beside
    return None


#: ``synth --audio-cost`` (:data:`animegraph.synthesis.audio.AUDIO_COSTS`, spelled out here
#: so that the command line starts without importing synthesis).
SYNTH_AUDIO_COSTS = ("plp", "posteriorgram", "plp+posteriorgram")


#: ``synth --guide`` (:data:`animegraph.synthesis.guide.GUIDES`, spelled out here too).
SYNTH_GUIDES = ("mu-mlp", "av-hmm", "ppg-ridge", "mu-mlp+ppg-ridge")


def _synth_guide(args: argparse.Namespace) -> tuple[str | None, float, bool]:
    """``synth --guide``, ``--guide-blend`` and ``--guide-rank``: the guiding baseline
    (None: off; by default the audio-only path's,
    :func:`animegraph.synthesis.path.audio_only_guide`), its share of the output motion,
    and whether it ranks the animes too."""
    from animegraph.synthesis.guide import GUIDE_BLEND
    from animegraph.synthesis.path import audio_only_guide

    share = GUIDE_BLEND if args.guide_blend is None else float(args.guide_blend)
    if not 0.0 <= share <= 1.0:
        raise UsageError(f"animegraph synth: --guide-blend must be in [0, 1], got {share:g}")
    _, known, searched = _synth_given(args)
    name = (audio_only_guide(known_phones=known, searched=searched) if args.guide is None
            else None if args.guide == "none" else args.guide)
    if name is None and (args.guide_blend is not None or args.guide_rank):
        flag = "--guide-rank" if args.guide_rank else "--guide-blend"
        raise UsageError(f"animegraph synth: {flag} needs a guide (e.g. --guide mu-mlp; "
                         f"the default one is for audio only without a search option)")
    if name is not None and share == 0 and not args.guide_rank:
        raise UsageError("animegraph synth: --guide-blend 0 leaves the guide nothing to do: "
                         "add --guide-rank, or --guide none")
    return name, share, args.guide_rank


def _load_guide(db, name: str | None, *, asked: bool = True):
    """The guiding baseline stored with the database ``db`` (mu-mlp and ppg-ridge restored
    without scikit-learn), fitted and stored on first use (saying so on stderr), or None;
    for a mean of several (``mu-mlp+ppg-ridge``), the tuple of those that could be had.

    A default guide (not ``asked``) that cannot be fitted or stored is left out with a
    warning line: the path falls back to k-best alone (or the other guides)."""
    if name is None:
        return None
    if "+" in name:
        parts = [_load_guide(db, part, asked=asked) for part in name.split("+")]
        parts = [p for p in parts if p is not None]
        return None if not parts else parts[0] if len(parts) == 1 else tuple(parts)
    from animegraph.baselines.stored import load_forward, model_path, record_unfit, unfit_reason

    model = load_forward(db, name)
    if model is not None:
        return model
    reason = None if asked else unfit_reason(db, name)
    if reason is not None:  # a default guide already failed on this version: not again
        print(f"animegraph: warning: no {name} guide ({reason}; kept from an earlier run, "
              f"--guide {name} to try again); each phone the mean of its best animes alone",
              file=sys.stderr)
        return None
    from animegraph.baselines.base import fitted_model, load_model

    if not model_path(db, name).is_file() or load_model(db, name) is None:
        print(f"animegraph: fitting {name} on {db} to guide the motion (first use; "
              f"stored with the database) ...", file=sys.stderr)
    if asked:
        return fitted_model(db, name)
    try:
        return fitted_model(db, name)
    except (AnimeGraphError, OSError) as exc:
        print(f"animegraph: warning: no {name} guide ({exc}); each phone the mean of its "
              f"best animes alone", file=sys.stderr)
        record_unfit(db, name, str(exc))
        return None


def _guide_shortfall(name: str | None, got: tuple[str, ...]) -> str:
    """What the path line adds when parts of the guide ``name`` could not be had."""
    missing = [part for part in (name or "").split("+") if part and part not in got]
    if not missing:
        return ""
    return f"; but without its {' and '.join(missing)} guide, which could not be fitted"


def _recognized_guide(args: argparse.Namespace):
    """With ``--text`` and no guide: what loads the speech-alone path's guide, for
    ``synthesize`` to call if the transcript cannot be aligned after all (the check
    before it passed, PocketSphinx found no path); else None."""
    from animegraph.synthesis.path import audio_only_guide

    if args.text is None or args.guide is not None:
        return None
    name = audio_only_guide(known_phones=False, searched=_synth_given(args)[2])
    if name is None:
        return None
    return lambda: _load_guide(args.db, name, asked=False)


def _synth_given(args: argparse.Namespace) -> tuple[str, bool, bool]:
    """What ``synth``'s phones come from (for the path line), whether they are known (labels
    or a transcript), and whether the paper's search was asked for."""
    engine = args.phones_engine or "auto"
    if args.labels is not None:
        given = "phone labels given"
    elif args.text is not None:
        given = f"transcript given (aligned by the {engine} phone engine)"
    else:
        how = ("named by hama, placed by PocketSphinx" if engine == "auto"
               else f"recognised by the {engine} phone engine")
        given = f"audio only (phones {how})"
    searched = (args.exact or args.window is not None or args.search is not None
                or args.helper is not None)
    return given, args.labels is not None or args.text is not None, searched


def _synth_plan(args: argparse.Namespace, path: str) -> tuple[str, str | None, float, bool]:
    """The path line completed with the audio cost, candidates and guide, and the guide
    (:func:`_synth_guide`)."""
    from animegraph.synthesis.path import guide_line

    if (args.audio_cost or "plp") != "plp":
        path += f"; audio cost {args.audio_cost} (beyond the paper)"
    if args.candidates == "likely":
        path += "; candidates from the likely phones (beyond the paper)"
    guide_name, guide_blend, guide_rank = _synth_guide(args)
    path += guide_line(guide_name, guide_blend, guide_rank, known_phones=args.labels is not
                       None or args.text is not None, asked=args.guide is not None)
    return path, guide_name, guide_blend, guide_rank


def _transcript_mismatch(args: argparse.Namespace, audio, sample_rate: int) -> str | None:
    """Why ``--text`` is not what the speech says, as far as the phone engine checks
    (:func:`ingest.speech.engines.check_transcript`); None if it is. ``audio`` is mono,
    as :func:`ingest.formats.media.read_audio` gives it."""
    from db.errors import DataError
    from ingest.speech.engines import check_transcript

    try:
        check_transcript(audio, sample_rate, args.text, args.phones_engine)
    except DataError as exc:
        return str(exc)
    return None


def _synth_path(args: argparse.Namespace) -> tuple[int | None, str]:
    """The k-best setting ``synth`` uses, and a line saying which path runs and why."""
    from animegraph.synthesis.path import synthesis_path  # shared with batch

    given, known, searched = _synth_given(args)
    return synthesis_path(given, known_phones=known, k_best=args.k_best, searched=searched,
                          context=args.context_ranking)


def _synth_baseline(args: argparse.Namespace) -> int:
    """``synth --method <baseline>``: motion from the audio alone by a fitted baseline."""
    import time

    import numpy as np

    from animegraph.baselines.base import fitted_model
    from animegraph.emotion.control import AUTO, check_names, parse_emotion
    from animegraph.motion.files import write_channels
    from animegraph.synthesis import to_world
    from db.store import Database
    from ingest.formats.media import read_audio

    search_only = [flag for flag, on in (
        ("--text", args.text is not None), ("--labels", args.labels is not None),
        ("--exact", args.exact), ("--window", args.window is not None),
        ("--search", args.search is not None), ("--explain", args.explain),
        ("--emotion-mix", args.emotion_mix is not None),
        ("--tolerance", args.tolerance is not None),
        ("--explain-json", args.explain_json is not None),
        ("--no-time-warp", args.no_time_warp), ("--no-blend", args.no_blend),
        ("--helper", args.helper is not None),
        ("--no-smooth", args.no_smooth), ("--k-best", args.k_best is not None),
        ("--audio-cost", args.audio_cost is not None),
        ("--candidates", args.candidates is not None), ("--guide", args.guide is not None),
        ("--guide-blend", args.guide_blend is not None), ("--guide-rank", args.guide_rank),
        ("--context-ranking", args.context_ranking is not None),
        ("--recentre", args.recentre is not None)) if on]
    if search_only:
        raise UsageError(f"animegraph synth: {', '.join(search_only)} only "
                         f"appl{'y' if len(search_only) > 1 else 'ies'} to --method "
                         f"anime-graph, not {args.method}")
    emotion = parse_emotion(args.emotion)
    if emotion == AUTO or isinstance(emotion, dict):
        raise UsageError(f"animegraph synth: --emotion {args.emotion} (classified or mixed) "
                         f"only applies to --method anime-graph; name one emotion for "
                         f"{args.method}")
    db = Database.open(args.db)
    _check_livelink_channels(args, db.table("channels").column("name").to_pylist())
    emotion = check_names(emotion, None, db.table("clips", columns=["emotion"])
                          .column("emotion").to_pylist())
    audio, sample_rate = read_audio(args.audio)  # a WAV, or a video's sound track
    t0 = time.perf_counter()
    model = fitted_model(args.db, args.method, refit=args.refit)
    t1 = time.perf_counter()
    motion = model.predict(audio, sample_rate, emotion=emotion)
    t2 = time.perf_counter()
    head = db.arrays().get("head_reference")
    write_channels(to_world(motion, model.groups_, head), model.fps_, model.channels_,
                   model.kind_, args.output, extra={"method": np.array(args.method)},
                   timecode=args.timecode)
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


def _cmd_batch(args: argparse.Namespace) -> int:
    from animegraph.apps.batch import BatchOptions, run_batch

    if args.scheduler is None and args.workers < 1:
        raise UsageError(f"animegraph batch: --workers must be at least 1, got {args.workers}")
    options = BatchOptions(db=args.db, out=args.out, workers=args.workers,
                           scheduler=args.scheduler, render=args.render, force=args.force)

    def say(line: str) -> None:
        if not args.quiet:
            print(f"animegraph: {line}", file=sys.stderr)

    result = run_batch(args.script, options, say=say,
                       progress=lambda total: _progress(total, args.quiet, "line",
                                                      "batch: lines"))
    for line in result.summary():
        print(line)
    return 0 if result.ok else 1


def _cmd_classify(args: argparse.Namespace) -> int:
    import json

    from animegraph.emotion.control import classify_speech
    from db.errors import DataError
    from db.store import Database
    from ingest.emotion.model import EmotionModel
    from ingest.formats.media import read_audio

    db = Database.open(args.db)
    model = EmotionModel.from_database(db)
    audio, sample_rate = read_audio(args.audio)
    if audio.ndim != 1:
        raise DataError(f"{args.audio}: expected mono speech")
    probabilities = classify_speech(model, audio, sample_rate)
    if args.json:
        print(json.dumps(probabilities, indent=1))
    else:
        for name, p in probabilities.items():
            print(f"{name:<12s} {p:6.3f}")
    return 0


def _cmd_map_emotion(args: argparse.Namespace) -> int:
    import time

    from animegraph.emotion.control import check_names, classify_speech, map_motion, parse_emotion
    from animegraph.motion.files import write_channels
    from animegraph.synthesis import Model, read_database_motion
    from ingest.formats.media import read_audio

    if args.output.suffix.lower() not in (".c3d", ".csv", ".npz"):
        raise UsageError(f"animegraph map-emotion: -o must end in .c3d, .csv or .npz, got "
                         f"{args.output.name!r}")
    target = parse_emotion(args.to)
    if target == "auto":
        raise UsageError("animegraph map-emotion: --to needs an emotion (or a mix), not auto")
    source = parse_emotion(args.source)
    if isinstance(source, dict):
        raise UsageError("animegraph map-emotion: --from takes one emotion or auto")
    t0 = time.perf_counter()
    model = Model.load(args.db)
    emotions = model.emotion_model
    if emotions is None:
        from db.errors import DataError

        raise DataError(f"database {args.db} has no emotion model (it was built by an older "
                        f"animegraph): run 'animegraph ingest SRC --db {args.db}' once to "
                        "learn it")
    for name in [target] if isinstance(target, str) else list(target):
        emotions.mapping(name, name)  # a single-emotion database, an unknown name: say so
    target, source = check_names(target, emotions, ()), check_names(source, emotions, ())
    if source != "auto":
        for name in [target] if isinstance(target, str) else list(target):
            emotions.mapping(source, name)  # too few parallel sentences: say so now
    motion, fps = read_database_motion(args.motion, model)
    how = "given"
    if source == "auto" and args.audio is not None:
        audio, sample_rate = read_audio(args.audio)
        source = next(iter(classify_speech(emotions, audio, sample_rate)))
        how = f"classified from {args.audio.name}"
    elif source == "auto":
        source = emotions.guess_emotion(model.decomposer.transform(
            model.to_local(motion)))
        how = "nearest mean emotion components"
    mapped = map_motion(model, motion, source, target, fps=fps)
    write_channels(mapped, fps, model.names, model.kind, args.output)
    name = target if isinstance(target, str) else ",".join(f"{k}={v:.2f}"
                                                            for k, v in target.items())
    print(f"animegraph: mapped {len(motion)} frames from {source} ({how}) to {name} in "
          f"{time.perf_counter() - t0:.2f} s; wrote {args.output}", file=sys.stderr)
    return 0


def _cmd_info(args: argparse.Namespace) -> int:
    import json

    from animegraph.apps.info import database_info, info_lines
    from db.store import Database

    info = database_info(Database.open(args.db))
    info["chosen_by"] = args.db_source
    if args.json:
        print(json.dumps(info, indent=1))
    else:
        for line in info_lines(info):
            print(line)
    return 0


class _LogFormatter(logging.Formatter):
    """``animegraph: warning: ...``: the style of the lines the commands print."""

    def formatMessage(self, record: logging.LogRecord) -> str:  # noqa: N802 (logging's name)
        return f"animegraph: {record.levelname.lower()}: {record.getMessage()}"


def _configure_logging(verbosity: int) -> None:
    level = logging.WARNING if verbosity == 0 else logging.INFO if verbosity == 1 else logging.DEBUG
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(_LogFormatter())
    logging.basicConfig(level=level, handlers=[handler])


def _on_interrupt(signum, frame) -> None:
    # The first Ctrl-C stops the work; later ones must not cut short the cleanup that
    # follows (ending worker processes, removing a half-built folder): they are ignored
    # until main() returns.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    raise KeyboardInterrupt


def _error_line(message: str) -> str:
    """The one error style: ``animegraph: error: [COMMAND: ]MESSAGE``."""
    if message.startswith("animegraph: "):
        message = message[len("animegraph: "):]
    elif message.startswith("animegraph "):
        message = message[len("animegraph "):]
    return f"animegraph: error: {message}"


def main(argv: Sequence[str] | None = None) -> int:
    """Run the tool; return the exit status (0, 1 bad input or data, 2 usage, 130 Ctrl-C)."""
    in_main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, _on_interrupt) if in_main else None
    try:
        status = _main(argv)
    except KeyboardInterrupt:
        # SIGINT stays ignored: the process is on its way out, and a Ctrl-C now would
        # turn the exit into a death by signal.
        return _interrupted()
    if previous is not None:
        signal.signal(signal.SIGINT, previous)
    return status


def _interrupted() -> int:
    with contextlib.suppress(OSError):
        print("animegraph: interrupted", file=sys.stderr)
    return 130


def _main(argv: Sequence[str] | None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        _configure_logging(args.verbose)
        if args.command is None:
            raise UsageError("animegraph: choose a command: corpus, demo, ingest, synth, "
                             "batch, fit, sql, query, render, plot, classify, map-emotion, "
                             "info "
                             "(see 'animegraph --help')")
        if not hasattr(args, "func"):
            raise UsageError(f"animegraph {args.command}: choose an action "
                             f"(see 'animegraph {args.command} --help')")
        if getattr(args, "default_db", False):
            _resolve_db(args)
        return int(args.func(args) or 0)
    except UsageError as exc:
        print(_error_line(str(exc)), file=sys.stderr)
        return 2
    except AnimeGraphError as exc:
        print(_error_line(str(exc)), file=sys.stderr)
        return 1
    except BrokenPipeError:
        # The reader went away (``animegraph sql ... | head``): not an error.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except OSError as exc:
        # Disk full, permission denied, a folder vanished: the environment, not a bug.
        where = f" {exc.filename}:" if exc.filename else ""
        print(f"animegraph: error:{where} {exc.strerror or exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
