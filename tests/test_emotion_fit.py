"""``emotion fit`` (a classifier trained on labelled recordings, to a file or into a
database), ``classify`` over many recordings and over time, and ``synth --emotion auto``
following the emotion over a long line: real audio through the real command line, and
bad input (one clear line, a non-zero exit, nothing written)."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from conftest import AS_INGESTED, require_shared

from animegraph.apps.cli import main
from db.errors import DataError
from db.store import Database, current_version
from ingest.formats.wav import read_wav, write_wav

EMOTIONS = ("angry", "frustrated", "happy", "neutral", "sad")


def _err_line(capsys, needle):
    err = capsys.readouterr().err.strip().splitlines()
    assert err and needle in err[-1], err
    return err


def _labels_csv(tiny_corpus, path, rows=None):
    """A labels CSV of the tiny corpus' clips (path relative to its clips folder)."""
    clips = sorted((tiny_corpus / "clips").glob("*.wav"))
    lines = ["path,emotion,speaker"] + [
        f"{c.name},{c.stem.split('_')[1]},synth" for c in clips] + list(rows or ())
    path.write_text("\n".join(lines) + "\n")
    return path


def test_the_parser_spells_what_the_modules_hold():
    from animegraph.apps import cli_parser_emotion as parser
    from ingest.emotion import labelled, timeline

    assert parser.PRESETS == labelled.PRESETS
    assert (parser.WINDOW_S, parser.HOP_S) == (timeline.WINDOW_S, timeline.HOP_S)


@pytest.mark.parametrize("preset,name,expected", [
    ("ravdess", "03-01-05-02-01-01-07.flac", ("angry", "07")),
    ("ravdess", "03-01-02-01-01-01-12.wav", ("calm", "12")),
    ("emodb", "03a01Fa.wav", ("happy", "03")),
    ("emodb", "16b10Wb.wav", ("angry", "16")),
    ("tess", "OAF_back_ps.wav", ("surprised", "OAF")),
    ("tess", "YAF_dog_fear.wav", ("fearful", "YAF")),
    ("crema-d", "1001_DFA_ANG_XX.wav", ("angry", "1001")),
    ("crema-d", "1091_IEO_SAD_HI.wav", ("sad", "1091")),
])
def test_presets_read_the_corpora_names(preset, name, expected):
    from ingest.emotion.labelled import preset_label

    assert preset_label(preset, name) == expected


@pytest.mark.parametrize("preset,name,why", [
    ("ravdess", "03-02-05-02-01-01-07.flac", "song"),
    ("ravdess", "03-01-09-02-01-01-07.flac", "not a ravdess"),
    ("emodb", "03a01Xa.wav", "not a emodb"),
    ("tess", "OAF_back_bored.wav", "not a tess"),
    ("crema-d", "1001_DFA_XYZ_XX.wav", "not a crema-d"),
])
def test_presets_refuse_other_names(preset, name, why):
    from ingest.emotion.labelled import preset_label

    with pytest.raises(DataError, match=why):
        preset_label(preset, name)


def test_labels_csv_rejects_bad_rows_and_keeps_the_good(tmp_path):
    from ingest.emotion.labelled import from_csv

    root = tmp_path / "rec"
    (root / "sub").mkdir(parents=True)
    for name in ("a.wav", "b.wav", "sub/c.wav"):
        (root / name).write_bytes(b"x")
    (tmp_path / "outside.wav").write_bytes(b"x")
    (root / "link.wav").symlink_to(tmp_path / "outside.wav")
    csv = tmp_path / "labels.csv"
    csv.write_text("path,emotion,speaker\n"
                   "a.wav,Happy,anna\n"
                   "sub/c.wav,sad,\n"
                   "../outside.wav,sad,anna\n"
                   f"{tmp_path / 'outside.wav'},sad,anna\n"
                   "link.wav,sad,anna\n"
                   "missing.wav,sad,anna\n"
                   "b.wav,,anna\n"
                   "b.wav,1bad,anna\n"
                   "a.wav,sad,anna\n"
                   "b.wav,sad\n")
    got = from_csv(csv, root)
    assert [p.name for p in got.paths] == ["a.wav", "c.wav"]
    assert got.emotions == ["happy", "sad"] and got.speakers == ["anna", None]
    reasons = "\n".join(got.rejected)
    assert len(got.rejected) == 8, reasons
    for why in ("leaves the folder", "absolute path", "no such file", "no emotion",
                "is not a name", "listed twice", "2 fields"):
        assert why in reasons
    csv.write_text("file,label\na.wav,sad\n")
    with pytest.raises(DataError, match="path,emotion"):
        from_csv(csv, root)


def test_fit_a_file_and_classify_many_with_it(tiny_corpus, tmp_path, capsys):
    """Trained on the synthetic corpus through the command line; the file is arrays only
    (read without pickles) and classifies the speaker's takes together."""
    clips = tiny_corpus / "clips"
    model = tmp_path / "emotion.npz"
    labels = _labels_csv(tiny_corpus, tmp_path / "labels.csv",
                         rows=["../escape.wav,sad,synth"])
    assert main(["emotion", "fit", str(clips), "--labels", str(labels), "-o", str(model),
                 "-q"]) == 0
    err = capsys.readouterr().err
    assert "leaves the folder" in err and f"wrote {model}" in err
    with np.load(model, allow_pickle=False) as stored:
        assert str(stored["animegraph_file"]) == "animegraph emotion classifier"
        assert json.loads(str(stored["trained_on"]))["speakers"] == 1
    files = [str(p) for p in sorted(clips.glob("s000[12]_*.wav"))]
    assert main(["classify", *files, "--model", str(model), "--speaker", "synth",
                 "--format", "json", "-q"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert len(rows) == len(files)
    for row in rows:
        assert row["speaker"] == "synth" and row["label"] in EMOTIONS
        assert sum(row[e] for e in EMOTIONS) == pytest.approx(1.0, abs=1e-3)
    right = sum(r["label"] == r["path"].rsplit("/", 1)[1].split("_")[1] for r in rows)
    assert right >= 0.8 * len(rows)  # training clips
    out = tmp_path / "rows.csv"
    # classify's CSV paths are relative to the CSV's own folder.
    shutil.copytree(clips, tmp_path / "takes",
                    ignore=shutil.ignore_patterns("*.c3d", "*.csv", "*.json"))
    shutil.copy(labels, tmp_path / "takes" / "labels.csv")
    assert main(["classify", str(tmp_path / "takes"), "--model", str(model), "--labels",
                 str(tmp_path / "takes" / "labels.csv"), "-o", str(out), "-q"]) == 0
    assert "classified as labelled" in capsys.readouterr().err
    text = out.read_text().splitlines()
    assert text[0].startswith('"path","speaker","truth","label"') and len(text) == 35
    # One file: each emotion's probability, a line each (what classify always printed).
    assert main(["classify", files[0], "--model", str(model)]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert {line.split()[0] for line in lines} == set(EMOTIONS)


def test_fit_into_a_database_for_classify_and_synth(tiny_db, tiny_corpus, tmp_path, capsys):
    db = tmp_path / "db"
    # As ingest left it: a guide another test of this worker stored in the shared one is
    # carried to the new version, and the check below is that emotion fit fits none.
    shutil.copytree(tiny_db[0], db, ignore=AS_INGESTED)
    before = current_version(db)
    labels = _labels_csv(tiny_corpus, tmp_path / "labels.csv")
    assert main(["emotion", "fit", str(tiny_corpus / "clips"), "--labels", str(labels),
                 "--db", str(db), "--emotions", "angry,sad,happy", "-q"]) == 0
    assert "stored it into" in capsys.readouterr().err
    assert not list((db / "baselines").glob(f"{current_version(db)}/*.parquet"))
    opened = Database.open(db)
    assert opened.version_dir.name != before
    entry = opened.manifest["emotion"]["classifier"]
    assert set(entry["trained_on"]["emotions"]) == {"angry", "happy", "sad"}
    wav = tiny_corpus / "clips" / "s0002_sad_1.wav"
    assert main(["classify", str(wav), "--db", str(db)]) == 0
    assert {ln.split()[0] for ln in capsys.readouterr().out.strip().splitlines()} == \
        {"angry", "happy", "sad"}
    # A label the database lacks is said before the work; nothing is written.
    labels.write_text("path,emotion\ns0002_sad_1.wav,bored\ns0001_sad_1.wav,bored\n"
                      "s0001_happy_1.wav,happy\ns0002_happy_1.wav,happy\n")
    version = current_version(db)
    assert main(["emotion", "fit", str(tiny_corpus / "clips"), "--labels", str(labels),
                 "--db", str(db), "-q"]) == 1
    _err_line(capsys, "emotions bored are not in database")
    assert current_version(db) == version


@pytest.mark.parametrize("setup,args,code,needle", [
    ("empty", ["--preset", "ravdess", "-o", "m.npz"], 1, "no labelled recordings"),
    ("clips", ["--preset", "ravdess", "-o", "m.npz"], 1, "no labelled recordings"),
    ("one", ["--labels", "one.csv", "-o", "m.npz"], 1, "all sad"),
    ("few", ["--labels", "few.csv", "-o", "m.npz"], 1, "happy 1"),
    ("clips", ["--labels", "x.csv", "--preset", "tess", "-o", "m.npz"], 2, "one of them"),
    ("clips", ["--preset", "tess"], 2, "-o MODEL"),
    ("clips", ["--preset", "tess", "-o", "m.pkl"], 2, "must end in .npz"),
    ("clips", ["--labels", "none.csv", "-o", "m.npz"], 1, "labels file not found"),
    ("clips", ["--preset", "msp", "-o", "m.npz"], 2, "invalid choice"),
    ("clips", ["--labels", "one.csv", "--emotions", "calm", "-o", "m.npz"], 1,
     "no recording is labelled calm"),
])
def test_fit_bad_input(tiny_corpus, tmp_path, capsys, setup, args, code, needle):
    folder = tmp_path / "empty" if setup == "empty" else tiny_corpus / "clips"
    folder.mkdir(exist_ok=True)
    (tmp_path / "one.csv").write_text("path,emotion\ns0001_sad_1.wav,sad\n"
                                      "s0002_sad_1.wav,sad\n")
    (tmp_path / "few.csv").write_text("path,emotion\ns0001_sad_1.wav,sad\n"
                                      "s0002_sad_1.wav,sad\ns0001_happy_1.wav,happy\n")
    args = [str(tmp_path / a) if a.endswith((".csv", ".npz", ".pkl")) else a for a in args]
    assert main(["emotion", "fit", str(folder), *args]) == code
    _err_line(capsys, needle)
    assert not (tmp_path / "m.npz").exists()


def test_classify_refuses_damaged_and_foreign_model_files(tiny_corpus, tmp_path, capsys):
    wav = str(tiny_corpus / "clips" / "s0002_sad_1.wav")
    np.savez(tmp_path / "foreign.npz", x=np.arange(3))
    (tmp_path / "text.npz").write_text("not a zip")
    np.savez(tmp_path / "objects.npz", animegraph_file=np.array([{"a": 1}], dtype=object))
    cases = {"foreign.npz": "an .npz of something else", "text.npz": "not an .npz",
             "objects.npz": "no usable emotion classifier", "none.npz": "not found"}
    for name, needle in cases.items():
        assert main(["classify", wav, "--model", str(tmp_path / name)]) == 1
        err = _err_line(capsys, needle)
        assert len(err) == 1


def test_a_damaged_classifier_file_is_one_line(tiny_corpus, tmp_path, capsys):
    from ingest.emotion.classifier_file import load_classifier, save_classifier
    from ingest.emotion.model import database_classifier

    rng = np.random.default_rng(3)
    X = rng.standard_normal((40, 6))
    y = np.repeat(["happy", "sad"], 20)
    clf = database_classifier().set_params(features="rich").fit(X, y)
    good = save_classifier(clf, tmp_path / "good.npz", {"recordings": 40})
    loaded, info = load_classifier(good)
    np.testing.assert_allclose(loaded.predict_proba(X), clf.predict_proba(X))
    assert info == {"recordings": 40}
    with np.load(good, allow_pickle=False) as stored:
        arrays = dict(stored)
    arrays["support_vectors"] = arrays["support_vectors"][:, :3]
    np.savez(tmp_path / "bad.npz", **arrays)
    with pytest.raises(DataError, match="no usable emotion classifier.*support_vectors") as e:
        load_classifier(tmp_path / "bad.npz")
    assert "re-ingest" not in str(e.value) and "\n" not in str(e.value)
    arrays["animegraph_file_version"] = np.array(99)
    np.savez(tmp_path / "newer.npz", **arrays)
    with pytest.raises(DataError, match="newer animegraph"):
        load_classifier(tmp_path / "newer.npz")
    raw = good.read_bytes()
    (tmp_path / "cut.npz").write_bytes(raw[: len(raw) // 2])
    with pytest.raises(DataError, match="emotion classifier"):
        load_classifier(tmp_path / "cut.npz")


def _two_emotions(tiny_corpus, tmp_path, first="angry", second="sad"):
    """Speech of ``first`` then ``second`` (their clips repeated), each longer than a window."""
    parts = []
    for emotion in (first, second):
        a, rate = read_wav(tiny_corpus / "clips" / f"s0002_{emotion}_1.wav")
        parts.append(np.tile(np.asarray(a, dtype=np.float32), 3))
    path = tmp_path / f"{first}_{second}.wav"
    write_wav(path, np.concatenate(parts), rate)
    return path, len(parts[0]) / rate, sum(len(p) for p in parts) / rate


def test_classify_timeline_table_and_plot(tiny_db, tiny_corpus, tmp_path, capsys):
    from collections import Counter

    wav, change, total = _two_emotions(tiny_corpus, tmp_path)
    png = tmp_path / "timeline.png"
    assert main(["classify", str(wav), "--db", str(tiny_db[0]), "--timeline", "--plot",
                 str(png)]) == 0
    rows = capsys.readouterr().out.strip().splitlines()[:-1]
    first = [r.split()[2] for r in rows if float(r.split()[1]) <= change]
    last = [r.split()[2] for r in rows if float(r.split()[0]) >= change]
    assert Counter(first).most_common(1)[0][0] == "angry"
    assert Counter(last).most_common(1)[0][0] == "sad"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main(["classify", str(wav), "--db", str(tiny_db[0]), "--timeline", "--window",
                 "2", "--hop", "0.5", "--format", "json"]) == 0
    windows = json.loads(capsys.readouterr().out)
    assert len(windows) == int((total - 2) / 0.5) + 1
    assert windows[1]["start"] == 0.5 and windows[1]["end"] == 2.5
    # One speaker's windows normalised together: other probabilities, the same windows.
    assert main(["classify", str(wav), "--db", str(tiny_db[0]), "--timeline", "--window",
                 "2", "--hop", "0.5", "--format", "json", "--speaker", "me"]) == 0
    together = json.loads(capsys.readouterr().out)
    assert [w["start"] for w in together] == [w["start"] for w in windows]
    assert together[1]["probabilities"] != windows[1]["probabilities"]
    for bad, needle in ((["--window", "0.2"], "the window must last"),
                        (["--hop", "9"], "the hop must be")):
        assert main(["classify", str(wav), "--db", str(tiny_db[0]), "--timeline",
                     *bad]) == 2
        _err_line(capsys, needle)


def test_synth_auto_follows_the_emotion_over_a_long_line(tiny_db, tiny_corpus, tmp_path):
    """The emotion components of the first half are those of the first emotion, of the
    second half those of the second: the weights change over time in the motion."""
    from animegraph.emotion.control import EmotionChoice, EmotionTimeline
    from animegraph.synthesis import Model, synthesize
    from ingest.emotion.timeline import Window

    model = Model.load(tiny_db[0])
    wav, change, total = _two_emotions(tiny_corpus, tmp_path, "happy", "sad")
    audio, rate = read_wav(wav)
    timeline = EmotionTimeline((Window(0.0, 2.0, {"happy": 1.0, "sad": 0.0}),
                                Window(change - 2.0, change, {"happy": 1.0, "sad": 0.0}),
                                Window(change, change + 2.0, {"sad": 1.0, "happy": 0.0}),
                                Window(total - 2.0, total, {"sad": 1.0, "happy": 0.0})))
    over = synthesize(model, audio, rate, emotion=EmotionChoice("happy", "happy", None,
                                                                 timeline))
    # The same search (happy's animes), mapped into one emotion throughout.
    happy = synthesize(model, audio, rate, emotion=EmotionChoice("happy", "happy"))
    sad = synthesize(model, audio, rate, emotion=EmotionChoice("sad", "happy"))
    e = model.emotion_model.split.emotion_components
    fps = over.fps
    a, b = int((change - 1.5) * fps), int((change + 1.5) * fps)

    def gap(x, y, rows):
        return float(np.abs(x.ics[rows][:, e] - y.ics[rows][:, e]).mean())

    early, late = slice(0, a), slice(b, len(over.ics))
    assert gap(over, happy, early) < 0.2 * gap(sad, happy, early)
    assert gap(over, sad, late) < 0.2 * gap(sad, happy, late)


def test_synth_cli_auto_over_a_long_line(tiny_db, tiny_corpus, tmp_path, capsys):
    wav, _, _ = _two_emotions(tiny_corpus, tmp_path, "angry", "sad")
    out = tmp_path / "o.npz"
    assert main(["synth", str(wav), "--db", str(tiny_db[0]), "--emotion", "auto",
                 "-o", str(out)]) == 0
    err = capsys.readouterr().err
    assert "follows the emotion over time" in err and "angry 0-" in err and "sad " in err
    assert out.exists()


def test_ravdess_fit_and_classify_a_speakers_takes(tmp_path, capsys):
    """Real English speech (FLAC): two actors' four emotions trained, a third's takes
    classified together by --preset (speaker from the names)."""
    root = require_shared("ravdess")
    train = tmp_path / "train"
    for actor in ("01", "02"):
        (train / actor).mkdir(parents=True)
        for f in sorted((root / f"Actor_{actor}").glob("03-01-0[1345]-*.flac")):
            shutil.copy(f, train / actor / f.name)
    model = tmp_path / "ravdess.npz"
    assert main(["emotion", "fit", str(train), "--preset", "ravdess", "-o", str(model),
                 "-q"]) == 0
    assert "4 emotions (angry 16, happy 16, neutral 8, sad 16)" in capsys.readouterr().err
    test = sorted((root / "Actor_03").glob("03-01-0[1345]-*.flac"))
    assert main(["classify", *map(str, test), "--model", str(model), "--preset", "ravdess",
                 "--format", "csv", "-q"]) == 0
    captured = capsys.readouterr()
    lines = captured.out.strip().splitlines()
    assert len(lines) == 1 + len(test) and all('"03"' in line for line in lines[1:])
    assert "classified as labelled" in captured.err


def test_weights_over_time_interpolate_between_window_centres():
    from ingest.emotion.timeline import Window, spans, weights_over_time

    windows = [Window(0.0, 4.0, {"happy": 0.8, "sad": 0.2}),
               Window(2.0, 6.0, None, "not speech"),
               Window(4.0, 8.0, {"sad": 1.0, "happy": 0.0})]
    names, w = weights_over_time(windows, [0.0, 2.0, 4.0, 6.0, 9.0])
    assert names == ["sad", "happy"]  # the more probable over the windows first
    np.testing.assert_allclose(w[:, 1], [0.8, 0.8, 0.4, 0.0, 0.0])
    np.testing.assert_allclose(w.sum(axis=1), 1.0)
    with pytest.raises(DataError, match="no window"):
        weights_over_time([Window(0.0, 4.0, None, "silence")], [1.0])
    assert spans(10.0, 4.0, 2.0) == [(0.0, 4.0), (2.0, 6.0), (4.0, 8.0), (6.0, 10.0)]


def test_fit_into_a_database_keeps_its_fitted_guides(tiny_db, tiny_corpus, tmp_path, capsys):
    """A classifier stored with --db makes a new version of the same clips and motion: the
    models fitted on the version before are stored for it too (not fitted again by synth)."""
    from animegraph.baselines import make_estimator
    from animegraph.baselines.base import read_model, save_model
    from animegraph.baselines.stored import model_path
    from ingest.tables import prepared_from_database

    db = tmp_path / "db"
    shutil.copytree(tiny_db[0], db)
    model = make_estimator("hier-pca", n_clusters=8).fit(prepared_from_database(Database.open(db)))
    save_model(model, db)
    labels = _labels_csv(tiny_corpus, tmp_path / "labels.csv")
    assert main(["emotion", "fit", str(tiny_corpus / "clips"), "--labels", str(labels),
                 "--db", str(db), "--emotions", "angry,sad,happy", "-q"]) == 0
    assert "kept its fitted hier-pca" in capsys.readouterr().err
    kept = model_path(db, "hier-pca")
    assert kept.parent.name == current_version(db) and kept.is_file()
    again = read_model(kept)
    for name, value in model.to_arrays().items():
        np.testing.assert_array_equal(again.to_arrays()[name], value)


def test_a_folder_of_links_says_links_are_not_followed(tiny_corpus, tmp_path, capsys):
    # --emotions used to answer first, with "no recording is labelled ... (the labels are none)"
    folder = tmp_path / "linked"
    folder.mkdir()
    (folder / "clips").symlink_to(tiny_corpus / "clips")
    assert main(["emotion", "fit", str(folder), "--preset", "ravdess", "-o",
                 str(tmp_path / "m.npz"), "--emotions", "sad,happy", "-q"]) == 1
    _err_line(capsys, "symbolic links in it are not followed")
    assert not (tmp_path / "m.npz").exists()


def test_fit_into_a_database_keeps_its_guides_as_a_refit_would_make_them(tiny_db, tiny_corpus,
                                                                         tmp_path, capsys):
    # The guides are fitted on the clips' speech, motion, labels, phones and posteriors;
    # emotion fit replaces the classifier alone, so the guides it carries into its new
    # version are the ones a synth would fit there (and it fits none).
    from animegraph.baselines.base import fitted_model, load_model, model_path
    from animegraph.baselines.data import training_set

    db = tmp_path / "db"
    shutil.copytree(tiny_db[0], db, ignore=AS_INGESTED)
    fitted = fitted_model(db, "ppg-ridge").to_arrays()
    before_version, before = current_version(db), training_set(db)
    labels = _labels_csv(tiny_corpus, tmp_path / "labels.csv")
    assert main(["emotion", "fit", str(tiny_corpus / "clips"), "--labels", str(labels),
                 "--db", str(db), "--emotions", "angry,sad,happy", "-q"]) == 0
    assert "kept its fitted ppg-ridge" in capsys.readouterr().err
    assert current_version(db) != before_version and model_path(db, "ppg-ridge").is_file()
    after = training_set(db)
    assert (after.names, after.fps, after.kind) == (before.names, before.fps, before.kind)
    for old, new in zip(before.clips, after.clips, strict=True):
        assert (new.clip_id, new.emotion, new.phones) == (old.clip_id, old.emotion, old.phones)
        for field in ("audio", "motion", "posteriors"):
            a, b = getattr(old, field), getattr(new, field)
            assert (a is None and b is None) or np.array_equal(a, b), field
    carried = load_model(db, "ppg-ridge").to_arrays()
    refitted = fitted_model(db, "ppg-ridge", refit=True).to_arrays()
    for arrays in (carried, refitted):
        assert arrays.keys() == fitted.keys()
        assert all(np.array_equal(arrays[k], fitted[k]) for k in fitted)
