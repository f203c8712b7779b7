"""What the probe's sections share: the command line, how a run is judged (held: exit 0,
or exit 1 with one line and no traceback), and the small corpus and database they probe
(``scripts/probe_security.py``, ``scripts/bench_interrupt.py``)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

CLI = [sys.executable, "-m", "animegraph"]


def _run(args, timeout=600, **kw) -> subprocess.CompletedProcess:
    return subprocess.run(CLI + list(args), capture_output=True, text=True, timeout=timeout,
                          **kw)


def _held(proc: subprocess.CompletedProcess) -> bool:
    lines = [line for line in proc.stderr.splitlines()
             if line.strip() and "Warning" not in line and not line.startswith(" ")
             and "%|" not in line]  # a progress bar's line (tqdm) is no error
    if proc.returncode == 0:
        return "Traceback" not in proc.stderr
    return proc.returncode == 1 and len(lines) == 1 and "Traceback" not in proc.stderr


def _snapshot(folder: Path) -> dict:
    return {p: p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def setup(work: Path) -> tuple[Path, Path]:
    corpus, db = work / "corpus", work / "db"
    if not corpus.exists():
        subprocess.run(CLI + ["corpus", "synth", "--out", str(corpus), "--sentences", "2",
                              "--parallel", "1", "--variations", "1", "--seed", "18",
                              "--quiet"], check=True)
    if not db.exists():
        subprocess.run(CLI + ["ingest", str(corpus), "--db", str(db), "--quiet"], check=True,
                       capture_output=True)
    return corpus, db
