"""Phone posteriorgrams: stored per anime at ingest, matched by DTW with -log(p . q)."""

from __future__ import annotations

import dataclasses
import shutil

import numpy as np
import pytest

from animegraph.apps.cli import SYNTH_AUDIO_COSTS, main
from animegraph.search.dtw import audio_cost, audio_costs_many
from animegraph.synthesis import Model, query_phones, score_candidates, synthesize
from animegraph.synthesis.audio import AUDIO_COSTS, candidate_costs, likely_candidates
from db.errors import DataError, ParameterError
from db.store import Database
from ingest.formats.phones_csv import read_phones_csv
from ingest.formats.wav import read_wav
from ingest.pipeline import build_database
from ingest.speech import ctc
from ingest.speech.phones import PHONES
from ingest.speech.posteriorgram import PHONE_COLUMNS, SMOOTHING, fold
from ingest.tables import prepared_from_database

needs_hama = pytest.mark.skipif(not ctc.available(), reason="the hama phone engine is not "
                                "installed (pip install hama)")


def _reference_cost(x: np.ndarray, y: np.ndarray) -> float:
    """Eq. 5 with -log(x . y), by the textbook recurrence and a Python backtrack."""
    n, m = len(x), len(y)
    local = -np.log(np.maximum(x @ y.T, 1e-10))
    acc = np.full((n, m), np.inf)
    for i in range(n):
        for j in range(m):
            prev = 0.0 if i == j == 0 else min(
                acc[i - 1, j - 1] if i and j else np.inf, acc[i - 1, j] if i else np.inf,
                acc[i, j - 1] if j else np.inf)
            acc[i, j] = local[i, j] + prev
    i, j, matched = n - 1, m - 1, {}
    while True:
        matched.setdefault(i, []).append(j)
        if i == j == 0:
            break
        steps = [(acc[i - 1, j - 1], i - 1, j - 1)] if i and j else []
        steps += [(acc[i - 1, j], i - 1, j)] if i else []
        steps += [(acc[i, j - 1], i, j - 1)] if j else []
        _, i, j = min(steps, key=lambda s: s[0])  # ties: the first (diagonal, then i-1)
    return float(np.mean([-np.log(x[k] @ y[matched[k]].mean(axis=0)) for k in range(n)]))


def _random_posteriorgram(rng, n: int, width: int = 5) -> np.ndarray:
    p = rng.dirichlet(np.full(width, 0.3), size=n)
    return 0.99 * p + 0.01 / width


def test_fold_removes_the_blank_and_smooths():
    probs = np.zeros((3, len(PHONES)))
    probs[0, PHONES.index("SIL")] = 1.0  # all blank: uniform over the phones
    probs[1, PHONES.index("M")] = 0.2
    probs[1, PHONES.index("SIL")] = 0.8  # 0.2 of M alone: M after renormalising
    probs[2, PHONES.index("AA")] = probs[2, PHONES.index("AE")] = 0.5
    out = fold(probs)
    assert out.shape == (3, len(PHONES) - 1) and out.dtype == np.float32
    np.testing.assert_allclose(out.sum(axis=1), 1.0, rtol=1e-6)
    np.testing.assert_allclose(out[0], 1.0 / len(PHONE_COLUMNS), rtol=1e-6)
    assert out[1, PHONE_COLUMNS.index("M")] == pytest.approx(1 - SMOOTHING + SMOOTHING / 39)
    assert out[2, PHONE_COLUMNS.index("AA")] == pytest.approx(out[2, PHONE_COLUMNS.index("AE")])
    assert out.min() >= SMOOTHING / len(PHONE_COLUMNS) * (1 - 1e-6)
    with pytest.raises(ValueError, match="posteriors must be"):
        fold(np.ones((2, 5)))


@pytest.mark.parametrize(("n", "m"), [(1, 1), (1, 6), (6, 1), (7, 4), (4, 9), (12, 12)])
def test_neglog_dot_cost_matches_the_textbook_recurrence(rng, n, m):
    x, y = _random_posteriorgram(rng, n), _random_posteriorgram(rng, m)
    assert audio_cost(x, y, metric="neglog-dot") == pytest.approx(_reference_cost(x, y),
                                                                  rel=1e-9)


def test_neglog_dot_cost_prefers_the_same_phones_and_runs_in_batches(rng):
    x = _random_posteriorgram(rng, 8)
    same = np.repeat(x, 2, axis=0)  # the same phones, spoken slower
    other = _random_posteriorgram(rng, 10)
    values = np.concatenate([same, other] * 40).astype(np.float32)
    offsets = np.cumsum([0] + [16, 10] * 40)
    nodes = np.arange(80)  # enough pairs for the parallel kernel
    costs = audio_costs_many([x], values, offsets, [nodes], metric="neglog-dot")[0]
    assert costs[0] < costs[1]
    np.testing.assert_allclose(costs[0::2], costs[0])
    assert costs[0] == pytest.approx(audio_cost(x, same, metric="neglog-dot"), rel=1e-6)
    with pytest.raises(ParameterError, match="metric must be one of"):
        audio_cost(x, same, metric="cosine")


def test_cli_spells_out_the_audio_costs():
    assert SYNTH_AUDIO_COSTS == AUDIO_COSTS


@pytest.fixture(scope="module")
def model(tiny_db):
    return Model.load(tiny_db[0])


@needs_hama
def test_ingest_stores_a_posteriorgram_per_anime(model):
    graph = model.graph
    assert graph.posterior_values is not None
    assert graph.posterior_values.shape[1] == len(PHONE_COLUMNS)
    assert len(graph.posterior_offsets) == graph.n_nodes + 1
    frames = np.diff(graph.posterior_offsets)
    durations = graph.end_time - graph.start_time
    # 50 frames a second, at least one a phone.
    assert (frames >= 1).all() and np.abs(frames - durations / 0.02).max() <= 1.5
    np.testing.assert_allclose(graph.posterior_values.sum(axis=1), 1.0, atol=5e-3)
    assert model.db.table("animes", columns=["posteriors"]).schema.field(
        "posteriors").type.value_type == "halffloat"  # compact: float16
    # DuckDB has no half floats: the SQL layer reads them as float32.
    from db.sql import query

    rows = query(model.db, "SELECT posterior_frames, len(posteriors) AS n, "
                 "list_sum(posteriors) AS total FROM animes ORDER BY node_id LIMIT 5")
    for row in rows.to_pylist():
        assert row["n"] == row["posterior_frames"] * len(PHONE_COLUMNS)
        assert row["total"] == pytest.approx(row["posterior_frames"], rel=0.01)


@needs_hama
def test_posteriorgram_cost_knows_the_phones(model, tiny_corpus):
    """A clip of the database, its phones matched against every anime by posteriorgram DTW:
    animes of the right phone cost less than the others, and the phone's own anime is
    among its cheapest. (-log of an inner product is not 0 for identical frames: a peakier
    posterior of the same phone can cost less, so the own anime need not come first.)"""
    graph = model.graph
    clip_id = graph.clip_ids[0]
    audio, sr = read_wav(tiny_corpus / "clips" / f"{clip_id}.wav")
    labels = read_phones_csv(tiny_corpus / "clips" / f"{clip_id}.phones.csv")
    phones, _ = query_phones(audio, sr, labels=labels, posteriorgram=True)
    own = np.flatnonzero(graph.node_clip == 0)
    every = np.arange(graph.n_nodes)
    costs = audio_costs_many([p.posteriors for p in phones], graph.posterior_values,
                             graph.posterior_offsets, [every] * len(phones),
                             metric="neglog-dot")
    right, beaten = [], []
    for phone, cost, node in zip(phones, costs, own, strict=True):
        same = graph.node_phone == PHONES.index(phone.phone)
        right.append(np.median(cost[same]) < np.median(cost[~same]))
        beaten.append(np.mean(cost[same] < cost[node]))
    assert np.mean(right) > 0.8
    assert np.mean(beaten) < 0.15
    c, post = score_candidates(model, phones, audio_cost="posteriorgram")
    mixed = candidate_costs(graph, phones, c.nodes, "plp+posteriorgram")
    for nodes, p, m in zip(c.nodes, post, mixed, strict=True):
        assert len(p) == len(m) == len(nodes) and np.isfinite(m).all()
    out = synthesize(model, audio, sr, labels=labels, audio_cost="posteriorgram", k_best=3)
    assert out.motion.shape[0] > 0 and np.isfinite(out.motion).all()
    # Candidates from the likely phones: a superset of the label's, with the phones the
    # posteriorgram finds likeliest.
    wide = likely_candidates(graph, phones, c)
    grew = 0
    for phone, own, more in zip(phones, c.nodes, wide.nodes, strict=True):
        assert np.isin(own, more).all() and (np.diff(more) > 0).all()
        if phone.phone == "SIL":
            assert np.array_equal(own, more)
        grew += len(more) > len(own)
    assert grew > len(phones) // 2
    out = synthesize(model, audio, sr, labels=labels, audio_cost="posteriorgram", k_best=3,
                     candidates_from="likely")
    assert out.motion.shape[0] > 0 and np.isfinite(out.motion).all()
    with pytest.raises(ParameterError, match="candidates_from"):
        synthesize(model, audio, sr, labels=labels, candidates_from="all")


@needs_hama
def test_a_database_without_posteriorgrams_says_so(tiny_db, tiny_corpus, tmp_path, capsys):
    clips = [dataclasses.replace(c, posteriors=None)
             for c in prepared_from_database(Database.open(tiny_db[0]))[:6]]
    path = tmp_path / "old.db"
    build_database(path, clips)
    old = Model.load(path)
    assert old.graph.posterior_values is None
    assert "posteriors" not in old.db.columns("animes")
    clip_id = old.graph.clip_ids[0]
    wav = tmp_path / "speech.wav"
    shutil.copy(tiny_corpus / "clips" / f"{clip_id}.wav", wav)
    audio, sr = read_wav(wav)
    with pytest.raises(DataError, match="no phone posteriorgrams"):
        synthesize(old, audio, sr, audio_cost="posteriorgram")
    assert synthesize(old, audio, sr, k_best=3).motion.shape[0] > 0  # the rest still works
    code = main(["synth", str(wav), "--db", str(path), "-o", str(tmp_path / "out.csv"),
                 "--audio-cost", "posteriorgram"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code != 0
    assert "no phone posteriorgrams" in err[-1] and "Traceback" not in "\n".join(err)


@needs_hama
def test_a_sliced_clip_keeps_posteriorgram_frames_to_its_end(tiny_db):
    """The within-speaker split cuts clips: each part's posteriorgram must cover its last
    phone (a cut at 17.99 s once left the last 10 ms phone outside it)."""
    from ingest.prepare import slice_clip
    from ingest.speech.features import slice_frames

    clip = prepared_from_database(Database.open(tiny_db[0]))[0]
    assert clip.posteriors is not None
    for cut in (0.37, 0.51, 0.7 * clip.duration):
        for part in (slice_clip(clip, 0.0, cut, suffix="_a"),
                     slice_clip(clip, cut, clip.duration, suffix="_b")):
            for phone in part.phones:
                assert len(slice_frames(part.posteriors, phone.start, phone.end, hop_s=0.02))


@needs_hama
def test_prepare_clip_stores_the_posteriorgram_unless_told_not_to(tiny_corpus):
    from ingest.prepare import prepare_clip
    from ingest.readers import discover, load

    raw = load(discover([tiny_corpus])[0])
    with_post = prepare_clip(raw)
    assert with_post.posteriors.dtype == np.float16
    assert abs(len(with_post.posteriors) - with_post.duration / 0.02) <= 1
    blank = with_post.posterior_blank  # the CTC blank, which the posteriorgram leaves out
    assert blank.shape == (len(with_post.posteriors),) and 0 <= blank.min() <= blank.max() <= 1
    labelled = prepare_clip(raw, posteriorgrams=False)
    assert labelled.posteriors is None and labelled.posterior_blank is None
    # Phones recognised by hama: it has heard the clip, so its outputs are kept anyway.
    recognised = prepare_clip(dataclasses.replace(raw, phones=(), text=None, words=None),
                              posteriorgrams=False)
    assert recognised.segmentation == "recognized"
    np.testing.assert_array_equal(recognised.posteriors, with_post.posteriors)
    np.testing.assert_array_equal(recognised.posterior_blank, blank)
    # A transcript: hama checks it before PocketSphinx aligns it, so it has heard the clip.
    aligned = prepare_clip(dataclasses.replace(raw, phones=(), words=None),
                           posteriorgrams=False)
    assert aligned.segmentation == "aligned"
    np.testing.assert_array_equal(aligned.posteriors, with_post.posteriors)
    # A transcript of another utterance is not forced onto the speech: recognised instead.
    other = prepare_clip(dataclasses.replace(raw, phones=(), words=None,
                                             text="Open the window and look at the sea."),
                         posteriorgrams=False)
    assert other.segmentation == "recognized"
    assert [p.phone for p in other.phones] == [p.phone for p in recognised.phones]


@needs_hama
def test_ppg_ridge_fits_on_the_stored_posteriors_without_hearing_the_speech_again(
        tiny_db, monkeypatch):
    from animegraph.baselines.data import training_set
    from animegraph.baselines.ppg_forward import stored_posteriors
    from animegraph.baselines.ppg_ridge import PpgRidge
    from ingest.speech import ctc

    data = training_set(Database.open(tiny_db[0]))
    assert all(stored_posteriors(c) is not None for c in data.clips)
    heard = []
    real = ctc.posteriors
    monkeypatch.setattr(ctc, "posteriors", lambda *a, **k: heard.append(1) or real(*a, **k))
    stored = PpgRidge().fit(data)
    assert heard == []
    # Without the blank (a database from before it was stored) hama hears every clip; the
    # fit agrees up to the stored values' float16 rounding.
    again = PpgRidge().fit(dataclasses.replace(data, clips=tuple(
        dataclasses.replace(c, posterior_blank=None) for c in data.clips)))
    assert len(heard) == len(data.clips)
    assert again.alpha_ == stored.alpha_
    scale = np.abs(again.coef_).max()
    np.testing.assert_allclose(stored.coef_, again.coef_, atol=2e-2 * scale)
    # Stored values that do not fit the audio are not used (someone else's database).
    clip = data.clips[0]
    for bad in (dict(posterior_blank=clip.posterior_blank[:-5]),
                dict(posteriors=clip.posteriors[:, :-1]),
                dict(posteriors=np.full_like(clip.posteriors, np.nan)),
                dict(posterior_blank=np.full_like(clip.posterior_blank, 7))):
        assert stored_posteriors(dataclasses.replace(clip, **bad)) is None
