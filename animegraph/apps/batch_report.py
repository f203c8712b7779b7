"""``OUT/report.csv`` of ``animegraph batch`` (:mod:`animegraph.apps.batch`): one row per
script line, rewritten atomically as lines finish."""

from __future__ import annotations

import csv
import io
from pathlib import Path

from animegraph.apps.script import ScriptLine
from db.atomic import atomic_write

#: Columns of ``OUT/report.csv``.
REPORT_COLUMNS = ("id", "status", "speaker", "speech", "path", "duration_s", "emotion",
                  "emotion_source", "motion_emotions", "jumps", "cost", "seconds",
                  "cpu_seconds", "warnings", "error")


def line_row(line: ScriptLine, *, status: str, error: str = "") -> dict:
    """A line's report row before it is made: what the script says, ``status``, ``error``."""
    row = dict.fromkeys(REPORT_COLUMNS, "")
    row.update(id=line.id, status=status, speaker=line.speaker,
               speech="recording" if line.audio is not None else "espeak",
               emotion=line.emotion.text or "none", emotion_source=line.emotion.source,
               error=error)
    return row


def write_report(path: Path, rows: list[dict]) -> Path:
    """``report.csv``: one row per script line, atomically."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=REPORT_COLUMNS, extrasaction="ignore",
                            lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    with atomic_write(path) as handle:
        handle.write(buffer.getvalue().encode())
    return path


def read_report(path: Path) -> list[dict]:
    """The rows of a ``report.csv``."""
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))
