"""The synthetic corpus against its own ground truth."""

from __future__ import annotations

import json
from collections import Counter

import numpy as np
import pytest

from db.errors import ParameterError
from ingest.corpus import face
from ingest.corpus.emotions import EMOTIONS, STYLES
from ingest.corpus.synthetic import (
    PAPER_PAIRS,
    CorpusConfig,
    generate_corpus,
    plan_corpus,
    synthesize_clip,
)
from ingest.formats.c3d import read_c3d
from ingest.formats.phones_csv import read_phones_csv
from ingest.formats.wav import read_wav

# --- the plan ---------------------------------------------------------------------


def test_default_plan_follows_the_paper_design():
    specs = plan_corpus(CorpusConfig())
    sentences = {s.sentence_id for s in specs}
    assert len(sentences) >= 40
    pairs = Counter((s.sentence_id, s.emotion) for s in specs)
    assert set(pairs.values()) == {3}  # three variations of every pair
    emotions_of = {}
    for sid, emotion in pairs:
        emotions_of.setdefault(sid, set()).add(emotion)
    parallel = [sid for sid, emos in emotions_of.items() if emos == set(EMOTIONS)]
    assert len(parallel) >= 10
    texts = {s.sentence_id: s.text for s in specs}
    assert len(set(texts.values())) == len(texts)


def test_paper_plan_has_the_papers_size():
    specs = plan_corpus(CorpusConfig(scale="paper"))
    assert len(specs) == 1326
    pairs = {(s.sentence_id, s.emotion) for s in specs}
    per_emotion = Counter(e for _, e in pairs)
    assert dict(per_emotion) == PAPER_PAIRS


def test_plan_is_deterministic_and_seeded():
    a, b = plan_corpus(CorpusConfig(seed=3)), plan_corpus(CorpusConfig(seed=3))
    assert a == b
    assert a != plan_corpus(CorpusConfig(seed=4))


@pytest.mark.parametrize("kwargs", [
    {"sentences": 0}, {"variations": 0}, {"fps": 0.0}, {"fps": -5.0},
    {"parallel": 50}, {"scale": "huge"}, {"seed": -1},
])
def test_impossible_sizes_are_refused(kwargs):
    with pytest.raises(ParameterError):
        plan_corpus(CorpusConfig(**kwargs))


# --- layout and formats ---------------------------------------------------------------


def _clips(corpus):
    return sorted(p.stem for p in (corpus / "clips").glob("*.json"))


def test_layout(tiny_corpus, tiny_config):
    meta = json.loads((tiny_corpus / "corpus.json").read_text())
    assert meta["format"] == "animegraph-corpus"
    ids = _clips(tiny_corpus)
    assert len(ids) == meta["n_clips"] == len(plan_corpus(tiny_config)) == 34
    for clip in ids:
        for suffix in (".wav", ".c3d", ".json", ".phones.csv", ".controls.csv"):
            assert (tiny_corpus / "clips" / f"{clip}{suffix}").is_file(), (clip, suffix)
    markers = (tiny_corpus / "markers.csv").read_text().splitlines()
    assert len(markers) - 1 == len(face.MARKERS) >= 60
    assert {line.split(",")[2] for line in markers[1:]} == set(face.MOTION_GROUPS)
    # Nothing left behind by the staging.
    assert [p.name for p in tiny_corpus.parent.iterdir()] == ["tiny"]


def test_c3d_holds_exactly_the_generated_motion(tiny_corpus, tiny_config):
    spec = plan_corpus(tiny_config)[0]
    clip = synthesize_clip(spec, tiny_config)  # deterministic: the same clip again
    data = read_c3d(tiny_corpus / "clips" / f"{spec.clip_id}.c3d")
    assert data.rate == pytest.approx(120.0)
    assert data.labels == tuple(m[0] for m in face.MARKERS)
    assert data.points.shape == clip.markers.shape
    np.testing.assert_array_equal(np.isnan(data.points), np.isnan(clip.markers))
    np.testing.assert_allclose(data.points, clip.markers, atol=1e-3, equal_nan=True)


def test_phone_segments_tile_the_audio(tiny_corpus):
    for clip in _clips(tiny_corpus):
        audio, sr = read_wav(tiny_corpus / "clips" / f"{clip}.wav")
        assert sr == 16000
        segs = read_phones_csv(tiny_corpus / "clips" / f"{clip}.phones.csv")
        assert segs[0].start == 0.0
        assert segs[-1].end == pytest.approx(len(audio) / sr, abs=1e-3)
        for a, b in zip(segs, segs[1:], strict=False):
            assert b.start == pytest.approx(a.end, abs=1e-4)
            assert a.end > a.start
        assert segs[0].phone == segs[-1].phone == "SIL"
        meta = json.loads((tiny_corpus / "clips" / f"{clip}.json").read_text())
        assert meta["n_frames"] == pytest.approx(meta["duration"] * meta["fps"], abs=1)


def test_parallel_sentences_exist_in_all_five_emotions(tiny_corpus):
    metas = [json.loads(p.read_text()) for p in (tiny_corpus / "clips").glob("*.json")]
    by_sentence = {}
    for m in metas:
        by_sentence.setdefault(m["sentence_id"], {}).setdefault(m["emotion"], set()).add(m["text"])
    parallel = [s for s, emos in by_sentence.items() if set(emos) == set(EMOTIONS)]
    assert len(parallel) == 3
    for sid in parallel:
        texts = set().union(*by_sentence[sid].values())
        assert len(texts) == 1  # the same words in every emotion
    corpus_meta = json.loads((tiny_corpus / "corpus.json").read_text())
    assert sorted(parallel) == corpus_meta["parallel_sentences"]


def test_same_seed_same_bytes_other_seed_other_motion(tmp_path, tiny_config):
    spec = plan_corpus(tiny_config)[0]
    a, b = synthesize_clip(spec, tiny_config), synthesize_clip(spec, tiny_config)
    np.testing.assert_array_equal(a.markers, b.markers)
    np.testing.assert_array_equal(a.utterance.audio, b.utterance.audio)
    other = synthesize_clip(type(spec)(**{**spec.__dict__, "seed": spec.seed + 1}), tiny_config)
    # Another seed varies the voice (so the length) and the face.
    n = min(len(a.markers), len(other.markers))
    assert not np.allclose(np.nan_to_num(a.markers[:n]), np.nan_to_num(other.markers[:n]))


# --- the face model's structure ---------------------------------------------------


@pytest.fixture(scope="module")
def parallel_clips(tiny_config):
    """All clips of the parallel sentences, without noise or dropouts for clean measures."""
    clean = CorpusConfig(**{**tiny_config.__dict__, "marker_noise_mm": 0.0,
                            "dropouts_per_second": 0.0})
    specs = [s for s in plan_corpus(clean) if s.sentence_id in ("s0001", "s0002", "s0003")]
    return [synthesize_clip(s, clean) for s in specs]


def _segment_frames(clip, phones):
    for seg in clip.utterance.phones:
        if seg.phone in phones:
            a, b = int(np.ceil(seg.start * clip.fps)), int(np.floor(seg.end * clip.fps))
            if b > a:
                yield seg, slice(a, b + 1)


def test_bilabials_close_the_lips(parallel_clips):
    closed, vowels = [], []
    for clip in parallel_clips:
        opening = face.marker_distance(clip.markers, "ulip_in_c", "llip_in_c")
        closed += [opening[s].min() for _, s in _segment_frames(clip, {"P", "B", "M"})]
        vowels += [opening[s].max() for _, s in _segment_frames(clip, {"AA", "AE", "AO", "AW"})]
    assert len(closed) > 20 and len(vowels) > 10
    assert max(closed) < 1.0  # mm: every bilabial brings the lips together
    assert np.median(vowels) > 6.0  # open vowels open the mouth


def test_labiodentals_raise_the_lower_lip(parallel_clips):
    up, low = face.marker_index("ulip_in_c"), face.marker_index("llip_in_c")
    tucked, open_ = [], []
    for clip in parallel_clips:
        # Height between the lips (the head turns by a few degrees at most, so y will do):
        # the tucked lower lip rises most of the way to the upper one, behind it.
        height = clip.markers[:, up, 1] - clip.markers[:, low, 1]
        tucked += [height[s].min() for _, s in _segment_frames(clip, {"F", "V"})]
        open_ += [height[s].max() for _, s in _segment_frames(clip, {"AA", "AE", "AH"})]
    assert len(tucked) > 5
    assert np.median(tucked) < 0.4 * np.median(open_)


def _by(clips, emotion):
    return {(c.spec.sentence_id, c.spec.variation): c for c in clips if c.spec.emotion == emotion}


def test_happy_raises_the_lip_corners(parallel_clips):
    happy, neutral = _by(parallel_clips, "happy"), _by(parallel_clips, "neutral")
    for key in happy:
        # Corner-to-eye distance is immune to head motion; a smile shortens it.
        h = face.marker_distance(happy[key].markers, "lip_corner_l", "eye_out_l").mean()
        n = face.marker_distance(neutral[key].markers, "lip_corner_l", "eye_out_l").mean()
        assert h < n - 2.0, key


def test_sad_depresses_corners_and_angry_lowers_brows(parallel_clips):
    sad, angry = _by(parallel_clips, "sad"), _by(parallel_clips, "angry")
    neutral = _by(parallel_clips, "neutral")
    for key in neutral:
        corner = {e: face.marker_distance(d[key].markers, "lip_corner_r", "eye_out_r").mean()
                  for e, d in (("sad", sad), ("neutral", neutral))}
        assert corner["sad"] > corner["neutral"] + 1.0
        brow = {e: face.marker_distance(d[key].markers, "brow_r1", "eye_in_r").mean()
                for e, d in (("angry", angry), ("neutral", neutral))}
        assert brow["angry"] < brow["neutral"] - 1.5


def test_articulation_amplitude_follows_the_emotion_presets(parallel_clips):
    """Jaw excursion per emotion ranks as the presets' articulation gains.

    Chin-to-nose distance measures the jaw alone: head motion leaves it alone, and so do
    the expressions that act on the lips (a lip press narrows the mouth, not the jaw).
    """
    amplitude = {}
    for emotion in EMOTIONS:
        values = []
        for clip in _by(parallel_clips, emotion).values():
            jaw = face.marker_distance(clip.markers, "chin_tip", "nose_tip")
            values.append(np.percentile(jaw, 95) - np.percentile(jaw, 5))
        amplitude[emotion] = float(np.mean(values))
    by_gain = sorted(EMOTIONS, key=lambda e: STYLES[e].articulation)
    by_amplitude = sorted(EMOTIONS, key=amplitude.get)
    assert by_amplitude == by_gain, amplitude
    assert amplitude["angry"] > 1.5 * amplitude["sad"]


def test_dropouts_are_short_nan_gaps(tiny_corpus):
    gaps, nan_frames, total = [], 0, 0
    for clip in _clips(tiny_corpus):
        data = read_c3d(tiny_corpus / "clips" / f"{clip}.c3d")
        nan = np.isnan(data.points)
        # A dropout loses the whole marker, never one coordinate.
        assert (nan.any(axis=2) == nan.all(axis=2)).all()
        missing = nan.any(axis=2)
        nan_frames += missing.sum()
        total += missing.size
        for m in range(missing.shape[1]):
            padded = np.concatenate([[0], missing[:, m].astype(int), [0]])
            edges = np.flatnonzero(np.diff(padded))
            gaps += list((edges[1::2] - edges[::2]) / data.rate)
    assert len(gaps) >= 5
    assert max(gaps) <= 0.25 + 1e-9
    assert nan_frames / total < 0.01


def test_head_markers_move_rigidly(parallel_clips):
    head = [i for i, m in enumerate(face.MARKERS) if m[2] == "head"]
    clip = parallel_clips[0]
    pts = clip.markers[:, head]
    d = np.linalg.norm(pts[:, :, None] - pts[:, None, :], axis=-1)
    # Pairwise distances of the rigid group stay what they are at rest.
    np.testing.assert_allclose(d, np.broadcast_to(d[0], d.shape), atol=1e-6)
    # ... while the head itself moves.
    assert np.ptp(pts[:, 0, 1]) > 1.0


def test_brow_raises_follow_pitch_accents(parallel_clips):
    from ingest.corpus import gestures

    clip = next(c for c in parallel_clips if c.spec.emotion == "happy")
    times = np.arange(len(clip.markers)) / clip.fps
    pros = gestures.analyze_prosody(clip.utterance.audio, clip.utterance.sample_rate, times)
    raises = gestures.brow_raises(pros, times, clip.fps)
    assert raises.max() > 0.2
    st = np.nan_to_num(pros.f0_semitones)
    assert st[raises > 0.5 * raises.max()].mean() > st[raises == 0].mean() + 1.0


# --- writing safely ------------------------------------------------------------------


def test_refuses_a_non_empty_folder_and_leaves_it_alone(tmp_path, tiny_config):
    out = tmp_path / "busy"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    with pytest.raises(ParameterError, match="exists"):
        generate_corpus(out, tiny_config, workers=1)
    assert [p.name for p in out.iterdir()] == ["keep.txt"]


def test_an_interrupted_run_leaves_nothing(tmp_path, tiny_config):
    out = tmp_path / "new"

    def stop_after_two(results):
        for k, r in enumerate(results):
            if k == 2:
                raise KeyboardInterrupt
            yield r

    with pytest.raises(KeyboardInterrupt):
        generate_corpus(out, tiny_config, workers=1, progress=stop_after_two)
    assert list(tmp_path.iterdir()) == []


def test_force_replaces_atomically(tmp_path):
    config = CorpusConfig(sentences=1, parallel=0, variations=1, seed=1)
    out = tmp_path / "c"
    generate_corpus(out, config, workers=1)
    generate_corpus(out, CorpusConfig(sentences=2, parallel=0, variations=1), workers=1,
                    force=True)
    assert len(_clips(out)) == 2
    assert [p.name for p in tmp_path.iterdir()] == ["c"]
