"""Baseline speech-to-face methods, measured side by side with the Anime Graph (issue #8).

Methods (:data:`METHODS`): ``anime-graph`` (this project: search of recorded motion,
:mod:`animegraph.synthesis`), ``mu-mlp`` (Hong, Wen & Huang 2002, :mod:`.mu_mlp`),
``hier-pca`` (Cosker et al., :mod:`.hier_pca`) and ``av-hmm`` (Terissi et al. 2013,
:mod:`.av_hmm`), the three papers' compact statistical audio-to-visual mappings; and,
beyond the papers, ``ppg-ridge`` (:mod:`.ppg_ridge`: a ridge regression of phone
posteriorgrams, a speaker-independent guide for the audio-only path).

The contract every baseline follows
-----------------------------------
* One module per method defining one subclass of
  :class:`animegraph.baselines.base.BaselineModel` (a scikit-learn ``BaseEstimator``)
  with ``method = "<name>"``; :data:`ESTIMATORS` maps the name to ``"module:Class"``.
* Constructor arguments are the hyper-parameters, with the paper's constants as
  defaults (named module constants, cited by section), stored unchanged.
* ``fit(clips)`` accepts a database, its path, a list of
  :class:`ingest.prepare.PreparedClip` or a :class:`.data.TrainingSet`; the base class
  turns it into a ``TrainingSet`` (per clip ``audio`` float32, ``sample_rate``,
  ``motion`` (n_frames, n_channels) at ``fps``, ``emotion``, ``phones``), sets
  ``channels_``, ``groups_``, ``kind_``, ``fps_``, ``emotions_`` and calls
  ``_fit(data)``.
* ``predict(audio, sample_rate, *, emotion=None, n_frames=None)`` validates its input
  and calls ``_predict(audio, sample_rate, times, emotion)`` which returns motion at
  ``times`` (s), shape (len(times), n_channels), in the database's space.
* ``_arrays()`` returns the learned state as named float arrays and ``_restore(arrays)``
  sets it back (after the constructor ran with the stored parameters): trained models
  are stored as arrays, never pickles (:func:`.base.save_model`).
* Too little data (fewer frames than parameters: :func:`.base.check_enough`; an emotion
  with no clips) raises :class:`db.errors.DataError` with one clear line; bad arguments
  raise :class:`db.errors.ParameterError`.
* Audio features: :func:`.data.audio_features` (MFCCs at motion-frame times with
  edge-padded context).

Imports: ``db``, ``ingest`` and :mod:`animegraph.motion` (the measures) -- never the
search or synthesis they are compared with.
"""

from __future__ import annotations

from importlib import import_module

from db.errors import ParameterError

#: Every synthesis method, the project's own first.
METHODS = ("anime-graph", "mu-mlp", "hier-pca", "av-hmm", "ppg-ridge")
#: Where each baseline's estimator lives.
ESTIMATORS = {
    "mu-mlp": "animegraph.baselines.mu_mlp:MuMlp",
    "hier-pca": "animegraph.baselines.hier_pca:HierPca",
    "av-hmm": "animegraph.baselines.av_hmm:AVHMMBaseline",
    "ppg-ridge": "animegraph.baselines.ppg_ridge:PpgRidge",
}
BASELINES = tuple(ESTIMATORS)


def estimator_class(method: str):
    """The estimator class of a baseline ``method``.

    Raises
    ------
    ParameterError
        For an unknown method, or ``anime-graph`` (not an estimator of this kind).
    """
    if method not in ESTIMATORS:
        raise ParameterError(f"unknown baseline method {method!r} (choose from "
                             f"{', '.join(BASELINES)})")
    module, name = ESTIMATORS[method].split(":")
    try:
        return getattr(import_module(module), name)
    except (ImportError, AttributeError) as exc:
        raise ParameterError(f"method {method!r} is not available yet ({exc})") from exc


def make_estimator(method: str, **params):
    """A new, unfitted estimator of ``method`` with ``params``."""
    return estimator_class(method)(**params)
