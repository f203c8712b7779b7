"""The README's Python example runs as written (against the tiny database)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

README = Path(__file__).resolve().parents[1] / "README.md"


def _python_block(heading: str) -> str:
    text = README.read_text()
    section = text[text.index(heading):]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


def test_the_from_python_example_runs(tiny_db, tmp_path, monkeypatch):
    from ingest.formats.wav import write_wav
    from ingest.speech.espeak import speak

    utterance = speak("Bin blue at F two now.")
    write_wav(tmp_path / "speech.wav", utterance.audio, utterance.sample_rate)
    (tmp_path / "motion.db").symlink_to(tiny_db[0])
    monkeypatch.chdir(tmp_path)
    scope: dict = {}
    exec(_python_block("### From Python"), scope)  # noqa: S102 - our own README
    result = scope["result"]
    assert result.motion.ndim == 2 and len(result.motion) > 10
    assert np.isfinite(result.motion).all()
    assert result.emotion.search == "happy"
