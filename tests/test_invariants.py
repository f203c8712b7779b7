"""A database's stored model arrays that contradict each other are refused when read
(:mod:`ingest.invariants`); those of a freshly learned model never are."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from crafted import ARRAY_MUTATIONS, crafted_database

from animegraph.apps.cli import main
from animegraph.synthesis.model import Model
from db.store import Database
from ingest.decompose import MotionDecomposer
from ingest.invariants import channel_ranges, check_decomposition, check_emotion
from ingest.motion import head_points


@pytest.fixture(scope="module")
def speech(tiny_corpus, tmp_path_factory):
    """A clip's speech with its phones beside it (a synth that would succeed)."""
    clip = sorted((tiny_corpus / "clips").glob("*_angry_1.wav"))[0]
    folder = tmp_path_factory.mktemp("speech")
    shutil.copy(clip, folder / "speech.wav")
    shutil.copy(clip.with_name(clip.stem + ".phones.csv"), folder / "speech.phones.csv")
    return folder / "speech.wav"


@pytest.mark.parametrize("mutation", sorted(ARRAY_MUTATIONS))
def test_contradicting_arrays_are_refused_by_synth_in_one_line(tiny_db, speech, tmp_path,
                                                               capsys, mutation):
    path = crafted_database(tiny_db[0], tmp_path / "db", mutation)
    name = mutation.partition(":")[2]
    for extra in ([], ["--emotion", "happy"]):
        status = main(["synth", str(speech), "--db", str(path), "-o",
                       str(tmp_path / "out.npz"), *extra])
        err = capsys.readouterr().err.strip()
        assert status == 1, (mutation, extra)
        assert "\n" not in err and "is damaged" in err and "model_arrays" in err, err
        # The line names the array (an emotion mapping's by its mapping).
        assert name.rsplit("/", 1)[0] in err or name in err, err
        assert not (tmp_path / "out.npz").exists()


def test_a_freshly_ingested_database_passes(tiny_db, speech, tmp_path):
    path = tiny_db[0]
    db = Database.open(path)
    channels = db.table("channels").to_pylist()
    ranges = channel_ranges(channels)
    frames = db.table("frames", columns=list(ranges))
    assert ranges == {name: (float(np.min(frames.column(name))),
                             float(np.max(frames.column(name)))) for name in ranges}
    assert channel_ranges([{k: v for k, v in c.items() if k not in ("min", "max")}
                           for c in channels]) is None  # an older database: not checked
    model = Model.load(path)
    assert model.emotion_model is not None and model.emotion_model.mappings
    assert main(["synth", str(speech), "--db", str(path), "-o", str(tmp_path / "o.npz"),
                 "--emotion", "happy"]) == 0


def test_a_changed_file_is_refused_by_its_checksum_an_old_database_opens(tiny_db, tmp_path):
    import json

    from db.errors import DataError

    path = crafted_database(tiny_db[0], tmp_path / "stale", "arrays_checksum_stale")
    with pytest.raises(DataError, match="SHA-256 differs"):
        Model.load(path)
    # The same database as written before checksums: the edit (a valid value) is read.
    manifest = Database.open(path).version_dir / "manifest.json"
    entry = json.loads(manifest.read_text())
    del entry["checksums"]
    manifest.write_text(json.dumps(entry))
    assert not Model.load(path).decomposer.ica_mean_.any()


def test_the_checks_see_what_synthesis_reads(tiny_db):
    db = Database.open(tiny_db[0])
    arrays = db.arrays()
    channels = db.table("channels").to_pylist()
    names = [c["name"] for c in channels]
    groups = [c["group"] for c in channels]
    args = (names, float(db.manifest["fps"]), int(db.manifest["n_frames"]),
            head_points(groups), channel_ranges(channels))
    check_decomposition(arrays, *args)
    # A scaled unmixing matrix with its inverse scaled back stays a valid pair: the
    # check is of relations, not of stored values.
    pair = {**arrays, "ica_unmixing": arrays["ica_unmixing"] * 2,
            "ica_mixing": arrays["ica_mixing"] / 2}
    check_decomposition(pair, *args)
    with pytest.raises(ValueError, match="ica_mixing"):
        check_decomposition({**arrays, "ica_mixing": arrays["ica_mixing"] * 2}, *args)
    with pytest.raises(ValueError, match="ic_cutoff_hz"):
        check_decomposition({**arrays, "ic_cutoff_hz": arrays["ic_cutoff_hz"] * 0
                             + db.manifest["fps"]}, *args)
    mean = arrays["channel_mean"].copy()
    mean[0] = args[4][names[0]][1] + 1.0  # beyond its channel's largest frame
    with pytest.raises(ValueError, match=f"channel_mean: {names[0]}"):
        check_decomposition({**arrays, "channel_mean": mean}, *args)

    entry = db.manifest["emotion"]
    rows = db.table("components").to_pylist()
    e = np.array(entry["emotion_components"])
    frames: dict[str, int] = {}
    for c in db.table("clips", columns=["emotion", "n_frames"]).to_pylist():
        frames[c["emotion"]] = frames.get(c["emotion"], 0) + c["n_frames"]
    check_emotion(arrays, entry, e, len(rows), frames)
    # A centroid moved a little: within its bound, but the emotions' frame-weighted
    # centroids no longer sum to the components' mean, 0.
    moved = {**arrays, "emotion/centroid/angry": arrays["emotion/centroid/angry"] + 0.01}
    with pytest.raises(ValueError, match="sum"):
        check_emotion(moved, entry, e, len(rows), frames)


@pytest.mark.parametrize("variance", [0.5, 0.95, 1.0])
@pytest.mark.parametrize("shape", [(400, 12), (9, 30)])
def test_no_false_alarm_on_fresh_decompositions(rng, variance, shape):
    # Motion with channels of very different offsets and scales (mm of a face far from
    # the origin), and fewer frames than channels.
    n, c = shape
    X = rng.normal(size=(n, 4)) @ rng.normal(size=(4, c)) * rng.uniform(0.1, 30, c)
    X += rng.normal(scale=0.01, size=(n, c)) + rng.uniform(-1e3, 1e3, c)
    model = MotionDecomposer(variance=variance).fit(X)
    arrays = model.to_arrays()
    arrays["ic_cutoff_hz"] = np.full(model.n_pcs_, 10.0)
    names = [f"c{k}" for k in range(c)]
    ranges = {f"c{k}": (X[:, k].min(), X[:, k].max()) for k in range(c)}
    check_decomposition(arrays, names, 30.0, n, 0, ranges)


@pytest.mark.parametrize("mutation", ["zeroed:pca_components", "negated:ica_mixing",
                                      "huge:channel_mean"])
def test_the_emotion_evaluation_reads_the_same_checked_model(tiny_db, tmp_path, mutation):
    from animegraph.emotion.evaluate import EmotionData
    from db.errors import DataError

    path = crafted_database(tiny_db[0], tmp_path / "db", mutation)
    with pytest.raises(DataError, match="is damaged.*" + mutation.partition(":")[2]):
        EmotionData.load(Database.open(path))
