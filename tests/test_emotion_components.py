"""Speech vs emotion components (Cao et al. 2005, §5.1.3) against the synthetic corpus' truth."""

from __future__ import annotations

import numpy as np
import pytest

from animegraph.emotion.evaluate import EmotionData, component_truth, read_controls
from db.store import Database
from ingest.corpus.face import EMOTION_CONTROLS, SPEECH_CONTROLS
from ingest.emotion.align import dtw_path, sample_at, warp_positions
from ingest.emotion.components import split_components


@pytest.fixture(scope="module")
def data(tiny_db):
    return EmotionData.load(Database.open(tiny_db[0]))


def test_numpy_dtw_matches_the_numba_kernel(rng):
    from animegraph.search.dtw import dtw

    for n, m in ((1, 5), (7, 7), (23, 31), (40, 12)):
        x, y = rng.normal(size=(n, 3)), rng.normal(size=(m, 3))
        np.testing.assert_array_equal(dtw_path(x, y), dtw(x, y).path)


def test_decimated_alignment_recovers_a_known_time_warp():
    t = np.arange(600) / 120.0
    x = np.column_stack([np.sin(2 * np.pi * 1.3 * t), np.cos(2 * np.pi * 0.7 * t)])
    warp = 1.25 * t  # y plays x 25 % slower
    y = np.column_stack([np.sin(2 * np.pi * 1.3 * np.arange(750) / 150.0),
                         np.cos(2 * np.pi * 0.7 * np.arange(750) / 150.0)])
    path = dtw_path(x[::4], y[::4])
    where = warp_positions(path, len(x), len(y), 4)
    assert np.median(np.abs(where - warp * 120.0)) < 3.0
    assert np.abs(sample_at(y, where) - x).mean() < 0.05


def test_split_finds_the_emotion_the_generator_put_there(data, tiny_corpus):
    """Every component that follows the rig's emotion controls (smile, brows, lip-corner
    depression, lip press) is labelled emotion, every one that follows articulation
    (jaw, rounding, closure ...) speech."""
    controls, names = read_controls(tiny_corpus, data.clip_ids)
    truth = component_truth(data.sources, controls, names, SPEECH_CONTROLS, EMOTION_CONTROLS)
    labels = data.model.split.labels
    kinds = [t["truth"] for t in truth]
    assert "emotion" in kinds and "speech" in kinds
    for t, label in zip(truth, labels, strict=True):
        if t["truth"] != "other":
            assert label == t["truth"], (t, label)
    # The held expressions each live in an emotion component.
    U = np.concatenate(data.sources)
    C = np.concatenate([c[:len(s)] for c, s in zip(controls, data.sources, strict=True)])
    emotion = data.model.split.emotion_components
    for name in ("smile", "lip_corner_depress", "brow_lower"):
        r = [abs(np.corrcoef(U[:, k], C[:, names.index(name)])[0, 1]) for k in emotion]
        assert max(r) > 0.6, name


def test_scores_and_labels_are_in_the_database(tiny_db):
    db = Database.open(tiny_db[0])
    rows = db.table("components").to_pylist()
    assert {"label", "speech_score", "emotion_score", "emotion_baseline",
            "emotion_pair"} <= set(rows[0])
    entry = db.manifest["emotion"]
    assert entry["emotion_components"] == [r["component"] for r in rows
                                           if r["label"] == "emotion"]
    assert all(0.0 <= r["speech_score"] <= 1.0 for r in rows)


def test_info_lists_every_component_with_its_scores(tiny_db, capsys):
    from animegraph.apps.cli import main

    assert main(["info", "--db", str(tiny_db[0])]) == 0
    out = capsys.readouterr().out
    assert "emotion (same-emotion baseline; pair)" in out and "mappings:" in out
    n = len(Database.open(tiny_db[0]).table("components"))
    assert sum(1 for line in out.splitlines()
               if line.strip().split(" ")[0].isdigit() and " Hz " in line) == n


def test_without_parallel_sentences_nothing_is_called_emotion(rng):
    sources = [rng.normal(size=(50, 3)) for _ in range(4)]
    motions = [s @ rng.normal(size=(3, 6)) for s in sources]
    split = split_components(sources, motions, ["happy", "sad", "happy", "sad"],
                             ["a", "b", "c", "d"], rng.normal(size=(3, 6)),
                             np.array([True] * 3 + [False] * 3), fps=30.0)
    assert np.isnan(split.emotion_score).all()
    assert "emotion" not in split.labels
