"""Trajectory-guided selection (animegraph.synthesis.guide): a baseline's predicted motion
as the target of the animes' choice, and as a blend."""

import json

import numpy as np
import pytest

from animegraph.apps import evaluate
from animegraph.baselines import make_estimator
from animegraph.search import candidates
from animegraph.synthesis import Model, query_phones, synthesize
from animegraph.synthesis.assemble import output_frames, warp_anime
from animegraph.synthesis.guide import (
    blend_guide,
    guide_trajectory,
    guided_costs,
    target_costs,
)
from db.errors import ParameterError
from db.store import Database
from ingest.formats.media import read_audio
from ingest.tables import prepared_from_database

SMALL_MLP = {"n_mfcc": 6, "context": 1, "subset_hidden": (3, 4), "expression_hidden": 4,
             "frame_rate": 60.0}


@pytest.fixture(scope="module")
def model(tiny_db):
    return Model.load(tiny_db[0])


@pytest.fixture(scope="module")
def mlp(tiny_db):
    return make_estimator("mu-mlp", **SMALL_MLP).fit(
        prepared_from_database(Database.open(tiny_db[0])))


@pytest.fixture(scope="module")
def speech(tiny_corpus, model):
    wav = sorted((tiny_corpus / "clips").glob("*_neutral_1.wav"))[0]
    audio, rate = read_audio(wav)
    phones, _ = query_phones(audio, rate, labels=None, engine="pocketsphinx")
    return audio, rate, phones


def test_target_cost_is_the_mean_distance_to_the_guide(model, speech):
    """The vectorised cost equals a loop over warp_anime (uniform stretch) and the
    distance in principal-component space; a candidate that is the guide costs 0."""
    _, _, phones = speech
    graph = model.graph
    cands = candidates(graph, [p.phone for p in phones])
    n, ranges = output_frames(phones, graph.fps)
    rng = np.random.default_rng(0)
    guide = rng.normal(size=(n, graph.motion_values.shape[1]))
    i = next(k for k, (a, b) in enumerate(ranges) if b - a >= 3 and len(cands.nodes[k]) > 2)
    a, b = ranges[i]
    guide[a:b] = warp_anime(graph, int(cands.nodes[i][1]), phones[i], b - a, time_warp=False)
    costs = target_costs(graph, model.decomposer.mixing_, phones, cands.nodes, guide)
    assert [len(c) for c in costs] == [len(c) for c in cands.nodes]
    assert costs[i][1] == pytest.approx(0.0, abs=1e-5)
    assert np.argmin(costs[i]) == 1
    pcs = model.decomposer.pcs_from_sources
    for j, node in enumerate(cands.nodes[i][:5]):
        warped = warp_anime(graph, int(node), phones[i], b - a, time_warp=False)
        want = np.linalg.norm(pcs(warped) - pcs(guide[a:b]), axis=1).mean()
        assert costs[i][j] == pytest.approx(want, rel=1e-5, abs=1e-6)


def test_guided_costs_scale_the_target_to_the_audio_median():
    audio = [np.array([1.0, 2.0, 3.0]), np.array([4.0]), np.array([])]
    target = [np.array([10.0, 20.0, 0.0]), np.array([0.0]), np.array([])]
    out = guided_costs(audio, target)
    np.testing.assert_allclose(out[0], [1.0 + 2.0 * 10 / 10, 2.0 + 2.0 * 20 / 10, 3.0])
    np.testing.assert_allclose(out[1], [4.0])  # a zero target median: the audio cost alone
    assert out[2].shape == (0,)


def test_blend_guide():
    a, b = np.zeros((4, 2)), np.ones((4, 2))
    np.testing.assert_allclose(blend_guide(a, b), 0.5)
    np.testing.assert_allclose(blend_guide(a, b, 1.0), b)
    with pytest.raises(ParameterError):
        blend_guide(a, b, 1.5)
    with pytest.raises(ParameterError):
        blend_guide(a, np.ones((3, 2)))


def test_synthesize_guided(model, mlp, speech):
    """Guided ranking changes which animes are averaged; the blend (the default use of a
    guide) keeps them and averages the motion with the guide's; with the guide's whole
    share the output is the guide's own motion."""
    audio, rate, phones = speech
    labels = [evaluate_segment(p) for p in phones]
    plain = synthesize(model, audio, rate, labels=labels, k_best=5)
    ranked = synthesize(model, audio, rate, labels=labels, k_best=5, guide=mlp,
                        guide_rank=True, guide_blend=0.0)
    assert plain.motion.shape == ranked.motion.shape
    assert any(not np.array_equal(x["node"], y["node"]) for x, y in
               zip(sum(plain.blended, []), sum(ranked.blended, []), strict=True))
    assert "target_cost" in ranked.explain[0] and "target_cost" not in plain.explain[0]
    blended = synthesize(model, audio, rate, labels=labels, k_best=5, guide=mlp)
    assert blended.blended == plain.blended and "guide_s" in blended.timings
    target = guide_trajectory(model, mlp, audio, rate, plain.phones)
    np.testing.assert_allclose(blended.ics, 0.5 * plain.ics + 0.5 * target, atol=1e-9)
    whole = synthesize(model, audio, rate, labels=labels, k_best=5, guide=mlp, guide_blend=1.0)
    np.testing.assert_allclose(whole.ics, target, atol=1e-9)
    with pytest.raises(ParameterError, match="nothing"):
        synthesize(model, audio, rate, labels=labels, guide=mlp, guide_blend=0.0)


def test_guide_of_other_channels_is_one_error(model, mlp, speech):
    audio, rate, phones = speech
    other = make_estimator("mu-mlp", **SMALL_MLP)
    other.__dict__.update({k: v for k, v in mlp.__dict__.items()})
    other.channels_ = tuple(mlp.channels_[:-1])
    with pytest.raises(Exception, match="channels"):
        guide_trajectory(model, other, audio, rate, phones)


def test_heldout_guided_rows(tiny_db, model, mlp):
    clip = prepared_from_database(Database.open(tiny_db[0]))[0]
    row = evaluate.score_heldout(model, clip, methods=("kbest20", "kbest20-guided",
                                                       "kbest20-guided-blend", "kbest20-blend"),
                                 guide=mlp)
    assert set(row["methods"]) == {"kbest20", "kbest20-guided", "kbest20-guided-blend",
                                   "kbest20-blend"}
    assert evaluate.split_guide("kbest20-mix-likely-guided-blend") == (
        "kbest20-mix-likely", True, True)
    with pytest.raises(ValueError, match="guide"):
        evaluate.score_heldout(model, clip, methods=("kbest20-guided",))


def copy_unfitted(db, to):
    """A copy of the shared database ``db`` without the baselines an earlier test (a
    ``synth`` of speech alone) may have fitted and stored in it."""
    import shutil

    from animegraph.baselines.stored import MODELS_DIR

    shutil.copytree(db, to, ignore=lambda folder, names: [MODELS_DIR] if folder == str(db)
                    else [])


def evaluate_segment(phone):
    from ingest.formats.phones_csv import Segment

    return Segment(phone.phone, phone.start, phone.end)


def test_cli_synth_guide(tiny_db, tiny_corpus, mlp, tmp_path, capsys):
    """Audio only, ``synth`` averages its motion with the mean of mu-mlp's and ppg-ridge's
    by default (fitting the one not stored) and says so; ``--guide none`` turns it off,
    ``--guide-rank`` ranks by it, ``--guide-blend 1`` writes the guide's motion; bad uses
    are one line."""
    import shutil

    from animegraph.apps.cli import SYNTH_GUIDES, main
    from animegraph.baselines.base import load_model, save_model
    from animegraph.synthesis.guide import GUIDES

    assert SYNTH_GUIDES == GUIDES
    db = tmp_path / "db"
    copy_unfitted(tiny_db[0], db)
    save_model(mlp, db)  # small, so that the test does not fit the paper's size
    wav = tmp_path / "speech.wav"
    shutil.copy(sorted((tiny_corpus / "clips").glob("*_neutral_1.wav"))[0], wav)
    base = ["synth", str(wav), "--db", str(db), "--phones-engine", "pocketsphinx"]
    assert main([*base, "-o", str(tmp_path / "g.npz"), "--explain"]) == 0
    captured = capsys.readouterr()
    assert ("the output the mean of that and the mean of mu-mlp's and ppg-ridge's predicted "
            "motion (the blend measured") in captured.err
    assert "fitting ppg-ridge" in captured.err and "fitting mu-mlp" not in captured.err
    assert "ppg-ridge's predicted motion" in captured.out
    assert main([*base, "-o", str(tmp_path / "p.npz"), "--guide", "none"]) == 0
    assert "predicted motion" not in capsys.readouterr().err
    assert main([*base, "-o", str(tmp_path / "r.npz"), "--guide", "mu-mlp", "--guide-rank",
                 "--explain"]) == 0
    captured = capsys.readouterr()
    # The path line reads as English, and claims of the ranking only what was measured.
    assert ("the output the mean of that and mu-mlp's predicted motion; each phone's animes "
            "also ranked by their distance to mu-mlp's predicted motion (as asked: it helped "
            "within one speaker, not across speakers)") in captured.err
    assert "target_cost" in captured.out and "0.5 mu-mlp" not in captured.err
    assert main([*base, "-o", str(tmp_path / "w.npz"), "--guide", "mu-mlp",
                 "--guide-blend", "1"]) == 0
    assert main(["synth", str(wav), "--db", str(db), "--method", "mu-mlp",
                 "-o", str(tmp_path / "m.npz")]) == 0
    capsys.readouterr()
    with np.load(tmp_path / "g.npz") as g, np.load(tmp_path / "p.npz") as p, \
            np.load(tmp_path / "w.npz") as w, np.load(tmp_path / "m.npz") as m, \
            np.load(tmp_path / "r.npz") as r:
        assert g["motion"].shape == p["motion"].shape == r["motion"].shape
        assert not np.allclose(g["motion"], p["motion"])
        assert not np.allclose(g["motion"], r["motion"])
        # The guide's motion as the database's PCA/ICA model holds it (95 % of the variance).
        held = Model.load(db)
        m_held = held.to_channels(held.decomposer.transform(held.to_local(m["motion"])))
        n = min(len(w["motion"]), len(m_held))
        np.testing.assert_allclose(w["motion"][:n - 1], m_held[:n - 1], atol=1e-4)
    assert load_model(db, "mu-mlp").get_params() == mlp.get_params()
    for extra, needle in ((["--guide", "none", "--guide-blend", "0.3"], "needs a guide"),
                          (["--exact", "--guide-rank"], "--guide-rank needs a guide"),
                          (["--guide-blend", "2"], "must be in [0, 1]"),
                          (["--guide-blend", "0"], "nothing to do"),
                          (["--method", "mu-mlp", "--guide", "mu-mlp"],
                           "--phones-engine, --guide only apply")):
        assert main([*base, "-o", str(tmp_path / "x.npz"), *extra]) in (1, 2)
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and needle in err[0], err


def test_cli_synth_mean_of_two_guides(tiny_db, tiny_corpus, mlp, tmp_path, capsys):
    """``--guide mu-mlp+ppg-ridge``: the guide is the mean of the two models' motion (with
    ``--guide-blend 1`` the output is that mean, as the database's components hold it),
    fitted and stored on first use; the path line names both."""
    import shutil

    from animegraph.apps.cli import main
    from animegraph.baselines.base import load_model, save_model

    db = tmp_path / "db"
    copy_unfitted(tiny_db[0], db)
    save_model(mlp, db)
    wav = tmp_path / "speech.wav"
    shutil.copy(sorted((tiny_corpus / "clips").glob("*_neutral_1.wav"))[0], wav)
    base = ["synth", str(wav), "--db", str(db), "--phones-engine", "pocketsphinx"]
    assert main([*base, "-o", str(tmp_path / "b.npz"), "--guide", "mu-mlp+ppg-ridge",
                 "--guide-blend", "1"]) == 0
    err = capsys.readouterr().err
    assert "fitting ppg-ridge" in err and "fitting mu-mlp" not in err
    assert "the output the mean of mu-mlp's and ppg-ridge's predicted motion alone" in err
    assert load_model(db, "ppg-ridge") is not None  # stored: not fitted again
    held = Model.load(db)

    def components(path):  # written in world coordinates: back to the database's components
        with np.load(path) as f:
            return held.decomposer.transform(held.to_local(f["motion"]))

    parts = []
    for method in ("mu-mlp", "ppg-ridge"):
        assert main(["synth", str(wav), "--db", str(db), "--method", method,
                     "-o", str(tmp_path / f"{method}.npz")]) == 0
        parts.append(components(tmp_path / f"{method}.npz"))
    capsys.readouterr()
    both = components(tmp_path / "b.npz")
    n = min(len(both), *(len(p) for p in parts)) - 1
    np.testing.assert_allclose(both[:n], (parts[0][:n] + parts[1][:n]) / 2, atol=1e-4)


def test_cli_default_guide_that_cannot_be_fitted_is_a_warning(tiny_db, tiny_corpus, tmp_path,
                                                              capsys):
    """The tiny database has too little speech for the paper's mu-mlp: audio-only synth
    warns and is guided by ppg-ridge alone (the default guide's other half); asked for by
    name, mu-mlp is one error line."""
    import shutil

    from animegraph.apps.cli import main

    db = tmp_path / "db"
    copy_unfitted(tiny_db[0], db)
    wav = tmp_path / "speech.wav"
    shutil.copy(sorted((tiny_corpus / "clips").glob("*_neutral_1.wav"))[0], wav)
    base = ["synth", str(wav), "--db", str(db), "--phones-engine", "pocketsphinx"]
    assert main([*base, "-o", str(tmp_path / "a.npz")]) == 0
    err = capsys.readouterr().err
    assert "warning: no mu-mlp guide (too little data" in err
    # The path line says why too (the Live Link database's said only "could not be fitted").
    [path] = [line for line in err.splitlines() if line.startswith("animegraph: path: ")]
    assert path.endswith("but without its mu-mlp guide, which could not be fitted (too little "
                         "data for mu-mlp's speech-to-face network (the paper's pooled "
                         "audio-to-UMUP MLP) on the 'neutral' clips: "
                         + path.split("'neutral' clips: ")[-1])
    assert "s where it needs" in path and "animes alone" not in err.split("path: ")[0]
    assert "fitting ppg-ridge" in err
    # The failure is kept with this version of the database: the next run does not fit
    # again (no "fitting" line), and says why.
    assert main([*base, "-o", str(tmp_path / "a2.npz")]) == 0
    err = capsys.readouterr().err
    assert "fitting" not in err
    assert "no mu-mlp guide (too little data" in err and "kept from an earlier run" in err
    assert "but without its mu-mlp guide, which could not be fitted (too little data" in err
    with np.load(tmp_path / "a2.npz") as a, np.load(tmp_path / "a.npz") as b:
        np.testing.assert_array_equal(a["motion"], b["motion"])  # ppg-ridge stored, reused
    assert main([*base, "-o", str(tmp_path / "b.npz"), "--guide", "mu-mlp"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert "too little data" in err[-1] and not any("Traceback" in e for e in err)


def test_stored_mu_mlp_predicts_as_the_estimator_without_scikit_learn(tiny_db, mlp, speech,
                                                                      tmp_path):
    """The NumPy-only restore of a stored mu-mlp gives the estimator's prediction, in a
    process that never imports scikit-learn."""
    import json
    import subprocess
    import sys

    from animegraph.baselines.base import save_model
    from animegraph.baselines.stored import load_forward

    db = tmp_path / "db"
    copy_unfitted(tiny_db[0], db)
    assert load_forward(db, "mu-mlp") is None and load_forward(db, "av-hmm") is None
    save_model(mlp, db)
    audio, rate, _ = speech
    stored = load_forward(db, "mu-mlp")
    for emotion in (None, "happy"):
        np.testing.assert_allclose(stored.predict(audio, rate, emotion=emotion),
                                   mlp.predict(audio, rate, emotion=emotion), atol=1e-9)
    np.save(tmp_path / "audio.npy", np.asarray(audio, dtype=np.float32))
    code = (
        "import json, sys\nimport numpy as np\n"
        "from animegraph.baselines.stored import load_forward\n"
        f"m = load_forward({str(db)!r}, 'mu-mlp')\n"
        f"y = m.predict(np.load({str(tmp_path / 'audio.npy')!r}), {rate})\n"
        f"np.save({str(tmp_path / 'y.npy')!r}, y)\n"
        "print(json.dumps([k for k in ('sklearn', 'scipy.special', 'pandas') "
        "if k in sys.modules]))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert json.loads(out.stdout.strip().splitlines()[-1]) == []
    np.testing.assert_allclose(np.load(tmp_path / "y.npy"), mlp.predict(audio, rate),
                               atol=1e-6)


def test_one_shot_guided_synth_imports_no_heavy_library(tiny_db, tiny_corpus, mlp, tmp_path):
    """Audio only, a stored guide (mu-mlp or ppg-ridge) adds no library to a one-shot
    ``synth``'s imports: not scikit-learn, librosa or pandas (tests/test_startup.py)."""
    import json
    import os
    import shutil
    import subprocess
    import sys

    from test_startup import HEAVY

    from animegraph.apps.cache import CACHE_ENV
    from animegraph.baselines.base import save_model

    db = tmp_path / "db"
    copy_unfitted(tiny_db[0], db)
    save_model(mlp, db)
    save_model(make_estimator("ppg-ridge").fit(db), db)
    wav = tmp_path / "speech.wav"
    shutil.copy(sorted((tiny_corpus / "clips").glob("*_neutral_1.wav"))[0], wav)
    loaded = {}
    for guide in ("mu-mlp", "ppg-ridge", "none"):
        code = (
            "import json, sys\n"
            "from animegraph.apps.cli import main\n"
            f"status = main(['synth', {str(wav)!r}, '--db', {str(db)!r}, '--guide', "
            f"{guide!r}, '-o', {str(tmp_path / 'out.npz')!r}])\n"
            f"print(json.dumps([status, [m for m in {HEAVY + ('scipy.special',)!r} "
            "if m in sys.modules]]))\n")
        # A cache of its own each: the phones a first run heard would spare the next runs
        # the phone engines (and their imports), which is not the guides' doing.
        env = {**os.environ, CACHE_ENV: str(tmp_path / f"cache-{guide}")}
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                             check=True, env=env)
        status, loaded[guide] = json.loads(out.stdout.strip().splitlines()[-1])
        assert status == 0
    assert loaded["mu-mlp"] == loaded["ppg-ridge"] == loaded["none"]
    assert not {"sklearn", "librosa", "pandas"} & set(loaded["mu-mlp"])


@pytest.mark.parametrize("corrupt", ["covariance", "nan", "shape", "std"])
def test_corrupt_stored_mu_mlp_is_one_line(tiny_db, tiny_corpus, mlp, tmp_path, capsys, corrupt):
    """A stored mu-mlp from someone else's database that would fail inside the prediction
    (a covariance not positive definite, a NaN, a network of the wrong shape, a zero
    spread) is refused when it is read: one error line from synth, never a traceback."""
    import shutil

    import pyarrow.parquet as pq

    from animegraph.apps.cli import main
    from animegraph.baselines.base import save_model
    from animegraph.baselines.stored import model_path
    from db.store import arrays_from_table, arrays_to_table

    db = tmp_path / "db"
    copy_unfitted(tiny_db[0], db)
    save_model(mlp, db)
    path = model_path(db, "mu-mlp")
    table = pq.read_table(path)
    arrays = arrays_from_table(table)
    if corrupt == "covariance":
        arrays["gmm/000/covariances"] = -np.abs(arrays["gmm/000/covariances"])
    elif corrupt == "nan":
        arrays["pooled/W1"] = np.full_like(arrays["pooled/W1"], np.nan)
    elif corrupt == "shape":
        arrays["pooled/W1"] = arrays["pooled/W1"][:, :1]
        arrays["pooled/b1"] = arrays["pooled/b1"][:1]
    else:
        arrays["x_std"] = np.zeros_like(arrays["x_std"])
    pq.write_table(arrays_to_table(arrays).replace_schema_metadata(table.schema.metadata),
                   path)
    wav = tmp_path / "speech.wav"
    shutil.copy(sorted((tiny_corpus / "clips").glob("*_neutral_1.wav"))[0], wav)
    engine = ["--phones-engine", "pocketsphinx"]  # a baseline hears no phones
    for extra in ([*engine], [*engine, "--guide", "mu-mlp"], ["--method", "mu-mlp"]):
        out = tmp_path / "out.npz"
        assert main(["synth", str(wav), "--db", str(db), "-o", str(out), *extra]) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert "mu-mlp" in err[-1], err[-1]
        assert ("is implausible" if corrupt != "nan" else "values not finite") in err[-1]
        assert not any("Traceback" in e for e in err) and not out.exists()


def test_a_transcript_that_does_not_fit_is_synthesized_as_speech_alone(model, mlp, speech,
                                                                       tiny_corpus):
    """``recognized_guide`` is the speech-alone path's guide for a transcript that turns out
    not to fit: the motion is that of no transcript with the guide, the record says which
    guide and the warning says why; a transcript that fits never loads it."""
    from animegraph.synthesis import explain_record

    audio, rate, _ = speech
    asked = []

    def load():
        asked.append(1)
        return mlp

    wrong = synthesize(model, audio, rate, text="nothing like what is said in it at all",
                       k_best=5, recognized_guide=load)
    alone = synthesize(model, audio, rate, k_best=5, guide=mlp)
    assert wrong.segmentation == alone.segmentation == "recognized" and asked == [1]
    np.testing.assert_array_equal(wrong.motion, alone.motion)
    assert wrong.guided == alone.guided == ("mu-mlp",)
    assert explain_record(wrong)["guide"] == "mu-mlp"
    assert wrong.warnings[0].startswith("transcript alignment failed: ")
    assert "fell back to phone recognition" in wrong.warnings[0]
    assert not any("alignment" in w for w in alone.warnings)
    # The guide given wins; without one to fall back on, the animes alone.
    unguided = synthesize(model, audio, rate, text="nothing like what is said in it at all",
                          k_best=5)
    assert unguided.guided == () and explain_record(unguided)["guide"] is None
    assert not np.array_equal(unguided.motion, wrong.motion)
    wav = sorted((tiny_corpus / "clips").glob("*_neutral_1.wav"))[0]
    said = json.loads(wav.with_suffix(".json").read_text())["text"]
    fits = synthesize(model, audio, rate, text=said, k_best=5, recognized_guide=load)
    assert fits.segmentation == "aligned" and fits.guided == () and asked == [1]


def test_a_kept_reason_from_someone_else_is_read_within_its_bound(tiny_db, tmp_path):
    """Why a guide could not be fitted is read from the database folder: a FIFO in its
    place (the read would block), or a file of gigabytes, is no reason rather than a hang
    or a memory bomb; a kept reason gives its first printable line."""
    import os

    from animegraph.baselines.stored import _unfit_path, record_unfit, unfit_reason

    db = tmp_path / "db"
    copy_unfitted(tiny_db[0], db)
    record_unfit(db, "mu-mlp", "too little data\x1b[31m\nsecond line")
    assert unfit_reason(db, "mu-mlp") == "too little data[31m"
    path = _unfit_path(db, "mu-mlp")
    path.unlink()
    os.mkfifo(path)
    assert unfit_reason(db, "mu-mlp") is None
    path.unlink()
    with open(path, "wb") as handle:  # sparse: no disk taken
        handle.truncate(4 << 30)
    assert unfit_reason(db, "mu-mlp") is None


def test_a_kept_reason_is_written_under_the_writer_lock(tiny_db, tmp_path):
    """Why a guide could not be fitted is written as a fitted guide is saved, under the
    database's writer lock: while another process writes the database nothing is written
    (not waited for either); once it is done, the reason is kept."""
    import signal

    from test_writer_lock import _hold

    from animegraph.baselines.stored import record_unfit, unfit_reason

    db = tmp_path / "db"
    copy_unfitted(tiny_db[0], db)
    proc = _hold(db)
    try:
        record_unfit(db, "mu-mlp", "too little data")
        assert unfit_reason(db, "mu-mlp") is None
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    record_unfit(db, "mu-mlp", "too little data")
    assert unfit_reason(db, "mu-mlp") == "too little data"


def test_the_path_line_of_a_guide_reads_as_english_and_claims_only_what_was_measured():
    """"the output 0.5 mu-mlp's predicted motion" read as no English, and the default
    guide's "measured best on real speech" was said of --guide-rank too, which
    docs/results/lipsync.md found to hurt across speakers."""
    from animegraph.synthesis.path import guide_line

    asked = guide_line("mu-mlp", 0.5, False, known_phones=False, asked=True)
    assert asked == "; the output the mean of that and mu-mlp's predicted motion (beyond the paper)"
    share = guide_line("mu-mlp", 0.3, False, known_phones=True, asked=True)
    assert "the output 0.3 mu-mlp's predicted motion, 0.7 the animes' motion" in share
    ranked = guide_line("mu-mlp+ppg-ridge", 0.5, True, known_phones=False, asked=False)
    claim, rank = ranked.split("; each phone's animes also ranked")
    assert "measured best" in claim and "the blend" in claim
    assert "measured best" not in rank and "not across speakers" in rank
    only = guide_line("mu-mlp", 0.0, True, known_phones=False, asked=True)
    assert "the output" not in only and "ranked" in only
