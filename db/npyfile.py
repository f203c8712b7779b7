"""NumPy files from other people: their headers' sizes checked before anything is read.

A ``.npy`` header states the array's shape and dtype, and ``np.load`` allocates what it
states before reading the data: a 200-byte file claiming (10**12, 2) float64 asks for
14.6 TiB, a ``MemoryError`` (a traceback, and a whole ingest lost with it) or, below the
machine's memory, minutes of swapping. Here a header's size must fit the bytes that hold
the data, and an ``.npz`` member's unpacked size a bound (a zip bomb unpacks a small file
into a huge one). Only arrays of real numbers or of text are read: numpy would cast
complex numbers to their real part, booleans to 0 and 1, dates to numbers without a word.
Nothing here unpickles (:func:`numpy.load` is always called with ``allow_pickle=False``
by the callers).
"""

from __future__ import annotations

import math
import zipfile
from pathlib import Path
from typing import BinaryIO

import numpy as np

from db.errors import DataError

__all__ = ["MAX_NPZ_BYTES", "REAL_KINDS", "TEXT_KINDS", "check_npy", "check_npz", "holds"]

#: Largest total unpacked size of an ``.npz``'s arrays (a motion written by ``synth``:
#: 2 min of 1,411 channels at 60 fps is 81 MB).
MAX_NPZ_BYTES = 4 * 2**30
#: ``dtype.kind`` of arrays of real numbers (signed and unsigned integers, floats) and of
#: text: the only arrays read from other people's files.
REAL_KINDS = "iuf"
TEXT_KINDS = "US"
_HOLDS = {"b": "booleans", "i": "integers", "u": "integers", "f": "real numbers",
          "c": "complex numbers", "M": "dates", "m": "time spans",
          "O": "Python objects (a pickle)", "S": "text", "U": "text", "V": "records"}


def holds(dtype: np.dtype) -> str:
    """What an array of ``dtype`` holds, for a message: "complex numbers (complex128)"."""
    what = _HOLDS.get(dtype.kind, "values")
    return what if dtype.kind == "O" else f"{what} ({dtype})"


def _declared(handle: BinaryIO, name: str) -> tuple[int, int]:
    """(bytes the array's data need, bytes of the header) of the ``.npy`` at the handle's
    start; DataError for a malformed header."""
    try:
        version = np.lib.format.read_magic(handle)
        if version == (1, 0):
            shape, _, dtype = np.lib.format.read_array_header_1_0(handle)
        else:
            shape, _, dtype = np.lib.format.read_array_header_2_0(handle)
    except (ValueError, OSError, EOFError) as exc:
        raise DataError(f"unreadable or truncated array file {name}: {exc}") from None
    if dtype.kind not in REAL_KINDS + TEXT_KINDS:
        # An object dtype means a pickle, which is never loaded.
        raise DataError(f"{name} holds {holds(dtype)}; refused: only arrays of real numbers "
                        "or of text are read")
    return math.prod(shape) * dtype.itemsize, handle.tell()


def check_npy(path: Path) -> None:
    """DataError unless the ``.npy`` file's header asks for no more data than it holds,
    of real numbers or text."""
    with open(path, "rb") as handle:
        need, header = _declared(handle, str(path))
    have = Path(path).stat().st_size - header
    if need > have:
        raise DataError(f"unreadable or truncated array file {path}: its header declares "
                        f"{need} bytes of data, the file holds {have}")


def check_npz(path: Path, max_bytes: int = MAX_NPZ_BYTES) -> None:
    """DataError unless every array of the ``.npz`` declares what its member holds (real
    numbers or text), and they unpack to at most ``max_bytes`` together."""
    try:
        with zipfile.ZipFile(path) as archive:
            total = 0
            for info in archive.infolist():
                if not info.filename.endswith(".npy"):
                    continue
                total += info.file_size
                if total > max_bytes:
                    raise DataError(f"{path} unpacks to more than {max_bytes} bytes; refused")
                with archive.open(info) as member:
                    need, header = _declared(member, f"{path}:{info.filename}")
                if need > info.file_size - header:
                    raise DataError(f"unreadable or truncated array file {path}: "
                                    f"{info.filename} declares {need} bytes of data, holds "
                                    f"{info.file_size - header}")
    except (zipfile.BadZipFile, OSError, EOFError) as exc:
        raise DataError(f"unreadable .npz file {path}: {exc}") from None
