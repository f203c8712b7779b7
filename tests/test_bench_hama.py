"""``scripts/bench_hama.py``: hama's cost per call, and a live stream's model."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_bench_hama_fits_a_line_and_counts_what_a_stream_hears(tmp_path):
    from ingest.speech import ctc

    if not ctc.available():
        pytest.skip("the hama phone engine is not installed")
    out = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "bench_hama.py"), "--lengths", "100", "400",
         "800", "--repeats", "2", "--settings", "300/40/40", "600/120/80",
         "--json", str(tmp_path / "out.json")],
        capture_output=True, text=True, timeout=900,
        env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert out.returncode == 0, out.stderr
    got = json.loads((tmp_path / "out.json").read_text())
    assert [c["ms"] for c in got["calls"]] == [100, 400, 800]
    assert all(c["cpu_ms"] > 0 for c in got["calls"])
    assert got["fit"]["ms_per_s_heard"] > 0  # a longer call costs more
    for row, heard, hop in zip(got["streams"], (380, 800), (40, 80), strict=True):
        assert row["heard_per_update_ms"] == pytest.approx(heard)
        # The track's model hears context + settled + hop per update: per second of
        # audio that many seconds over the hop (the stream's first updates hear the
        # silence before it, a little more).
        assert row["model_s_heard_per_s"] == pytest.approx(heard / hop, rel=0.05)


def test_bench_hama_says_a_bad_option_in_one_line():
    out = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "bench_hama.py"), "--repeats", "0"],
        capture_output=True, text=True, timeout=120,
        env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert "must be positive" in out.stderr.strip().splitlines()[-1]
