"""Speech as the readers hand it on, WAV files and sound tracks through ffmpeg alike: fast
rates resampled to 48 kHz, slow ones refused, opposite-phase channels not cancelled, cut
files refused in one line; and ``synth`` and ingest reading such files."""

from __future__ import annotations

import logging
import subprocess

import imageio_ffmpeg
import numpy as np
import pytest
import soundfile
from crafted import disguised_playlists, flac_declaring
from scipy.signal import resample_poly

from db.errors import DataError
from ingest.formats.media import read_audio, read_frames, video_length
from ingest.formats.wav import read_wav


def _ffmpeg(*args: str) -> None:
    subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-nostdin", "-v", "error", "-y", *args],
                   check=True)


def _tone(seconds: float, rate: int, freq: float = 440.0, amp: float = 0.5) -> np.ndarray:
    t = np.arange(int(round(seconds * rate))) / rate
    return (amp * np.sin(2 * np.pi * freq * t)).astype(np.float32)


def _warnings(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]


# --------------------------------------------------------------------------- sample rates


@pytest.mark.parametrize("rate", [88200, 96000, 192000])
def test_fast_wav_is_read_at_48k(tmp_path, rate):
    tone = _tone(1.0, rate)
    path = tmp_path / "fast.wav"
    soundfile.write(str(path), np.stack([tone, 0.5 * tone], axis=1), rate, subtype="PCM_24")
    for read in (read_wav, read_audio):
        audio, sr = read(path)
        assert sr == 48000 and audio.shape == (48000,)
        # the same tone, averaged over the channels: nothing but the rate changed
        expected = 0.75 * _tone(1.0, 48000)
        np.testing.assert_allclose(audio[200:-200], expected[200:-200], atol=2e-3)


@pytest.mark.parametrize("rate", [8000, 16000, 44100, 48000])
def test_rates_the_features_take_are_kept(tmp_path, rate):
    tone = _tone(0.5, rate)
    path = tmp_path / "ok.wav"
    soundfile.write(str(path), tone, rate, subtype="FLOAT")
    audio, sr = read_audio(path)
    assert sr == rate
    np.testing.assert_array_equal(audio, tone)


def test_slow_wav_is_one_line_naming_the_file(tmp_path):
    path = tmp_path / "slow.wav"
    soundfile.write(str(path), _tone(1.0, 4000), 4000, subtype="PCM_16")
    with pytest.raises(DataError, match=r"slow\.wav: sampled at 4000 Hz; speech needs at "
                                        r"least 8000 Hz") as info:
        read_audio(path)
    assert "\n" not in str(info.value)


def test_fast_sound_track_is_read_at_48k(tmp_path):
    wav, m4a = tmp_path / "fast.wav", tmp_path / "fast.m4a"
    soundfile.write(str(wav), _tone(1.0, 96000), 96000, subtype="PCM_24")
    _ffmpeg("-i", str(wav), "-c:a", "aac", str(m4a))
    audio, sr = read_audio(m4a)
    assert sr == 48000 and abs(len(audio) - 48000) < 0.05 * 48000  # codec padding only
    # an explicit rate is still decoded by ffmpeg at that rate
    assert read_audio(m4a, 16000)[1] == 16000


# --------------------------------------------------------------------------- channels


def test_opposite_phase_stereo_keeps_the_louder_channel(tmp_path, caplog):
    left = _tone(1.0, 16000)
    path = tmp_path / "antiphase.wav"
    soundfile.write(str(path), np.stack([left, -0.8 * left], axis=1), 16000, subtype="FLOAT")
    with caplog.at_level(logging.WARNING):
        audio, sr = read_audio(path)
    np.testing.assert_array_equal(audio, left)
    [warning] = _warnings(caplog)
    assert "antiphase.wav" in warning and "opposite phase" in warning
    assert "using channel 1 alone" in warning


@pytest.mark.parametrize("right_of", [lambda left: 0.0 * left,  # one channel silent
                                      lambda left: 0.7 * left,  # in phase
                                      lambda left: _tone(1.0, 16000, 310.0)])  # unrelated
def test_stereo_that_does_not_cancel_is_averaged_quietly(tmp_path, caplog, right_of):
    left = _tone(1.0, 16000)
    right = right_of(left)
    path = tmp_path / "stereo.wav"
    soundfile.write(str(path), np.stack([left, right], axis=1), 16000, subtype="FLOAT")
    with caplog.at_level(logging.WARNING):
        audio, _ = read_audio(path)
    np.testing.assert_allclose(audio, (left + right) / 2, atol=1e-7)
    assert _warnings(caplog) == []


def test_opposite_phase_sound_track(tmp_path, caplog):
    left = _tone(1.0, 16000)
    wav, m4a = tmp_path / "antiphase.wav", tmp_path / "antiphase.m4a"
    soundfile.write(str(wav), np.stack([left, -left], axis=1), 16000, subtype="PCM_16")
    _ffmpeg("-i", str(wav), "-c:a", "aac", "-b:a", "128k", str(m4a))
    with caplog.at_level(logging.WARNING):
        audio, _ = read_audio(m4a)
    assert np.sqrt(np.mean(audio ** 2)) > 0.3  # the tone (RMS 0.35), not its cancellation
    assert len(_warnings(caplog)) == 1 and "opposite phase" in _warnings(caplog)[0]


# --------------------------------------------------------------------------- truncation


def _video(path, *, seconds: float = 3.0, audio_seconds: float | None = None) -> None:
    """A faststart video (index first, as phones and web exports write it) with a tone."""
    sound = ["-f", "lavfi", "-i",
             f"sine=frequency=300:sample_rate=16000:duration={audio_seconds or seconds}"]
    picture = [] if path.suffix == ".m4a" else [
        "-f", "lavfi", "-i", f"color=c=gray:s=64x48:r=25:d={seconds}", "-c:v", "libx264"]
    extra = ["-movflags", "+faststart"] if path.suffix in (".mp4", ".mov", ".m4a") else []
    _ffmpeg(*sound, *picture, "-c:a", "aac", *extra, str(path))


@pytest.mark.parametrize("suffix", [".mp4", ".mov", ".m4a", ".mkv"])
def test_cut_sound_track_is_refused_in_one_line(tmp_path, suffix):
    full, half = tmp_path / f"full{suffix}", tmp_path / f"half{suffix}"
    _video(full)
    audio, sr = read_audio(full)
    assert abs(len(audio) / sr - 3.0) < 0.05
    data = full.read_bytes()
    half.write_bytes(data[: len(data) // 2])
    # ffmpeg decodes the first second or so, says "partial file" and exits 0
    with pytest.raises(DataError, match=rf"truncated audio file .*half\{suffix}: 1\.\d+ s of "
                                        r"sound decoded, the file declares 3\.\d+ s") as info:
        read_audio(half)
    assert "\n" not in str(info.value)


def test_sound_track_shorter_than_the_pictures_is_no_cut(tmp_path, caplog):
    video = tmp_path / "short_sound.mp4"
    _video(video, seconds=3.0, audio_seconds=2.0)
    with caplog.at_level(logging.WARNING):
        audio, sr = read_audio(video)
    assert abs(len(audio) / sr - 2.0) < 0.05
    assert _warnings(caplog) == []


# --------------------------------------------------------------------------- synth, ingest


def test_synth_reads_such_speech(tiny_corpus, tiny_db, tmp_path, capsys, caplog):
    from animegraph.apps.cli import main

    wav = sorted((tiny_corpus / "clips").glob("*.wav"))[0]
    speech, rate = read_wav(wav)
    base = ["--db", str(tiny_db[0]), "-o", str(tmp_path / "out.npz")]

    fast = tmp_path / "fast.wav"  # 96 kHz stereo, as a studio recorder writes it
    up = resample_poly(speech, 96000, rate).astype(np.float32)
    soundfile.write(str(fast), np.stack([up, 0.5 * up], axis=1), 96000, subtype="PCM_24")
    assert main(["synth", str(fast), *base]) == 0
    assert "error" not in capsys.readouterr().err

    antiphase = tmp_path / "antiphase.wav"
    soundfile.write(str(antiphase), np.stack([speech, -speech], axis=1), rate, subtype="FLOAT")
    with caplog.at_level(logging.WARNING):
        assert main(["synth", str(antiphase), *base]) == 0
    assert "silent" not in capsys.readouterr().err
    assert any("opposite phase" in w for w in _warnings(caplog))

    video = tmp_path / "take.mp4"
    _ffmpeg("-f", "lavfi", "-i", "color=c=gray:s=64x48:r=25", "-i", str(wav), "-shortest",
            "-c:v", "libx264", "-c:a", "aac", "-movflags", "+faststart", str(video))
    data = video.read_bytes()
    cut = tmp_path / "cut.mp4"
    cut.write_bytes(data[: len(data) // 2])
    assert main(["synth", str(cut), *base]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "truncated audio file" in err and "cut.mp4" in err
    assert "Traceback" not in err


# --------------------------------------------------------------------------- disguised files


@pytest.mark.parametrize("kind", ["dash", "hls", "concat", "concat-relative"])
def test_a_playlist_named_like_a_video_opens_no_other_file(tmp_path, kind):
    # ffmpeg picks its demuxer by content: a DASH manifest named speech.mp4 used to be read,
    # and the private video it names decoded as the speech (no other file may be opened)
    private = tmp_path / "elsewhere" / "private.mp4"
    private.parent.mkdir()
    _video(private, seconds=2.0)
    clip = tmp_path / "clip"
    clip.mkdir()
    (clip / "private.mp4").symlink_to(private)
    disguised = clip / "speech.mp4"
    disguised.write_text(disguised_playlists(private)[kind])
    for read in (read_audio, video_length):
        with pytest.raises(DataError, match=r"speech\.mp4") as info:
            read(disguised)
        assert "\n" not in str(info.value)
        # ffmpeg itself no longer probes HLS in a file named .mp4; the others are ours to stop
        assert ("not a container its suffix names" in str(info.value)) == (kind != "hls")
    with pytest.raises((OSError, RuntimeError)):
        next(read_frames(disguised))


# --------------------------------------------------------------------------- decompression


def test_a_header_declaring_hours_is_refused_before_decoding(tmp_path):
    # 10 KB of FLAC named .wav declaring 2**36 samples: soundfile would allocate 256 GiB
    # for them (a MemoryError, not one line); now refused before anything is decoded
    path = flac_declaring(tmp_path / "speech.wav", 2**36 - 1)
    for read in (read_wav, read_audio):
        with pytest.raises(DataError, match=r"speech\.wav: at least 71583 min of sound in 1 "
                                             r"channel\(s\) at 16000 Hz; speech is read up to"):
            read(path)


@pytest.mark.parametrize("name", ["speech.wav", "speech.mp4", "speech.mkv"])
def test_compressed_silence_decodes_to_a_bounded_size(tmp_path, monkeypatch, name):
    # A few bytes a second of FLAC or AAC silence decode to 32 bytes a sample x channels:
    # the bound holds for the samples decoded (by ffmpeg, whatever a header says), not the
    # file's size. Lowered to 2 s of 8 kHz mono here so that the file stays small.
    for module in ("ingest.formats.wav", "ingest.formats.media"):
        monkeypatch.setattr(f"{module}.MAX_SPEECH_SAMPLES", 16000)
    short, long = tmp_path / f"short_{name}", tmp_path / name
    for path, seconds in ((short, 1.9), (long, 2.5)):
        codec = ["-c:a", "flac", "-f", "flac"] if name.endswith(".wav") else ["-c:a", "aac"]
        _ffmpeg("-f", "lavfi", "-i", f"anullsrc=r=8000:cl=mono:d={seconds}", *codec, str(path))
    assert len(read_audio(short)[0]) <= 16000
    with pytest.raises(DataError, match=rf"{name}: at least 0 min of sound in 1 channel\(s\) "
                                        r"at 8000 Hz; speech is read up to 16,000 samples"):
        read_audio(long)
