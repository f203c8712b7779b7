"""Live: a stream of speech in, frames out (animegraph.live, ``animegraph live``).

Real sockets, a real WebSocket client, eSpeak NG speech and the tiny database; no mocks."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import require_shared

from db.errors import DataError, ParameterError

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def speech():
    from ingest.speech.espeak import speak

    u = speak("Bring the blue box to the table, please.")
    return u.audio.astype(np.float32), u.sample_rate


@pytest.fixture(scope="module")
def model(tiny_db):
    from animegraph.synthesis import Model

    return Model.load(tiny_db[0])


def _after_noise(audio, sr):
    """``audio`` (peak 0.8) after a second of silence, all in a room's faint white noise."""
    rng = np.random.default_rng(0)
    said = 0.8 * audio / np.abs(audio).max()
    noisy = np.concatenate([np.zeros(sr, np.float32), said])
    return (noisy + 0.004 * rng.standard_normal(len(noisy))).astype(np.float32)


def _play(stream, audio, chunk_s=0.02):
    batches, heard = [], []
    step = int(chunk_s * stream.sample_rate)
    for k in range(0, len(audio), step):
        frames = stream.push(audio[k:k + step])
        if len(frames):
            batches.append(frames)
            heard.append(stream.heard_s)
    batches.append(stream.close())
    heard.append(stream.heard_s)
    return batches, heard


# --- the stream -------------------------------------------------------------------------


def test_stream_sends_every_frame_once_in_order_after_its_lookahead(model, speech):
    from animegraph.live import Stream

    audio, sr = speech
    stream = Stream(model, sample_rate=sr, lookahead_ms=100, hop_ms=200)
    batches, heard = _play(stream, audio)
    indices = np.concatenate([b.indices for b in batches])
    motion = np.concatenate([b.motion for b in batches])
    n = int(round(len(audio) / sr * model.graph.fps))
    np.testing.assert_array_equal(indices, np.arange(n))  # each frame once, in order
    assert motion.shape == (n, len(model.names)) and np.isfinite(motion).all()
    for frames, h in zip(batches[:-1], heard[:-1], strict=True):
        # Sent only once the look-ahead after it was heard.
        assert frames.times[-1] <= h - 0.1 + 1e-9
    assert stream.stats.updates >= len(audio) / sr / 0.2 - 1
    # It moves with the speech: the mouth is not the rest pose throughout.
    assert np.ptp(motion, axis=0).max() > 0


def test_stream_follows_the_offline_mouth(model, speech):
    """The live mouth opening correlates with the offline synthesis of the same speech."""
    from animegraph.live import Stream
    from animegraph.motion.measures import mouth_opening, pearson
    from animegraph.synthesis import synthesize

    audio, sr = speech
    batches, _ = _play(Stream(model, sample_rate=sr, lookahead_ms=200, hop_ms=200), audio)
    live = np.concatenate([b.motion for b in batches])
    offline = synthesize(model, audio, sr, k_best=20, phones_engine="hama").motion
    n = min(len(live), len(offline))
    r = pearson(mouth_opening(live[:n], model.names, model.kind),
                mouth_opening(offline[:n], model.names, model.kind))
    assert r > 0.5, r


def test_silence_is_the_rest_pose_and_no_error(model):
    from animegraph.live import Stream
    from animegraph.live.stream import rest_pose

    stream = Stream(model, sample_rate=16000, hop_ms=200)
    batches, _ = _play(stream, np.zeros(16000, dtype=np.float32))
    motion = np.concatenate([b.motion for b in batches])
    assert len(motion) == int(round(model.graph.fps))
    np.testing.assert_allclose(motion, np.repeat(rest_pose(model)[None], len(motion), 0))
    assert stream.stats.pauses >= 1


def test_a_window_heard_as_silence_is_synthesized_as_offline_silence(model, monkeypatch):
    """Room noise (not quiet enough to be a pause by its level) in which hama hears only
    silence is synthesized as offline synthesizes an utterance's silences (the silence
    animes and the guide), not held at the rest pose; offline, audio whose phones are
    all silence is still refused."""
    from animegraph.live import Stream
    from animegraph.live.stream import rest_pose
    from animegraph.synthesis.pipeline import query_phones
    from ingest.formats.phones_csv import Segment
    from ingest.speech import ctc

    heard = []
    recognize = ctc.recognize

    def recognized(*args, **kwargs):  # hama's own phones, noted
        segments = recognize(*args, **kwargs)
        heard.append([s.phone for s in segments])
        return segments

    monkeypatch.setattr(ctc, "recognize", recognized)
    rng = np.random.default_rng(1)
    noise = (0.01 * rng.standard_normal(32000)).astype(np.float32)
    stream = Stream(model, sample_rate=16000, backlog_ms=None, phones_engine="hama")
    batches, _ = _play(stream, noise)
    motion = np.concatenate([b.motion for b in batches])
    assert heard and all(set(h) == {"SIL"} for h in heard)  # hama heard only silence
    assert not any("no speech" in w for w in stream.stats.warnings)
    assert np.abs(motion - rest_pose(model)).max() > 1e-3  # synthesized, not the rest pose
    labels = [Segment("SIL", 0.0, 0.5)]
    with pytest.raises(DataError, match="no speech found"):
        query_phones(noise[:8000], 16000, labels=labels)
    phones, _ = query_phones(noise[:8000], 16000, labels=labels, silence=True)
    assert [p.phone for p in phones] == ["SIL"]


def test_posterior_track_hears_silence_before_the_streams_first_sample(speech):
    """At a stream's start the model hears the context's worth of silence before the first
    sample, as every later frame hears context before it: the first update's rows are the
    model's output on [silence, audio], not on the audio alone (the start of its input
    is heard as the start of speech: GRID's leading noise there was heard as phones)."""
    from animegraph.live.frontend import LEVEL, MODEL_RATE, PosteriorTrack, to_model_rate
    from ingest.speech import ctc

    audio, sr = speech
    rng = np.random.default_rng(2)
    x = np.concatenate([0.01 * rng.standard_normal(int(0.3 * sr)), audio[: int(0.2 * sr)]])
    x = x.astype(np.float32)
    peak = float(np.abs(x).max())
    track = PosteriorTrack(sr, context_s=0.6, settle_s=0.12)
    track.update(x, 0, len(x), peak)
    rows = track.posteriors(0, track.frames)
    y = (to_model_rate(x, sr) * (LEVEL / peak)).astype(np.float32)
    pad = np.zeros(30 * (MODEL_RATE // 50), dtype=np.float32)  # 600 ms
    want = ctc.phone_probs(np.concatenate([pad, y]))[30:]
    n = min(len(rows), len(want))
    assert n >= len(rows) - 1
    np.testing.assert_allclose(rows[:n], want[:n], atol=1e-6)
    alone = ctc.phone_probs(y)[:n]
    assert np.abs(alone - rows[:n]).sum(axis=1).max() > 0.05  # the silence before matters


def test_noise_before_the_first_word_is_not_heard_as_speech(model, speech, monkeypatch):
    """A second of room noise (-48 dBFS) before the speech: its level reference is 30 dB
    over the noise, not the noise's own peak (with the loudest sample so far as the
    reference it was the noise's), and hama hears no phone in it (its windows are a
    silence or a pause). This white noise is heard as silence at either reference since
    hama hears silence before the stream's first sample
    (test_posterior_track_hears_silence_before_the_streams_first_sample)."""
    from animegraph.live import Stream
    from animegraph.live import stream as live_stream
    from ingest.speech import ctc

    audio, sr = speech
    noisy = _after_noise(audio, sr)
    heard = []
    recognize = ctc.recognize

    def recognized(*args, **kwargs):  # hama's own phones, noted
        segments = recognize(*args, **kwargs)
        heard.append({s.phone for s in segments})
        return segments

    monkeypatch.setattr(ctc, "recognize", recognized)

    def play(db):
        monkeypatch.setattr(live_stream, "SPEECH_OVER_NOISE_DB", db)
        stream = Stream(model, sample_rate=sr, backlog_ms=None, phones_engine="hama")
        heard.clear()
        stream.push(noisy[:sr])  # windows of the noise alone
        in_noise, level = list(heard), stream.level()
        _play(stream, noisy[sr:])
        return in_noise, level, stream

    in_noise, level, stream = play(30.0)
    noise_peak = float(np.abs(noisy[:sr]).max())
    assert 10 * noise_peak < level < 1.0  # not the noise's peak
    assert stream.level() == pytest.approx(float(np.abs(noisy).max()))  # the speech's
    assert all(h == {"SIL"} for h in in_noise)
    before, level, _ = play(-np.inf)
    assert level == pytest.approx(noise_peak)
    assert all(h == {"SIL"} for h in before)


def test_guide_loudness_is_against_all_the_stream_heard(model, speech, monkeypatch):
    """ppg-ridge's loudness feature is relative to the loud level of all the stream has
    heard (:class:`animegraph.live.frontend.LoudLevel`, given by
    :func:`animegraph.baselines.ppg_forward.loud_level`), as offline to the whole clip's:
    before the first word at least 30 dB over the quietest 20 ms (not the room's noise's
    own level, which made the noise as loud as speech), then the 95th percentile of every
    20 ms frame's RMS; each window's guide hears that level, not the window's own."""
    from animegraph.baselines import ppg_forward
    from animegraph.live import Stream
    from animegraph.live import stream as live_stream

    audio, sr = speech
    noisy = _after_noise(audio, sr)
    given = []
    window_motion = live_stream.window_motion

    def heard(*args, **kwargs):
        given.append(ppg_forward._LOUD.get())
        return window_motion(*args, **kwargs)

    monkeypatch.setattr(live_stream, "window_motion", heard)
    stream = Stream(model, sample_rate=sr, backlog_ms=None)
    stream.push(noisy[:sr])
    n = sr // 50  # 20 ms frames
    noise_rms = np.sqrt((noisy[:sr].reshape(-1, n).astype(np.float64) ** 2).mean(axis=1))
    assert stream._loud.level() == pytest.approx(noise_rms.min() * 10 ** 1.5, rel=0.02)
    assert stream._loud.level() > 10 * np.percentile(noise_rms, 95)  # not the noise's own
    _play(stream, noisy[sr:])
    m = len(noisy) // n
    rms = np.sqrt((noisy[: m * n].reshape(m, n).astype(np.float64) ** 2).mean(axis=1))
    level = stream._loud.level()
    assert level == pytest.approx(np.percentile(rms, 95), rel=0.03)  # the speech's
    assert given and all(g is not None and g > 10 * noise_rms.max() for g in given)
    assert given[-1] == pytest.approx(level, rel=0.03)


def test_bad_input_is_refused_in_one_line(model):
    from animegraph.live import Stream

    with pytest.raises(ParameterError, match="4000 Hz is not supported"):
        Stream(model, sample_rate=4000)
    with pytest.raises(ParameterError, match="lookahead_ms"):
        Stream(model, lookahead_ms=-5)
    stream = Stream(model)
    with pytest.raises(ParameterError, match="NaN"):
        stream.push(np.array([0.0, np.nan], dtype=np.float32))
    with pytest.raises(ParameterError, match="mono"):
        stream.push(np.zeros((10, 2), dtype=np.float32))
    stream.close()
    with pytest.raises(ParameterError, match="closed"):
        stream.push(np.zeros(10, dtype=np.float32))


def test_threads_cap_an_update_and_change_no_frame(model, speech, monkeypatch):
    """threads=1 (the default): the DTW runs on the updating thread and BLAS on one
    thread while an update runs, both restored after it; the frames are those of the
    uncapped stream."""
    import numba

    import animegraph.live.stream as stream_module
    import animegraph.search.dtw as dtw_module
    from animegraph.baselines.predicting import threadpools
    from animegraph.live import Stream

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("numba has one thread here: nothing to cap")
    monkeypatch.setattr(dtw_module, "_PARALLEL_MIN_NODES", 1)  # the pool for any batch
    seen = []
    real = stream_module.window_motion

    def window_motion(*args, **kw):
        blas = [p["num_threads"] for p in threadpools().info() if p["user_api"] == "blas"]
        seen.append((numba.get_num_threads(), max(blas, default=1)))
        return real(*args, **kw)

    monkeypatch.setattr(stream_module, "window_motion", window_motion)
    audio, sr = speech
    before = numba.get_num_threads()
    capped = np.concatenate([b.motion for b in _play(
        Stream(model, sample_rate=sr, hop_ms=80, backlog_ms=None), audio)[0]])
    assert seen and set(seen) == {(1, 1)}
    assert numba.get_num_threads() == before
    seen.clear()
    free = np.concatenate([b.motion for b in _play(
        Stream(model, sample_rate=sr, hop_ms=80, backlog_ms=None, threads=None), audio)[0]])
    assert seen and all(n == before for n, _ in seen)
    np.testing.assert_allclose(capped, free, rtol=1e-9, atol=1e-9)
    with pytest.raises(ParameterError, match="threads must be"):
        Stream(model, threads=0)


def test_what_updates_keep_between_windows_changes_no_frame(model, speech, tiny_db,
                                                            monkeypatch):
    """What an update keeps for the next windows (the low-pass's filter design, the
    MFCCs' mel filters and DCT rows, RASTA-PLP's critical bands, the guide's factorised
    mixtures and its channel check): a stream that builds all of it again before every
    window sends the same frames, bit for bit."""
    import animegraph.live.stream as stream_module
    from animegraph.baselines import make_estimator
    from animegraph.live import Stream
    from db.store import Database
    from ingest import lowpass
    from ingest.speech import features
    from ingest.tables import prepared_from_database

    guide = make_estimator("mu-mlp", n_mfcc=6, context=1, subset_hidden=(3, 4),
                           expression_hidden=4, frame_rate=60.0).fit(
        prepared_from_database(Database.open(tiny_db[0])))
    audio, sr = speech
    setting = {"sample_rate": sr, "guide": guide, "backlog_ms": None, "hop_ms": 80}
    kept = np.concatenate([b.motion for b in _play(Stream(model, **setting), audio)[0]])
    real, windows = stream_module.window_motion, []

    def afresh(*args, **kw):
        lowpass._sections.cache_clear()
        features._mel_bases.cache_clear()
        features._bark_filterbank.cache_clear()
        guide.__dict__.pop("_mixtures", None)
        out = real(*args, **kw)
        windows.append((lowpass._sections.cache_info().misses,
                        features._mel_bases.cache_info().misses,
                        features._bark_filterbank.cache_info().misses,
                        "_mixtures" in vars(guide)))
        return out

    monkeypatch.setattr(stream_module, "window_motion", afresh)
    fresh = np.concatenate([b.motion for b in _play(Stream(model, **setting), audio)[0]])
    # Every window built them all again (its motion low-passed, its MFCCs and RASTA-PLP taken).
    assert windows and all(w == (1, 1, 1, True) for w in windows), windows
    np.testing.assert_array_equal(fresh, kept)


def test_guide_share_reaches_each_windows_blend(model, speech, tiny_db):
    """``Stream(guide_share=s)`` blends each window's motion as ``(1 - s) * animes + s *
    guide``: share 0 sends the animes alone (as no guide, bit for bit), share 1 other
    frames, and the default share (:data:`LIVE_GUIDE_SHARE`, not offline's 0.5) frames
    near ``(1 - s) * share 0 + s * share 1`` (not exactly: the frames are not linear in
    the window's motion) and away from share 0.5's; a share out of [0, 1] is refused."""
    from animegraph.baselines import make_estimator
    from animegraph.live import Stream
    from animegraph.live.stream import LIVE_GUIDE_SHARE as S
    from db.store import Database
    from ingest.tables import prepared_from_database

    guide = make_estimator("mu-mlp", n_mfcc=6, context=1, subset_hidden=(3, 4),
                           expression_hidden=4, frame_rate=60.0).fit(
        prepared_from_database(Database.open(tiny_db[0])))
    audio, sr = speech
    setting = {"sample_rate": sr, "backlog_ms": None, "hop_ms": 80}

    def sent(**kw):
        return np.concatenate([b.motion for b in _play(Stream(model, **setting, **kw),
                                                       audio)[0]])

    alone = sent(guide=None)
    shares = {s: sent(guide=guide, guide_share=s) for s in (0.0, 0.5, 1.0)}
    default = sent(guide=guide)
    np.testing.assert_array_equal(shares[0.0], alone)
    apart = np.linalg.norm(shares[1.0] - shares[0.0])
    assert apart > 1e-3
    off = np.linalg.norm(default - ((1 - S) * shares[0.0] + S * shares[1.0]))
    assert off < 0.1 * apart
    assert np.linalg.norm(default - shares[0.5]) > 5 * off
    assert Stream(model).guide_share == S != 0.5
    for bad in (1.5, -0.1, float("nan"), True):
        with pytest.raises(ParameterError, match="guide_share"):
            Stream(model, guide_share=bad)


@pytest.mark.shared
def test_default_guide_share_follows_the_databases_sessions(model, tmp_path):
    """The default share is :data:`LIVE_GUIDE_SHARE` (calibrated on one speaker) on a
    database of one recording session (the tiny corpus: one speaker) and offline's 0.5
    on one of two speakers (two talkingface clips ingested), where offline recentres each
    anime: that database's streams send the frames of an explicit 0.5, not of 0.65. An
    explicit share wins on both."""
    import shutil

    from animegraph.baselines import make_estimator
    from animegraph.live import Stream
    from animegraph.live.stream import LIVE_GUIDE_SHARE, default_guide_share
    from animegraph.synthesis import Model, recentres
    from animegraph.synthesis.guide import GUIDE_BLEND
    from db.store import Database
    from ingest.formats.wav import read_wav
    from ingest.pipeline import ingest
    from ingest.tables import prepared_from_database

    assert len(model.sessions) == 1 and not recentres(model)
    assert default_guide_share(model) == Stream(model).guide_share == LIVE_GUIDE_SHARE != 0.5
    assert Stream(model, guide_share=0.5).guide_share == 0.5

    root = require_shared("talkingface")
    corpus = tmp_path / "talkingface"
    for name in ("styletalk_feifeili_clip3", "edtalk_mouth_source"):  # 7 s and 10 s
        shutil.copytree(root / name, corpus / name)
    ingest([corpus], tmp_path / "db")
    two = Model.load(tmp_path / "db")
    assert len({speaker for _, speaker in two.sessions}) == 2 and recentres(two)
    assert default_guide_share(two) == Stream(two).guide_share == GUIDE_BLEND == 0.5
    assert Stream(two, guide_share=LIVE_GUIDE_SHARE).guide_share == LIVE_GUIDE_SHARE

    guide = make_estimator("mu-mlp", n_mfcc=6, context=1, subset_hidden=(3, 4),
                           expression_hidden=4, frame_rate=25.0).fit(
        prepared_from_database(Database.open(tmp_path / "db")))
    audio, sr = read_wav(root / "styletalk_feifeili_clip3" / "audio_16k.wav")
    audio = audio[: 2 * sr]

    def sent(**kw):
        stream = Stream(two, sample_rate=sr, backlog_ms=None, guide=guide, **kw)
        return np.concatenate([b.motion for b in _play(stream, audio)[0]])

    default = sent()
    np.testing.assert_array_equal(default, sent(guide_share=0.5))
    assert np.linalg.norm(default - sent(guide_share=LIVE_GUIDE_SHARE)) > 1e-3


# --- Live Link over UDP -----------------------------------------------------------------


def _arkit_frame(value_of):
    from ingest.formats.livelink import ARKIT_CHANNELS

    return list(ARKIT_CHANNELS), np.array([value_of(n) for n in ARKIT_CHANNELS])


def test_livelink_packets_arrive_and_decode_by_name():
    """A real UDP socket receives the packets; values are placed by name (the packet's
    order is Unreal's enum's: jawLeft before jawRight, unlike the CSV)."""
    from animegraph.live.livelink import LiveLinkSender, decode

    names, frame = _arkit_frame(lambda n: 0.9 if n == "jawLeft" else
                                0.1 if n == "jawRight" else 0.5 if n == "jawOpen" else 0.0)
    receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    receiver.bind(("127.0.0.1", 0))
    receiver.settimeout(5)
    port = receiver.getsockname()[1]
    sender = LiveLinkSender(f"127.0.0.1:{port}", names, 30.0, subject="face")
    for k in range(3):
        sender.send(k, frame)
    packets = [decode(receiver.recv(2048)) for _ in range(3)]
    sender.close()
    receiver.close()
    assert [p.frame for p in packets] == [0, 1, 2]
    p = packets[0]
    assert p.version == 6 and p.subject == "face" and p.rate == (30, 1)
    assert len(p.device_id) == 36 and p.values.shape == (61,)
    assert p.value("jawLeft") == pytest.approx(0.9) and p.value("jawRight") == pytest.approx(0.1)
    assert p.values[15] == pytest.approx(0.9)  # EARFaceBlendShape: JawLeft = 15
    assert p.value("jawOpen") == pytest.approx(0.5)
    assert sender.sent == 3 and sender.dropped == 0


def test_livelink_packet_matches_pylivelinkface():
    """An independent decoder (pylivelinkface 0.1, packet version 6) reads the packets."""
    pll = pytest.importorskip("pylivelinkface")
    from animegraph.live.livelink import PACKET_ORDER, encode

    values = np.linspace(0.0, 1.0, 61)
    data = encode(values, frame=1234, fps=60.0, device_id="0" * 8 + "-1111-2222-3333-" + "4" * 12,
                  subject="animegraph")
    ok, face = pll.PyLiveLinkFace.decode(data)
    assert ok and face._version == 6 and face.name == "animegraph"
    assert face._frames == 1234 and face.fps == 60 and face._denominator == 1
    np.testing.assert_allclose(face._blend_shapes, values, atol=1e-6)
    # Its enum is the packet's order.
    assert [b.name for b in pll.FaceBlendShape] == [n[0].upper() + n[1:] for n in PACKET_ORDER]


def test_livelink_refuses_what_it_cannot_send(model):
    from animegraph.live.livelink import LiveLinkSender, decode

    with pytest.raises(DataError, match="lack 52"):  # points, not mapped onto the shapes
        LiveLinkSender("127.0.0.1:11111", model.names, 30.0)
    names, _ = _arkit_frame(lambda n: 0.0)
    with pytest.raises(ParameterError, match="HOST:PORT"):
        LiveLinkSender("localhost", names, 30.0)
    with pytest.raises(DataError, match="cannot resolve"):
        LiveLinkSender("no-such-host.invalid:11111", names, 30.0)
    with pytest.raises(DataError):
        decode(b"\x06\x00\x00\x10\x00")  # a string longer than the packet
    with pytest.raises(DataError):
        decode(b"")


def test_livelink_to_a_port_nobody_listens_on_never_stalls():
    """Nothing listens there: every frame is sent or dropped and counted, no error."""
    from animegraph.live.livelink import LiveLinkSender

    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()  # now nobody listens there
    names, frame = _arkit_frame(lambda n: 0.2)
    sender = LiveLinkSender(f"127.0.0.1:{port}", names, 30.0)
    for k in range(50):
        sender.send(k, frame)
    assert sender.sent + sender.dropped == 50
    sender.close()


def test_points_map_onto_the_arkit_shapes(model):
    """A marker database's frame displaced by a pure ARKit shape maps back to that shape;
    the rest pose maps to no shape."""
    from animegraph.face.arkit import arkit_shapes
    from animegraph.face.mesh import default_marker_map
    from animegraph.live.arkit_map import PointsToArkit
    from animegraph.live.stream import rest_pose
    from animegraph.motion.files import point_labels
    from animegraph.synthesis.model import to_world
    from ingest.formats.livelink import ARKIT_BLENDSHAPES

    mapping = PointsToArkit(model)
    rest = rest_pose(model)
    assert np.abs(mapping.weights(rest)).max() < 1e-6
    vertices = default_marker_map(point_labels(model.names)).vertices
    for shape, amount in (("jawOpen", 0.5), ("mouthSmileLeft", 0.7), ("mouthPucker", 0.3)):
        k = ARKIT_BLENDSHAPES.index(shape)
        local = model.to_local(rest[None])[0]
        local[mapping.columns] += amount * arkit_shapes()[k, vertices].reshape(-1) / mapping.scale
        w = mapping.weights(to_world(local[None], model.groups, model.head_reference))[0]
        assert int(np.argmax(w)) == k and w[k] == pytest.approx(amount, abs=0.1), shape
        assert np.delete(w, k).max() < 0.1


def test_live_mouth_reaches_livelink_from_a_marker_database(model, speech):
    """Stream -> points mapped onto ARKit -> UDP: jawOpen follows the mouth opening."""
    from animegraph.live import Stream
    from animegraph.live.arkit_map import PointsToArkit
    from animegraph.live.livelink import LiveLinkSender, decode
    from animegraph.motion.measures import mouth_opening, pearson

    audio, sr = speech
    receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    receiver.bind(("127.0.0.1", 0))
    receiver.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
    receiver.settimeout(5)
    sender = LiveLinkSender(f"127.0.0.1:{receiver.getsockname()[1]}", model.names,
                            model.graph.fps, convert=PointsToArkit(model))
    batches, _ = _play(Stream(model, sample_rate=sr, hop_ms=200), audio)
    motion = np.concatenate([b.motion for b in batches])
    jaw = []
    for k, frame in enumerate(motion):
        sender.send(k, frame)
        jaw.append(decode(receiver.recv(2048)).value("jawOpen"))
    sender.close()
    receiver.close()
    assert pearson(np.asarray(jaw), mouth_opening(motion, model.names, model.kind)) > 0.5


# --- WebSocket --------------------------------------------------------------------------


def test_websocket_client_gets_frames_in_order():
    pytest.importorskip("websockets")
    from websockets.sync.client import connect

    from animegraph.live.websocket import FrameServer

    server = FrameServer(0, ["a", "b"], 30.0)
    with connect(f"ws://127.0.0.1:{server.port}/") as ws:
        hello = json.loads(ws.recv(timeout=5))
        assert hello == {"type": "hello", "fps": 30.0, "channels": ["a", "b"]}
        for k in range(40):
            server.send(k, np.array([k, -k], dtype=float))
        got = [json.loads(ws.recv(timeout=5)) for _ in range(40)]
        server.close(frames=40)
        assert json.loads(ws.recv(timeout=5)) == {"type": "end", "frames": 40}
    assert [m["index"] for m in got] == list(range(40))
    assert got[3]["values"] == [3.0, -3.0] and got[3]["time"] == pytest.approx(0.1)
    assert server.dropped == 0


def test_websocket_slow_and_gone_clients_are_counted_not_waited_for():
    pytest.importorskip("websockets")
    from websockets.sync.client import connect

    from animegraph.live.websocket import QUEUE_FRAMES, FrameServer

    server = FrameServer(0, [f"c{i}" for i in range(500)], 30.0)
    frame = np.random.default_rng(0).random(500)
    # close_timeout: the client, leaving, waits that long for the close handshake, which
    # the server's full queue holds up (10 s by default); what is tested is the server.
    with connect(f"ws://127.0.0.1:{server.port}/", close_timeout=1) as ws:
        ws.recv(timeout=5)
        for k in range(3000):  # ~30 MB to a client that reads nothing
            server.send(k, frame)
        deadline = time.monotonic() + 30
        while server.dropped == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert server.dropped > 0 and server.sent >= QUEUE_FRAMES
    deadline = time.monotonic() + 30  # the client has gone: forgotten, not waited for
    while server.clients and time.monotonic() < deadline:
        server.send(0, frame)
        time.sleep(0.05)
    assert server.clients == 0
    server.close(frames=3000)


# --- a file at real-time pace, the command, the recording ---------------------------------


def test_file_at_real_time_pace_gives_frames_that_track_the_clock(model, speech, tmp_path):
    """Played at its pace: no frame is sent before the audio it shows (and its look-ahead)
    was spoken, sending never goes back in time, and frame times rise with the clock."""
    from animegraph.live import Stream
    from animegraph.live.run import run
    from animegraph.live.sources import FileSource
    from ingest.formats.wav import write_wav

    audio, sr = speech
    write_wav(tmp_path / "s.wav", audio, sr)
    stream = Stream(model, sample_rate=sr, lookahead_ms=100, hop_ms=200)
    take = run(stream, FileSource(tmp_path / "s.wav"))
    n = int(round(len(audio) / sr * model.graph.fps))
    assert take.frames == n
    sent, arrived = np.asarray(take.sent_at), np.asarray(take.arrived_at)
    times = np.arange(n) / model.graph.fps
    assert np.all(np.diff(sent) >= 0) and np.all(np.diff(arrived) >= 0)
    assert np.all(sent >= arrived)
    assert np.all(arrived >= times - 1e-3)  # a sample arrives once it has been spoken
    before_end = times < len(audio) / sr - 0.1 - 0.02  # not the frames the end flushed
    assert np.all(sent[before_end] >= times[before_end] + 0.1 - 1e-3)
    assert np.corrcoef(times, sent)[0, 1] > 0.9


def _live(args, **kw):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "animegraph", "live", *args], env=env,
                          capture_output=True, text=True, timeout=600, **kw)


def test_live_command_records_what_it_sent(tiny_db, speech, tmp_path):
    from ingest.formats.c3d import read_c3d
    from ingest.formats.wav import read_wav, write_wav

    audio, sr = speech
    write_wav(tmp_path / "s.wav", audio, sr)
    out = _live(["--db", str(tiny_db[0]), "--source", str(tmp_path / "s.wav"), "--fast",
                 "--hop", "200", "--guide", "none", "--record", str(tmp_path / "take"),
                 "--threads", "0"])  # 0: no cap
    assert out.returncode == 0, out.stderr
    assert "Traceback" not in out.stderr and "frames for" in out.stderr
    heard, rate = read_wav(tmp_path / "take" / "take.wav")
    assert rate == sr and len(heard) == len(audio)
    markers = read_c3d(tmp_path / "take" / "take.c3d")
    assert len(markers.points) == int(round(len(audio) / sr * 120))


def test_live_command_bad_input_is_one_line(tiny_db, tmp_path):
    db = str(tiny_db[0])
    cases = [
        (["--source", "-", "--rate", "4000", "--record", str(tmp_path)], 2, "not supported"),
        (["--source", "-", "--record", str(tmp_path)], 2, "--rate"),
        (["--source", str(tmp_path / "none.wav"), "--record", str(tmp_path)], 2, "no such"),
        (["--source", "-", "--rate", "16000"], 2, "say where"),
        (["--source", "-", "--rate", "16000", "--livelink", "11111"], 2, "HOST:PORT"),
        # the CLI's own spelling of no cap (0), not the Python API's (None)
        (["--source", "-", "--rate", "16000", "--threads", "-1"], 2, "or 0 for no cap"),
        (["--source", "-", "--rate", "16000", "--guide-share", "1.5", "--record",
          str(tmp_path)], 2, "guide_share must be a number in [0, 1]"),
        (["--source", "-", "--rate", "16000", "--phones-engine", "pocketsphinx"], 2,
         "invalid choice"),
    ]
    for args, status, words in cases:
        out = _live(["--db", db, *args], input="")
        lines = out.stderr.strip().splitlines()
        assert out.returncode == status and "Traceback" not in out.stderr, out.stderr
        assert any(words in line for line in lines), out.stderr


def test_microphone_without_portaudio_is_one_line(tiny_db, tmp_path):
    try:
        import sounddevice  # noqa: F401
        pytest.skip("a microphone stack is installed here")
    except (ImportError, OSError):
        pass
    out = _live(["--db", str(tiny_db[0]), "--source", "mic", "--record", str(tmp_path)])
    assert out.returncode == 1 and "Traceback" not in out.stderr
    assert "sounddevice" in out.stderr or "PortAudio" in out.stderr


def test_ctrl_c_ends_cleanly_and_keeps_the_recording(tiny_db, speech, tmp_path):
    audio, sr = speech
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "animegraph", "live", "--db",
                             str(tiny_db[0]), "--source", "-", "--rate", str(sr), "--hop",
                             "200", "--guide", "none", "--record", str(tmp_path / "take")],
                            stdin=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    lines = []
    for line in proc.stderr:  # until the stream runs (the model is loaded)
        lines.append(line.decode())
        if "Ctrl-C ends" in lines[-1]:
            break
    proc.stdin.write((audio * 32767).astype("<i2").tobytes())  # the stdin stays open
    proc.stdin.flush()
    time.sleep(3)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    err = "".join(lines) + err.decode()
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "interrupted" in err
    assert (tmp_path / "take" / "take.wav").is_file()


# --- an ARKit database from the real capture (../shared) ----------------------------------


@pytest.fixture(scope="module")
def arkit_db(tmp_path_factory):
    from ingest.formats.wav import read_wav, write_wav
    from ingest.pipeline import ingest

    capture = require_shared("livelink", "neurosync_testset.csv")
    folder = tmp_path_factory.mktemp("arkit") / "corpus"
    folder.mkdir()
    lines = capture.read_text().splitlines()
    n = int(12.0 * 59.9)
    (folder / "part.csv").write_text("\n".join(lines[: n + 1]) + "\n")
    audio, sr = read_wav(capture.with_suffix(".wav"))
    write_wav(folder / "part.wav", audio[: int(n / 59.9 * sr)], sr)
    db = folder.parent / "db"
    ingest([folder], db)
    line = folder.parent / "line.wav"
    write_wav(line, audio[-4 * sr:], sr)  # speech the database does not hold
    return db, line


def test_live_command_sends_livelink_packets(arkit_db, tmp_path):
    from animegraph.live.livelink import decode
    from ingest.formats.livelink import read_livelink

    db, line = arkit_db
    receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    receiver.bind(("127.0.0.1", 0))
    receiver.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
    port = receiver.getsockname()[1]
    out = _live(["--db", str(db), "--source", str(line), "--fast", "--hop", "200",
                 "--livelink", f"127.0.0.1:{port}", "--record", str(tmp_path / "take")])
    assert out.returncode == 0, out.stderr
    receiver.settimeout(2)
    packets = []
    try:
        while True:
            packets.append(decode(receiver.recv(2048)))
    except TimeoutError:
        pass
    receiver.close()
    take = read_livelink(tmp_path / "take" / "take.livelink.csv")
    assert len(packets) == len(take.values) > 0
    assert [p.frame for p in packets] == list(range(len(packets)))
    k = len(packets) // 2
    for name in ("jawOpen", "jawLeft", "mouthRight", "eyeBlinkLeft"):
        col = take.names.index(name)
        assert packets[k].value(name) == pytest.approx(take.values[k, col], abs=1e-4)


# --- the incremental front end ----------------------------------------------------------


@pytest.mark.parametrize("rate", [16000, 24000])
def test_incremental_posteriors_match_the_windowed_ones(speech, rate):
    """hama's posteriors computed once per frame (PosteriorTrack: 300 ms of context, settled
    40 ms later) agree with those of the model re-run on a 600 ms window ending at the
    same sample, as the windowed stream computed them, as well as those agree with the
    whole utterance's; posteriors shifted by one 20 ms frame do not."""
    from scipy.signal import resample_poly

    from animegraph.live.frontend import FRAME_RATE, PosteriorTrack
    from ingest.speech import ctc

    audio, sr = speech
    if rate != sr:
        audio = resample_poly(audio, rate, sr).astype(np.float32)
    full = ctc.posteriors(audio, rate)
    track = PosteriorTrack(rate, context_s=0.3, settle_s=0.04)
    hop, peak = int(0.04 * rate), float(np.max(np.abs(audio)))
    windowed = {}
    for end in range(hop, len(audio) + 1, hop):
        track.update(audio, 0, end, peak)
        first = max(0, track.settled - 36)  # 600 ms + a hop before the newest settled frame
        rows = ctc.posteriors(audio[int(round(first * rate / FRAME_RATE)): end], rate)
        for f in range(max(0, track.settled - 2), track.settled):
            if f - first < len(rows):
                windowed[f] = rows[f - first]
    frames = sorted(windowed)
    assert len(frames) > 0.8 * len(full)
    win = np.array([windowed[f] for f in frames])
    inc = track.posteriors(0, track.frames)[frames]

    def tv(p, q):  # total variation per frame, and agreement of the likeliest phone
        return 0.5 * np.abs(p - q).sum(axis=1).mean(), (p.argmax(1) == q.argmax(1)).mean()

    tv_inc, agree_inc = tv(inc, win)
    tv_full, agree_full = tv(win, full[frames])
    assert tv_inc <= 0.2 and agree_inc >= 0.8, (tv_inc, agree_inc)
    assert tv_inc <= tv_full + 0.05 and agree_inc >= agree_full - 0.05
    tv_shift, agree_shift = tv(np.roll(inc, 1, axis=0), win)
    assert tv_shift > tv_inc + 0.1 and agree_shift < agree_inc - 0.1


def test_stream_runs_hama_once_per_frame_not_per_window(model, speech):
    """The model hears each update's unsettled frames and their context, not the window:
    about (context + settle + hop) / hop seconds per second of audio, far below the
    window's (context + hop + look-ahead) / hop."""
    from animegraph.live import Stream

    audio, sr = speech
    stream = Stream(model, sample_rate=sr, lookahead_ms=120, hop_ms=80, context_ms=600,
                    posterior_context_ms=300, settle_ms=40, backlog_ms=None)
    _play(stream, audio)
    per_second = stream._track.model_s / (len(audio) / sr)
    assert per_second <= (0.3 + 0.04 + 0.08 + 0.04) / 0.08  # a frame's rounding either side
    assert per_second < (0.6 + 0.08 + 0.12) / 0.08 * 0.6


def test_websocket_source_takes_pcm_split_anywhere_and_ends_with_its_client():
    pytest.importorskip("websockets")
    from websockets.exceptions import ConnectionClosed
    from websockets.sync.client import connect

    from animegraph.live.sources import WebSocketSource

    source = WebSocketSource(0, 16000)
    samples = (np.sin(np.arange(1000) / 7.0) * 20000).astype("<i2")
    raw = samples.tobytes()
    with connect(f"ws://127.0.0.1:{source.port}/") as ws:
        ws.send(raw[:301])  # a sample split between two messages
        ws.send("not audio")  # refused, counted
        ws.send(raw[301:])
        with connect(f"ws://127.0.0.1:{source.port}/") as second:  # one client at a time
            with pytest.raises(ConnectionClosed) as closed:
                second.recv(timeout=5)
            assert closed.value.rcvd.code == 1013
    got = np.concatenate(list(source))
    np.testing.assert_array_equal(got, samples.astype(np.float32) / 32768.0)
    assert source.refused == 2


def test_live_command_hears_pcm_from_a_websocket_client(tiny_db, speech, tmp_path):
    pytest.importorskip("websockets")
    from websockets.sync.client import connect

    from ingest.formats.wav import read_wav

    audio, sr = speech
    with socket.socket() as s:  # a free port
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    cmd = [sys.executable, "-m", "animegraph", "live", "--db", str(tiny_db[0]), "--source",
           f"ws:{port}", "--rate", str(sr), "--hop", "200", "--guide", "none", "--record",
           str(tmp_path / "take")]
    proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONPATH": str(ROOT)})
    line = proc.stderr.readline()
    assert f"waiting for PCM at ws://127.0.0.1:{port}/" in line, line
    pcm = (np.clip(audio, -1, 1) * 32767).astype("<i2")
    with connect(f"ws://127.0.0.1:{port}/") as ws:
        for k in range(0, len(pcm), 1600):
            ws.send(pcm[k:k + 1600].tobytes())
    err = proc.communicate(timeout=600)[1]
    assert proc.returncode == 0, err
    assert "Traceback" not in err and "frames for" in err
    heard, rate = read_wav(tmp_path / "take" / "take.wav")
    assert rate == sr and len(heard) == len(pcm)


def test_websocket_source_needs_a_rate_and_a_port(tiny_db, tmp_path):
    for args, said in ((["--source", "ws:80x"], "give ws:PORT"),
                       (["--source", "ws:0"], "needs --rate"),
                       (["--source", "ws:0", "--rate", "100"], "not supported")):
        out = _live(["--db", str(tiny_db[0]), "--record", str(tmp_path / "t"), *args])
        assert out.returncode != 0 and said in out.stderr, out.stderr
        assert "Traceback" not in out.stderr


def test_bench_live_unpaced_and_drift_run_at_the_first_lookahead_given(tiny_db, tmp_path):
    """``bench_live.py --unpaced`` and the drift stream run at ``--lookaheads``' first
    (they always used 120 ms, whatever was asked). One short sentence (``--sentences
    1``) keeps the real script quick: it still speaks, streams and times it."""
    from ingest.speech.espeak import speak

    out = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "bench_live.py"), "--quality", "--db",
         str(tiny_db[0]), "--sentences", "1", "--unpaced", "--lookaheads", "40",
         "--latency-seconds", "0", "--drift-seconds", "1", "--json",
         str(tmp_path / "out.json")],
        capture_output=True, text=True, timeout=900,
        env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert out.returncode == 0, out.stderr
    got = json.loads((tmp_path / "out.json").read_text())
    u = speak("Please bring the blue box to the table.")  # bench_live.SENTENCES[0]
    assert got["unpaced"]["lookahead_ms"] == 40 and got["unpaced"]["updates"] > 0
    assert got["unpaced"]["seconds"] == pytest.approx(len(u.audio) / u.sample_rate)
    assert got["drift"]["lookahead_ms"] == 40
    assert got["drift"]["frames"] == got["drift"]["expected_frames"] > 0


@pytest.mark.parametrize("fps", [25.0, 30.0, 120.0])
def test_bench_joins_each_clip_on_its_own_frames(fps):
    """``bench_live.py --joined`` plays held-out clips back to back as one stream and scores
    each clip's frames from the index it gives. Each clip starts on a frame of the stream
    and of hama's 20 ms frames, as it does streamed alone: joined end to end, a clip began
    between two frames (GRID's 2.978 s clips at 25 fps) and its frames were scored up to
    half a frame off its own. The pad before it is the clip before's own end, mirrored."""
    from types import SimpleNamespace

    sys.path.insert(0, str(ROOT / "scripts"))
    import bench_live

    rng = np.random.default_rng(0)
    clips = [SimpleNamespace(audio=rng.integers(-3000, 3000, n).astype(np.int16),
                             sample_rate=16000) for n in (47648, 47648, 30001, 47648)]
    clips.insert(2, SimpleNamespace(audio=np.zeros(1000, np.int16), sample_rate=22050))
    joined, rate, firsts = bench_live.join_clips(clips, fps)
    assert rate == 16000 and firsts[0] == 0 and firsts[2] is None  # another rate: left out
    end = 0
    for clip, first in zip(clips, firsts, strict=True):
        if first is None:
            continue
        at = first / fps * rate  # the clip's first sample: on both frame grids
        assert at == int(at) and int(at) % (rate // 50) == 0
        at = int(at)
        assert 0 <= at - end < rate // 10
        np.testing.assert_array_equal(joined[at: at + len(clip.audio)],
                                      clip.audio / np.float32(32768.0))
        np.testing.assert_array_equal(joined[end:at], joined[end - 1: 2 * end - at - 1: -1])
        end = at + len(clip.audio)
    assert len(joined) == end
