"""Arrow columns to NumPy, and a constant string column, without importing pandas.

pyarrow imports pandas (a third of a second or more) the first time it converts to or
from Python or NumPy objects (``to_numpy``, ``pa.array``, ``pa.scalar``, ``fill_null``
with a Python value), even when no pandas object is involved. A one-shot ``animegraph
synth`` only reads numeric and string columns, so these helpers read the Arrow buffers
directly: the same values, the same NumPy dtype (``tests/test_arrow.py`` compares them
with ``to_numpy``).
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa


def numbers(values: pa.Array | pa.ChunkedArray, null=None) -> np.ndarray:
    """A numeric (integer or floating) Arrow column as a NumPy array of its dtype.

    Parameters
    ----------
    values : pa.Array or pa.ChunkedArray, shape (n,)
    null : number, optional
        Value for nulls. Without it a column with nulls is converted by ``to_numpy``
        (floats with NaN, as pyarrow does; this imports pandas).

    Returns
    -------
    np.ndarray, shape (n,)
        A copy, dtype the column's (``int64`` for ``int64`` ...).

    Raises
    ------
    TypeError
        If the column is not numeric.
    """
    if isinstance(values, pa.ChunkedArray):
        values = values.combine_chunks()
    kind = values.type
    if pa.types.is_floating(kind):
        code = "f"
    elif pa.types.is_unsigned_integer(kind):
        code = "u"
    elif pa.types.is_integer(kind):
        code = "i"
    else:
        raise TypeError(f"not a numeric column: {kind}")
    dtype = np.dtype(f"<{code}{kind.bit_width // 8}")
    if len(values) == 0:
        return np.empty(0, dtype=dtype)
    if values.null_count and null is None:
        return values.to_numpy(zero_copy_only=False)
    validity, data = values.buffers()[:2]
    out = np.frombuffer(data, dtype=dtype, count=len(values),
                        offset=values.offset * dtype.itemsize).copy()
    if values.null_count:
        bits = np.unpackbits(np.frombuffer(validity, dtype=np.uint8), bitorder="little")
        out[~bits[values.offset:values.offset + len(values)].astype(bool)] = null
    return out


def repeat_string(value: str, n: int) -> pa.Array:
    """A string column of ``n`` copies of ``value`` (like ``pa.array([value] * n)``)."""
    data = value.encode()
    offsets = np.arange(n + 1, dtype=np.int32) * len(data)
    return pa.StringArray.from_buffers(n, pa.py_buffer(offsets), pa.py_buffer(data * n))
