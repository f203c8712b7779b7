"""``animegraph emotion fit``: the emotion classifier trained on labelled recordings, written
to a file or stored into a database."""

from __future__ import annotations

import argparse

from animegraph.apps.commands.common import UsageError, interruptible, progress, say

#: Fewest usable recordings of an emotion (the probability calibration's out-of-fold split
#: needs two per class: :data:`ingest.emotion.model.MIN_CLASSIFIER_CLIPS`).
MIN_PER_EMOTION = 2


def cmd_emotion_fit(args: argparse.Namespace) -> int:
    import time

    import numpy as np

    from db.errors import DataError
    from ingest.emotion.classifier import SpeechFeatures
    from ingest.emotion.labelled import from_csv, from_preset
    from ingest.emotion.model import database_classifier

    if (args.output is None) == (args.db is None):
        raise UsageError("animegraph emotion fit: give -o MODEL (a file) or --db DB (store "
                         "it into a database), one of them")
    if (args.labels is None) == (args.preset is None):
        raise UsageError("animegraph emotion fit: give --labels CSV or --preset NAME, one of "
                         "them")
    if args.output is not None and args.output.suffix.lower() != ".npz":
        raise UsageError(f"animegraph emotion fit: -o must end in .npz, got "
                         f"{args.output.name!r}")
    if not args.folder.is_dir():
        raise DataError(f"no such folder: {args.folder}")
    t0 = time.perf_counter()
    labelled = (from_csv(args.labels, args.folder) if args.labels is not None
                else from_preset([args.folder], args.preset))
    _keep_emotions(labelled, args.emotions)
    db_emotions = _database_emotions(args.db) if args.db is not None else None
    if db_emotions is not None:
        _spell_as_database(labelled, db_emotions, args.db)
    for line in labelled.rejected[:10]:
        say(f"left out {line}")
    if len(labelled.rejected) > 10:
        say(f"... and {len(labelled.rejected) - 10} more left out")
    _check_classes(labelled.emotions, args)
    rows, labels, speakers = _features(labelled, args.quiet)
    _check_classes(labels, args, usable=True)
    frames = None if rows[0].frames is None else [f for r in rows for f in r.frames]
    X = SpeechFeatures(np.vstack([r.functionals for r in rows]), frames)
    say(f"emotion fit: training on {len(labels)} recordings of {len(set(speakers))} "
        f"speaker{'s' * (len(set(speakers)) != 1)} ...")
    classifier = interruptible(lambda: database_classifier().fit(
        X, np.array(labels), speakers=np.array(speakers)))
    counts = dict(zip(*np.unique(labels, return_counts=True), strict=True))
    trained_on = {"recordings": len(labels), "speakers": len(set(speakers)),
                  "emotions": {str(k): int(v) for k, v in counts.items()},
                  "labels": "preset " + args.preset if args.preset else "labels CSV"}
    if args.db is not None:
        from animegraph.baselines.base import FIT_WAIT_S, carry_models
        from db.lock import writer_lock
        from db.store import current_version
        from ingest.emotion.classifier_file import store_in_database

        before = current_version(args.db)
        # The fitted guides (and every baseline) are kept: a model is a function of the
        # clips' speech, motion, emotion labels, phones and posteriors and of the channels,
        # all hard-linked unchanged into the new version; none reads the classifier, the
        # one thing replaced. A refit would give the same model
        # (tests/test_emotion_fit.py). One lock over both steps: a synth meanwhile waits
        # for the carried guides rather than fitting them again (baselines.base).
        with writer_lock(args.db, wait=FIT_WAIT_S, what="database"):
            where = store_in_database(args.db, classifier, trained_on, based_on=before)
            carried = carry_models(args.db, before)
        done = (f"stored it into {args.db} (version {where.name})"
                + (f"; kept its fitted {', '.join(carried)}" if carried else ""))
    else:
        from ingest.emotion.classifier_file import save_classifier

        save_classifier(classifier, args.output, trained_on)
        done = f"wrote {args.output}"
    say(f"emotion fit: {len(counts)} emotions ({', '.join(f'{k} {v}' for k, v in counts.items())})"
        f" in {time.perf_counter() - t0:.1f} s; {done}")
    return 0


def _keep_emotions(labelled, wanted: str | None) -> None:
    """Leave out the recordings of emotions not in ``--emotions`` (a count, not a line each)."""
    if wanted is None:
        return
    names = {n.strip().lower() for n in wanted.split(",") if n.strip()}
    if not names:
        raise UsageError("animegraph emotion fit: --emotions names no emotion")
    if not labelled.emotions:  # nothing to choose from: said as such by _check_classes
        return
    keep = [k for k, e in enumerate(labelled.emotions) if e in names]
    missing = names - {labelled.emotions[k] for k in keep}
    if missing:
        from db.errors import DataError

        raise DataError(f"no recording is labelled {', '.join(sorted(missing))} (the labels "
                        f"are {', '.join(sorted(set(labelled.emotions))) or 'none'})")
    for field in ("paths", "emotions", "speakers"):
        setattr(labelled, field, [getattr(labelled, field)[k] for k in keep])


def _database_emotions(db_path) -> tuple[str, ...]:
    from db.errors import DataError
    from db.store import Database

    emotion = Database.open(db_path).manifest.get("emotion")
    if emotion is None:
        raise DataError(f"database {db_path} has no emotion model (it was built by an older "
                        f"animegraph): run 'animegraph ingest SRC --db {db_path}' once")
    return tuple(emotion.get("emotions", ()))


def _spell_as_database(labelled, emotions, db_path) -> None:
    """Labels as the database spells its emotions; one it lacks is said before the work."""
    from db.errors import AnimeGraphError, DataError
    from ingest.emotion.model import find_emotion

    lacking = set()
    for k, name in enumerate(labelled.emotions):
        try:
            labelled.emotions[k] = find_emotion(name, emotions)
        except AnimeGraphError:  # not one of the database's
            lacking.add(name)
    if lacking:
        raise DataError(f"emotions {', '.join(sorted(lacking))} are not in database {db_path} "
                        f"(it has {', '.join(emotions) or 'none'}): 'synth --emotion auto' "
                        "could not use them; leave them out with --emotions")


def _check_classes(labels, args, usable: bool = False) -> None:
    from db.errors import DataError

    what = "usable recordings" if usable else "labelled recordings"
    if not labels:
        links = not usable and any(p.is_symlink() for p in args.folder.rglob("*"))
        raise DataError(f"no {what} in {args.folder}"
                        + (f" ({args.preset} names files as its README says)"
                           if args.preset and not usable else "")
                        + ("; symbolic links in it are not followed" if links else ""))
    counts: dict[str, int] = {}
    for name in labels:
        counts[name] = counts.get(name, 0) + 1
    names = sorted(counts)
    if len(names) < 2:
        raise DataError(f"the {what} are all {names[0]}: a classifier needs two emotions "
                        "or more")
    few = [f"{n} {counts[n]}" for n in names if counts[n] < MIN_PER_EMOTION]
    if few:
        raise DataError(f"every emotion needs at least {MIN_PER_EMOTION} {what}; "
                        + ", ".join(few) + " (leave it out with --emotions)")


def _features(labelled, quiet: bool):
    """Each recording's features (a progress bar); one that cannot be used is left out
    with its reason."""
    from db.errors import AnimeGraphError
    from ingest.emotion.model import classifier_features
    from ingest.formats.media import read_audio

    rows, labels, speakers, dropped = [], [], [], []
    bar = progress(len(labelled.paths), quiet, "file", "features")
    for k, path in enumerate(bar(labelled.paths)):
        try:
            audio, rate = read_audio(path)
        except AnimeGraphError as exc:
            dropped.append(f"{path.name}: {exc}")
            continue
        row = classifier_features(audio, rate)
        if isinstance(row, str):
            dropped.append(f"{path.name}: {row}")
            continue
        rows.append(row)
        labels.append(labelled.emotions[k])
        speakers.append(labelled.speakers[k] or "unknown")
    for line in dropped[:10]:
        say(f"left out {line}")
    if len(dropped) > 10:
        say(f"... and {len(dropped) - 10} more recordings left out")
    return rows, labels, speakers
