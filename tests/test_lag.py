"""Lip-audio lag: evidence pooled per speaker/session, used only where identifiable (#14)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import require_shared

from ingest.clip import ChannelSchema
from ingest.lag import decide_lags, pooled_estimates
from ingest.prepare import PreparedClip
from ingest.readers import discover, load
from ingest.readers.sync import (
    LAG_GRID_S,
    MIN_EVIDENCE_S,
    lag_evidence,
    lag_from_evidence,
)

FPS = 25.0


def _syllables(rng, n_frames: int) -> np.ndarray:
    """Lip activity of speech-like rhythm: bursts about every 0.2 s (5 syllables a second)."""
    t = np.arange(n_frames) / FPS
    phase = 2 * np.pi * 5.0 * t + np.cumsum(rng.normal(0, 0.15, n_frames))
    return 1.0 + np.sin(phase) + 0.3 * rng.normal(size=n_frames)


def _clip_signals(rng, seconds: float, lag_s: float, noise: float = 1.0):
    """(lips, loudness): loudness follows the lips ``lag_s`` later, plus much noise."""
    n = int(seconds * FPS)
    lips = _syllables(rng, n + 40)
    shift = int(round(lag_s * FPS))
    loud_db = np.roll(lips, shift) + noise * rng.normal(size=len(lips))
    lips, loud_db = lips[20:20 + n], loud_db[20:20 + n]
    return lips, 10 ** ((loud_db - loud_db.max()) / 20)  # RMS whose dB follows loud_db


def test_pooled_lag_finds_what_short_clips_cannot(rng):
    evidence, own = [], []
    for _ in range(60):
        lips, loudness = _clip_signals(rng, 3.0, lag_s=0.0)
        e = lag_evidence(lips, loudness, FPS)
        assert e.shape == (3, len(LAG_GRID_S))
        evidence.append(e)
        own.append(lag_from_evidence([e], 3.0))
    # one short clip is never identifiable, and its estimate strays to side peaks
    assert not any(o.identifiable() for o in own)
    assert max(abs(o.lag_s) for o in own) >= 0.1
    pooled = lag_from_evidence(evidence, 180.0)
    assert pooled.identifiable() and pooled.n_clips == 60
    assert abs(pooled.lag_s) < 0.02
    assert pooled.margin > 0.05 and 0 < pooled.confidence <= 1


def test_pooled_lag_recovers_a_real_offset_at_any_frame_rate(rng):
    evidence = []
    for k in range(20):
        fps = (25.0, 30.0)[k % 2]
        n = int(3.0 * fps)
        t = np.arange(n) / fps
        lips = _syllables(rng, n)
        # loudness 200 ms after the lips, sampled at this clip's own rate
        loud_db = np.interp(t - 0.2, t, lips) + 0.5 * rng.normal(size=n)
        evidence.append(lag_evidence(lips, 10 ** (loud_db / 20), fps))
    pooled = lag_from_evidence(evidence, 60.0)
    assert pooled.lag_s == pytest.approx(0.2, abs=0.02) and pooled.identifiable()
    # too little audio behind it: not identifiable, whatever the margin
    assert not lag_from_evidence(evidence[:2], 6.0).identifiable()
    assert MIN_EVIDENCE_S > 6.0


def _prepared(clip_id: str, speaker: str | None, evidence, seconds: float = 3.0,
              corpus: str = "c") -> PreparedClip:
    n = int(seconds * FPS)
    motion = np.arange(n, dtype=np.float32)[:, None] * np.ones((1, 2), np.float32)
    schema = ChannelSchema("landmarks", ("a", "b"), ("lips", "lips"), "mm")
    return PreparedClip(
        clip_id=clip_id, corpus=corpus, source=clip_id, checksum=clip_id, schema=schema,
        fps=FPS, source_fps=FPS, motion=motion, missing=np.zeros_like(motion, bool),
        audio=np.zeros(int(seconds * 16000), np.int16), sample_rate=16000, phones=(),
        segmentation="labels", prosody=np.zeros((1, 9), np.float32), emotion="unknown",
        speaker=speaker, sentence_id=None, text=None,
        extra={} if evidence is None else {"lag_evidence": np.asarray(evidence).tolist()})


def test_decide_lags_pools_per_speaker_and_applies_identifiable_lags(rng):
    def evidence(lag_s):
        return lag_evidence(*_clip_signals(rng, 3.0, lag_s, noise=0.5), FPS)

    led = [_prepared(f"a{k}", "A", evidence(0.2)) for k in range(12)]  # lips lead 200 ms
    sync = [_prepared(f"b{k}", "B", evidence(0.0)) for k in range(12)]
    lone = _prepared("c0", "C", evidence(0.2))  # 3 s on its own: not identifiable
    curves = _prepared("d0", "D", None)  # no evidence: untouched
    out = decide_lags(led + sync + [lone, curves])
    for clip in out[:12]:
        assert clip.extra["lag_basis"] == "pooled over 12 clips"
        assert clip.extra["lag_corrected_s"] == pytest.approx(0.2, abs=0.02)
        # motion delayed by the lag: frame t shows what was at t - 5 frames
        assert clip.motion[20, 0] == pytest.approx(20 - clip.extra["lag_corrected_s"] * FPS,
                                                   abs=1e-3)
    for clip in out[12:24]:
        assert clip.extra["lag_basis"].startswith("pooled")
        assert clip.extra["lag_corrected_s"] == 0.0  # in sync: under the smallest lag corrected
        assert abs(clip.extra["lag_estimate_s"]) < 0.04
        np.testing.assert_array_equal(clip.motion, led[0].motion)
    assert out[24].extra["lag_basis"] == "not identifiable"
    assert out[24].extra["lag_corrected_s"] == 0.0
    assert out[25] is curves
    # correction off: reported, not applied
    off = decide_lags(led, correct=False)
    assert all(c.extra["lag_corrected_s"] == 0.0 for c in off)
    assert off[0].extra["lag_estimate_s"] == pytest.approx(0.2, abs=0.02)
    # stored clips of the speaker join the pool
    joined = decide_lags(led[:1], stored=led[1:])
    assert joined[0].extra["lag_basis"] == "pooled over 12 clips"
    # the earlier per-clip rule, kept to measure against
    per_clip = decide_lags(sync, pooled=False)
    assert all(c.extra["lag_basis"] == "own (not checked)" for c in per_clip)
    # speakerless clips of one corpus folder are one session
    keys = pooled_estimates([_prepared(f"e{k}", None, evidence(0.0)) for k in range(3)])
    assert list(keys) == [("c", "")] and keys[("c", "")].n_clips == 3


@pytest.mark.shared
def test_talkingface_lags_pooled_per_speaker():
    root = require_shared("talkingface")
    clips = [load(s) for s in discover([root])]
    estimates = pooled_estimates(clips)  # duck-typed: corpus, speaker, duration, extra
    by_speaker = {speaker: e for (_, speaker), e in estimates.items()}
    obama = next(e for s, e in by_speaker.items() if s.startswith("Barack Obama"))
    # meta.json: the lips lead by 133-233 ms in the three Obama clips
    assert obama.n_clips == 3 and obama.identifiable()
    assert obama.lag_s == pytest.approx(0.2, abs=0.04)
    noem = next(e for s, e in by_speaker.items() if s.startswith("Kristi Noem"))
    assert not noem.identifiable()  # 18 s, side peak as high as the peak (meta: z 0.8)
    for speaker in ("Fei-Fei Li", "Andrew Ng", "Ronald Reagan", "CNN"):
        estimate = next(e for s, e in by_speaker.items() if s.startswith(speaker))
        assert estimate.identifiable() and abs(estimate.lag_s) < 0.06, speaker


@pytest.mark.shared
def test_ingest_reports_and_applies_the_pooled_lag(tmp_path):
    import shutil

    from ingest.pipeline import ingest

    root = require_shared("talkingface")
    corpus = tmp_path / "talkingface"
    for name in ("styletalk_Obama_clip1", "styletalk_Obama_clip3", "styletalk_feifeili_clip3"):
        shutil.copytree(root / name, corpus / name)
    report = ingest([corpus], tmp_path / "db")
    rows = {c.clip_id: c for c in report.clips}
    for name in ("styletalk_Obama_clip1", "styletalk_Obama_clip3"):
        row = rows[name]
        assert row.status == "added" and row.lag_basis == "pooled over 2 clips"
        assert row.lag_applied_s == row.lag_estimate_s == pytest.approx(0.21, abs=0.04)
        assert row.lag_margin > 0.05 and row.lag_confidence > 0.4
    lone = rows["styletalk_feifeili_clip3"]  # 7 s of its speaker: not identifiable
    assert lone.lag_basis == "not identifiable" and lone.lag_applied_s == 0.0
    text = "\n".join(report.lines())
    assert "(pooled over 2 clips, r " in text and "applied to 2 clips" in text
    assert "not identifiable, r " in text and "not applied to 1 clip (" in text
    assert ("less than 20 s of audio" in text) == (lone.lag_margin >= 0.05)
    assert "lag_basis" in report.to_csv().splitlines()[0]
    from db.store import Database

    units = {r["name"]: r["units"] for r in Database.open(tmp_path / "db").table(
        "channels").to_pylist()}
    assert (units["lm1.x"], units["pose.rx"], units["pose.tz"], units["pose.scale"]) == (
        "mm", "0.01 rad", "mm", "%")


def test_prepared_clips_read_back_from_the_database(tiny_db, tiny_corpus):
    """prepared_from_database gives back each clip's frames."""
    from db.store import Database
    from ingest.pipeline import prepare_sources
    from ingest.tables import prepared_from_database

    db = Database.open(tiny_db[0])
    clips = {c.clip_id: c for c in prepared_from_database(db)}
    frames = db.table("frames")
    assert len(clips) == 34 and sum(len(c.motion) for c in clips.values()) == frames.num_rows
    first = sorted((tiny_corpus / "clips").glob("*.c3d"))[0]
    original = prepare_sources(discover([first]))[0][0]
    back = clips[first.stem]
    np.testing.assert_allclose(back.motion, original.motion, atol=1e-3)
    np.testing.assert_array_equal(back.missing, original.missing)
    assert back.phones == original.phones and back.extra == original.extra


def test_a_lag_not_applied_says_why():
    from types import SimpleNamespace

    from ingest.pipeline import _not_applied

    def rows(margin, lag):
        return [SimpleNamespace(lag_margin=margin, lag_estimate_s=lag)]

    assert _not_applied("own", rows(0.2, -0.02)) == "under the 80 ms worth correcting"
    assert _not_applied("not identifiable", rows(0.67, 0.12)).startswith(
        "less than 20 s of audio")
    assert _not_applied("not identifiable", rows(0.01, 0.12)) == (
        "its peak beats the side peaks by less than 0.05")
    assert _not_applied("pooled over 3 clips", rows(0.2, 0.2)) == "lag correction is off"
