"""The stored model arrays' invariants (ingest/invariants.py) on real and damaged databases.

Usage::

    python scripts/check_model_arrays.py DB [DB ...]
    python scripts/check_model_arrays.py --fuzz SPEECH.wav [--refresh-checksum] DB
    valgrind --tool=callgrind python scripts/check_model_arrays.py --load-once [--no-checks] DB

Without ``--fuzz``: for each database, whether it loads (``Model.load``, which checks
every invariant), and the headroom of the round-off tolerances: the smallest multiple
of the round-off bound (``ingest.invariants.SAFETY``, 16 by default) at which it still
loads, found by bisection; 16 over it is how much larger the allowed deviations are
than the largest measured one. A database must load at the default: one that does not
is a false alarm.

With ``--fuzz``: each stored model array of ``DB`` (not the emotion classifier's; of
the emotion mappings and offsets only angry -> happy's) is corrupted in a copy five
ways (negated: -|v| - 1, zeroed, one NaN, its last column cut, times 1e30) and
``animegraph synth SPEECH.wav`` is run on it with and without ``--emotion happy``;
``--refresh-checksum`` writes the corrupted file's checksum into the copy's manifest, as a
deliberate editor would (without it a database with checksums refuses every change);
printed: the (corruption, exit status) counts, the arrays whose corruption was
accepted (exit 0), and the runs that were neither exit 0 nor one line (tracebacks).
The fuzz's counts are in docs/results/robustness.md ("Stored model arrays checked
when read").

With ``--load-once``: ``Model.load(DB)`` once and nothing else, for an instruction count
of the checks (``--no-checks`` replaces both check functions by no-ops).
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import io
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

import ingest.invariants as invariants
from animegraph.apps.cli import main
from animegraph.synthesis.model import Model
from db.errors import DataError

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from crafted import CORRUPTIONS, array_corrupted, edit_arrays  # noqa: E402  (the fuzz tests')


def loads(db: str, safety: float) -> bool:
    """True if ``db`` loads with the round-off tolerances at ``safety`` times the bound."""
    saved = invariants.SAFETY
    invariants.SAFETY = safety
    try:
        Model.load(db)
        return True
    except DataError:
        return False
    finally:
        invariants.SAFETY = saved


def headroom(db: str) -> None:
    ok = loads(db, invariants.SAFETY)
    lo, hi = 1e-6, invariants.SAFETY  # fails at lo (or passes everywhere), passes at hi
    if ok and loads(db, lo):
        hi = lo
    elif ok:
        for _ in range(30):
            mid = np.sqrt(lo * hi)
            lo, hi = (lo, mid) if loads(db, mid) else (mid, hi)
    print(f"{db}: loads at the default ({invariants.SAFETY:g}): {ok}; smallest passing "
          f"multiple {hi:.3g} (headroom {invariants.SAFETY / hi:.3g}x)" if ok else
          f"{db}: FALSE ALARM at the default")


def fuzz(db0: Path, wav: str, refresh: bool) -> None:
    version = (db0 / "CURRENT").read_text().strip()
    rows0 = pq.read_table(db0 / version / "model_arrays.parquet").to_pylist()
    names = [r["name"] for r in rows0 if not r["name"].startswith("emotion/classifier")
             and not (r["name"].startswith("emotion/map/") and "/angry/happy/" not in r["name"])
             and not (r["name"].startswith("emotion/offset/")
                      and not r["name"].endswith("angry/happy"))]
    runs, bad = [], []
    for name in names:
        for how in CORRUPTIONS:
            tmp = Path(tempfile.mkdtemp())
            db = tmp / "db"
            shutil.copytree(db0, db)
            edit_arrays(db, array_corrupted(name, how), checksum=refresh)
            for extra in ([], ["--emotion", "happy"]):
                err = io.StringIO()
                with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                    try:
                        rc = main(["synth", wav, "--db", str(db), "-o", str(tmp / "o.npz"),
                                   *extra])
                    except BaseException as exc:  # noqa: BLE001 -- counted, not raised
                        rc = f"EXC {type(exc).__name__}: {exc}"
                finite = True
                if rc == 0:
                    out = np.load(tmp / "o.npz")
                    finite = all(np.isfinite(out[k]).all() for k in out.files
                                 if out[k].dtype.kind == "f")
                runs.append((name, how, rc))
                if isinstance(rc, str) or "Traceback" in err.getvalue() or not finite:
                    bad.append((name, how, extra, rc if isinstance(rc, str) else
                                "non-finite output"))
            shutil.rmtree(tmp)
    for b in bad:
        print(b)
    print(collections.Counter((h, r) for _, h, r in runs))
    for n in sorted({n for n, h, r in runs if r == 0 and h in ("zeroed", "huge", "negated")}):
        print("accepted:", n, sorted({h for m, h, r in runs if m == n and r == 0}))
    print("runs:", len(runs), "bad:", len(bad))


def run() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("db", nargs="+")
    parser.add_argument("--fuzz", metavar="SPEECH.wav", help="corrupt the arrays of DB")
    parser.add_argument("--refresh-checksum", action="store_true",
                        help="update the manifest's checksum of each corrupted copy")
    parser.add_argument("--load-once", action="store_true", help="load DB's model once")
    parser.add_argument("--no-checks", action="store_true",
                        help="with --load-once: without the invariants' checks")
    args = parser.parse_args()
    if args.load_once:
        if args.no_checks:
            import animegraph.synthesis.model as model
            import ingest.emotion.model as emotion

            model.check_stored_decomposition = emotion.check_emotion = lambda *a, **k: None
        Model.load(args.db[0])
        return
    if args.fuzz:
        fuzz(Path(args.db[0]), args.fuzz, args.refresh_checksum)
        return
    for db in args.db:
        headroom(db)


if __name__ == "__main__":
    run()
