"""``animegraph demo`` on the embedded default data, as a new user runs it."""

from __future__ import annotations

import json

import numpy as np

from animegraph.apps.cache import CACHE_ENV, default_corpus_dir, default_db_dir
from animegraph.apps.cli import main
from animegraph.apps.demo import DEMO_SENTENCE
from db.store import Database, current_version
from ingest.corpus.sentences import cmudict, words
from ingest.corpus.synthetic import CorpusConfig, plan_corpus
from ingest.formats.c3d import read_c3d


def test_demo_sentence_is_held_out_and_pronounceable():
    texts = {s.text for s in plan_corpus(CorpusConfig())}
    assert DEMO_SENTENCE not in texts
    assert all(w in cmudict() for w in words(DEMO_SENTENCE))


def test_demo_creates_then_reuses_the_default_corpus(tmp_path, capsys, monkeypatch):
    # A cache folder of its own: the session's is shared by the other tests of this
    # worker, some of which need the default database absent (test_first_hour.py).
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "cache"))
    out = tmp_path / "demo"
    # --no-prepare: the guides' fit beside the demo is tests/test_prepare.py's
    assert main(["demo", "--out", str(out), "--quiet", "--no-prepare"]) == 0
    first = capsys.readouterr().out
    assert "generated" in first and "built" in first
    db = Database.open(default_db_dir())
    assert db.manifest["n_clips"] == len(plan_corpus(CorpusConfig()))
    assert "every one has matching animes" in first
    # the guides of speech alone left unfitted: it says so, and how to fit them
    assert "fits its guides first (mu-mlp about" in first and "animegraph warmup" in first
    meta = json.loads((default_corpus_dir() / "corpus.json").read_text())
    assert meta["n_clips"] == len(plan_corpus(CorpusConfig()))
    assert meta["duration_s"] >= 300  # at least five minutes of speech

    png = out / "demo.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    video = out / "demo_happy_synthesized.mp4"
    assert video.read_bytes()[4:8] == b"ftyp" and str(video) in first
    motion = read_c3d(out / "demo_happy.c3d")
    assert motion.points.shape[1] >= 60 and np.isfinite(motion.points).mean() > 0.98

    stamp = (default_corpus_dir() / "corpus.json").stat().st_mtime_ns
    assert main(["demo", "--out", str(out), "--quiet", "--emotion", "sad", "--no-prepare"]) == 0
    second = capsys.readouterr().out
    assert "(reused" in second and "reused;" in second
    assert (default_corpus_dir() / "corpus.json").stat().st_mtime_ns == stamp
    assert current_version(default_db_dir()) == "v000001"
    assert (out / "demo_sad.wav").exists()
