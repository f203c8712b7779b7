"""The emotion commands' arguments: ``classify``, ``map-emotion`` and ``emotion fit``.

Apart from :mod:`animegraph.apps.cli_parser`, which calls :func:`add_emotion_commands` with
its shared option helpers (passed in, so that this module does not import it back)."""

from __future__ import annotations

from pathlib import Path

from animegraph.apps.commands.emotion import cmd_classify, cmd_map_emotion
from animegraph.apps.commands.emotion_fit import cmd_emotion_fit

#: ``--preset``: :data:`ingest.emotion.labelled.PRESETS`, spelled out so that ``--help``
#: does not import it (tests/test_emotion_fit.py checks that they are the same).
PRESETS = ("ravdess", "emodb", "tess", "crema-d")
#: ``classify --window`` and ``--hop`` defaults, seconds
#: (:data:`ingest.emotion.timeline.WINDOW_S`, ``HOP_S``; checked the same by the tests).
WINDOW_S, HOP_S = 4.0, 2.0


def add_emotion_commands(sub, *, db_option, output_file, number, parser_class, speech) -> None:
    """Add ``classify``, ``map-emotion`` and ``emotion`` (``emotion fit``) to ``sub``."""
    _add_classify(sub, db_option, output_file, number, speech)
    _add_map_emotion(sub, db_option, output_file)
    _add_emotion(sub, output_file, parser_class)


def _labels_options(parser, *, train: bool) -> None:
    where = "DIR" if train else "the CSV's folder"
    parser.add_argument("--labels", type=Path, default=None, metavar="CSV",
                        help="a CSV with a header naming path,emotion[,speaker]: one row a "
                        f"recording, its path relative to {where} (a row whose path leaves "
                        "it, names no file or has a malformed label is left out with the "
                        "reason)")
    parser.add_argument("--preset", choices=PRESETS, default=None,
                        help="the emotion and speaker of each file from the corpus' file "
                        "names (RAVDESS 03-01-05-02-01-01-07, EmoDB 03a01Fa, TESS "
                        "OAF_back_angry, CREMA-D 1001_DFA_ANG_XX), in one vocabulary: "
                        "neutral, calm, happy, sad, angry, fearful, disgust, surprised, "
                        "boredom")


def _add_classify(sub, db_option, output_file, number, speech) -> None:
    """``classify``: the emotion of speech."""
    cls = sub.add_parser(
        "classify", help="the emotion of speech, by a database's or a file's classifier",
        description="Print the probability of each emotion for each recording (any rate, "
        "mono or stereo), by the classifier trained on the database's clips at ingest or "
        "by one fitted with 'animegraph emotion fit' (--model): prosodic and spectral "
        "features, frame-averaged cepstrum coefficients and a bag of audio words, "
        "normalised per speaker, a linear SVM and probabilities by Platt scaling (Cao et "
        "al. 2005 §6 uses an SVM on the signal's mean, variance, RMS and first 500 "
        "real-cepstrum coefficients). A speaker's takes given together (--speaker, or the "
        "speaker column of --labels, or --preset) are normalised by their own statistics "
        "when there are at least five of them: more accurate than one take at a time.",
    )
    cls.add_argument("inputs", type=Path, nargs="+", metavar="AUDIO",
                     help=f"{speech}; a folder: every .wav, .flac, .ogg and .mp3 in it")
    db_option(cls)
    cls.add_argument("--model", type=Path, default=None, metavar="MODEL",
                     help="a classifier file written by 'animegraph emotion fit' (instead "
                     "of the database's)")
    cls.add_argument("--speaker", default=None, metavar="NAME",
                     help="every recording is this one speaker's (with --timeline: the "
                     "windows are normalised together, docs/results/emotion.md)")
    _labels_options(cls, train=False)
    cls.add_argument("--format", choices=("table", "csv", "json"), default=None,
                     help="output format (default: table, or as -o's suffix says)")
    cls.add_argument("-o", "--output", type=output_file, default=None,
                     help="write the rows here (.csv, .json or .txt) instead of stdout")
    cls.add_argument("--json", action="store_true", help="the same as --format json")
    cls.add_argument("--timeline", action="store_true",
                     help="classify one recording window by window and print each window's "
                     "start, end, label and probabilities, or why it is not classified "
                     "(silence, not speech); a recording over 15 s is always classified "
                     "so, its probabilities their mean")
    cls.add_argument("--window", type=number, default=WINDOW_S, metavar="S",
                     help=f"--timeline's window, seconds (default {WINDOW_S:g}; 2 to 4 "
                     "measured, docs/results/emotion.md)")
    cls.add_argument("--hop", type=number, default=HOP_S, metavar="S",
                     help=f"--timeline's step between windows, seconds (default {HOP_S:g})")
    cls.add_argument("--plot", type=output_file, default=None, metavar="PNG",
                     help="with --timeline: draw each emotion's probability over time")
    cls.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    cls.set_defaults(func=cmd_classify)


def _add_map_emotion(sub, db_option, output_file) -> None:
    """``map-emotion``: a motion mapped into another emotion."""
    mp = sub.add_parser(
        "map-emotion", help="change the emotion of a facial motion",
        description="Map the emotion components of a motion (as written by 'synth': .c3d, "
        ".csv or .npz, in the database's channels) from one emotion to another with the "
        "database's RBF mapping (Cao et al. 2005 §5.2); speech components are kept.",
    )
    mp.add_argument("motion", type=Path, metavar="IN", help="motion file (.c3d, .csv, .npz)")
    db_option(mp)
    mp.add_argument("--to", required=True, metavar="E|E=W,...",
                    help="target emotion, or a mix such as happy=0.7,neutral=0.3")
    mp.add_argument("--from", dest="source", default="auto", metavar="E|auto",
                    help="emotion of IN; 'auto' (default): classify --audio if given, else "
                    "the emotion whose mean emotion components are nearest IN's")
    mp.add_argument("--audio", type=Path, default=None,
                    help="the speech of IN, for --from auto")
    mp.add_argument("-o", "--output", required=True, type=output_file,
                    help="motion file to write (.c3d, .csv or .npz)")
    mp.set_defaults(func=cmd_map_emotion)


def _add_emotion(sub, output_file, parser_class) -> None:
    """``emotion`` and its action ``emotion fit``."""
    emo = sub.add_parser("emotion", help="the emotion classifier of speech",
                         description="'emotion fit' trains the emotion classifier of speech "
                         "on labelled recordings, for 'classify' and 'synth --emotion auto'.")
    actions = emo.add_subparsers(dest="emotion_command", metavar="ACTION",
                                 parser_class=parser_class)
    fit = actions.add_parser(
        "fit", help="train the emotion classifier on labelled recordings",
        description="Train the emotion classifier (the one ingest learns, with "
        "probabilities) on the recordings under DIR, labelled by --labels or --preset, "
        "normalised per speaker; write it to a file (-o, for 'classify --model') or store "
        "it into a database (--db, a new version, for 'classify' and 'synth --emotion "
        "auto'; a later ingest learns the database's own again).",
    )
    fit.add_argument("folder", type=Path, metavar="DIR", help="the folder of recordings")
    fit.add_argument("-o", "--output", type=output_file, default=None, metavar="MODEL",
                     help="the classifier file to write (.npz)")
    fit.add_argument("--db", type=Path, default=None,
                     help="store the classifier into this database instead (its emotions "
                     "must be the database's)")
    _labels_options(fit, train=True)
    fit.add_argument("--emotions", default=None, metavar="E,E,...",
                     help="train on these emotions only (e.g. neutral,happy,sad,angry)")
    fit.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    fit.set_defaults(func=cmd_emotion_fit)
