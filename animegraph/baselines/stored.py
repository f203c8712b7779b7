"""Which baseline models are stored with a database, and (mu-mlp, ppg-ridge) the model
itself, read without scikit-learn.

``animegraph info`` lists them, and a one-shot ``synth --guide mu-mlp`` predicts with the
stored model (:func:`load_forward`); importing :mod:`animegraph.baselines.base` (the
estimators) would import scikit-learn, SciPy and pandas for it.
"""

from __future__ import annotations

import json
from pathlib import Path

#: Key of the model description in a stored model's Parquet metadata.
META_KEY = b"animegraph.baseline"
#: Folder of stored baseline models inside a database folder.
MODELS_DIR = "baselines"


def stored_models(db_root) -> list[dict]:
    """What baseline models are stored with a database, read from their metadata only.

    Returns
    -------
    list of dict
        One per model file, sorted by method: ``method``, ``params``, ``n_channels``,
        ``fps``, ``emotions``, ``db_version``, ``bytes`` and ``current`` (fitted on the
        live version, so ``synth --method`` uses it; a stale model is refitted there).
        An unreadable file is listed with an ``error`` instead of the description.
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    from db.store import current_version

    root = Path(db_root)
    live = current_version(root)
    out = []
    for path in sorted((root / MODELS_DIR).glob("*/*.parquet")):
        row = {"method": path.stem, "db_version": path.parent.name,
               "current": path.parent.name == live, "bytes": path.stat().st_size}
        try:
            meta = json.loads(pq.read_schema(path).metadata[META_KEY])
        except (OSError, KeyError, TypeError, ValueError, pa.ArrowException) as exc:
            row["error"] = f"unreadable ({exc})"
        else:
            row |= {"params": meta["params"], "n_channels": len(meta["channels"]),
                    "fps": meta["fps"], "emotions": meta["emotions"]}
        out.append(row)
    return sorted(out, key=lambda r: (not r["current"], r["method"], r["db_version"]))


def model_path(db_root, method: str) -> Path:
    """Where the model ``method`` fitted on the live version of ``db_root`` is stored."""
    from db.store import current_version, own_folder

    root = Path(db_root)
    return own_folder(root, MODELS_DIR, current_version(root)) / f"{method}.parquet"



#: Largest reason file read (what :func:`record_unfit` writes is one line of a few hundred
#: bytes).
_MAX_REASON_BYTES = 64 << 10


def _unfit_path(db_root, method: str) -> Path:
    return model_path(db_root, method).with_suffix(".unfit")


def unfit_reason(db_root, method: str) -> str | None:
    """Why ``method`` could not be fitted on the live version of ``db_root``, as
    :func:`record_unfit` kept it, or None. The text comes from a database folder (someone
    else's): only its first line, printable characters, at most 300 of them."""
    from db.errors import DataError
    from ingest.formats.text import read_bytes

    try:  # a file only (a FIFO would block), and no more than a reason's worth of it
        data = read_bytes(_unfit_path(db_root, method), "reason", _MAX_REASON_BYTES)
    except DataError:
        return None
    text = data.decode("utf-8", errors="replace")
    line = "".join(c for c in (text.splitlines() or [""])[0] if c.isprintable())[:300]
    return line or "no reason kept"


def record_unfit(db_root, method: str, reason: str) -> None:
    """Keep why ``method`` cannot be fitted on the live version of ``db_root``, so that a
    default use (``synth``'s audio-only guide) does not fit it again on every run; a new
    version (another ingest) tries again. Written under the database's writer lock, as
    a fitted model is saved (:func:`animegraph.baselines.base.save_model`): the version
    cannot move, nor its stale folders be removed, under the write. A database that
    cannot be written, or that another process is writing (not waited for: a reason is
    a saving, not a result), is left as it is."""
    from db.atomic import atomic_write
    from db.errors import DataError
    from db.lock import writer_lock

    _unfit_path(db_root, method)  # a database, before its folder is locked
    try:
        with writer_lock(db_root, wait=0.0, what="database"):
            path = _unfit_path(db_root, method)  # the version the lock holds still
            path.parent.mkdir(parents=True, exist_ok=True)
            with atomic_write(path) as handle:
                handle.write(reason.encode("utf-8"))
    except (OSError, DataError):  # BusyError is a DataError
        pass

#: Stored models :func:`load_forward` restores without scikit-learn: method -> class.
FORWARD = {"mu-mlp": "animegraph.baselines.mu_mlp_forward:StoredMuMlp",
           "ppg-ridge": "animegraph.baselines.ppg_forward:StoredPpgRidge"}


def load_forward(db_root, method: str):
    """The stored ``method`` model of the live database version, restored without
    scikit-learn (:data:`FORWARD`), or None if none is stored or the method has no such
    restorer (then :func:`animegraph.baselines.base.fitted_model`).

    Raises
    ------
    DataError
        If the stored file is unreadable, or its channels are not the database's.
    """
    from importlib import import_module

    import pyarrow as pa
    import pyarrow.parquet as pq

    from db.errors import DataError
    from db.store import Database, arrays_from_table

    path = model_path(db_root, method)
    if method not in FORWARD or not path.is_file():
        return None
    module, name = FORWARD[method].split(":")
    try:  # ParquetFile, not read_table: that imports pyarrow.dataset (and pandas)
        table = pq.ParquetFile(path).read()
        meta = json.loads(table.schema.metadata[META_KEY])
        model = getattr(import_module(module), name).from_arrays(arrays_from_table(table),
                                                                 meta)
    except (OSError, KeyError, ValueError, TypeError, IndexError, pa.ArrowException) as exc:
        raise DataError(f"stored model {path} is unreadable ({exc})") from exc
    channels = Database.open(db_root).table("channels").column("name").to_pylist()
    model.check_channels(channels, f"database {db_root}")
    model.check_restored(str(path))
    return model
