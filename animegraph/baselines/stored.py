"""Which baseline models are stored with a database, read without scikit-learn.

``animegraph info`` lists them; importing :mod:`animegraph.baselines.base` (the
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
