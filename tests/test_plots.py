"""Evaluation plots: one held-out clip's mouth opening, recorded against synthesized."""

from __future__ import annotations

import numpy as np
import pytest

from animegraph.apps.plots import plot_heldout, plot_systems
from animegraph.motion import measures
from animegraph.synthesis import Model
from db.store import Database
from ingest.tables import prepared_from_database


@pytest.fixture(scope="module")
def model_and_clip(tiny_db):
    clips = prepared_from_database(Database.open(tiny_db[0]))
    return Model.load(tiny_db[0]), clips[0]


def _image(path):
    import matplotlib.image

    return matplotlib.image.imread(path)


def test_plot_heldout_draws_every_search_method(model_and_clip, tmp_path):
    model, clip = model_and_clip
    path = plot_heldout(model, clip, tmp_path / "heldout.png", methods=("exact", "random"))
    img = _image(path)
    assert img.shape[:2] == (385, 1210)  # 11 x 3.5 in at 110 dpi
    assert img[..., :3].std() > 0.05  # not a blank canvas


def test_plot_systems_overlays_each_prediction(model_and_clip, tmp_path):
    model, clip = model_and_clip
    truth = clip.motion.astype(np.float64)
    flat = np.repeat(truth.mean(axis=0, keepdims=True), len(truth), axis=0)
    one = _image(plot_systems(clip, {"mean pose": flat}, model.names, model.kind,
                              tmp_path / "one.png"))
    two = _image(plot_systems(clip, {"mean pose": flat, "recorded again": truth},
                              model.names, model.kind, tmp_path / "two.png"))
    assert one.shape == two.shape and np.abs(one - two).max() > 0  # the second line shows
    assert measures.mouth_opening(flat, model.names, model.kind).std() == pytest.approx(0)


def test_plot_systems_can_show_the_first_seconds_only(model_and_clip, tmp_path):
    model, clip = model_and_clip
    truth = clip.motion.astype(np.float64)
    whole = _image(plot_systems(clip, {"x": truth}, model.names, model.kind,
                                tmp_path / "whole.png"))
    part = _image(plot_systems(clip, {"x": truth}, model.names, model.kind,
                               tmp_path / "part.png", seconds=clip.duration / 3))
    same = _image(plot_systems(clip, {"x": truth}, model.names, model.kind,
                               tmp_path / "same.png", seconds=clip.duration + 1))
    assert part.shape == whole.shape and np.abs(part - whole).max() > 0
    np.testing.assert_array_equal(same, whole)  # a span past the end is the whole clip
