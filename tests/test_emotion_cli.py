"""The emotion commands (classify, map-emotion, synth --emotion auto/--emotion-mix) and their
bad input: one clear error line, a non-zero exit, nothing written."""

from __future__ import annotations

import numpy as np
import pytest

from animegraph.apps.cli import main
from animegraph.emotion.control import check_names, parse_emotion
from animegraph.emotion.evaluate import EmotionData, cross_validate
from animegraph.synthesis import Model, read_database_motion, synthesize
from db.errors import DataError, ParameterError
from db.store import Database
from ingest.formats.phones_csv import read_phones_csv
from ingest.formats.wav import read_wav, write_wav


def _subset_db(tiny_db, path, keep):
    from ingest.pipeline import build_database
    from ingest.tables import prepared_from_database

    clips = [c for c in prepared_from_database(Database.open(tiny_db[0])) if keep(c)]
    build_database(path, clips)
    return path


@pytest.fixture(scope="module")
def one_parallel_db(tiny_db, tmp_path_factory):
    """One sentence in all five emotions, two in one emotion: too few to learn mappings."""
    return _subset_db(tiny_db, tmp_path_factory.mktemp("one") / "db",
                      lambda c: c.sentence_id in ("s0001", "s0004", "s0005"))


@pytest.fixture(scope="module")
def neutral_db(tiny_db, tmp_path_factory):
    """A single-emotion database."""
    return _subset_db(tiny_db, tmp_path_factory.mktemp("neutral") / "db",
                      lambda c: c.emotion == "neutral")


def _clip(tiny_corpus, emotion="sad", sentence="s0002"):
    return tiny_corpus / "clips" / f"{sentence}_{emotion}_1"


def _one_error_line(capsys, needle):
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1, err
    assert needle in err[0], err[0]


def test_parse_emotion():
    assert parse_emotion(None) is None
    assert parse_emotion("auto") == "auto"
    assert parse_emotion("happy") == "happy"
    assert parse_emotion("happy=0.7, neutral=0.3") == pytest.approx({"happy": 0.7,
                                                                     "neutral": 0.3})
    assert parse_emotion({"happy": 2, "sad": 2}) == {"happy": 0.5, "sad": 0.5}
    assert parse_emotion("happy=1") == "happy"
    for bad in ("", "happy=x", "happy=-1,sad=1", "happy=0", "happy,sad", "auto=1", "1x"):
        with pytest.raises(ParameterError):
            parse_emotion(bad)


@pytest.mark.parametrize("weight", ["1e999", "inf", "-inf", "nan"])
def test_a_weight_that_is_no_finite_number_is_said_so(weight):
    # 1e999 was told "must be >= 0, got 1e999".
    with pytest.raises(ParameterError, match="not a finite number"):
        parse_emotion(f"happy={weight},sad=1")


def test_emotion_names_match_whatever_their_case():
    """Requests match the database's spelling (one written before ingest lowercased
    labels may hold ``Happy``); a mix adds up names that differ only in case."""
    assert check_names("HAPPY", None, ["happy", "sad"]) == "happy"
    assert check_names("happy", None, ["Happy", "sad"]) == "Happy"
    assert check_names({"Sad": 0.5, "sad": 0.25, "happy": 0.25}, None, ["happy", "sad"]) \
        == {"sad": 0.75, "happy": 0.25}
    assert check_names("auto", None, []) == "auto"
    with pytest.raises(ParameterError, match="unknown emotion 'bored'"):
        check_names("bored", None, ["happy"])


def test_synth_and_query_take_an_emotion_in_any_case(tiny_db, tiny_corpus, tmp_path, capsys):
    stem = _clip(tiny_corpus, "happy")
    out = tmp_path / "o.npz"
    assert main(["synth", str(stem.with_suffix(".wav")), "--db", str(tiny_db[0]), "--labels",
                 f"{stem}.phones.csv", "-o", str(out), "--emotion", "Happy"]) == 0
    assert out.exists()
    assert main(["query", "--db", str(tiny_db[0]), "--emotion", "SAD", "--format",
                 "csv"]) == 0
    rows = capsys.readouterr().out.strip().splitlines()
    assert len(rows) > 1 and all(',"sad",' in row for row in rows[1:])


def test_classify_prints_probabilities(tiny_db, tiny_corpus, capsys):
    stem = _clip(tiny_corpus, "happy")
    assert main(["classify", str(stem.with_suffix(".wav")), "--db", str(tiny_db[0])]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    probs = {line.split()[0]: float(line.split()[1]) for line in lines}
    assert set(probs) == {"angry", "frustrated", "happy", "neutral", "sad"}
    assert sum(probs.values()) == pytest.approx(1.0, abs=0.01)
    assert max(probs, key=probs.get) == "happy"  # a training clip


def test_classify_refuses_noise_and_tones_and_hears_quiet_speech(tiny_db, tiny_corpus,
                                                                   tmp_path, capsys):
    """3 s of white noise was "angry 0.81" without a word, and real speech at -70 dBFS peak
    was "audio is silence" though its level is normalised later."""
    rng = np.random.default_rng(10)
    t = np.arange(3 * 16000) / 16000
    for name, x in (("noise", 0.3 * rng.standard_normal(t.size)),
                    ("tone", 0.3 * np.sin(2 * np.pi * 220 * t))):
        write_wav(tmp_path / f"{name}.wav", x.astype(np.float32), 16000)
        assert main(["classify", str(tmp_path / f"{name}.wav"), "--db", str(tiny_db[0])]) == 1
        _one_error_line(capsys, "audio is not speech")
    audio, rate = read_wav(_clip(tiny_corpus, "happy").with_suffix(".wav"))
    quiet = audio / np.abs(audio).max() * 10 ** (-70 / 20)
    write_wav(tmp_path / "quiet.wav", quiet.astype(np.float32), rate)
    assert main(["classify", str(tmp_path / "quiet.wav"), "--db", str(tiny_db[0])]) == 0
    assert capsys.readouterr().out.split()[0] == "happy"  # the training clip, heard


def test_classify_a_long_recording_window_by_window(tiny_db, tiny_corpus, tmp_path, capsys):
    """A long recording was one label (a 10-minute one: 157 s, 1.9 GB): it is classified
    in windows, and --timeline prints each (or why it is not classified)."""
    from ingest.emotion.timeline import HOP_S, MAX_UTTERANCE_S, WINDOW_S

    rng = np.random.default_rng(11)
    audio, rate = read_wav(_clip(tiny_corpus, "angry").with_suffix(".wav"))
    audio = np.asarray(audio, dtype=np.float32)
    noise = 0.3 * rng.standard_normal(int(2 * WINDOW_S * rate)).astype(np.float32)
    speech = np.tile(audio, int(np.ceil(MAX_UTTERANCE_S * rate / len(audio))))
    long = np.concatenate([speech, noise])
    write_wav(tmp_path / "long.wav", long, rate)
    assert main(["classify", str(tmp_path / "long.wav"), "--db", str(tiny_db[0]),
                 "--timeline"]) == 0
    rows = capsys.readouterr().out.strip().splitlines()
    windows, overall = rows[:-1], rows[-1]
    assert len(windows) == int(np.floor((len(long) / rate - WINDOW_S) / HOP_S)) + 1 or \
        len(windows) == int(np.floor((len(long) / rate - WINDOW_S) / HOP_S)) + 2
    assert windows[0].split()[2] == "angry" and "not speech" in windows[-1]
    assert overall.startswith("overall  angry")
    assert main(["classify", str(tmp_path / "long.wav"), "--db", str(tiny_db[0])]) == 0
    assert capsys.readouterr().out.split()[0] == "angry"


def test_classify_audio_too_short(tiny_db, tmp_path, capsys):
    write_wav(tmp_path / "short.wav", 0.1 * np.sin(np.arange(1600) / 5.0).astype(np.float32),
              16000)
    assert main(["classify", str(tmp_path / "short.wav"), "--db", str(tiny_db[0])]) == 1
    _one_error_line(capsys, "too short")


def test_map_emotion_changes_emotion_keeps_speech(tiny_db, tiny_corpus, tmp_path, capsys):
    stem = _clip(tiny_corpus, "neutral")
    out = tmp_path / "happy.csv"
    assert main(["map-emotion", str(stem.with_suffix(".c3d")), "--db", str(tiny_db[0]),
                 "--to", "happy", "-o", str(out)]) == 0
    err = capsys.readouterr().err
    assert "from neutral (nearest mean emotion components) to happy" in err
    model = Model.load(tiny_db[0])
    source, _ = read_database_motion(stem.with_suffix(".c3d"), model)
    mapped, fps = read_database_motion(out, model)
    assert mapped.shape == source.shape and fps == pytest.approx(120.0, rel=1e-3)
    # The smile the mapping adds lifts the lip corners relative to the eyes.
    pts_s, pts_m = source.reshape(len(source), -1, 3), mapped.reshape(len(mapped), -1, 3)
    names = [n[:-2] for n in model.names[::3]]
    corner = names.index("lip_corner_r")
    assert np.nanmean(pts_m[:, corner, 1] - pts_s[:, corner, 1]) > 0.5  # mm up
    # The mapped motion is the neutral one with its emotion components changed, so a
    # round trip back to neutral lands near where it started.
    back = tmp_path / "back.npz"
    assert main(["map-emotion", str(out), "--db", str(tiny_db[0]), "--to", "neutral",
                 "--from", "happy", "-o", str(back)]) == 0
    again, _ = read_database_motion(back, model)
    assert np.nanmean(np.abs(again - source)) < np.nanmean(np.abs(mapped - source))


@pytest.mark.parametrize("args, needle", [
    (["--to", "bored"], "unknown emotion 'bored'"),
    (["--to", "happy", "--from", "bored"], "unknown emotion 'bored'"),
    (["--to", "auto"], "not auto"),
    (["--to", "happy", "-o", "{tmp}/x.mp4"], "'animegraph render' makes .mp4, .gif"),
])
def test_map_emotion_bad_input(tiny_db, tiny_corpus, tmp_path, capsys, args, needle):
    argv = ["map-emotion", str(_clip(tiny_corpus).with_suffix(".c3d")), "--db",
            str(tiny_db[0]), "-o", str(tmp_path / "out.csv"),
            *[a.format(tmp=tmp_path) for a in args]]
    assert main(argv) in (1, 2)
    _one_error_line(capsys, needle)
    assert list(tmp_path.iterdir()) == []


def test_map_emotion_single_emotion_database(neutral_db, tiny_corpus, tmp_path, capsys):
    for target in ("happy", "neutral"):
        argv = ["map-emotion", str(_clip(tiny_corpus, "neutral").with_suffix(".c3d")), "--db",
                str(neutral_db), "--to", target, "-o", str(tmp_path / "o.csv")]
        assert main(argv) == 1
        _one_error_line(capsys, "single emotion (neutral): there is nothing to map between")
    assert list(tmp_path.iterdir()) == []
    assert Model.load(neutral_db).emotion_model.classifier is None


def test_too_few_parallel_sentences(one_parallel_db, tiny_corpus, tmp_path, capsys):
    model = Model.load(one_parallel_db).emotion_model
    assert model.split.emotion_components.size > 0  # the split still works
    assert model.mappings == {}
    argv = ["map-emotion", str(_clip(tiny_corpus, "neutral", "s0001").with_suffix(".c3d")),
            "--db", str(one_parallel_db), "--from", "neutral", "--to", "happy", "-o",
            str(tmp_path / "o.csv")]
    assert main(argv) == 1
    _one_error_line(capsys, "1 sentence recorded in both, a mapping needs 2")
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(DataError, match="needs 3"):
        cross_validate(EmotionData.load(Database.open(one_parallel_db)))


def test_synth_emotion_auto_and_mix(tiny_db, tiny_corpus, tmp_path, capsys):
    stem = _clip(tiny_corpus, "sad")
    base = ["synth", str(stem.with_suffix(".wav")), "--db", str(tiny_db[0]), "--labels",
            f"{stem}.phones.csv"]
    assert main([*base, "--emotion", "auto", "-o", str(tmp_path / "auto.npz")]) == 0
    assert "emotion auto: the speech sounds sad" in capsys.readouterr().err
    assert main([*base, "--emotion-mix", "happy=0.7,neutral=0.3", "-o",
                 str(tmp_path / "mix.npz")]) == 0
    assert "emotion mix happy=0.70,neutral=0.30" in capsys.readouterr().err
    assert main([*base, "--emotion-mix", "happy", "-o", str(tmp_path / "x.npz")]) == 2
    _one_error_line(capsys, "name=weight")
    assert main([*base, "--emotion-mix", "happy=0.5,bored=0.5", "-o",
                 str(tmp_path / "x.npz")]) == 1
    _one_error_line(capsys, "unknown emotion 'bored'")
    assert not (tmp_path / "x.npz").exists()


def test_synth_auto_on_audio_too_short(tiny_db, tmp_path, capsys):
    write_wav(tmp_path / "short.wav", 0.1 * np.sin(np.arange(2400) / 5.0).astype(np.float32),
              16000)
    assert main(["synth", str(tmp_path / "short.wav"), "--db", str(tiny_db[0]), "--emotion",
                 "auto", "-o", str(tmp_path / "o.npz")]) == 1
    _one_error_line(capsys, "too short")
    assert not (tmp_path / "o.npz").exists()


def test_synthesize_api_emotion_forms(tiny_db, tiny_corpus):
    model = Model.load(tiny_db[0])
    stem = _clip(tiny_corpus, "angry", "s0003")
    audio, sr = read_wav(stem.with_suffix(".wav"))
    labels = read_phones_csv(f"{stem}.phones.csv")
    plain = synthesize(model, audio, sr, labels=labels, emotion="happy")
    assert plain.emotion.target == "happy" and plain.emotion.search == "happy"
    auto = synthesize(model, audio, sr, labels=labels, emotion="auto")
    assert auto.emotion.probabilities is not None
    assert auto.emotion.target == next(iter(auto.emotion.probabilities))
    mix = synthesize(model, audio, sr, labels=labels, emotion={"happy": 1, "sad": 1})
    same = synthesize(model, audio, sr, labels=labels, emotion="happy=0.5,sad=0.5")
    np.testing.assert_allclose(mix.motion, same.motion)
    assert mix.emotion.search in ("happy", "sad")
    none = synthesize(model, audio, sr, labels=labels)
    assert none.emotion.target is None
    # The emotion components differ between happy and sad, the speech ones do not need to.
    e = model.emotion_model.split.emotion_components
    sad = synthesize(model, audio, sr, labels=labels, emotion="sad")
    assert np.abs(plain.ics[:, e] - sad.ics[:, e]).mean() > 0.5


@pytest.fixture(scope="module")
def few_clips_db(tiny_db, tmp_path_factory):
    """Every neutral clip, and one clip of each other emotion: too few for a classifier."""
    seen = set()

    def keep(c):
        if c.emotion == "neutral":
            return True
        if c.emotion in seen:
            return False
        seen.add(c.emotion)
        return True

    return _subset_db(tiny_db, tmp_path_factory.mktemp("few") / "db", keep)


def test_too_few_clips_per_emotion_still_ingests(few_clips_db, tiny_corpus, tmp_path, capsys):
    model = Model.load(few_clips_db).emotion_model
    assert model.classifier is None
    assert any("no emotion classifier: it needs two emotions with at least 2" in n
               for n in model.notes)
    stem = _clip(tiny_corpus, "sad")
    assert main(["synth", str(stem.with_suffix(".wav")), "--db", str(few_clips_db),
                 "--labels", f"{stem}.phones.csv", "--emotion", "auto", "-o",
                 str(tmp_path / "o.npz")]) == 1
    _one_error_line(capsys, "no emotion classifier")
    assert not (tmp_path / "o.npz").exists()


def test_a_database_without_emotion_labels_says_so(unlabelled_db, tiny_corpus, tmp_path,
                                                   capsys):
    # It said "it is not in the database (it has unknown)", and classify "give the
    # emotion instead of 'auto'", an option classify does not have.
    stem = _clip(tiny_corpus, "sad")
    wav = str(stem.with_suffix(".wav"))
    assert main(["classify", wav, "--db", str(unlabelled_db)]) == 1
    _one_error_line(capsys, "the database has no emotion classifier (its clips carry no "
                            "emotion labels): classifying needs a database of clips labelled "
                            "with two emotions or more")
    synth = ["synth", wav, "--db", str(unlabelled_db), "--labels", f"{stem}.phones.csv",
             "-o", str(tmp_path / "o.npz"), "--emotion"]
    assert main([*synth, "happy"]) == 1
    _one_error_line(capsys, "unknown emotion 'happy': the database has no emotions (its "
                            "clips carry no emotion labels): leave the emotion out")
    assert main([*synth, "auto"]) == 1
    _one_error_line(capsys, "the database has no emotion classifier (its clips carry no "
                            "emotion labels): leave the emotion out instead of 'auto'")
    assert not (tmp_path / "o.npz").exists()


def test_classify_on_too_few_clips_names_the_labels(few_clips_db, tiny_corpus, capsys):
    wav = str(_clip(tiny_corpus, "sad").with_suffix(".wav"))
    assert main(["classify", wav, "--db", str(few_clips_db)]) == 1
    _one_error_line(capsys, "the database has no emotion classifier (its clips carry 5 "
                            "emotion labels, angry, frustrated, happy, neutral, sad; it needs "
                            "two emotions with at least 2 usable clips each): re-ingest with "
                            "more labelled clips to classify")


def test_classify_silence_and_stereo(tiny_db, tiny_corpus, tmp_path, capsys):
    write_wav(tmp_path / "hush.wav", np.zeros(16000, np.float32), 16000)
    assert main(["classify", str(tmp_path / "hush.wav"), "--db", str(tiny_db[0])]) == 1
    _one_error_line(capsys, "audio is silence")
    audio, sr = read_wav(_clip(tiny_corpus, "sad").with_suffix(".wav"))
    from ingest.emotion.classifier import EmotionClassifier

    clf = Model.load(tiny_db[0]).emotion_model.classifier
    assert isinstance(clf, EmotionClassifier) and clf.normalize == "speaker+population"
    mono = clf.predict_proba([(audio, sr)])
    stereo = clf.predict_proba([(np.stack([audio, audio], 1), float(sr))])
    np.testing.assert_allclose(stereo, mono, atol=1e-6)


def test_old_stored_classifier_says_reingest(tiny_db, tiny_corpus):
    from animegraph.emotion.control import classify_speech
    from ingest.emotion.model import EmotionModel

    db = Database.open(tiny_db[0])

    class OldDatabase:  # the real database, its classifier as an older animegraph stored it
        root, manifest = db.root, db.manifest

        def table(self, name, columns=None):
            return db.table(name, columns)

        def arrays(self):
            return {k: v for k, v in db.arrays().items() if k != "emotion/classifier/format"}

    model = EmotionModel.from_database(OldDatabase())
    assert model.classifier is None and model.mappings  # the rest still loads
    audio, sr = read_wav(_clip(tiny_corpus, "sad").with_suffix(".wav"))
    with pytest.raises(DataError, match="re-ingest the database"):
        classify_speech(model, audio, sr)


def test_classifier_features_are_computed_in_the_workers(tiny_db, tiny_corpus):
    # Each labelled clip's classifier features come with the prepared clip (ingest's
    # workers); the stored classifier is the one fitted on features computed afterwards.
    from ingest.emotion.classifier import SpeechFeatures
    from ingest.emotion.model import _fit_classifier, classifier_features
    from ingest.prepare import prepare_clip
    from ingest.readers import discover, load
    from ingest.tables import prepared_from_database

    source = next(s for s in discover([tiny_corpus]) if "_sad_" in s.clip_id)
    clip = prepare_clip(load(source))
    assert clip.emotion == "sad" and isinstance(clip.emotion_features, SpeechFeatures)
    again = classifier_features(clip.audio, clip.sample_rate)
    np.testing.assert_array_equal(clip.emotion_features.functionals, again.functionals)
    assert len(clip.emotion_features.frames) == 1
    np.testing.assert_array_equal(clip.emotion_features.frames[0], again.frames[0])

    stored = Model.load(tiny_db[0]).emotion_model.classifier
    assert stored.bag_ is not None and stored.block_widths_ == (171, 5000)  # 5 pairs
    clips = prepared_from_database(Database.open(tiny_db[0]))
    assert all(c.emotion_features is None for c in clips)  # not stored in the database
    # the order ingest met them in (the codebooks' random seeding depends on it)
    order = {s.clip_id: k for k, s in enumerate(discover([tiny_corpus]))}
    clips = sorted(clips, key=lambda c: order[c.clip_id])
    notes: list[str] = []
    refit = _fit_classifier([(c.audio, c.sample_rate) for c in clips],
                            [c.emotion for c in clips], [c.speaker for c in clips], notes)
    X = [(c.audio, c.sample_rate) for c in clips]
    who = [c.speaker for c in clips]
    np.testing.assert_array_equal(stored.classes_, refit.classes_)
    np.testing.assert_allclose(stored.decision_function(X, who), refit.decision_function(X, who),
                               atol=1e-8)
    np.testing.assert_allclose(stored.predict_proba(X), refit.predict_proba(X), atol=1e-6)
    assert classifier_features(np.zeros(16000, np.int16), 16000).startswith("audio is silence")


def test_classify_with_a_damaged_stored_classifier(tiny_db, tiny_corpus, tmp_path, capsys):
    """The stored classifier is someone else's data: a codebook cut short or of the wrong
    shape, a zero or non-finite number, any array cut short or made negative (picked at
    random, fixed seed) gives classify one error line, never a traceback."""
    import shutil

    import pyarrow.parquet as pq
    from crafted import refresh_checksum

    from db.store import arrays_from_table, arrays_to_table

    db = tmp_path / "db"
    shutil.copytree(tiny_db[0], db)
    path = Database.open(db).table_path("model_arrays")
    table = pq.read_table(path)
    arrays = arrays_from_table(table)
    pre = "emotion/classifier/"
    wav = str(_clip(tiny_corpus, "sad").with_suffix(".wav"))

    def classify(corrupt):
        pq.write_table(arrays_to_table(corrupt).replace_schema_metadata(
            table.schema.metadata), path)
        refresh_checksum(db)  # a deliberate edit: the classifier's own checks must tell
        code = main(["classify", wav, "--db", str(db)])
        err = capsys.readouterr().err.strip().splitlines()
        assert not any("Traceback" in e for e in err), err
        return code, err

    book = arrays[pre + "boaw_codebook0"]
    nan = book.copy()
    nan[3, 4] = np.nan
    pairs = int(arrays[pre + "n_codebooks"])  # the ensemble's codebook pairs
    last = f"boaw_codebook{2 * pairs - 1}"
    for name, bad, needle in [
            ("boaw_codebook0", book[:, :-1], "boaw_codebook0"),
            ("boaw_codebook1", book.T, "boaw_codebook1"),
            ("boaw_codebook0", nan, "not finite"),
            (last, arrays[pre + last][:-1], last),
            ("boaw_scale", np.zeros_like(arrays[pre + "boaw_scale"]), "boaw_scale"),
            ("boaw_assignments", np.array(0.0), "boaw_assignments"),
            ("boaw_n_codebooks", np.array(pairs + 1.0), f"boaw_codebook{2 * pairs}"),
            ("n_codebooks", np.array(pairs + 1.0), "codebook pairs stored"),
            ("block_widths_fitted", np.array([171.0, 999.0]), "block widths")]:
        code, err = classify({**arrays, pre + name: bad})
        assert code == 1 and len(err) == 1 and needle in err[0], (name, err)
    rng = np.random.default_rng(0)
    names = [k for k, v in arrays.items() if k.startswith(pre) and v.ndim >= 1
             and v.shape[-1] >= 2]
    for name in rng.choice(names, size=6, replace=False):
        for bad in (arrays[name][..., :-1], -np.abs(arrays[name]) - 1.0):
            code, err = classify({**arrays, name: bad})
            if code != 0:  # a change the model tolerates may still classify
                assert code == 1 and len(err) == 1 \
                    and err[0].startswith("animegraph: error:"), (name, err)
    code, err = classify(arrays)  # the database as it was
    assert code == 0 and err == []


def test_info_of_a_single_emotion_database_reads_as_words(neutral_db):
    # It said "emotion components none" and "(clips per emotion: none)"
    from animegraph.apps.info import database_info, info_lines
    from db.store import Database

    lines = info_lines(database_info(Database.open(neutral_db)))
    (emotion,) = [line for line in lines if line.startswith("emotion:")]
    assert "no emotion components" in emotion and "components none" not in emotion
    assert not any(line.rstrip(")").endswith(": none") for line in lines if "note:" in line)


def test_ingest_summary_of_a_database_without_emotion_components_reads_as_words():
    # ingest said "emotion: emotion components none" where info says "no emotion
    # components".
    from pathlib import Path

    from ingest.pipeline import IngestReport

    report = IngestReport(db=Path("x.db"), written=True, version="v000001", summary={
        "n_clips": 1, "n_animes": 9, "duration_s": 60.0, "n_pcs": 3, "variance_kept": 0.95,
        "emotion": {"classifier": None, "emotion_components": [], "mappings": []}})
    (line,) = [line for line in report.lines() if line.startswith("emotion:")]
    assert line == "emotion: no emotion components, 0 emotion mappings, no classifier"


def test_info_orders_tied_phones_by_name(neutral_db):
    # The rarest list took ties in the order the clips happened to be read.
    from animegraph.apps.info import database_info, info_lines
    from db.store import Database

    info = database_info(Database.open(neutral_db))
    assert list(info["phones"]) == sorted(info["phones"], key=lambda p: (-info["phones"][p], p))
    lines = [info_lines({**info, "phones": phones})
             for phones in ({"ZH": 1, "OY": 1, "AA": 1, "B": 2, "UH": 1, "K": 1, "T": 9},
                            {"T": 9, "K": 1, "UH": 1, "B": 2, "AA": 1, "OY": 1, "ZH": 1})]
    assert lines[0] == lines[1]
    assert "rarest AA 1, K 1, OY 1, UH 1, ZH 1" in next(x for x in lines[0] if "rarest" in x)
