"""The Parquet motion database and its SQL layer.

``db`` is the bottom layer of the project: it imports neither ``ingest`` nor
``animegraph``. It also holds the small vocabulary every layer shares (the error
hierarchy).
"""

from db.errors import AnimeGraphError, DataError, ParameterError

__all__ = ["AnimeGraphError", "DataError", "ParameterError"]
