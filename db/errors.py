"""The project's exception hierarchy (after librosa's ``util/exceptions.py``).

Every error a user can cause derives from :class:`AnimeGraphError`; the command-line
tool turns these into one readable line and a non-zero exit. Any other exception is
a bug and keeps its traceback.
"""


class AnimeGraphError(Exception):
    """Base class for every error a user can cause."""


class ParameterError(AnimeGraphError, ValueError):
    """A parameter has an invalid value (names the parameter and the value received)."""


class DataError(AnimeGraphError):
    """Input data (a file, a clip, a database) is missing, corrupt or inconsistent."""


class BusyError(DataError):
    """A folder (a database) is being written by another process, past the wait allowed."""
