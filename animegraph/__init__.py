"""animegraph: expressive speech-driven facial animation from a motion-capture database.

After Cao, Faloutsos, Kohler & Pighin, "Expressive Speech-Driven Facial Animation"
(ACM TOG 24(4), 2005). ``animegraph`` reads what ``ingest`` writes into ``db``; it is
laid out in rooms, each importing only the ones listed before it:

* :mod:`animegraph.motion` -- motion files and the measures taken on motion;
* :mod:`animegraph.search` -- the Anime Graph and its search (§4.1-4.2);
* :mod:`animegraph.emotion` -- emotion requests and mappings in synthesis (§5-6);
* :mod:`animegraph.synthesis` -- speech in, facial motion out (§4.2-4.3);
* :mod:`animegraph.face` -- mesh deformation, rendering and glTF (§7);
* :mod:`animegraph.baselines` -- the three published systems it is measured against;
* :mod:`animegraph.apps` -- the command line, demo, batch, query, plots, evaluation.

The names most users need are importable from here (loaded on first use, so that
``import animegraph`` stays quick): :func:`synthesize`, :class:`Model`,
:class:`SearchWeights`, :class:`AnimeGraph`, :class:`Motion`, the baseline estimators
(:class:`MuMlp`, :class:`HierPca`, :class:`AVHMMBaseline`) and the estimators learned at
ingest (:class:`MotionDecomposer`, :class:`EmotionClassifier`, :class:`EmotionMapping`).
"""

from importlib import import_module

from db.errors import AnimeGraphError, DataError, ParameterError

__version__ = "0.1.0"

#: Public name -> the module that defines it (imported on first access).
_LAZY = {
    "synthesize": "animegraph.synthesis",
    "Model": "animegraph.synthesis",
    "Synthesis": "animegraph.synthesis",
    "PostOptions": "animegraph.synthesis",
    "SearchWeights": "animegraph.search",
    "AnimeGraph": "animegraph.search",
    "Motion": "animegraph.motion.files",
    "read_motion": "animegraph.motion.files",
    "MuMlp": "animegraph.baselines.mu_mlp",
    "HierPca": "animegraph.baselines.hier_pca",
    "AVHMMBaseline": "animegraph.baselines.av_hmm",
    "MotionDecomposer": "ingest.decompose",
    "EmotionClassifier": "ingest.emotion.classifier",
    "EmotionMapping": "ingest.emotion.mapping",
}

__all__ = ["AnimeGraphError", "DataError", "ParameterError", "__version__", *_LAZY]


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'animegraph' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
