"""Video clips: a real tracker run on a GRID clip, the tracking cache, bad videos (#14).

Needs ``../shared/data/grid`` and the optional tracker (``pip install -e ".[video]"``);
each test says which is missing when it skips.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import imageio_ffmpeg
import numpy as np
import pytest
from conftest import require_shared

from db.errors import DataError
from ingest.clip import checksum_files
from ingest.formats.media import DECODING_VERSION
from ingest.readers import discover, load
from ingest.readers.video import (
    TRACKER_HINT,
    cache_path,
    cached_tracking,
    native_log_filtered,
    track_video,
    tracker_available,
    video_audio,
)

CLIP = "bbaf2n"


def _needs_tracker():
    if not tracker_available():
        pytest.skip(f"the optional face tracker is absent ({TRACKER_HINT})")


def _ffmpeg(*args: str) -> None:
    subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-nostdin", "-v", "error", "-y", *args],
                   check=True)


@pytest.fixture(scope="module")
def grid_clip(tmp_path_factory):
    """GRID s1's bbaf2n (video, transcript, word alignment) copied to a private folder."""
    root = require_shared("grid", "s1")
    _needs_tracker()
    folder = tmp_path_factory.mktemp("grid") / "s1"
    folder.mkdir()
    for suffix in (".mp4", ".txt", ".align"):
        shutil.copy(root / f"{CLIP}{suffix}", folder / f"{CLIP}{suffix}")
    return folder


@pytest.mark.shared
def test_track_a_grid_clip(grid_clip, capfd):
    source = discover([grid_clip])[0]
    assert (source.kind, source.layout, source.clip_id) == ("landmarks", "video", CLIP)
    video = grid_clip / f"{CLIP}.mp4"
    target = cache_path(checksum_files([video]))
    target.unlink(missing_ok=True)
    capfd.readouterr()
    clip = load(source)
    # mediapipe's native set-up lines (absl, glog, TFLite) do not reach stderr
    err = capfd.readouterr().err
    assert "W0000" not in err and "absl::" not in err and "TensorFlow Lite" not in err, err
    # 3 s at 25 fps, a face on every frame, 468 landmarks + pose as any landmark clip
    assert clip.fps == 25.0 and clip.n_frames == 75 and clip.motion.shape == (75, 1411)
    assert clip.extra["frames_without_face"] == 0 and np.isfinite(clip.motion).all()
    assert clip.sample_rate == 16000 and abs(clip.duration - 3.0) < 0.05
    assert clip.text == "bin blue at f two now"
    assert [w.word for w in clip.words if w.word] == clip.text.split()
    # a frontal face: the head-pose fit leaves a few mm, the mouth opens and closes
    assert clip.extra["procrustes_rms_mm"] < 6.0
    points = clip.motion[:, :1404].reshape(-1, 468, 3)
    opening = np.linalg.norm(points[:, 13] - points[:, 14], axis=1)
    assert opening.max() - opening.min() > 3.0
    # the tracking is cached by the video's checksum ...
    assert target.is_file()
    again = cached_tracking(video)
    assert again.seconds == 0.0  # read, not tracked
    np.testing.assert_array_equal(load(source).motion, clip.motion)
    # ... and a damaged cache entry is tracked again
    target.write_bytes(b"not an npz")
    assert cached_tracking(video, progress=False).seconds > 0


@pytest.mark.shared
def test_bad_videos_are_rejected_with_their_reason(grid_clip, tmp_path):
    video = grid_clip / f"{CLIP}.mp4"
    # no audio track (the face is there)
    silent = tmp_path / "silent.mp4"
    _ffmpeg("-i", str(video), "-an", "-c:v", "copy", str(silent))
    with pytest.raises(DataError, match="no audio track"):
        video_audio(silent)
    with pytest.raises(DataError, match="no audio track"):
        load(discover([silent])[0])
    # no face: a plain grey picture with the clip's speech
    blank = tmp_path / "blank.mp4"
    _ffmpeg("-f", "lavfi", "-i", "color=c=gray:s=160x120:r=25:d=2", "-i", str(video),
            "-map", "0:v", "-map", "1:a", "-shortest", "-c:v", "libx264", "-c:a", "aac",
            str(blank))
    with pytest.raises(DataError, match="a face in only 0 of"):
        load(discover([blank])[0])
    # two faces: the clip beside itself
    two = tmp_path / "two.mp4"
    _ffmpeg("-i", str(video), "-i", str(video), "-filter_complex", "[0:v][1:v]hstack[v]",
            "-map", "[v]", "-map", "0:a", "-c:v", "libx264", "-c:a", "aac", str(two))
    with pytest.raises(DataError, match="two faces in"):
        load(discover([two])[0])
    # a corrupt file
    broken = tmp_path / "broken.mp4"
    broken.write_bytes(video.read_bytes()[:2000])
    with pytest.raises(DataError, match="broken.mp4"):
        load(discover([broken])[0])
    # a transcript of another utterance beside its word alignment
    other = tmp_path / "other"
    other.mkdir()
    for suffix in (".mp4", ".align"):
        shutil.copy(grid_clip / f"{CLIP}{suffix}", other / f"{CLIP}{suffix}")
    (other / f"{CLIP}.txt").write_text("lay green by q nine again")
    with pytest.raises(DataError, match="not the transcript's"):
        load(discover([other])[0])


def _hide_mediapipe(monkeypatch):
    import builtins

    real_import = builtins.__import__

    def no_mediapipe(name, *args, **kwargs):
        if name.startswith("mediapipe"):
            raise ImportError("No module named 'mediapipe'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_mediapipe)


def test_missing_tracker_is_one_line(monkeypatch, tmp_path, capsys):
    from animegraph.apps.cli import main
    from ingest.readers.video import track_video

    video = tmp_path / "clips" / "grey.mp4"
    video.parent.mkdir()
    _ffmpeg("-f", "lavfi", "-i", "color=c=gray:s=64x48:r=25:d=1", "-f", "lavfi", "-i",
            "sine=frequency=200:sample_rate=16000:duration=1", "-c:v", "libx264",
            "-c:a", "aac", "-shortest", str(video))
    _hide_mediapipe(monkeypatch)
    assert not tracker_available()
    with pytest.raises(DataError) as info:
        track_video(video)
    assert str(info.value) == TRACKER_HINT and "\n" not in TRACKER_HINT
    capsys.readouterr()
    assert main(["ingest", str(video.parent), "--db", str(tmp_path / "db")]) != 0
    err = capsys.readouterr().err.strip()
    assert err.endswith(TRACKER_HINT) and len(err.splitlines()) == 1
    assert not (tmp_path / "db").exists() or not any((tmp_path / "db").iterdir())


def test_synth_takes_its_speech_from_a_video(tiny_corpus, tiny_db, tmp_path, capsys):
    from animegraph.apps.cli import main
    from ingest.formats.media import read_audio
    from ingest.formats.wav import read_wav

    wav = sorted((tiny_corpus / "clips").glob("*.wav"))[0]
    video = tmp_path / "take.mp4"
    _ffmpeg("-f", "lavfi", "-i", "color=c=gray:s=64x48:r=25", "-i", str(wav), "-shortest",
            "-c:v", "libx264", "-c:a", "aac", str(video))
    speech, rate = read_audio(video)
    original, original_rate = read_wav(wav)
    assert rate == 16000 == original_rate
    assert abs(len(speech) - len(original)) < 0.05 * rate  # codec padding only
    n = min(len(speech), len(original)) - 2048
    assert np.corrcoef(speech[1024:n], original[1024:n])[0, 1] > 0.9
    out = tmp_path / "out.npz"
    assert main(["synth", str(video), "--db", str(tiny_db[0]), "-o", str(out)]) == 0
    assert out.is_file()
    with pytest.raises(DataError, match="not found"):
        read_audio(tmp_path / "absent.mp4")


def test_sound_track_is_cached_by_checksum(tmp_path):
    """A video's decoded sound track is kept beside its tracking: read again without ffmpeg
    (the video itself may be gone), and a damaged entry is decoded again and replaced."""
    video = tmp_path / "tone.mp4"
    _ffmpeg("-f", "lavfi", "-i", "color=c=gray:s=64x48:r=25:d=1", "-f", "lavfi", "-i",
            "sine=frequency=300:sample_rate=16000:duration=1", "-c:v", "libx264",
            "-c:a", "aac", "-shortest", str(video))
    checksum = checksum_files([video])
    decoded = video_audio(video)
    first = video_audio(video, checksum=checksum)
    np.testing.assert_array_equal(first, decoded)
    entry = cache_path(checksum).with_name(f"{checksum}-audio16000-d{DECODING_VERSION}.npy")
    assert entry.is_file()
    # A copy decoded by an earlier way of reading is another name: never met.
    stale = entry.with_name(f"{checksum}-audio16000.npy")
    np.save(stale, np.zeros(4, np.float32))
    np.testing.assert_array_equal(video_audio(video, checksum=checksum), decoded)
    moved = video.rename(tmp_path / "elsewhere.mp4")
    np.testing.assert_array_equal(video_audio(video, checksum=checksum), decoded)
    entry.write_bytes(b"not an npy")
    np.testing.assert_array_equal(video_audio(moved, checksum=checksum), decoded)
    assert np.load(entry, allow_pickle=False).dtype == np.float32


def test_native_log_noise_is_dropped_and_errors_kept(capfd):
    noise = ("INFO: Created TensorFlow Lite XNNPACK delegate for CPU.\n"
             "WARNING: All log messages before absl::InitializeLog() is called are written "
             "to STDERR\n"
             "W0000 00:00:1796176167.348217   21167 inference_feedback_manager.cc:114] "
             "Feedback manager requires a model with a single signature inference.\n"
             "I0000 00:00:1796176167.3 21166 gl_context.cc:357] GL version: 3.2\n")
    error = ("E0000 00:00:1796176167.381494   21166 graph.cc:12] Calculator failed "
             "to open the model\n")
    capfd.readouterr()
    with native_log_filtered():
        os.write(2, (noise + error).encode())
        print("animegraph: a Python line meanwhile", file=sys.stderr)
    os.write(2, b"after\n")  # fd 2 is back
    err = capfd.readouterr().err
    # (pytest's sys.stderr may bypass fd 2, so the Python line's place is not fixed)
    assert sorted(err.splitlines()) == sorted(
        [error.strip(), "animegraph: a Python line meanwhile", "after"])
    assert err.splitlines()[-1] == "after"
    with pytest.raises(RuntimeError), native_log_filtered():  # restored on an error too
        raise RuntimeError("boom")
    os.write(2, b"restored\n")
    assert capfd.readouterr().err == "restored\n"


def test_a_video_is_bounded_before_and_while_it_is_tracked(tmp_path, monkeypatch):
    _needs_tracker()
    monkeypatch.setattr("ingest.readers.video.MAX_VIDEO_FRAMES", 25)
    # From a pipe, Matroska declares no duration: no frame count was checked at all, and a
    # static 16 x 16 picture takes ~20 bytes a frame (ten hours, 20 MB, tracked into 15 GB)
    endless = tmp_path / "endless.mkv"
    with endless.open("wb") as out:
        subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-nostdin", "-v", "error", "-f",
                        "lavfi", "-i", "color=c=gray:s=16x16:r=25:d=1.6", "-c:v", "libx264",
                        "-f", "matroska", "-"], stdout=out, check=True)
    with pytest.raises(DataError, match=r"endless\.mkv: 26 frames or more; a video clip may "
                                        r"have at most 25 \("):
        track_video(endless, progress=False)
    # a declared length past the bound is refused before tracking; so are huge frames
    declared = tmp_path / "declared.mp4"
    _ffmpeg("-f", "lavfi", "-i", "color=c=gray:s=16x16:r=25:d=1.6", "-c:v", "libx264",
            str(declared))
    with pytest.raises(DataError, match=r"declared\.mp4: 40 frames or more"):
        track_video(declared, progress=False)
    monkeypatch.setattr("ingest.readers.video.MAX_FRAME_PIXELS", 16 * 16 - 1)
    with pytest.raises(DataError, match=r"declared\.mp4: frames of 16 x 16 pixels"):
        track_video(declared, progress=False)
