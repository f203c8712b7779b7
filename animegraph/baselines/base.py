"""The estimator contract of the baselines, and how trained models are stored.

A trained model is a dict of named float arrays (:meth:`BaselineModel.to_arrays`) plus a
small JSON description (:meth:`BaselineModel.describe`: method, hyper-parameters,
channels, frame rate, emotions). It is stored as one Parquet file of rows (name, shape,
values) — :func:`db.store.arrays_to_table`, no pickles — with the description in the
file's metadata, under the database folder::

    DB/baselines/<version>/<method>.parquet

``<version>`` is the database version the model was fitted on (``v000003``), so a
re-ingest makes a stale model invisible; folders of versions that no longer exist are
removed when a model is saved.

A model is fitted and saved under the database's writer lock (:mod:`db.lock`): the
version cannot change under the fit, and a process needing a model another is fitting
(a ``synth`` while the demo fits its guides beside it) waits for that fit and takes the
stored model, rather than fitting the same model again on the same cores, which is
never sooner and leaves the two to overwrite each other.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import ClassVar

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.utils.validation import check_is_fitted
from threadpoolctl import threadpool_limits

from animegraph.baselines.data import TrainingSet, resample_to, training_set
from animegraph.baselines.predicting import BLAS_THREADS, Predicting
from animegraph.baselines.stored import META_KEY, MODELS_DIR, model_path
from db.errors import DataError


class BaselineModel(Predicting, BaseEstimator):
    """An audio-to-visual mapping fitted on clips of one motion database.

    Subclasses set :attr:`method` and implement ``_fit(data)``, ``_predict(audio,
    sample_rate, times, emotion)``, ``_arrays()`` and ``_restore(arrays)``; every
    constructor argument is a hyper-parameter with the paper's value as its default
    (scikit-learn convention: stored unchanged, validated in ``fit``).

    Fitted attributes common to all methods: ``channels_``, ``groups_`` (tuple of str),
    ``kind_``, ``fps_`` (the training frame rate) and ``emotions_`` (labels seen).
    """

    method: ClassVar[str] = ""

    # -- the scikit-learn API -------------------------------------------------------
    #: What fitting it is, for the line said before a first use's fit (with a progress
    #: bar on stderr for those that take minutes: :func:`fit_progress`).
    FIT_WHAT: ClassVar[str] = ""

    def fit(self, clips, y=None) -> BaselineModel:
        """Fit on ``clips``: a database (or its path), prepared clips or a TrainingSet.

        Raises
        ------
        DataError
            Too little data for the model's parameters, clips of several channel layouts.
        """
        data = training_set(clips)
        self.channels_ = data.names
        self.groups_ = data.groups
        self.kind_ = data.kind
        self.fps_ = float(data.fps)
        self.emotions_ = data.emotions
        with threadpool_limits(limits=BLAS_THREADS):
            self._fit(data)
        return self

    # -- to be implemented ---------------------------------------------------------
    def _fit(self, data: TrainingSet) -> None:
        raise NotImplementedError

    def _arrays(self) -> dict[str, np.ndarray]:
        raise NotImplementedError

    def _restore(self, arrays: dict[str, np.ndarray]) -> None:
        raise NotImplementedError

    # -- storage -------------------------------------------------------------------
    def describe(self) -> dict:
        """JSON-serialisable description: method, hyper-parameters, channels, fps."""
        check_is_fitted(self, "channels_")
        return {"method": self.method, "params": self.get_params(),
                "channels": list(self.channels_), "groups": list(self.groups_),
                "kind": self.kind_, "fps": self.fps_, "emotions": list(self.emotions_)}

    def to_arrays(self) -> dict[str, np.ndarray]:
        """The learned state as named float arrays (no pickles)."""
        check_is_fitted(self, "channels_")
        return {k: np.asarray(v, dtype=np.float64) for k, v in self._arrays().items()}

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray], description: dict) -> BaselineModel:
        """Rebuild a fitted model from :meth:`to_arrays` and :meth:`describe`."""
        if description.get("method") != cls.method:
            raise DataError(f"stored model is {description.get('method')!r}, not {cls.method!r}")
        # JSON has no tuples: sequence parameters come back as lists.
        model = cls(**{k: tuple(v) if isinstance(v, list) else v
                       for k, v in description["params"].items()})
        model._set_described(description)
        model._restore(dict(arrays))
        return model


def check_enough(n_samples: int, n_params: int, what: str, rate: float | None = None,
                 ) -> None:
    """Raise DataError if ``n_samples`` is fewer than ``n_params``; with the ``rate`` of
    the frames (a second), the message says the seconds needed too."""
    if n_samples < n_params:
        seconds = ("" if rate is None else f", {n_samples / rate:.1f} s where it needs "
                   f"{n_params / rate:.1f} s")
        raise DataError(f"too little data for {what}: {n_samples} frames for {n_params} "
                        f"parameters{seconds}")


def sample_times(clips, rate: float):
    """Frames of each of ``clips`` (TrainingClip) resampled at ``rate`` frames/s.

    Yields
    ------
    (clip, times (n,), motion (n, n_channels))
    """
    for clip in clips:
        times = clip_times(clip, rate)
        yield clip, times, resample_to(clip.motion, clip.fps, times)


def clip_times(clip, rate: float) -> np.ndarray:
    """The times (s) of a clip's (TrainingClip) frames resampled at ``rate`` frames/s
    (:func:`sample_times`): shape (n,)."""
    return np.arange(0.0, (clip.n_frames - 1) / clip.fps + 1e-9, 1.0 / rate)


# -- stored models ------------------------------------------------------------------
#: Seconds a fit waits for another writer of the database (another fit of the guides,
#: an ingest) before giving up: as long as ``animegraph ingest``'s own fit waits.
FIT_WAIT_S = 600.0


def save_model(model: BaselineModel, db_root) -> Path:
    """Store a fitted model with the database at ``db_root`` (atomic; see module doc)."""
    import pyarrow.parquet as pq

    from db.atomic import atomic_write
    from db.lock import writer_lock
    from db.store import arrays_to_table, current_version, dictionary_columns

    root = Path(db_root)
    table = arrays_to_table(model.to_arrays())
    current_version(root)  # a database, before its folder is locked
    with writer_lock(root, wait=FIT_WAIT_S, what="database"):
        path = model_path(root, model.method)
        path.parent.mkdir(parents=True, exist_ok=True)
        meta = {**model.describe(), "db_version": current_version(root)}
        table = table.replace_schema_metadata({META_KEY: json.dumps(meta).encode()})
        with atomic_write(path) as handle:
            pq.write_table(table, handle, use_dictionary=dictionary_columns(table))
        for stale in (root / MODELS_DIR).iterdir():
            if stale.is_dir() and not (root / stale.name).is_dir():
                shutil.rmtree(stale, ignore_errors=True)
    return path


def carry_models(db_root, from_version: str) -> list[str]:
    """Store again, under the live version of ``db_root``, the models fitted on its version
    ``from_version``: for a new version whose clips and motion are that one's (e.g. only
    its emotion classifier replaced), so its first ``synth`` does not fit them again.

    Returns
    -------
    list of str
        The methods carried (a model that can no longer be read is left behind).
    """
    from db.store import own_folder

    root = Path(db_root)
    carried = []
    for path in sorted(own_folder(root, MODELS_DIR, from_version).glob("*.parquet")):
        try:
            model = read_model(path)
        except DataError:
            continue
        save_model(model, root)
        carried.append(model.method)
    return carried


def read_model(path) -> BaselineModel:
    """Load a stored model file."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from animegraph.baselines import estimator_class
    from db.store import arrays_from_table

    try:
        table = pq.read_table(path)
        meta = json.loads(table.schema.metadata[META_KEY])
        cls = estimator_class(meta["method"])
        arrays = arrays_from_table(table)
    except (OSError, KeyError, ValueError, TypeError, pa.ArrowException) as exc:
        raise DataError(f"stored model {path} is unreadable ({exc})") from exc
    try:
        model = cls.from_arrays(arrays, meta)
    except (KeyError, ValueError, TypeError, IndexError) as exc:
        raise DataError(f"stored model {path} is unreadable ({exc})") from exc
    model.check_restored(str(path))
    return model


def load_model(db_root, method: str) -> BaselineModel | None:
    """The stored ``method`` model of the live database version, or None if there is none.

    Raises
    ------
    DataError
        If the stored model's channels are not the database's.
    """
    from db.store import Database

    path = model_path(db_root, method)
    if not path.is_file():
        return None
    model = read_model(path)
    channels = Database.open(db_root).table("channels").column("name").to_pylist()
    model.check_channels(channels, f"database {db_root}")
    return model


def fit_progress(total: int, what: str):
    """A progress bar on stderr (tqdm, when stderr is a terminal) for a fit's ``total``
    steps (EM iterations, clips): a first use's fit took minutes in silence."""
    import sys

    from tqdm import tqdm

    return tqdm(total=total, desc=what, file=sys.stderr, disable=None, leave=False,
                dynamic_ncols=True)


def fitting_line(method: str, db_root, purpose: str = "") -> str:
    """The line said once before ``method`` is fitted on a database on first use: what is
    fitted, that it is stored, and that a bar follows for the slow ones."""
    from animegraph.baselines import estimator_class

    what = estimator_class(method).FIT_WHAT
    return (f"fitting {method} on {db_root}{purpose} ({what + '; ' if what else ''}first "
            f"use: stored with the database) ...")


def fitted_model(db_root, method: str, *, refit: bool = False, data: TrainingSet | None = None,
                 on_wait=None, **params) -> BaselineModel:
    """The ``method`` model of a database: the stored one if there is one (whatever its
    parameters) unless ``refit``, else fitted with ``params`` on all its clips and stored.
    ``data``: the database's clips already read (:func:`training_set`), for several fits.

    The fit holds the database's writer lock (see the module doc), waiting up to
    :data:`FIT_WAIT_S` for another writer, with ``on_wait(holder)`` called once if it
    waits; a model stored meanwhile is taken instead of fitted (unless ``refit``).

    Raises
    ------
    BusyError
        If another process still writes the database after :data:`FIT_WAIT_S`.
    """
    from animegraph.baselines import estimator_class
    from db.lock import writer_lock
    from db.store import current_version

    cls = estimator_class(method)
    current_version(db_root)  # a database, before its folder is locked
    if not refit:
        model = load_model(db_root, method)
        if model is not None:
            return model
    with writer_lock(db_root, wait=FIT_WAIT_S, what="database", on_wait=on_wait):
        if not refit:  # fitted by the writer this one waited for
            model = load_model(db_root, method)
            if model is not None:
                return model
        model = cls(**params).fit(db_root if data is None else data)
        save_model(model, db_root)
    return model
