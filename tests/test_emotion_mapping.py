"""The RBF emotion mapping F_ij (Cao et al. 2005, §5.2) and its cross-validation."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.base import clone

from animegraph.emotion.evaluate import (
    EmotionData,
    cross_validate,
    held_out,
    summarize,
    unit_cube_rms,
)
from animegraph.emotion.plots import plot_mapping, plot_split
from db.errors import DataError, ParameterError
from db.store import Database
from ingest.emotion.mapping import N_CENTRES, EmotionMapping
from ingest.emotion.model import EmotionModel


@pytest.fixture(scope="module")
def data(tiny_db):
    return EmotionData.load(Database.open(tiny_db[0]))


@pytest.mark.parametrize("kernel", ["exp", "gauss"])
def test_mapping_interpolates_its_centres(rng, kernel):
    x = rng.normal(size=(400, 3))
    y = x + np.column_stack([np.sin(x[:, 0]), x[:, 1] ** 2, np.ones(400)])
    f = EmotionMapping(n_centres=50, kernel=kernel).fit(x, y)
    assert f.centres_.shape == (50, 3) and f.coef_.shape == (50, 3)
    np.testing.assert_allclose(f.transform(f.centres_), f.targets_, atol=1e-8)
    assert f.transform(x).shape == x.shape
    g = EmotionMapping.from_arrays(f.to_arrays())
    np.testing.assert_allclose(g.transform(x), f.transform(x))
    assert clone(f).get_params() == f.get_params()
    assert EmotionMapping().n_centres == N_CENTRES == 250


def test_mappings_from_one_source_share_its_clustering(rng):
    x = rng.normal(size=(300, 3))
    y1, y2 = x + 1.0, np.tanh(x)
    clusters: dict = {}
    shared = [EmotionMapping(n_centres=40).fit(x, y, clusters=clusters) for y in (y1, y2)]
    assert len(clusters) == 1  # one K-means for both targets
    alone = [EmotionMapping(n_centres=40).fit(x, y) for y in (y1, y2)]
    for a, b in zip(shared, alone, strict=True):
        np.testing.assert_array_equal(a.centres_, b.centres_)
        np.testing.assert_array_equal(a.coef_, b.coef_)
    EmotionMapping(n_centres=40, random_state=1).fit(x, y1, clusters=clusters)
    EmotionMapping(n_centres=40).fit(x[:200], y1[:200], clusters=clusters)
    assert len(clusters) == 3  # another seed, other samples: clustered anew


def test_mapping_with_offset_falls_back_to_the_mean_offset(rng):
    x = rng.normal(size=(300, 2))
    y = x + 3.0
    far = np.full((1, 2), 50.0)
    plain = EmotionMapping(n_centres=30).fit(x, y)
    offset = EmotionMapping(n_centres=30, offset=True).fit(x, y)
    np.testing.assert_allclose(plain.transform(far), far, atol=1e-6)
    np.testing.assert_allclose(offset.transform(far), far + 3.0, atol=1e-6)


def test_mapping_rejects_bad_input(rng):
    with pytest.raises(ParameterError):
        EmotionMapping(kernel="cubic").fit(np.ones((5, 2)), np.ones((5, 2)))
    with pytest.raises(ParameterError):
        EmotionMapping().fit(rng.normal(size=(5, 2)), rng.normal(size=(4, 2)))
    with pytest.raises(DataError):
        EmotionMapping().fit(np.ones((5, 2)), np.ones((5, 2)))


def test_database_holds_every_mapping_and_the_classifier(tiny_db):
    model = EmotionModel.from_database(Database.open(tiny_db[0]))
    assert len(model.emotions) == 5
    assert len(model.mappings) == 20  # every ordered pair: 3 parallel sentences each
    assert model.classifier is not None and set(model.classifier.classes_) == set(model.emotions)
    ics = np.random.default_rng(0).normal(size=(30, len(model.split.labels)))
    out = model.map_components(ics, "neutral", "happy")
    keep = [k for k in range(ics.shape[1]) if k not in model.split.emotion_components]
    np.testing.assert_array_equal(out[:, keep], ics[:, keep])
    mix = model.map_components(ics, "neutral", {"happy": 0.5, "neutral": 0.5})
    e = model.split.emotion_components
    np.testing.assert_allclose(mix[:, e], 0.5 * (out[:, e] + ics[:, e]))
    with pytest.raises(ParameterError, match="not in the database"):
        model.mapping("neutral", "bored")


def test_unit_cube_rms():
    rng = np.random.default_rng(1)
    names = [f"m{i}.{a}" for i in range(4) for a in "xyz"]
    truth = rng.uniform(0, 10, size=(20, 12))
    assert unit_cube_rms(truth, truth, names) == 0.0
    shifted = truth.copy()
    shifted[:, 0::3] += 1.0  # every marker 1 along x
    extent = np.ptp(truth.reshape(-1, 3), axis=0).max()
    assert unit_cube_rms(shifted, truth, names) == pytest.approx(1.0 / extent)


def test_cross_validation_beats_no_mapping(data):
    rows = cross_validate(data, [("neutral", "happy"), ("sad", "happy")])
    assert {r["n_train"] for r in rows} == {2}
    summary = summarize(rows)
    assert summary[-1]["src"] == "all" and summary[-1]["n"] == len(rows) == 12
    for s in summary:
        assert s["mapped"] < s["none"]


def test_plots(data, tmp_path):
    plot_split(data.model.split, tmp_path / "split.png")
    parallel = data.parallel()
    h = held_out(data, "neutral", "happy", parallel.sentences("neutral", "happy")[-1],
                 parallel=parallel)[0]
    plot_mapping(h, data.names, tmp_path / "fig7.png",
                 rms={"mapped": 0.01, "none": 0.02, "offset": 0.01})
    assert (tmp_path / "split.png").stat().st_size > 10_000
    assert (tmp_path / "fig7.png").stat().st_size > 10_000
