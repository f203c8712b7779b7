"""An emotion classifier trained apart from a database (``animegraph emotion fit``): kept in
a file of its own, or stored into a database in place of the one ingest learned.

The file is a NumPy ``.npz`` archive of plain arrays (never pickles: read with
``allow_pickle=False``): :meth:`EmotionClassifier.to_arrays
<ingest.emotion.classifier.EmotionClassifier.to_arrays>` plus ``animegraph_file`` (what
the file is), ``animegraph_file_version`` (:data:`FILE_VERSION`) and ``trained_on`` (a JSON
object: recordings, speakers, emotions). Reading checks each of them, then the classifier's
arrays as a database's are checked
(:func:`ingest.emotion.classifier_arrays.classifier_from_arrays`): a damaged or foreign file
is one line.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np

from db.errors import DataError

__all__ = ["FILE_KIND", "FILE_VERSION", "load_classifier", "save_classifier",
           "store_in_database"]

#: ``animegraph_file`` of a classifier file.
FILE_KIND = "animegraph emotion classifier"
#: Version of the file's layout (its classifier arrays carry their own ``format``).
FILE_VERSION = 1
#: Most bytes a classifier file may unpack to (a default classifier on 700 recordings
#: takes about 40 MB): a crafted archive is not decoded into gigabytes.
MAX_UNPACKED_BYTES = 2 << 30
_META = ("animegraph_file", "animegraph_file_version", "trained_on")


def save_classifier(classifier, path, trained_on: dict) -> Path:
    """Write the fitted ``classifier`` (probabilities fitted) to ``path`` atomically.

    Parameters
    ----------
    classifier : EmotionClassifier
    path : path
        The ``.npz`` to write.
    trained_on : dict
        JSON-serialisable description of the training data.
    """
    from db.atomic import atomic_write

    arrays = classifier.to_arrays()
    arrays.update(animegraph_file=np.array(FILE_KIND),
                  animegraph_file_version=np.array(FILE_VERSION),
                  trained_on=np.array(json.dumps(trained_on)))
    path = Path(path)
    with atomic_write(path) as handle:
        np.savez(handle, **arrays)
    return path


def _damaged(path: Path, why: str) -> DataError:
    return DataError(f"{path} is no usable emotion classifier ({why}): fit it again "
                     "(animegraph emotion fit DIR -o MODEL)")


def load_classifier(path):
    """The classifier in the file at ``path`` and what it was trained on.

    Returns
    -------
    (EmotionClassifier, dict)

    Raises
    ------
    DataError
        No such file; not an ``.npz``; an archive of something else, of a newer animegraph,
        too large, holding object arrays, or damaged (naming what).
    """
    from ingest.emotion.classifier import EmotionClassifier

    path = Path(path)
    if not path.is_file():
        raise DataError(f"emotion classifier file not found: {path}")
    try:
        with zipfile.ZipFile(path) as archive:
            unpacked = sum(info.file_size for info in archive.infolist())
        if unpacked > MAX_UNPACKED_BYTES:
            raise _damaged(path, f"it unpacks to {unpacked >> 20} MB, more than "
                           f"{MAX_UNPACKED_BYTES >> 20} MB")
        with np.load(path, allow_pickle=False) as stored:
            arrays = {key: stored[key] for key in stored.files}
    except zipfile.BadZipFile:
        raise DataError(f"{path} is not an animegraph emotion classifier (not an .npz "
                        "archive)") from None
    except (ValueError, OSError, EOFError, zipfile.LargeZipFile) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise _damaged(path, first) from None
    kind = arrays.get("animegraph_file")
    if kind is None or kind.shape != () or str(kind) != FILE_KIND:
        raise DataError(f"{path} is not an animegraph emotion classifier (an .npz of "
                        "something else)")
    version = arrays.get("animegraph_file_version")
    if version is None or version.shape != () or version.dtype.kind not in "iu":
        raise _damaged(path, "no file version")
    if int(version) > FILE_VERSION:
        raise DataError(f"{path} was written by a newer animegraph (file version "
                        f"{int(version)}; this one reads {FILE_VERSION}): upgrade")
    try:
        trained_on = json.loads(str(arrays.get("trained_on", "{}")))
    except ValueError:
        trained_on = None
    if not isinstance(trained_on, dict):
        raise _damaged(path, "trained_on is not a JSON object")
    try:
        classifier = EmotionClassifier.from_arrays(
            {k: v for k, v in arrays.items() if k not in _META})
    except DataError as exc:
        # Its message ends with the advice for a database ("re-ingest ..."): a file is
        # fitted again instead, which _damaged says.
        raise _damaged(path, str(exc).split(": re-ingest")[0].split(" (animegraph ingest")[0]
                       ) from None
    if classifier.calibrator_ is None:
        raise _damaged(path, "it was fitted without probabilities")
    return classifier, trained_on


def store_in_database(db_path, classifier, trained_on: dict, based_on: str | None = None) -> Path:
    """Store ``classifier`` into the database at ``db_path`` in place of its own (a new
    version, atomic, under the writer lock: :func:`db.store.write_model_arrays`), for
    ``classify --db`` and ``synth --emotion auto``. A later ``ingest`` learns the
    database's own again. ``based_on``: the version the caller read (refused if the
    database has moved on since).

    Raises
    ------
    DataError
        No database, one without an emotion model, or a class that is not one of the
        database's emotions (``synth --emotion auto`` could not use it).
    """
    from db.store import Database, write_model_arrays
    from ingest.emotion.model import PREFIX, classifier_entry

    db = Database.open(db_path)
    if based_on is not None and db.version_dir.name != based_on:
        raise DataError(f"database {db.root} changed while the classifier was fitted (it is "
                        f"now {db.version_dir.name}, was {based_on}); nothing written")
    emotion = db.manifest.get("emotion")
    if emotion is None:
        raise DataError(f"database {db.root} has no emotion model (it was built by an older "
                        f"animegraph): run 'animegraph ingest SRC --db {db.root}' once")
    check_classes(classifier.classes_, emotion.get("emotions", ()), db.root)
    arrays = {k: v for k, v in db.arrays().items()
              if not k.startswith(PREFIX + "classifier/")}
    stored, entry = classifier_entry(classifier)
    arrays.update(stored)
    entry["trained_on"] = trained_on
    manifest = {**db.manifest, "emotion": {**emotion, "classifier": entry}}
    return write_model_arrays(db.root, arrays, manifest, based_on=db.version_dir.name)


def check_classes(classes, emotions, where) -> None:
    """DataError unless every class is one of the database's ``emotions`` (spelled so)."""
    extra = sorted(str(c) for c in classes if str(c) not in set(emotions))
    if extra:
        raise DataError(f"the classifier's emotions {', '.join(extra)} are not in database "
                        f"{where} (it has {', '.join(emotions) or 'none'}): leave them out "
                        "(--emotions) or relabel them")
