"""Lip-sync synthesis end to end: speech in, motion out, against the synthetic ground truth."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from animegraph.apps.cli import main
from animegraph.synthesis import Model, PostOptions, explain_record, synthesize, warp_positions
from animegraph.synthesis.assemble import Phone, warp_anime, warp_animes
from db.errors import DataError, ParameterError
from ingest.corpus import face
from ingest.corpus.synthetic import ClipSpec, CorpusConfig, synthesize_clip, write_clip
from ingest.formats.c3d import read_c3d
from ingest.formats.phones_csv import read_phones_csv
from ingest.formats.wav import read_wav


@pytest.fixture(scope="module")
def model(tiny_db):
    return Model.load(tiny_db[0])


@pytest.fixture(scope="module")
def held_out(tmp_path_factory):
    """A sentence the database has never seen, spoken happily, with its true motion."""
    config = CorpusConfig(marker_noise_mm=0.0, dropouts_per_second=0.0)
    spec = ClipSpec(clip_id="held_out", sentence_id="x", text="Bob moved the warm vase away.",
                    emotion="happy", variation=1, speaker="synth01", seed=99)
    clip = synthesize_clip(spec, config)
    folder = tmp_path_factory.mktemp("held")
    write_clip(clip, folder)
    return folder / "held_out", clip


def test_synthesizes_a_held_out_sentence(model, held_out):
    stem, clip = held_out
    audio, sr = read_wav(stem.with_suffix(".wav"))
    labels = read_phones_csv(f"{stem}.phones.csv")
    out = synthesize(model, audio, sr, labels=labels, emotion="happy")
    assert out.segmentation == "labels"
    assert out.motion.shape == (round(len(audio) / sr * 120), 216)
    assert np.isfinite(out.motion).all()
    assert [e["phone"] for e in out.explain] == [s.phone for s in labels]
    assert all(e["anime_phone"] == e["phone"] for e in out.explain)  # same phonemes
    # Lips follow the speech: mouth opening correlates with the truth.
    truth = face.marker_distance(clip.markers, "ulip_in_c", "llip_in_c")
    synth = face.marker_distance(out.motion.reshape(len(out.motion), -1, 3), "ulip_in_c",
                                 "llip_in_c")
    n = min(len(truth), len(synth))
    assert np.corrcoef(truth[:n], synth[:n])[0, 1] > 0.5


def test_a_recorded_utterance_comes_back_as_itself(model, tiny_corpus, tiny_db):
    clip_id = model.graph.clip_ids[0]
    audio, sr = read_wav(tiny_corpus / "clips" / f"{clip_id}.wav")
    labels = read_phones_csv(tiny_corpus / "clips" / f"{clip_id}.phones.csv")
    out = synthesize(model, audio, sr, labels=labels,
                     options=PostOptions(smooth=False))
    assert out.result.n_jumps == 0
    assert {e["clip_id"] for e in out.explain} == {clip_id}
    truth = read_c3d(tiny_corpus / "clips" / f"{clip_id}.c3d").points
    motion = out.motion.reshape(len(out.motion), -1, 3)
    n = min(len(truth), len(motion))
    err = np.sqrt(np.nanmean((motion[:n] - truth[:n]) ** 2))
    assert err < 1.0  # mm: PCA's loss and frame rounding only


def test_every_search_mode_and_post_step_runs(model, held_out):
    stem, _ = held_out
    audio, sr = read_wav(stem.with_suffix(".wav"))
    labels = read_phones_csv(f"{stem}.phones.csv")
    exact = synthesize(model, audio, sr, labels=labels)
    for kwargs in ({"method": "window", "window": 3}, {"method": "dp"}):
        other = synthesize(model, audio, sr, labels=labels, **kwargs)
        assert other.result.cost >= exact.result.cost - 1e-9
    raw = synthesize(model, audio, sr, labels=labels,
                     options=PostOptions(time_warp=False, blend=False, smooth=False))
    assert raw.motion.shape == exact.motion.shape


def test_bad_input(model):
    with pytest.raises(DataError, match="silent"):
        synthesize(model, np.zeros(16000, np.float32), 16000)
    with pytest.raises(ParameterError, match="emotion"):
        synthesize(model, np.ones(16000, np.float32) * 0.1, 16000, emotion="bored")
    with pytest.raises(ParameterError, match="mono"):
        synthesize(model, np.zeros((100, 2), np.float32), 16000)


def test_cli_synth_writes_c3d_and_explains(tiny_db, held_out, tmp_path, capsys):
    stem, _ = held_out
    out = tmp_path / "out.c3d"
    argv = ["synth", str(stem.with_suffix(".wav")), "--db", str(tiny_db[0]), "--labels",
            f"{stem}.phones.csv", "--emotion", "happy", "-o", str(out), "--explain",
            "--explain-json", str(tmp_path / "explain.json")]
    assert main(argv) == 0
    captured = capsys.readouterr()
    assert "jump matches" in captured.err and "clip_id" in captured.out
    assert read_c3d(out).points.shape[1] == 72
    record = json.loads((tmp_path / "explain.json").read_text())
    assert len(record["phones"]) == len(read_phones_csv(f"{stem}.phones.csv"))
    for suffix in (".csv", ".npz"):
        assert main([*argv[:-5], "-o", str(tmp_path / f"out{suffix}")]) == 0
    assert main([*argv[:-5], "--tolerance", "0.05", "-o", str(tmp_path / "tol.npz")]) == 0
    assert main([*argv[:-5], "--k-best", "3", "-o", str(tmp_path / "k3.npz")]) == 0
    with np.load(tmp_path / "out.npz") as exact, np.load(tmp_path / "tol.npz") as tol, \
            np.load(tmp_path / "k3.npz") as k3:
        assert exact["motion"].shape == tol["motion"].shape == k3["motion"].shape


def test_cli_synth_picks_its_path_by_what_it_has(tiny_db, held_out, tmp_path, capsys,
                                                 monkeypatch):
    """Labels or a transcript, and audio only: k-best 20 (one function decides for labels,
    shared with batch), said on stderr and in --explain; --exact brings the paper's
    search back."""
    stem, _ = held_out
    # The speech alone, without the phone labels written beside it (synth would use them).
    shutil.copy(stem.with_suffix(".wav"), tmp_path / "speech.wav")
    base = ["synth", str(tmp_path / "speech.wav"), "--db", str(tiny_db[0])]
    assert main([*base, "--labels", f"{stem}.phones.csv", "-o", str(tmp_path / "a.npz"),
                 "--explain"]) == 0
    captured = capsys.readouterr()
    assert ("path: phone labels given: each phone the mean of its 20 best animes, ranked by "
            "phonetic context first") in captured.err
    assert "path: phone labels given" in captured.out and "k-best 20" in captured.err
    assert main([*base, "--labels", f"{stem}.phones.csv", "--no-context-ranking", "-o",
                 str(tmp_path / "a3.npz")]) == 0
    err = capsys.readouterr().err
    assert "phonetic context" not in err and "mean of its 20 best animes" in err
    with np.load(tmp_path / "a.npz") as by_context, np.load(tmp_path / "a3.npz") as by_audio:
        assert not np.allclose(by_context["motion"], by_audio["motion"])
    assert main([*base, "--labels", f"{stem}.phones.csv", "--exact", "-o",
                 str(tmp_path / "a2.npz")]) == 0
    assert "path: phone labels given: the paper's search" in capsys.readouterr().err
    with np.load(tmp_path / "a.npz") as kbest, np.load(tmp_path / "a2.npz") as exact:
        assert kbest["motion"].shape == exact["motion"].shape
        assert not np.allclose(kbest["motion"], exact["motion"])
    assert main([*base, "-o", str(tmp_path / "b.npz")]) == 0
    err = b_err = capsys.readouterr().err
    assert "path: audio only (phones named by hama, placed by PocketSphinx)" in err
    assert "mean of its 20 best animes" in err and "(recognized)" in err
    assert main([*base, "--exact", "--phones-engine", "pocketsphinx",
                 "-o", str(tmp_path / "c.npz")]) == 0
    err = capsys.readouterr().err
    assert "audio only (phones recognised by the pocketsphinx phone engine): the paper's" in err
    assert main([*base, "--text", "nothing like what is said in it at all", "-o",
                 str(tmp_path / "d.npz")]) == 0
    err = capsys.readouterr().err  # checked before anything is aligned: speech alone
    assert "does not match the audio" in err and "synthesizing from the speech alone" in err
    assert "path: audio only (phones named by hama" in err and "phonetic context" not in err
    with np.load(tmp_path / "b.npz") as alone, np.load(tmp_path / "d.npz") as dropped:
        np.testing.assert_array_equal(alone["motion"], dropped["motion"])
    assert main([*base, "--text", "nothing like what is said in it at all", "-o",
                 str(tmp_path / "e.npz"), "--phones-engine", "hama"]) == 0
    err = capsys.readouterr().err
    assert "does not match the audio" in err and "path: audio only (phones recognised" in err
    # A transcript that passes the check but cannot be aligned after all: the speech
    # alone, with its guide, all the same.
    import animegraph.apps.commands.synth as synth_command

    monkeypatch.setattr(synth_command, "_transcript_mismatch", lambda *args: None)
    assert main([*base, "--text", "nothing like what is said in it at all", "-o",
                 str(tmp_path / "f.npz")]) == 0
    err = capsys.readouterr().err
    assert "warning: transcript alignment failed: " in err
    assert "path: audio only (phones named by hama" in err and "phonetic context" not in err
    assert "(transcript alignment failed: synthesized from the speech alone)" in err
    # (the tiny database is too small for mu-mlp: its path line says so, as for b.npz)
    assert ("but without its mu-mlp guide" in err) == ("without its mu-mlp" in b_err)
    with np.load(tmp_path / "b.npz") as alone, np.load(tmp_path / "f.npz") as late:
        np.testing.assert_array_equal(alone["motion"], late["motion"])


@pytest.mark.parametrize("extra, needle", [
    (["--emotion", "bored"], "not in the database"),
    (["-o", "{tmp}/out.mp3"], "must end in"),
    (["-o", "{tmp}/out.glb"], "'animegraph render' makes .mp4, .gif, .png or .glb"),
    # a missing folder was found when writing, after the synthesis and its lines
    (["-o", "{tmp}/no/o.c3d"], "folder {tmp}/no does not exist"),
    (["--method", "mu-mlp", "-o", "{tmp}/no/o.c3d"], "folder {tmp}/no does not exist"),
    (["--search", "window"], "--window"),
    (["--method", "mu-mlp", "--window", "3"], "--window only applies"),
    (["--method", "hmm"], "invalid choice"),
    (["--tolerance", "1.5"], "--tolerance must be a number in [0, 1)"),
    (["--window", "3", "--tolerance", "0.1"], "only used by method='exact'"),
    (["--method", "mu-mlp", "--tolerance", "0.1", "--k-best", "10"],
     "--tolerance, --k-best only apply"),
    (["--method", "mu-mlp", "--k-best", "10"], "--k-best only applies"),
    (["--k-best", "0"], "--k-best must be at least 1, got 0"),
    (["--helper", "anchored", "--k-best", "3"], "--helper blends the paper's search"),
    (["--helper", "nearest"], "invalid choice"),
    (["--exact", "--context-ranking"], "--context-ranking ranks the animes k-best averages"),
    (["--method", "mu-mlp", "--no-context-ranking"], "--context-ranking only applies"),
    (["--method", "mu-mlp", "--helper", "paper"], "--helper only applies"),
    (["--method", "mu-mlp", "--phones-engine", "hama"], "--phones-engine only applies"),
])
def test_cli_synth_errors(tiny_db, held_out, tmp_path, capsys, extra, needle):
    stem, _ = held_out
    argv = ["synth", str(stem.with_suffix(".wav")), "--db", str(tiny_db[0]), "-o",
            str(tmp_path / "o.c3d"), *[e.format(tmp=tmp_path) for e in extra]]
    assert main(argv) in (1, 2)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle.format(tmp=tmp_path) in err[0]


def test_a_minute_long_utterance_at_any_rate_in_stereo(model, tmp_path):
    """The paper's longest synthesis was 62 s; 44.1 kHz stereo input is read as mono."""
    from scipy.signal import resample_poly

    from ingest.formats.phones_csv import Segment
    from ingest.formats.wav import write_wav
    from ingest.speech.espeak import speak

    text = " ".join(["Bob moved the warm vase away from the window, and Pam sang."] * 16)
    utt = speak(text)
    assert utt.duration > 60
    mono = resample_poly(utt.audio, 441, 160).astype(np.float32)
    write_wav(tmp_path / "long.wav", np.stack([mono, mono], axis=1), 44100)
    audio, sr = read_wav(tmp_path / "long.wav")
    labels = [Segment(p.phone, p.start, p.end) for p in utt.phones]
    out = synthesize(model, audio, sr, labels=labels)
    assert sr == 44100 and audio.ndim == 1
    assert abs(len(out.motion) / 120 - utt.duration) < 0.05
    assert np.isfinite(out.motion).all()


def test_a_database_without_animes_is_refused(tmp_path):
    import pyarrow as pa

    from db.store import write_version

    empty = {name: pa.table({"emotion": pa.array([], pa.string())})
             for name in ("clips", "animes", "frames")}
    empty.update({name: pa.table({"x": pa.array([], pa.int32())})
                  for name in ("audio", "channels", "model_arrays", "components")})
    write_version(tmp_path / "db", empty, {"fps": 120.0, "n_channels": 0})
    with pytest.raises(DataError):
        Model.load(tmp_path / "db")


def test_warp_positions_pin_the_ends():
    # The anime's first three frames all match the input's first frame, its last two
    # the last: DTW's mean would start at 1.0 and end at 6.5; the warp starts at the
    # anime's first frame and ends at its last.
    c_input = np.array([[0.0], [1.0], [2.0]])
    c_anime = np.array([[0.0], [0.0], [0.0], [1.0], [1.5], [2.0], [2.0], [2.0]])
    src = warp_positions(c_input, c_anime)
    assert src[0] == 0.0 and src[-1] == 7.0
    assert np.all(np.diff(src) >= 0)
    assert warp_positions(c_input[:1], c_anime).tolist() == [0.0]


def test_animes_warped_at_once_play_each_anime_on_the_phone_timing(model):
    # Against §4.3 written out for one anime at a time: the output frame's place in the
    # input phone, through the pinned DTW warp, to a place in the anime's motion.
    graph = model.graph
    rng = np.random.default_rng(3)
    nodes = rng.choice(graph.n_nodes, size=12, replace=False)
    phone = Phone("AA", 0.0, 0.2, graph.prosody(int(nodes[0]))[::-1].astype(np.float64))
    for n_out in (1, 7, 40):
        got = warp_animes(graph, nodes, phone, n_out)
        assert got.shape == (12, n_out, graph.motion_values.shape[1])
        for a, piece in zip(nodes, got, strict=True):
            motion = graph.motion(int(a)).astype(np.float64)
            prosody = graph.prosody(int(a))
            u = (np.arange(n_out) + 0.5) / n_out
            if len(motion) > 1 and len(prosody) > 1:
                src = warp_positions(phone.prosody, prosody)
                v = np.interp(u * (len(phone.prosody) - 1), np.arange(len(src)), src)
                u = np.clip(v / (len(prosody) - 1), 0.0, 1.0)
            pos = u * (len(motion) - 1)
            lo = np.floor(pos).astype(int)
            hi = np.minimum(lo + 1, len(motion) - 1)
            t = (pos - lo)[:, None]
            np.testing.assert_array_equal(piece, (1 - t) * motion[lo] + t * motion[hi])
        np.testing.assert_array_equal(warp_anime(graph, int(nodes[1]), phone, n_out), got[1])
    assert warp_animes(graph, nodes, phone, 0).shape == (12, 0, graph.motion_values.shape[1])


def test_k_best_blends_animes_and_one_is_the_pick_unblended(model, held_out):
    stem, clip = held_out
    audio, sr = read_wav(stem.with_suffix(".wav"))
    labels = read_phones_csv(f"{stem}.phones.csv")
    plain = synthesize(model, audio, sr, labels=labels)
    one = synthesize(model, audio, sr, labels=labels, k_best=1,
                     options=PostOptions(blend=False))
    unblended = synthesize(model, audio, sr, labels=labels, options=PostOptions(blend=False))
    np.testing.assert_allclose(one.motion, unblended.motion)
    assert one.joins == []
    many = synthesize(model, audio, sr, labels=labels, emotion="happy", k_best=4)
    assert many.motion.shape == plain.motion.shape and np.isfinite(many.motion).all()
    assert not np.allclose(many.motion, plain.motion)
    truth = face.marker_distance(clip.markers, "ulip_in_c", "llip_in_c")
    opening = face.marker_distance(many.motion.reshape(len(many.motion), -1, 3), "ulip_in_c",
                                   "llip_in_c")
    n = min(len(truth), len(opening))
    assert np.corrcoef(truth[:n], opening[:n])[0, 1] > 0.5
    # What was averaged is explained: per phone the pick first, weights falling, summing to 1.
    assert plain.blended == () and "k_best" not in explain_record(plain)
    assert len(many.blended) == len(many.phones) == len(explain_record(many)["k_best"])
    for row, animes in zip(many.explain, many.blended, strict=True):
        weights = [a["weight"] for a in animes]
        assert animes[0]["node"] == row["node"] and row["k_best"] == len(animes) <= 4
        assert weights == sorted(weights, reverse=True)
        assert sum(weights) == pytest.approx(1, abs=1e-3)
        assert row["pick_weight"] == weights[0]
    with pytest.raises(ParameterError, match="k must be"):
        synthesize(model, audio, sr, labels=labels, k_best=0)



def test_shortlist_cuts_k_bests_candidates_and_none_restores_the_full_search(model, held_out):
    from test_shortlist import full_ranking_first

    from animegraph.search import SearchWeights, search
    from animegraph.synthesis.pipeline import query_phones, score_candidates

    stem, _ = held_out
    audio, sr = read_wav(stem.with_suffix(".wav"))
    labels = read_phones_csv(f"{stem}.phones.csv")
    phones, _ = query_phones(audio, sr, labels=labels)
    cands, costs = score_candidates(model, phones)
    assert max(cands.sizes) > 4  # more animes of a phone than the shortlist below keeps
    full = synthesize(model, audio, sr, labels=labels, k_best=4, shortlist=None)
    np.testing.assert_array_equal(full.result.nodes, search(model.graph, cands, costs).nodes)
    # A shortlist of 2 with k-best 4 keeps 4 a phone (never fewer than k): the first 4 by
    # the ranking (context first: the phones are known), which are the 4 blended.
    cut = synthesize(model, audio, sr, labels=labels, k_best=4, shortlist=2)
    first = full_ranking_first(model.graph, cands, costs, 4, emotion=None, context=True,
                               weights=SearchWeights())
    for i, animes in enumerate(cut.blended):
        assert sorted(a["node"] for a in animes) == first[i].tolist()
        assert int(cut.result.nodes[i]) in first[i]
    for bad in (0, -1, True, 1.5):
        with pytest.raises(ParameterError, match="shortlist must be"):
            synthesize(model, audio, sr, labels=labels, k_best=4, shortlist=bad)

def _played_through(graph, nodes):
    """Input phones on the recorded frames of ``nodes``, one after another."""
    from animegraph.synthesis import Phone
    from ingest.speech.phones import PHONES

    phones, t = [], 0.0
    for a in nodes:
        n = len(graph.motion(a)) / graph.fps
        phones.append(Phone(PHONES[graph.node_phone[a]], t, t + n, graph.prosody(a)))
        t += n
    return phones


def test_k_best_cross_fades_phones_through_their_recorded_transitions(model):
    from dataclasses import replace

    from animegraph.synthesis import Phone, blend_k_best

    graph = model.graph
    opts = PostOptions(time_warp=False, smooth=False)

    def both(ranked, phones):
        return (blend_k_best(graph, ranked, phones, options=opts),
                blend_k_best(graph, ranked, phones, options=replace(opts, blend=False)))

    # Five animes of one recording played through: each phone's recorded neighbour is the
    # next phone's own anime, so cross-fading changes nothing.
    run = [int(np.flatnonzero(graph.prev_node < 0)[0])]
    for _ in range(4):
        run.append(int(graph.next_node[run[-1]]))
    assert min(run) >= 0
    phones = _played_through(graph, run)
    faded, cut = both([np.array([a]) for a in run], phones)
    np.testing.assert_allclose(faded, cut, atol=1e-9)
    # The third phone's anime taken from elsewhere, from after the second phone's phoneme:
    # its recorded predecessor is mixed into the second phone's second half, and the
    # third phone's first half gets the second phone's recorded successor.
    same = graph.by_phone[graph.node_phone[run[2]]]
    prev = graph.prev_node[same]
    other = same[(prev >= 0) & (graph.node_phone[np.maximum(prev, 0)] == graph.node_phone[run[1]])
                 & (graph.node_clip[same] != graph.node_clip[run[2]])]
    if len(other) == 0:
        pytest.skip("no anime of the third phone recorded after the second phone elsewhere")
    ranked = [np.array([a]) for a in run]
    ranked[2] = other[:1]
    faded, cut = both(ranked, phones)
    edges = np.cumsum([0] + [len(graph.motion(a)) for a in run])
    centres = (edges[:-1] + edges[1:] - 1) / 2
    changed = np.flatnonzero(np.abs(faded - cut).max(axis=1) > 1e-9)
    # from the second phone's centre on (its second half: the predecessor mixed in) to at
    # most the fourth's (the new anime's own successor may show the fourth phone)
    assert len(changed) and centres[1] < changed.min() < edges[2]
    assert changed.max() < centres[3]
    # ... only where the recording shows the input's phones: relabelled, the second phone
    # is shown by no recorded neighbour, and its frames stay its own mean.
    label = next(p for p in ("ZH", "OY", "UH", "TH") if p not in {x.phone for x in phones})
    phones[1] = Phone(label, phones[1].start, phones[1].end, phones[1].prosody)
    faded, cut = both(ranked, phones)
    np.testing.assert_allclose(faded[:edges[2]], cut[:edges[2]], atol=1e-9)


def test_recording_means_are_each_clips_mean_motion(model):
    from animegraph.synthesis.assemble import recording_means

    graph = model.graph
    means = recording_means(graph)
    assert means.shape == (len(graph.clip_ids), graph.motion_values.shape[1])
    for c in (0, len(graph.clip_ids) - 1):
        nodes = np.flatnonzero(graph.node_clip == c)
        frames = np.concatenate([graph.motion_values[graph.motion_offsets[a]:
                                                     graph.motion_offsets[a + 1]]
                                 for a in nodes])
        np.testing.assert_allclose(means[c], frames.mean(axis=0, dtype=np.float64), rtol=1e-9,
                                   atol=1e-9)


def test_sessions_are_speakers_within_corpus_folders():
    from animegraph.synthesis.model import sessions_of

    # GRID: one folder, no speaker named -> one session (recentring off by default).
    assert sessions_of(["s1"] * 3, [None] * 3) == (("s1", ""),)
    # Two folders of unnamed speakers (two actors, or two days) -> two sessions.
    assert sessions_of(["day1", "day2", "day1"], [None, None, ""]) == (
        ("day1", ""), ("day2", ""))
    # Named speakers in one folder -> one session each.
    assert len(sessions_of(["tf"] * 4, ["a", "b", "a", None])) == 3


def test_k_best_recentres_each_anime_on_its_recording(model, held_out, capsys):
    from animegraph.synthesis import recentres
    from animegraph.synthesis.assemble import output_frames, recording_means

    stem, _ = held_out
    audio, sr = read_wav(stem.with_suffix(".wav"))
    labels = read_phones_csv(f"{stem}.phones.csv")
    # By default only with several speakers or sessions: the tiny corpus has one.
    assert PostOptions().recentre is None and len(model.sessions) == 1
    assert model.sessions[0][1] == "synth01"
    assert not recentres(model) and recentres(model, PostOptions(recentre=True))
    raw = synthesize(model, audio, sr, labels=labels, k_best=4,
                     options=PostOptions(smooth=False, blend=False, recentre=False))
    rc = synthesize(model, audio, sr, labels=labels, k_best=4,
                    options=PostOptions(smooth=False, blend=False, recentre=True))
    default = synthesize(model, audio, sr, labels=labels, k_best=4,
                         options=PostOptions(smooth=False, blend=False))
    np.testing.assert_array_equal(default.ics, raw.ics)
    # The record says how the animes were averaged (labels: ranked by context first).
    assert (rc.recentred, default.recentred) == (True, False)
    assert explain_record(rc)["recentred"] and not explain_record(default)["recentred"]
    assert explain_record(rc)["k_best_ranking"] == "context"
    assert explain_record(rc)["k_best_joins"] == "cut" and not rc.cross_faded
    assert synthesize(model, audio, sr, labels=labels, k_best=4).cross_faded
    picked = [[(a["node"], a["weight"]) for a in animes] for animes in rc.blended]
    assert picked == [[(a["node"], a["weight"]) for a in animes] for animes in raw.blended]
    # Unsmoothed and cut at the phones' boundaries, each phone's frames move by one pose:
    # minus the weighted mean of its animes' recording means, plus the utterance's offset
    # (their mean over its frames).
    means = recording_means(model.graph)
    _, ranges = output_frames(rc.phones, model.graph.fps)
    shift = np.zeros_like(rc.ics)
    for animes, (s, b) in zip(picked, ranges, strict=True):
        nodes, w = zip(*animes, strict=True)
        w = np.array(w) / np.sum(w)  # the explained weights are rounded
        shift[s:b] = -w @ means[model.graph.node_clip[list(nodes)]]
    shift -= shift.mean(axis=0)
    np.testing.assert_allclose(rc.ics - raw.ics, shift, atol=1e-3 * np.abs(shift).max())
    assert np.abs(shift).max() > 1e-3  # the tiny corpus' recordings differ in pose
    args = ["synth", str(stem.with_suffix(".wav")), "--db", str(model.db.root),
            "--labels", f"{stem}.phones.csv", "-o", str(stem.parent / "x.npz")]
    assert main([*args, "--exact", "--recentre"]) == 2  # one anime a phone: nothing to do
    capsys.readouterr()
    assert main([*args, "--k-best", "4", "--recentre"]) == 0
    assert "recording's mean pose (as asked)" in capsys.readouterr().err
    assert main([*args, "--k-best", "4"]) == 0
    err = capsys.readouterr().err
    assert "mean pose" not in err and "cross-faded into its neighbours" in err
    assert main([*args, "--k-best", "4", "--no-blend"]) == 0
    assert "cut at its boundaries" in capsys.readouterr().err


def test_k_best_ranks_by_phonetic_context_when_asked(model, held_out):
    from animegraph.search import problem
    from animegraph.synthesis.path import KNOWN_PHONES_CONTEXT

    stem, _ = held_out
    audio, sr = read_wav(stem.with_suffix(".wav"))
    labels = read_phones_csv(f"{stem}.phones.csv")
    # Over every candidate: a shortlist is cut by the ranking itself, so its search's pick
    # may differ between the two rankings.
    by_audio = synthesize(model, audio, sr, labels=labels, k_best=4, context=False,
                          shortlist=None)
    by_context = synthesize(model, audio, sr, labels=labels, k_best=4, context=True,
                            shortlist=None)
    default = synthesize(model, audio, sr, labels=labels, k_best=4)
    assert not by_audio.context_ranked and by_context.context_ranked
    assert default.context_ranked == KNOWN_PHONES_CONTEXT
    assert not synthesize(model, audio, sr, labels=labels, context=True).context_ranked
    # Same picks; the others ranked by context first: their context matches never worse
    # in rank order than by audio cost, and somewhere better.
    assert [r["node"] for r in by_audio.explain] == [r["node"] for r in by_context.explain]
    cands = problem.candidates(model.graph, [p.phone for p in by_context.phones])
    match = problem.context_match(model.graph, cands)
    off = np.concatenate([[0], np.cumsum(cands.sizes)])
    gained = 0.0
    for i, (a, c) in enumerate(zip(by_audio.blended, by_context.blended, strict=True)):
        layer = dict(zip(cands.nodes[i].tolist(), match[off[i]:off[i + 1]], strict=True))
        ctx = [layer[x["node"]] for x in c[1:]]
        assert ctx == sorted(ctx, reverse=True)  # no emotion given: context decides
        gained += sum(ctx) - sum(layer[x["node"]] for x in a[1:])
    assert gained > 0
    assert not np.allclose(by_audio.motion, by_context.motion)


def test_anchor_moves_the_helper_onto_the_animes_poses(rng):
    from animegraph.synthesis.assemble import anchor

    helper = rng.normal(size=(30, 4))
    first, last = rng.normal(size=4), rng.normal(size=4)
    out = anchor(helper, first, last)
    np.testing.assert_allclose(out[0], first)
    np.testing.assert_allclose(out[-1], last)
    # Only a linear displacement is added: the helper's transition is kept.
    np.testing.assert_allclose(np.diff(out - helper, n=2, axis=0), 0.0, atol=1e-12)
    np.testing.assert_allclose(anchor(helper, helper[0], helper[-1]), helper)


def test_anchored_helper_changes_only_the_blend_inside_a_jump(model, held_out):
    stem, _ = held_out
    audio, sr = read_wav(stem.with_suffix(".wav"))
    labels = read_phones_csv(f"{stem}.phones.csv")
    raw = PostOptions(smooth=False)
    paper = synthesize(model, audio, sr, labels=labels, options=raw)
    anchored = synthesize(model, audio, sr, labels=labels,
                          options=PostOptions(smooth=False, helper="anchored"))
    np.testing.assert_array_equal(paper.result.nodes, anchored.result.nodes)
    helped = [j for j in paper.joins if j["blend"] == "helper"]
    assert helped, "the held-out sentence has no helper-blended jump to test"
    from animegraph.synthesis.assemble import output_frames

    _, ranges = output_frames(paper.phones, model.graph.fps)
    inside = np.zeros(len(paper.motion), dtype=bool)
    for j in helped:
        s0, s2 = ranges[j["index"]][0], ranges[j["index"] + 1][1]
        inside[s0 + 1:s2 - 1] = True  # w = 0 at the blend's first and last frames
    differs = np.abs(paper.motion - anchored.motion).max(axis=1) > 1e-9
    assert differs.any() and not (differs & ~inside).any()
    with pytest.raises(ParameterError, match="helper must be one of"):
        PostOptions(helper="nearest")


def test_nonspeech_anchoring_leaves_the_speech_components_as_recorded(model, held_out):
    stem, _ = held_out
    audio, sr = read_wav(stem.with_suffix(".wav"))
    labels = read_phones_csv(f"{stem}.phones.csv")
    out = {mode: synthesize(model, audio, sr, labels=labels,
                            options=PostOptions(smooth=False, helper=mode))
           for mode in ("paper", "anchored-nonspeech")}
    speech = model.emotion_model.split.speech_components
    rest = np.setdiff1d(np.arange(out["paper"].ics.shape[1]), speech)
    assert speech.size and rest.size
    np.testing.assert_array_equal(out["paper"].ics[:, speech],
                                  out["anchored-nonspeech"].ics[:, speech])
    assert np.abs(out["paper"].ics[:, rest] - out["anchored-nonspeech"].ics[:, rest]).max() > 0


def test_cli_helper_choices_are_the_synthesis_modes():
    from animegraph.apps.cli import HELPER_CHOICES
    from animegraph.synthesis import HELPER_MODES

    assert HELPER_CHOICES == HELPER_MODES


def test_cli_synth_helper(tiny_db, held_out, tmp_path, capsys):
    stem, _ = held_out
    out = tmp_path / "o.npz"
    argv = ["synth", str(stem.with_suffix(".wav")), "--db", str(tiny_db[0]), "-o", str(out)]
    assert main([*argv, "--helper", "anchored-nonspeech"]) == 0
    assert "the paper's search" in capsys.readouterr().err
    with np.load(out) as f:
        anchored = f["motion"]
    assert main(argv) == 0
    with np.load(out) as f:
        assert not np.array_equal(anchored, f["motion"])



def test_synth_says_once_that_a_transcript_may_be_another_utterances(tiny_db, tmp_path,
                                                                     capsys):
    from conftest import require_shared
    from test_ctc import LOOK_ALIKE

    from ingest.speech import ctc

    if not ctc.available():
        pytest.skip("hama's native library is absent")
    name, own, other = LOOK_ALIKE
    video = require_shared("grid", "s1", name)  # synth hears a video's sound track
    for text, said in ((own, 0), (other, 1)):
        assert main(["synth", str(video), "--db", str(tiny_db[0]), "--text", text, "-o",
                     str(tmp_path / "out.npz"), "--guide", "none"]) == 0
        err = capsys.readouterr().err
        assert err.count("fits the audio poorly") == said, err
        assert "phonetic context" in err  # aligned: the transcript's path all the same
