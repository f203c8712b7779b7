"""``animegraph classify`` (the emotion of speech, many recordings at once or one over
time), ``animegraph map-emotion`` (a motion mapped into another emotion); ``emotion fit``
is in :mod:`.emotion_fit`."""

from __future__ import annotations

import argparse
import sys

from animegraph.apps.commands.common import (
    UsageError,
    check_motion_suffix,
    check_output,
    interruptible,
    progress,
    say,
)


def _classifier(args: argparse.Namespace):
    """(classifier, where it is from): ``--model``'s file, else the database's."""
    from animegraph.emotion.control import no_classifier
    from db.errors import DataError

    if args.model is not None:
        from ingest.emotion.classifier_file import load_classifier

        return load_classifier(args.model)[0], str(args.model)
    from db.store import Database
    from ingest.emotion.model import EmotionModel

    model = EmotionModel.from_database(Database.open(args.db))
    if model.classifier is None:
        raise DataError(no_classifier(model, auto=False))
    return model.classifier, str(args.db)


def _labelled(args: argparse.Namespace, command: str):
    """The recordings of ``classify``: files and folders, with speakers (and emotions, if
    the CSV or preset knows them)."""
    from ingest.emotion.labelled import Labelled, audio_files, from_csv, from_preset

    if args.labels is not None and args.preset is not None:
        raise UsageError(f"animegraph {command}: give --labels or --preset, not both")
    if args.speaker is not None and (args.labels is not None or args.preset is not None):
        raise UsageError(f"animegraph {command}: --speaker names every recording's speaker; "
                         "--labels and --preset name each one's: give one of them")
    files = audio_files(args.inputs)
    if args.preset is not None:
        return from_preset(files, args.preset)
    out = Labelled()
    if args.labels is not None:
        listed = from_csv(args.labels, args.labels.resolve().parent, need_emotion=False)
        known = {p: (e, s) for p, e, s in zip(listed.paths, listed.emotions, listed.speakers,
                                               strict=True)}
        out.rejected = listed.rejected
        for path in files:
            emotion, speaker = known.get(path.resolve(), (None, None))
            out.add(path, emotion, speaker)
        return out
    for path in files:
        out.add(path, None, args.speaker)
    return out


def cmd_classify(args: argparse.Namespace) -> int:
    from ingest.formats.media import read_audio

    if args.json and args.format not in (None, "json"):
        raise UsageError("animegraph classify: --json is --format json; give one")
    one = len(args.inputs) == 1 and args.inputs[0].is_file()
    if args.timeline or args.plot is not None:
        if not one:
            raise UsageError("animegraph classify: --timeline and --plot take one recording")
        classifier, _ = _classifier(args)
        audio, sample_rate = read_audio(args.inputs[0])  # mono, whatever the file holds
        return _timeline(args, classifier, audio, sample_rate)
    if one and args.format is None and args.output is None and args.speaker is None \
            and args.labels is None and args.preset is None:
        return _classify_one(args, read_audio)
    args.format = "json" if args.json else args.format
    labelled = _labelled(args, "classify")
    for line in labelled.rejected[:10]:
        say(f"left out {line}")
    if not labelled.paths:
        from db.errors import DataError

        raise DataError("no recordings to classify (.wav, .flac, .ogg, .mp3) in "
                        + ", ".join(str(p) for p in args.inputs))
    classifier, _ = _classifier(args)
    rows = _classify_many(classifier, labelled, read_audio, args.quiet)
    _write_rows(args, rows, [str(c) for c in classifier.classes_])
    _say_accuracy(rows)
    return 0 if any(r["label"] for r in rows) else 1


def _classify_one(args, read_audio) -> int:
    """One recording: each emotion's probability, a line each (or a JSON object); speech
    that is not (noise, a tone) is an error."""
    import json

    from ingest.emotion.timeline import utterance_probabilities

    classifier, _ = _classifier(args)
    audio, rate = read_audio(args.inputs[0])
    probabilities = interruptible(utterance_probabilities, classifier, audio, rate)
    if args.json:
        print(json.dumps(probabilities, indent=1))
    else:
        for name, p in probabilities.items():
            print(f"{name:<12s} {p:6.3f}")
    return 0


def _classify_many(classifier, labelled, read_audio, quiet: bool) -> list[dict]:
    """A row per recording: its features computed one by one (progress bar), then all
    classified together, each speaker's takes normalised by their own statistics."""
    import numpy as np

    from db.errors import AnimeGraphError
    from ingest.emotion.audio import check_speech
    from ingest.emotion.classifier import SpeechFeatures
    from ingest.emotion.timeline import MAX_UTTERANCE_S, utterance_probabilities

    rows, described, who, at = [], [], [], []
    bar = progress(len(labelled.paths), quiet, "file", "features")
    for k, path in enumerate(bar(labelled.paths)):
        speaker = labelled.speakers[k]
        row = {"path": str(path), "speaker": speaker or "", "truth": labelled.emotions[k] or "",
               "label": "", "reason": ""}
        rows.append(row)
        try:
            audio, rate = read_audio(path)
            if len(audio) / rate > MAX_UTTERANCE_S:  # a long one: its windows' mean, alone
                probabilities = utterance_probabilities(classifier, audio, rate)
                row.update(label=next(iter(probabilities)), probabilities=probabilities)
                continue
            check_speech(audio, rate)
            described.append(classifier.describe([(audio, rate)]))
        except AnimeGraphError as exc:
            row["reason"] = str(exc.__cause__ or exc)
            continue
        who.append(speaker if speaker else f"\x01alone {k}")  # no speaker: alone
        at.append(k)
    if described:
        frames = (None if described[0].frames is None
                  else [f for d in described for f in d.frames])
        X = SpeechFeatures(np.vstack([d.functionals for d in described]), frames)
        proba = interruptible(classifier.predict_proba, X, np.array(who))
        for k, p in zip(at, proba, strict=True):
            order = np.argsort(-p)
            probabilities = {str(classifier.classes_[j]): float(p[j]) for j in order}
            rows[k].update(label=next(iter(probabilities)), probabilities=probabilities)
    return rows


def _write_rows(args, rows: list[dict], classes: list[str]) -> None:
    import pyarrow as pa

    from animegraph.apps.tabular import format_for, format_table

    fmt = args.format or format_for(None, args.output)
    if fmt not in ("table", "csv", "json"):
        fmt = "table"
    columns = {"path": [r["path"] for r in rows], "speaker": [r["speaker"] for r in rows]}
    if any(r["truth"] for r in rows):
        columns["truth"] = [r["truth"] for r in rows]
    columns["label"] = [r["label"] or None for r in rows]
    for name in classes:
        columns[name] = [round(r["probabilities"][name], 4) if r["label"] else None
                         for r in rows]
    columns["not_classified"] = [r["reason"] or None for r in rows]
    text = format_table(pa.table(columns), fmt, max_rows=max(1, len(rows)))
    if args.output is None:
        sys.stdout.write(text)
        return
    from db.atomic import atomic_write

    with atomic_write(args.output) as handle:
        handle.write(text.encode())
    say(f"classified {sum(bool(r['label']) for r in rows)} of {len(rows)} recording"
        f"{'s' * (len(rows) != 1)}; wrote {args.output}")


def _say_accuracy(rows: list[dict]) -> None:
    """With the true emotions known (--labels, --preset): the share classified right."""
    labelled = [r for r in rows if r["truth"] and r["label"]]
    # an emotion the classifier does not know cannot be classified right: not scored
    scored = [r for r in labelled if r["truth"] in r["probabilities"]]
    if scored:
        right = sum(r["truth"] == r["label"] for r in scored)
        unknown = len(labelled) - len(scored)
        say(f"{right} of {len(scored)} classified as labelled "
            f"({100 * right / len(scored):.1f} %)"
            + (f"; {unknown} labelled with emotions the classifier does not know, not "
               "scored" if unknown else ""))


def _timeline(args, classifier, audio, sample_rate) -> int:
    import json

    from db.errors import ParameterError
    from ingest.emotion.timeline import classify_windows, mean_probabilities, spans

    try:
        spans(0.0, args.window, args.hop)  # the command line's values, said as such
    except ParameterError as exc:
        raise UsageError(f"animegraph classify: {exc}") from None
    # --speaker: the windows are that one speaker's takes, normalised together.
    windows = interruptible(lambda: classify_windows(
        classifier, audio, sample_rate, window=args.window, hop=args.hop,
        one_speaker=args.speaker is not None))
    overall = mean_probabilities(windows)
    if args.plot is not None:
        from animegraph.emotion.plots import plot_timeline

        plot_timeline(windows, args.plot, title=f"{args.inputs[0].name}: emotion over time")
        say(f"wrote {args.plot}")
    if args.format == "json":
        text = json.dumps([{"start": w.start, "end": w.end, "probabilities":
                            w.probabilities, "not_classified": w.reason or None}
                           for w in windows], indent=1) + "\n"
    else:
        lines = []
        for w in windows:
            lines.append(f"{w.start:8.2f} {w.end:8.2f}  " + (
                f"{next(iter(w.probabilities)):<12s} " + " ".join(
                    f"{k} {v:.3f}" for k, v in w.probabilities.items())
                if w.probabilities is not None else f"{'-':<12s} {w.reason}"))
        lines.append("overall  " + " ".join(f"{k} {v:.3f}" for k, v in overall.items()))
        text = "".join(line + "\n" for line in lines)
    if args.output is None:
        sys.stdout.write(text)
    else:
        from db.atomic import atomic_write

        with atomic_write(args.output) as handle:
            handle.write(text.encode())
        say(f"wrote {args.output}")
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
