"""Held-out scoring (animegraph.apps.evaluate): the k-best rows, context-ranked or not."""

from __future__ import annotations

import numpy as np

from animegraph.apps import evaluate
from animegraph.synthesis import Model
from db.store import Database
from ingest.tables import prepared_from_database


def test_kbest_ctx_row_ranks_by_context_and_scores(tiny_db):
    model = Model.load(tiny_db[0])
    clip = prepared_from_database(Database.open(tiny_db[0]))[0]
    assert "kbest20-ctx" in evaluate.DEFAULT_METHODS
    phones, emotion, cands, cost = evaluate.heldout_query(model, clip)
    plain, _ = evaluate.method_motion(model, phones, cands, cost, "kbest4", emotion=emotion)
    ctx, jumps = evaluate.method_motion(model, phones, cands, cost, "kbest4-ctx",
                                        emotion=emotion)
    assert plain.shape == ctx.shape and np.isfinite(ctx).all()
    assert not np.allclose(plain, ctx)  # another ranking, other animes blended
    row = evaluate.score_heldout(model, clip, methods=("kbest20", "kbest20-ctx"))
    assert set(row["methods"]) == {"kbest20", "kbest20-ctx"}
    for scores in row["methods"].values():
        assert np.isfinite(scores["mouth_r"]) and scores["synth_s"] > 0


def test_grid_split_holds_out_every_fifth_clip_in_clip_id_order():
    from types import SimpleNamespace

    clips = [SimpleNamespace(clip_id=f"c{k:02d}") for k in (7, 3, 9, 0, 1, 2, 8, 4, 5, 6, 10)]
    train, test = evaluate.grid_split(clips)
    assert [c.clip_id for c in test] == ["c04", "c09"]
    assert [c.clip_id for c in train] == [f"c{k:02d}" for k in (0, 1, 2, 3, 5, 6, 7, 8, 10)]


def test_frames_filled_across_a_gap_are_not_scored(tiny_db):
    """A frame without observed truth (e.g. a video frame with no face, filled by holding
    the first tracked frame) is left out of every score."""
    from dataclasses import replace

    model = Model.load(tiny_db[0])
    clip = prepared_from_database(Database.open(tiny_db[0]))[0]
    missing = clip.missing.copy()  # the synthetic capture's own dropouts, and 15 frames more
    missing[:15] = True
    wild = clip.motion.copy()
    wild[:15] = wild[15]  # the filler's guess: the first observed frame held
    methods = ("kbest20",)
    clean = evaluate.score_heldout(model, replace(clip, missing=missing), methods=methods)
    held = evaluate.score_heldout(model, replace(clip, motion=wild, missing=missing),
                                  methods=methods)
    scored_all = evaluate.score_heldout(model, replace(clip, motion=wild), methods=methods)
    assert held["frames_scored"] == int((~missing.any(axis=1)).sum())
    assert scored_all["frames_scored"] == int((~clip.missing.any(axis=1)).sum())
    assert held["frames_scored"] < scored_all["frames_scored"] <= held["frames"]
    for key in ("mouth_r", "rmse_all", "rmse_lips"):
        assert held["methods"]["kbest20"][key] == clean["methods"]["kbest20"][key]
    assert held["methods"]["kbest20"]["rmse_all"] != scored_all["methods"]["kbest20"]["rmse_all"]
