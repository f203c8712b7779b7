"""animegraph: expressive speech-driven facial animation from a motion-capture database.

After Cao, Faloutsos, Kohler & Pighin, "Expressive Speech-Driven Facial Animation"
(ACM TOG 24(4), 2005). ``animegraph`` holds the graph, search, synthesis, emotion,
rendering and the command-line tool; it reads what ``ingest`` writes into ``db``.
"""

from db.errors import AnimeGraphError, DataError, ParameterError

__version__ = "0.1.0"
__all__ = ["AnimeGraphError", "DataError", "ParameterError", "__version__"]
