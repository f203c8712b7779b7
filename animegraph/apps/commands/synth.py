"""``animegraph synth``: facial motion for speech, by the Anime Graph or a fitted
baseline; and ``animegraph batch``, every line of a dialogue script.

Which path ``synth`` takes and with what guide is :mod:`.synth_plan`'s."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from animegraph.apps.commands.common import (
    UsageError,
    check_motion_suffix,
    check_output,
    interruptible,
    progress,
    sidecar_labels,
)
from animegraph.apps.commands.synth_plan import (
    guide_shortfall,
    load_guide,
    recognized_guide,
    synth_path,
    synth_plan,
)


def cmd_synth(args: argparse.Namespace) -> int:
    from ingest.speech.heard import remembered

    with remembered() as heard:  # a recording's phones found once, whatever options follow
        # In a worker thread: a Ctrl-C inside a long compiled call ends synth at once.
        return interruptible(_synth, args, heard)


def _synth(args: argparse.Namespace, heard) -> int:
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
    from ingest.readers.common import read_labels_for

    check_motion_suffix("synth", args.output)
    _check_timecode(args)
    if args.method != "anime-graph":
        return _synth_baseline(args)
    method = _search_method(args)
    sidecar = sidecar_labels(args.audio) if args.labels is None and args.text is None else None
    args.labels = sidecar or args.labels
    k_best, path = synth_path(args)
    _check_k_best_options(args, k_best)
    audio_cost = args.audio_cost or "plp"
    path, guide_name, guide_blend, guide_rank = synth_plan(args, path)
    t0 = time.perf_counter()
    model = Model.load(args.db)
    check_output("synth", args.output, model.names, model.kind)
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
        k_best, path = synth_path(args)
        path, guide_name, guide_blend, guide_rank = synth_plan(args, path)
    t0 += time.perf_counter() - t_check  # hearing the speech is not loading the database
    if sidecar is not None:
        print(f"animegraph: using the phone labels beside the speech, {sidecar} "
              "(--labels or --text to use others)", file=sys.stderr)
    # A GRID word alignment (.align) too, as ingest reads it (phones aligned in its words).
    labels = (read_labels_for(Path(args.labels), audio if np.ndim(audio) == 1
                              else np.mean(audio, axis=1), sample_rate)
              if args.labels else None)
    # Classify ("auto") before any progress line, so that a failure is one line.
    choice = resolve_emotion(emotion, model.emotion_model, model.graph.emotions,
                             audio if np.ndim(audio) == 1 else np.mean(audio, axis=1),
                             sample_rate, timeline=True)
    t_guide = time.perf_counter()
    guide = load_guide(args.db, guide_name, asked=args.guide is not None)
    t0 += time.perf_counter() - t_guide  # a first use's fit is not loading the database
    path += guide_shortfall(args.db, guide_name, guide_names(guide))
    print(f"animegraph: loaded {model.graph.n_nodes} anime{'s' * (model.graph.n_nodes != 1)} in "
          f"{time.perf_counter() - t0:.2f} s; synthesizing {len(audio) / sample_rate:.1f} s "
          f"of speech ...", file=sys.stderr)
    options = PostOptions(time_warp=not args.no_time_warp, blend=not args.no_blend,
                          smooth=not args.no_smooth, helper=args.helper or PostOptions.helper,
                          recentre=args.recentre)
    if choice.timeline is not None:
        print(f"animegraph: emotion auto: the face follows the emotion over time, window by "
              f"window ({choice.timeline.describe()})", file=sys.stderr)
    elif choice.probabilities is not None:
        probs = ", ".join(f"{k} {v:.2f}" for k, v in choice.probabilities.items())
        print(f"animegraph: emotion auto: the speech sounds {choice.target} ({probs})",
              file=sys.stderr)
    from animegraph.search.kernels import compile_notice

    notice = compile_notice(method)
    if notice:
        print(f"animegraph: {notice}", file=sys.stderr)
    out = synthesize(model, audio, sample_rate, text=args.text, labels=labels,
                     emotion=choice, method=method, window=args.window,
                     tolerance=args.tolerance or 0.0, options=options, k_best=k_best,
                     phones_engine=args.phones_engine, audio_cost=audio_cost,
                     candidates_from=args.candidates or "label", guide=guide,
                     guide_blend=guide_blend, guide_rank=guide_rank,
                     context=args.context_ranking, recognized_guide=recognized_guide(args),
                     shortlist=_shortlist_size(args))
    from animegraph.synthesis.path import CONTEXT_PHRASE

    if mismatch is not None:
        # Said only now that phones were found: on music or noise the one line is
        # synthesize's "no speech found", not a transcript nothing could have matched.
        print(f"animegraph: warning: {mismatch}: synthesizing from the speech alone",
              file=sys.stderr)
    if args.text is not None and out.segmentation == "recognized":
        # The check passed, the alignment failed: what ran is the speech-alone path.
        alone = argparse.Namespace(**{**vars(args), "text": None})
        path, name, _, _ = synth_plan(alone, synth_path(alone)[1])
        path += guide_shortfall(args.db, name, out.guided)
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
    for line in _emotion_lines(out.emotion) + list(out.notes):
        print(f"animegraph: {line}", file=sys.stderr)
    print(f"animegraph: {_summary(out, k_best, heard.hits)}; wrote {args.output}",
          file=sys.stderr)
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


def _search_method(args: argparse.Namespace) -> str:
    """The search ``synth`` runs (``exact`` unless asked), its options checked."""
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
    return method


def _check_k_best_options(args: argparse.Namespace, k_best: int | None) -> None:
    """The options of k-best only with k-best, ``--helper`` only without it."""
    if args.context_ranking is not None and not k_best:
        raise UsageError("animegraph synth: --context-ranking ranks the animes k-best "
                         "averages; the paper's search (--exact, --window, --search) takes "
                         "one anime a phone")
    if args.helper is not None and k_best:
        raise UsageError("animegraph synth: --helper blends the paper's search (one anime a "
                         "phone) at its jumps; --k-best averages animes instead: give one")
    if args.shortlist is not None and not k_best:
        raise UsageError("animegraph synth: --shortlist cuts the candidates k-best ranks; "
                         "the paper's search (--exact, --window, --search) sees every one")
    if args.recentre is not None and not k_best:
        raise UsageError("animegraph synth: --recentre changes how k-best averages "
                         "animes; the paper's search (--exact, --window, --search) takes one "
                         "anime a phone")


def _shortlist_size(args: argparse.Namespace) -> int | None:
    """``synthesize``'s ``shortlist`` from ``--shortlist`` (None: every candidate)."""
    from animegraph.search.shortlist import SHORTLIST

    if args.shortlist is None:
        return SHORTLIST
    return None if args.shortlist == "all" else args.shortlist


def _emotion_lines(emotion) -> list[str]:
    """What the user is told of the emotion synthesized (a mix, or one mapped into)."""
    if isinstance(emotion.target, dict):
        return [f"emotion mix {emotion.describe()}: animes preferred from "
                f"{emotion.search}, emotion components blended from their mappings"]
    if emotion.target is not None and emotion.search != emotion.target:
        return [f"the database has no {emotion.target} animes: preferred "
                f"{emotion.search}, mapped into {emotion.target}"]
    return []


def _summary(out, k_best: int | None, heard_before: int = 0) -> str:
    """The line of phones, jumps, cost and time that ends a synthesis (``heard_before``:
    the phones were read from the cache, :mod:`ingest.speech.heard`)."""
    r, t = out.result, out.timings
    line = (f"{len(out.phones)} phone{'s' * (len(out.phones) != 1)} "
            f"({out.segmentation}), {r.n_jumps} jump match{'es' * (r.n_jumps != 1)}, cost "
            f"{r.cost:.3f} ({r.method}, {r.n_expanded} expansion{'s' * (r.n_expanded != 1)}); "
            f"{t['total_s']:.2f} s = segment {t['segment_s']:.2f}"
            f"{' (phones heard before, from the cache)' if heard_before else ''} + audio cost "
            f"{t['audio_cost_s']:.2f} + search {t['search_s']:.3f} + post {t['post_s']:.2f}")
    if k_best:
        joined = ("cross-faded into its neighbours through the recorded transitions"
                  if out.cross_faded else "cut at its boundaries")
        line += (f" (k-best {k_best}: each phone the mean of up to {k_best} "
                 f"anime{'s' * (k_best != 1)}, {joined})")
    return line


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


def _transcript_mismatch(args: argparse.Namespace, audio, sample_rate: int) -> str | None:
    """Why ``--text`` is not what the speech says, as far as the phone engine checks
    (:func:`ingest.speech.engines.check_transcript`); None if it is. ``audio`` is mono,
    as :func:`ingest.formats.media.read_audio` gives it."""
    from db.errors import DataError
    from ingest.speech.ctc import doubts
    from ingest.speech.engines import check_transcript

    try:
        with doubts():  # a doubt is the synthesis' own warning, said once there
            check_transcript(audio, sample_rate, args.text, args.phones_engine)
    except DataError as exc:
        return str(exc)
    return None


def _synth_baseline(args: argparse.Namespace) -> int:
    """``synth --method <baseline>``: motion from the audio alone by a fitted baseline."""
    import time

    import numpy as np

    from animegraph.baselines.base import fitted_model, fitting_line, load_model
    from animegraph.emotion.control import AUTO, check_names, parse_emotion
    from animegraph.motion.files import write_channels
    from animegraph.synthesis import to_world
    from animegraph.synthesis.model import read_channels
    from db.store import Database
    from ingest.formats.media import read_audio

    search_only = [flag for flag, on in (
        ("--text", args.text is not None), ("--labels", args.labels is not None),
        ("--exact", args.exact), ("--window", args.window is not None),
        ("--search", args.search is not None), ("--explain", args.explain),
        ("--emotion-mix", args.emotion_mix is not None),
        ("--tolerance", args.tolerance is not None),
        ("--explain-json", args.explain_json is not None),
        ("--phones-engine", args.phones_engine is not None),
        ("--no-time-warp", args.no_time_warp), ("--no-blend", args.no_blend),
        ("--helper", args.helper is not None),
        ("--no-smooth", args.no_smooth), ("--k-best", args.k_best is not None),
        ("--audio-cost", args.audio_cost is not None),
        ("--candidates", args.candidates is not None), ("--guide", args.guide is not None),
        ("--guide-blend", args.guide_blend is not None), ("--guide-rank", args.guide_rank),
        ("--context-ranking", args.context_ranking is not None),
        ("--recentre", args.recentre is not None),
        ("--shortlist", args.shortlist is not None)) if on]
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
    _, names, _, kind = read_channels(db)  # the kind from the channels, as synthesis reads it
    check_output("synth", args.output, names, kind)
    emotion = check_names(emotion, None, db.table("clips", columns=["emotion"])
                          .column("emotion").to_pylist())
    audio, sample_rate = read_audio(args.audio)  # a WAV, or a video's sound track
    t0 = time.perf_counter()
    if args.refit or load_model(args.db, args.method) is None:  # minutes, once: said
        print(f"animegraph: {fitting_line(args.method, args.db)}", file=sys.stderr)
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


def cmd_batch(args: argparse.Namespace) -> int:
    from animegraph.apps.batch import BatchInterrupted, BatchOptions, run_batch

    if args.scheduler is None and args.workers < 1:
        raise UsageError(f"animegraph batch: --workers must be at least 1, got {args.workers}")
    options = BatchOptions(db=args.db, out=args.out, workers=args.workers,
                           scheduler=args.scheduler, render=args.render, force=args.force,
                           motion_formats=args.motion_format)

    def say(line: str) -> None:
        if not args.quiet:
            print(f"animegraph: {line}", file=sys.stderr)

    try:
        result = run_batch(args.script, options, say=say,
                           progress=lambda total: progress(total, args.quiet, "line",
                                                           "batch: lines"))
    except BatchInterrupted as stop:  # what was done, and how to go on
        for line in stop.result.summary():
            print(line)
        print("batch: interrupted: " + (
            "the lines not run keep what they had (--force again remakes every line)"
            if args.force else "the lines made are kept; the same command makes the rest"))
        raise  # the command line's "interrupted", status 130
    for line in result.summary():
        print(line)
    return 0 if result.ok else 1
