"""``animegraph classify`` (the emotion of speech) and ``animegraph map-emotion`` (a
motion mapped into another emotion)."""

from __future__ import annotations

import argparse
import sys

from animegraph.apps.commands.common import UsageError, check_motion_suffix, check_output


def cmd_classify(args: argparse.Namespace) -> int:
    import json

    from animegraph.emotion.control import classify_speech, classify_timeline
    from db.store import Database
    from ingest.emotion.model import EmotionModel
    from ingest.emotion.timeline import mean_probabilities
    from ingest.formats.media import read_audio

    db = Database.open(args.db)
    model = EmotionModel.from_database(db)
    audio, sample_rate = read_audio(args.audio)  # mono, whatever the file holds
    if args.timeline:
        windows = classify_timeline(model, audio, sample_rate, auto=False)
        if args.json:
            print(json.dumps([{"start": w.start, "end": w.end, "probabilities":
                               w.probabilities, "not_classified": w.reason or None}
                              for w in windows], indent=1))
            return 0
        for w in windows:
            row = (f"{w.start:8.2f} {w.end:8.2f}  " + (
                f"{next(iter(w.probabilities)):<12s} " + " ".join(
                    f"{k} {v:.3f}" for k, v in w.probabilities.items())
                if w.probabilities is not None else f"{'-':<12s} {w.reason}"))
            print(row)
        overall = mean_probabilities(windows)
        print("overall  " + " ".join(f"{k} {v:.3f}" for k, v in overall.items()))
        return 0
    probabilities = classify_speech(model, audio, sample_rate, auto=False)
    if args.json:
        print(json.dumps(probabilities, indent=1))
    else:
        for name, p in probabilities.items():
            print(f"{name:<12s} {p:6.3f}")
    return 0


def cmd_map_emotion(args: argparse.Namespace) -> int:
    import time

    from animegraph.emotion.control import check_names, classify_speech, map_motion, parse_emotion
    from animegraph.motion.files import write_channels
    from animegraph.synthesis import Model, read_database_motion
    from ingest.formats.media import read_audio

    check_motion_suffix("map-emotion", args.output)
    target = parse_emotion(args.to)
    if target == "auto":
        raise UsageError("animegraph map-emotion: --to needs an emotion (or a mix), not auto")
    source = parse_emotion(args.source)
    if isinstance(source, dict):
        raise UsageError("animegraph map-emotion: --from takes one emotion or auto")
    t0 = time.perf_counter()
    model = Model.load(args.db)
    check_output("map-emotion", args.output, model.names, model.kind)
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
    print(f"animegraph: mapped {len(motion)} frame{'s' * (len(motion) != 1)} from {source} "
          f"({how}) to {name} in {time.perf_counter() - t0:.2f} s; wrote {args.output}",
          file=sys.stderr)
    return 0
