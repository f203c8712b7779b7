"""``animegraph render`` and ``plot``: real files through the real ffmpeg, read back."""

from __future__ import annotations

import json
import logging
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest
from crafted import disguised_playlists

from animegraph.apps.cli import main
from animegraph.face.animation import animate
from animegraph.face.gltf import read_glb_frames
from animegraph.face.mesh import canonical_mesh, default_marker_map
from animegraph.face.render import deformer_for, ffmpeg_exe
from animegraph.motion.files import Motion, read_motion
from ingest.corpus import face
from ingest.formats.c3d import MarkerData, write_c3d
from ingest.formats.wav import write_wav

FPS = 120.0


@pytest.fixture(scope="module")
def take(tmp_path_factory):
    """One second of rig motion (jaw, smile, blink, a head turn) as C3D, with a WAV."""
    folder = tmp_path_factory.mktemp("take")
    n = int(FPS)
    t = np.arange(n) / FPS
    controls = np.zeros((n, len(face.CONTROLS)))
    col = face.CONTROLS.index
    controls[:, col("jaw_open")] = 0.5 + 0.5 * np.sin(2 * np.pi * 2 * t)
    controls[:, col("smile")] = t
    controls[:, col("blink")] = np.exp(-((t - 0.5) / 0.05) ** 2)
    controls[:, col("head_yaw")] = 12 * np.sin(2 * np.pi * t)
    points = face.FaceRig.for_points(face.marker_rest()).pose(controls)
    labels = tuple(m[0] for m in face.MARKERS)
    write_c3d(folder / "take.c3d", MarkerData(points=points, labels=labels, rate=FPS))
    write_wav(folder / "take.wav", 0.3 * np.sin(2 * np.pi * 220 * np.arange(16000) / 16000),
              16000)
    phones = [{"phone": "SIL", "start": 0.0, "end": 0.2}, {"phone": "AA", "start": 0.2,
                                                            "end": 0.6},
              {"phone": "M", "start": 0.6, "end": 1.0, "jump": True, "clip_id": "x"}]
    (folder / "take.json").write_text(json.dumps({"phones": phones}))
    return folder


def _streams(path):
    out = subprocess.run([ffmpeg_exe(), "-hide_banner", "-i", str(path)], capture_output=True,
                         text=True)
    return [line.strip() for line in out.stderr.splitlines() if "Stream #" in line]


def _duration(path):
    """Seconds, from the container."""
    info = subprocess.run([ffmpeg_exe(), "-hide_banner", "-i", str(path)], capture_output=True,
                          text=True).stderr
    hours, minutes, seconds = re.search(r"Duration: (\d+):(\d+):([\d.]+)", info).groups()
    return 3600 * int(hours) + 60 * int(minutes) + float(seconds)


def _decode(path, width, height):
    raw = subprocess.run([ffmpeg_exe(), "-loglevel", "error", "-i", str(path), "-f",
                          "rawvideo", "-pix_fmt", "rgb24", "-"], capture_output=True,
                         check=True).stdout
    return np.frombuffer(raw, np.uint8).reshape(-1, height, width, 3)


def _no_leftovers(folder):
    return [p.name for p in folder.iterdir() if p.name.startswith(".")]


def _actor_video(path, seconds=1.0, *, sound=True, faststart=False, keep=1.0):
    """A red 160 x 120 "video of the actor" at 25 fps (with a tone), its first ``keep`` of bytes.

    Cut short, a plain MP4 loses its index (written last: nothing decodes); a faststart one
    keeps it (the header still declares ``seconds``) and decodes up to the cut.
    """
    cmd = [ffmpeg_exe(), "-nostdin", "-y", "-loglevel", "error", "-f", "lavfi", "-i",
           f"color=c=red:s=160x120:r=25:d={seconds}"]
    if sound:
        cmd += ["-f", "lavfi", "-i", f"sine=frequency=300:sample_rate=16000:duration={seconds}",
                "-c:a", "aac"]
    if keep < 1:  # noise makes every frame about as big, so a cut falls mid-video
        cmd += ["-vf", "noise=alls=30:allf=t"]
    cmd += ["-c:v", "libx264", "-pix_fmt", "yuv420p"]
    subprocess.run([*cmd, *(["-movflags", "+faststart"] if faststart else []), str(path)],
                   check=True)
    data = path.read_bytes()
    path.write_bytes(data[:int(len(data) * keep)])
    return path


def test_mp4_beside_the_actor_video(take, capsys):
    actor = _actor_video(take / "actor.mp4")
    out = take / "both.mp4"
    assert main(["render", str(take / "take.c3d"), "--audio", str(actor), "--beside",
                 str(actor), "-o", str(out), "--quiet", "--size", "240x270"]) == 0
    # the video scaled to the face's height (160 x 120 -> 360 x 270) left of it, with sound
    streams = _streams(out)
    assert any("Video: h264" in s and "600x270" in s for s in streams), streams
    assert any("Audio: aac" in s for s in streams)
    frames = _decode(out, 600, 270)
    frame = frames[5].astype(int)
    assert frame[100:170, 20:340, 0].mean() > 180 > frame[100:170, 20:340, 1].mean() + 100
    # one frame rate, the face's 30 fps: the 25 fps actor is not interleaved with it
    assert abs(len(frames) - 30 * _duration(out)) <= 1.5, (len(frames), _duration(out))
    assert not _no_leftovers(take)
    assert main(["render", str(take / "take.c3d"), "--beside", str(actor), "-o",
                 str(take / "face.gif"), "--quiet"]) == 2
    assert "--beside needs an .mp4" in capsys.readouterr().err
    for suffix in (".gif", ".png", ".glb"):  # nothing to carry the sound: said, not dropped
        assert main(["render", str(take / "take.c3d"), "--audio", str(take / "take.wav"),
                     "-o", str(take / f"face{suffix}"), "--quiet"]) == 2
        assert "--audio needs an .mp4" in capsys.readouterr().err
        assert not (take / f"face{suffix}").exists()


@pytest.mark.parametrize("what", ["index lost", "no video track", "a manifest"])
def test_failed_beside_keeps_the_previous_output(take, tmp_path, capsys, what):
    # An actor video with no picture to show is refused before anything is rendered, in
    # one line naming it, and the output from an earlier run is left as it was. A DASH
    # manifest named actor.mp4 does not put the video it names (another file) beside.
    if what == "index lost":
        bad = _actor_video(tmp_path / "actor.mp4", keep=0.5)
    elif what == "no video track":
        bad = take / "take.wav"
    else:
        bad = tmp_path / "actor.mp4"
        bad.write_text(disguised_playlists(_actor_video(tmp_path / "private.mp4"))["dash"])
    out = tmp_path / "out"
    out.mkdir()
    (out / "r.mp4").write_bytes(b"an earlier render")
    line = _one_line(capsys, main(["render", str(take / "take.c3d"), "--audio",
                                   str(take / "take.wav"), "--beside", str(bad), "-o",
                                   str(out / "r.mp4"), "--size", "240x270"]), 1)
    assert bad.name in line and ("no video track" in line) == (what == "no video track"), line
    assert (out / "r.mp4").read_bytes() == b"an earlier render"
    assert sorted(p.name for p in out.iterdir()) == ["r.mp4"]


def test_beside_failing_after_the_render_keeps_the_previous_output(take, tmp_path, capsys,
                                                                    monkeypatch):
    # The face is rendered into a temporary file: -o is replaced only once the pair is made.
    from animegraph.face import render
    from db.errors import DataError

    def fail(*args, **kwargs):
        raise DataError("ffmpeg could not put actor.mp4 beside r.mp4: disk full")

    monkeypatch.setattr(render, "place_beside", fail)
    actor = _actor_video(tmp_path / "actor.mp4")
    out = tmp_path / "out"
    out.mkdir()
    (out / "r.mp4").write_bytes(b"an earlier render")
    line = _one_line(capsys, main(["render", str(take / "take.c3d"), "--beside", str(actor),
                                   "-o", str(out / "r.mp4"), "--size", "240x270",
                                   "--quiet"]), 1)
    assert "disk full" in line
    assert (out / "r.mp4").read_bytes() == b"an earlier render"
    assert sorted(p.name for p in out.iterdir()) == ["r.mp4"]


def test_beside_interrupted_leaves_nothing_behind(take, tmp_path, capsys, monkeypatch):
    # A Ctrl-C while ffmpeg writes the pair: no half-written file beside -o, -o unchanged.
    from animegraph.face import render

    real = subprocess.run

    def interrupted(cmd, **kwargs):
        if "hstack" not in " ".join(cmd):
            return real(cmd, **kwargs)
        Path(cmd[-1]).write_bytes(b"half a pair")  # ffmpeg had begun its output
        raise KeyboardInterrupt

    monkeypatch.setattr(render.subprocess, "run", interrupted)
    actor = _actor_video(tmp_path / "actor.mp4")
    out = tmp_path / "out"
    out.mkdir()
    (out / "r.mp4").write_bytes(b"an earlier render")
    assert main(["render", str(take / "take.c3d"), "--beside", str(actor), "-o",
                 str(out / "r.mp4"), "--size", "240x270", "--quiet"]) == 130
    assert (out / "r.mp4").read_bytes() == b"an earlier render"
    assert sorted(p.name for p in out.iterdir()) == ["r.mp4"]


@pytest.mark.parametrize(("seconds", "keep"), [(0.5, 1.0), (1.0, 0.5)],
                         ids=["short", "cut in half"])
def test_shorter_video_beside_ends_the_result_with_a_warning(take, tmp_path, caplog,
                                                             seconds, keep):
    # A video shorter than the motion (or declaring 1 s but cut short) ends the result
    # where its pictures end, instead of freezing its last picture, and says so.
    actor = _actor_video(tmp_path / "actor.mp4", seconds, sound=False, faststart=True,
                         keep=keep)
    out = tmp_path / "both.mp4"
    with caplog.at_level(logging.WARNING, logger="animegraph.face.render"):
        assert main(["render", str(take / "take.c3d"), "--beside", str(actor), "-o", str(out),
                     "--quiet", "--size", "240x270"]) == 0
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1 and "actor.mp4" in warnings[0], warnings
    assert "1.00 s" in warnings[0]  # the motion's length, and the video's:
    shown = float(re.search(r"actor\.mp4 \D*([\d.]+) s", warnings[0]).group(1))
    assert shown < 0.8 and abs(_duration(out) - shown) < 0.1, (shown, _duration(out))


def test_mp4_beside_an_equal_video_has_no_warning(take, tmp_path, caplog):
    actor = _actor_video(tmp_path / "actor.mp4")
    with caplog.at_level(logging.WARNING, logger="animegraph.face.render"):
        assert main(["render", str(take / "take.c3d"), "--beside", str(actor), "-o",
                     str(tmp_path / "both.mp4"), "--quiet", "--size", "240x270"]) == 0
    assert not [r for r in caplog.records if r.levelno == logging.WARNING]


def _write_bad_audio(folder, what):
    import soundfile

    path = folder / f"{what.replace(' ', '_')}.wav"
    if what == "non-finite":
        x = np.zeros(16000, np.float32)
        x[4000:4100] = np.nan
        soundfile.write(path, x, 16000, subtype="FLOAT")
    elif what == "corrupt":
        path.write_bytes(b"RIFF\x24\x00\x00\x00WAVEfmt junk" + bytes(64))
    else:  # a video without a sound track
        path = _actor_video(folder / "silent.mp4", sound=False)
    return path


@pytest.mark.parametrize(("what", "says"), [("non-finite", "non-finite samples"),
                                            ("corrupt", "corrupt"),
                                            ("no sound", "no audio track")])
def test_bad_audio_is_the_readers_one_line_before_rendering(take, tmp_path, capsys, what,
                                                            says):
    # Not --quiet: the progress bar must not even start; the error is the reader's line.
    audio = _write_bad_audio(tmp_path, what)
    out = tmp_path / "out"
    out.mkdir()
    line = _one_line(capsys, main(["render", str(take / "take.c3d"), "--audio", str(audio),
                                   "-o", str(out / "r.mp4"), "--size", "240x270"]), 1)
    assert says in line and audio.name in line and "ffmpeg" not in line, line
    assert list(out.iterdir()) == []


def test_progress_bar_is_closed_before_an_error(take, tmp_path, capsys, monkeypatch):
    # ffmpeg failing mid-render (a full disk, say): the bar ends its line before the error.
    from animegraph.face import render

    fake = tmp_path / "ffmpeg"
    fake.write_text("#!/bin/sh\necho 'No space left on device' >&2\nexit 1\n")
    fake.chmod(0o755)
    monkeypatch.setattr(render, "ffmpeg_exe", lambda: str(fake))
    assert main(["render", str(take / "take.c3d"), "-o", str(tmp_path / "r.mp4"),
                 "--size", "240x270"]) == 1
    err = capsys.readouterr().err
    assert "rendering" in err  # the bar was shown
    last = err.rstrip("\n").split("\n")[-1]
    assert last == "animegraph: error: ffmpeg could not write r.mp4: No space left on device", err
    assert not _no_leftovers(tmp_path)


def test_mp4_with_audio(take, capsys):
    out = take / "face.mp4"
    assert main(["render", str(take / "take.c3d"), "--audio", str(take / "take.wav"),
                 "--explain", str(take / "take.json"), "-o", str(out), "--quiet",
                 "--size", "240x270"]) == 0
    streams = _streams(out)
    assert any("Video: h264" in s and "240x270" in s for s in streams)
    assert any("Audio: aac" in s for s in streams)
    frames = _decode(out, 240, 270)
    assert len(frames) == 30  # one second at 30 fps
    # A face is drawn (skin-coloured pixels in the middle) and the jaw moves it.
    assert frames[0][115:155, 100:140].mean() > 80 and frames[0][:10, :10].mean() < 45
    assert np.abs(frames[7].astype(int) - frames[0].astype(int)).mean() > 1.0
    assert not _no_leftovers(take)


def test_gif_and_png(take):
    assert main(["render", str(take / "take.c3d"), "-o", str(take / "face.gif"),
                 "--quiet"]) == 0
    assert (take / "face.gif").read_bytes()[:6] == b"GIF89a"
    assert main(["render", str(take / "take.c3d"), "-o", str(take / "face.png")]) == 0
    assert (take / "face.png").read_bytes()[:4] == b"\x89PNG"


def test_size_is_the_frame_size_of_every_picture(take, capsys):
    # --size was taken for an MP4 and a PNG of a face and silently ignored for a GIF (always
    # 240x270), for curves and for a glTF.
    from PIL import Image

    for name, size in (("sized.gif", (160, 180)), ("default.gif", (240, 270)),
                       ("sized.png", (160, 180))):
        extra = [] if name.startswith("default") else ["--size", "160x180"]
        assert main(["render", str(take / "take.c3d"), "-o", str(take / name), "--quiet",
                     *extra]) == 0
        assert Image.open(take / name).size == size, name
    curves = Motion(values=np.random.default_rng(0).random((30, 2)), names=("jaw", "smile"),
                    fps=30.0)
    from animegraph.motion.files import write_channel_csv

    write_channel_csv(take / "curves.csv", curves.values, curves.names, curves.fps)
    assert main(["render", str(take / "curves.csv"), "-o", str(take / "curves.gif"),
                 "--size", "320x180", "--quiet"]) == 0
    assert Image.open(take / "curves.gif").size == (320, 180)
    capsys.readouterr()
    assert main(["render", str(take / "take.c3d"), "-o", str(take / "sized.glb"), "--size",
                 "160x180"]) == 2
    assert "--size needs an .mp4, .gif or .png output" in capsys.readouterr().err
    assert not (take / "sized.glb").exists()


def test_an_animation_beyond_its_memory_is_one_line(take, monkeypatch, capsys):
    """The whole animation is held at once: a mesh of 10^6 vertices (a scanned head)
    took 17 GB for 12 s, and the kernel killed the render. The budget is lowered here so
    that the canonical face's second (2.7 MB of vertex positions) is beyond it."""
    monkeypatch.setattr("animegraph.face.animation.MAX_ANIMATION_BYTES", 2_000_000,
                        raising=False)
    out = take / "too_big.glb"
    assert main(["render", str(take / "take.c3d"), "-o", str(out)]) == 1
    err = capsys.readouterr().err.strip()
    assert "120 frames of the 468-vertex mesh" in err and "decimate" in err
    assert "\n" not in err and not out.exists()


def test_glb_round_trip(take):
    import pygltflib
    import trimesh

    out = take / "face.glb"
    assert main(["render", str(take / "take.c3d"), "-o", str(out)]) == 0
    motion = read_motion(take / "take.c3d")
    expected = animate(motion, deformer_for(motion.names)).vertices
    times, vertices, faces = read_glb_frames(out)
    assert vertices.shape == expected.shape == (120, 468, 3)
    assert np.allclose(times, np.arange(120) / FPS, atol=1e-5)
    assert np.abs(vertices - expected).max() < 0.02  # mm, float32 in metres
    assert np.array_equal(faces, canonical_mesh().faces)
    gltf = pygltflib.GLTF2().load(str(out))
    assert {c.target.path for c in gltf.animations[0].channels} == {"weights", "rotation",
                                                                     "translation"}
    scene = trimesh.load(out)
    geometry = next(iter(scene.geometry.values()))
    assert len(geometry.vertices) == 468 and len(geometry.faces) == len(faces)


def test_obj_frames_and_force(take, capsys):
    import trimesh

    out = take / "frames"
    argv = ["render", str(take / "take.c3d"), "-o", str(out), "--fps", "10"]
    assert main(argv) == 0
    files = sorted(out.glob("*.obj"))
    assert len(files) == 10
    mesh = trimesh.load(files[3], process=False)
    assert len(mesh.vertices) == 468
    assert main(argv) == 1
    assert "--force" in capsys.readouterr().err
    assert main([*argv, "--fps", "5", "--force"]) == 0
    assert len(list(out.glob("*.obj"))) == 5
    assert not _no_leftovers(take)


def test_landmark_motion_renders(tmp_path):
    from animegraph.motion.files import write_channel_csv

    verts = canonical_mesh().vertices
    values = np.repeat(verts.reshape(1, -1), 6, axis=0)
    values[:, 14 * 3 + 1] -= np.linspace(0, 8, 6)  # the lower lip drops
    names = [f"lm{i}.{a}" for i in range(468) for a in "xyz"] + ["pose.rx"]
    write_channel_csv(tmp_path / "lm.csv", np.column_stack([values, np.zeros(6)]), names, 30)
    assert main(["render", str(tmp_path / "lm.csv"), "-o", str(tmp_path / "lm.glb")]) == 0
    _, vertices, _ = read_glb_frames(tmp_path / "lm.glb")
    assert abs(vertices[5, 14, 1] - (verts[14, 1] - 8)) < 0.01


def test_curves_render_as_curves(tmp_path, capsys):
    from animegraph.motion.files import write_channel_csv

    t = np.arange(60) / 30
    values = np.column_stack([np.sin(t * 6) ** 2, 0.5 * t, np.zeros_like(t)])
    write_channel_csv(tmp_path / "c.csv", values, ["jawOpen", "smile_l", "brow"], 30)
    assert main(["render", str(tmp_path / "c.csv"), "-o", str(tmp_path / "c.mp4")]) == 0
    assert len(_decode(tmp_path / "c.mp4", 960, 540)) == 60
    capsys.readouterr()
    line = _one_line(capsys, main(["render", str(tmp_path / "c.csv"), "-o",
                                   str(tmp_path / "c.glb")]), 1)
    assert "cannot become a mesh animation" in line
    assert not (tmp_path / "c.glb").exists()


def _one_line(capsys, code, expected):
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == expected, err
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_bad_inputs_are_one_line_and_write_nothing(take, tmp_path, capsys):
    import trimesh

    mesh = canonical_mesh()
    trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).export(tmp_path / "m.obj")
    markers = default_marker_map([m[0] for m in face.MARKERS])
    (tmp_path / "bad_vertex.csv").write_text("label,vertex,region\nlip_corner_r,5000,"
                                            "lower_jaw\n")
    (tmp_path / "other.csv").write_text("label,vertex,region\n" + "".join(
        f"{lab}_x,{v},{r[0]}\n" for lab, v, r in zip(markers.labels, markers.vertices,
                                                      markers.regions, strict=True)))
    (tmp_path / "junk.obj").write_bytes(b"\x00\xff\x00 junk")
    out = tmp_path / "out"
    out.mkdir()
    motion = str(take / "take.c3d")
    cases = [
        (["--mesh", str(tmp_path / "m.obj"), "--marker-map", str(tmp_path / "bad_vertex.csv")],
         1, "names vertex 5000"),
        (["--mesh", str(tmp_path / "junk.obj"), "--marker-map", str(tmp_path / "other.csv")],
         1, "cannot read mesh"),
        (["--mesh", str(tmp_path / "m.obj"), "--marker-map", str(tmp_path / "other.csv")],
         1, "do not match the mesh's marker map"),
        (["--mesh", str(tmp_path / "m.obj")], 2, "--marker-map"),
        (["--size", "big"], 2, "--size"),
        (["--audio", str(tmp_path / "nope.wav")], 2, "does not exist"),
    ]
    for extra, code, needle in cases:
        line = _one_line(capsys, main(["render", motion, "-o", str(out / "x.mp4"), *extra]),
                         code)
        assert needle in line, line
    line = _one_line(capsys, main(["render", str(tmp_path / "none.c3d"), "-o",
                                   str(out / "x.mp4")]), 1)
    assert "does not exist" in line
    line = _one_line(capsys, main(["render", motion, "-o", str(out / "x.avi")]), 1)
    assert ".mp4" in line
    # a missing folder is said before the frames are drawn (it came after a progress bar)
    line = _one_line(capsys, main(["render", motion, "-o", str(out / "no" / "x.mp4")]), 1)
    assert "folder" in line and "does not exist" in line, line
    assert list(out.iterdir()) == []


def test_custom_mesh_renders(take, tmp_path):
    import trimesh

    mesh = canonical_mesh()
    keep = np.setdiff1d(np.arange(len(mesh.faces)), mesh.mouth)
    trimesh.Trimesh(mesh.vertices, mesh.faces[keep], process=False).export(tmp_path / "m.ply")
    markers = default_marker_map([m[0] for m in face.MARKERS])
    (tmp_path / "map.csv").write_text("label,vertex,region\n" + "".join(
        f"{lab},{v},{'|'.join(r)}\n" for lab, v, r in zip(markers.labels, markers.vertices,
                                                           markers.regions, strict=True)))
    assert main(["render", str(take / "take.c3d"), "--mesh", str(tmp_path / "m.ply"),
                 "--marker-map", str(tmp_path / "map.csv"), "-o", str(tmp_path / "m.glb")]) == 0
    _, vertices, faces = read_glb_frames(tmp_path / "m.glb")
    assert vertices.shape == (120, 468, 3) and len(faces) == len(keep)


def test_plot_against_truth(take, tmp_path, capsys):
    motion = read_motion(take / "take.c3d")
    noisy = Motion(values=motion.values + 0.3, names=motion.names, fps=motion.fps)
    from animegraph.motion.files import write_channel_csv

    write_channel_csv(tmp_path / "syn.csv", noisy.values, noisy.names, noisy.fps)
    out = tmp_path / "p.png"
    assert main(["plot", str(tmp_path / "syn.csv"), "--truth", str(take / "take.c3d"),
                 "--explain", str(take / "take.json"), "--audio", str(take / "take.wav"),
                 "-o", str(out)]) == 0
    assert out.read_bytes()[:4] == b"\x89PNG"
    # Without speech or phones there is no top panel: no empty box over the measures.
    bare = tmp_path / "bare.png"
    assert main(["plot", str(tmp_path / "syn.csv"), "-o", str(bare)]) == 0
    height = int.from_bytes(out.read_bytes()[20:24], "big")  # PNG's IHDR height
    assert int.from_bytes(bare.read_bytes()[20:24], "big") < height - 100
    capsys.readouterr()
    for bad in ("{\"nope\": 1}", "{\"phones\": " + "[" * 100_000 + "]" * 100_000 + "}"):
        (tmp_path / "bad.json").write_text(bad)  # not an explanation; nested too deeply
        line = _one_line(capsys, main(["plot", str(tmp_path / "syn.csv"), "--explain",
                                       str(tmp_path / "bad.json"), "-o",
                                       str(tmp_path / "q.png")]), 1)
        assert "--explain-json" in line
    line = _one_line(capsys, main(["plot", str(tmp_path / "syn.csv"), "-o",
                                   str(tmp_path / "q.jpg")]), 2)
    assert ".png" in line
    assert not (tmp_path / "q.png").exists()


def _sparse(path, head: str, size: int):
    """A file of ``size`` bytes starting ``head`` (the rest a hole: no disk, no time)."""
    with open(path, "w") as handle:
        handle.write(head)
        handle.truncate(size)
    return path


def test_motion_files_and_explanations_beyond_their_bound_are_one_line(take, tmp_path,
                                                                        capsys):
    """Read whole and parsed at ~5-50 times their size: a large crafted file was a memory
    bomb for plot, render, synth and map-emotion."""
    from animegraph.motion.files import write_channel_csv
    from ingest.formats.livelink import ARKIT_CHANNELS, livelink_column
    from ingest.formats.text import MAX_MOTION_TABLE_BYTES, MAX_SIDE_FILE_BYTES

    big = MAX_MOTION_TABLE_BYTES + 1
    livelink = "Timecode,BlendshapeCount," + ",".join(map(livelink_column, ARKIT_CHANNELS))
    for name, head in (("channels.csv", "frame,time,a\n0,0,1\n"),
                       ("take.csv", livelink + "\n")):
        motion = _sparse(tmp_path / name, head, big)
        line = _one_line(capsys, main(["plot", str(motion), "-o", str(tmp_path / "p.png")]), 1)
        assert f"is larger than {MAX_MOTION_TABLE_BYTES:,} bytes" in line
    write_channel_csv(tmp_path / "syn.csv", np.zeros((3, 1)), ["a"], 30.0)
    explain = _sparse(tmp_path / "e.json", '{"phones": [', MAX_SIDE_FILE_BYTES + 1)
    line = _one_line(capsys, main(["plot", str(tmp_path / "syn.csv"), "--explain",
                                   str(explain), "-o", str(tmp_path / "p.png")]), 1)
    assert f"is larger than {MAX_SIDE_FILE_BYTES:,} bytes" in line
    assert not (tmp_path / "p.png").exists()


def test_plot_names_the_motion_by_its_file(take, tmp_path, monkeypatch):
    # A recorded snippet (query --export) was labelled "synthesized"
    import matplotlib.axes

    shown = []
    legend = matplotlib.axes.Axes.legend

    def seen(ax, *args, **kwargs):
        shown.extend(t.get_text() for t in legend(ax, *args, **kwargs).get_texts())

    monkeypatch.setattr(matplotlib.axes.Axes, "legend", seen)
    assert main(["plot", str(take / "take.c3d"), "-o", str(tmp_path / "p.png")]) == 0
    assert shown and set(shown) == {"take.c3d"}


def test_plot_refuses_a_truth_of_other_channels(take, tmp_path, capsys):
    # A truth with none of the motion's channels used to draw no truth at all (exit 0).
    from animegraph.motion.files import write_channel_csv

    motion = read_motion(take / "take.c3d")
    curves = ("jawOpen", "mouthSmileLeft", "eyeBlinkLeft")
    write_channel_csv(tmp_path / "curves.csv", np.random.default_rng(0).random((60, 3)),
                      curves, 60.0)
    out = tmp_path / "p.png"
    for a, b in ((take / "take.c3d", tmp_path / "curves.csv"),
                 (tmp_path / "curves.csv", take / "take.c3d")):
        line = _one_line(capsys, main(["plot", str(a), "--truth", str(b), "-o", str(out)]), 1)
        assert "the truth's channels are not the motion's: none of the motion's" in line
        assert "jawOpen" in line and "give a truth with the motion's channels" in line, line
        assert not out.exists()
    # Some in common: the truth is drawn where it can be, and the user is told.
    keep = [i for i, n in enumerate(motion.names) if not n.startswith("ulip_in_c.")]
    write_channel_csv(tmp_path / "part.csv", motion.values[:, keep],
                      [motion.names[i] for i in keep], motion.fps)
    assert main(["plot", str(take / "take.c3d"), "--truth", str(tmp_path / "part.csv"),
                 "-o", str(out)]) == 0
    err = capsys.readouterr().err
    assert (f"the truth has {len(keep)} of the motion's {len(motion.names)} channels (not "
            "ulip_in_c.x, ...): ground truth drawn in 2 of 3 panels") in err, err
    assert out.read_bytes()[:4] == b"\x89PNG"
    # Too few in common for any measure: refused.
    few = [i for i, n in enumerate(motion.names) if n.startswith("lip_corner_r.")]
    write_channel_csv(tmp_path / "few.csv", motion.values[:, few],
                      [motion.names[i] for i in few], motion.fps)
    line = _one_line(capsys, main(["plot", str(take / "take.c3d"), "--truth",
                                   str(tmp_path / "few.csv"), "-o", str(tmp_path / "f.png")]),
                     1)
    assert "only 3 of the motion's" in line and "too few for any plotted measure" in line
    assert not (tmp_path / "f.png").exists()


def test_rest_frame_is_the_mesh_as_modelled(take, tmp_path):
    # With frame 30 as the rest frame, that frame shows the mesh exactly as it is.
    assert main(["render", str(take / "take.c3d"), "--rest-frame", "30", "-o",
                 str(tmp_path / "r.glb")]) == 0
    _, vertices, _ = read_glb_frames(tmp_path / "r.glb")
    assert np.abs(vertices[30] - canonical_mesh().vertices).max() < 0.01
    assert np.abs(vertices[0] - canonical_mesh().vertices).max() > 1.0
    assert main(["render", str(take / "take.c3d"), "--rest-frame", "500", "-o",
                 str(tmp_path / "s.glb")]) == 2


@pytest.mark.shared
def test_real_landmark_track_renders(tmp_path):
    """A real tracked face (EDTalk sample, ../shared/data) on the canonical mesh, as MP4."""
    from conftest import require_shared

    from animegraph.motion.files import write_channel_csv
    from ingest.readers.landmarks import normalise_landmarks

    folder = require_shared("talkingface", "edtalk_mouth_source")
    meta = json.loads((folder / "meta.json").read_text())
    raw = np.load(folder / "landmarks.npy")[:50]
    points = normalise_landmarks(raw, meta["width"], meta["height"]).points
    names = [f"lm{i}.{a}" for i in range(468) for a in "xyz"]
    write_channel_csv(tmp_path / "lm.csv", points.reshape(len(points), -1), names, meta["fps"])
    assert main(["render", str(tmp_path / "lm.csv"), "-o", str(tmp_path / "lm.mp4"),
                 "--size", "240x270", "--quiet"]) == 0
    assert len(_decode(tmp_path / "lm.mp4", 240, 270)) == 60  # 2 s at 30 fps
    assert main(["render", str(tmp_path / "lm.csv"), "-o", str(tmp_path / "lm.glb")]) == 0
    _, vertices, _ = read_glb_frames(tmp_path / "lm.glb")
    # Every vertex is a landmark: the mesh follows the track (mouth opening included).
    assert np.abs(vertices - points).max() < 0.02


def test_mesh_without_marker_map_is_said_before_the_motion_is_read(tmp_path, capsys,
                                                                    monkeypatch):
    import animegraph.motion.files as files

    def unread(*args, **kwargs):
        raise AssertionError("the motion was read before the command line was checked")

    monkeypatch.setattr(files, "read_motion", unread)
    mesh = tmp_path / "face.obj"
    mesh.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    line = _one_line(capsys, main(["render", str(tmp_path / "motion.c3d"), "--mesh", str(mesh),
                                   "-o", str(tmp_path / "face.mp4")]), 2)
    assert "--mesh needs --marker-map" in line
    assert not (tmp_path / "face.mp4").exists()


def _ply(path, vertices, faces) -> None:
    """An ASCII PLY written as is (trimesh's export would check the faces)."""
    head = (f"ply\nformat ascii 1.0\nelement vertex {len(vertices)}\nproperty float x\n"
            f"property float y\nproperty float z\nelement face {len(faces)}\n"
            "property list uchar int vertex_indices\nend_header\n")
    path.write_text(head + "".join(f"{x} {y} {z}\n" for x, y, z in vertices)
                    + "".join(f"3 {a} {b} {c}\n" for a, b, c in faces))


@pytest.mark.parametrize("vertex", [10**8, -5])
def test_a_mesh_whose_faces_name_missing_vertices_is_one_line(take, tmp_path, capsys, vertex):
    # PLY faces are read as written: a vertex number past the end (or negative, which
    # numpy would take from the end) is refused by name, not a traceback or a wrong face
    mesh = canonical_mesh()
    faces = mesh.faces.copy()
    faces[7, 2] = vertex
    _ply(tmp_path / "m.ply", mesh.vertices, faces)
    markers = default_marker_map([m[0] for m in face.MARKERS])
    (tmp_path / "map.csv").write_text("label,vertex,region\n" + "".join(
        f"{lab},{v},{'|'.join(r)}\n" for lab, v, r in zip(markers.labels, markers.vertices,
                                                           markers.regions, strict=True)))
    line = _one_line(capsys, main(["render", str(take / "take.c3d"), "--mesh",
                                   str(tmp_path / "m.ply"), "--marker-map",
                                   str(tmp_path / "map.csv"), "-o", str(tmp_path / "m.glb")]),
                     1)
    assert f"m.ply: face 7 names vertex {vertex}" in line, line
    assert not (tmp_path / "m.glb").exists()


@pytest.mark.parametrize("option", ["--beside", "--audio"])
def test_the_output_is_not_an_input(take, tmp_path, capsys, option):
    # -o onto the actor's video (or the speech) used to replace it with the render
    actor = _actor_video(tmp_path / "actor.mp4")
    before = actor.read_bytes()
    line = _one_line(capsys, main(["render", str(take / "take.c3d"), option, str(actor), "-o",
                                   str(tmp_path / "." / "actor.mp4"), "--quiet"]), 2)
    assert f"is also {option}: the render would replace it" in line, line
    assert actor.read_bytes() == before


def test_plot_title_counts_jumps_of_a_synthesis_only(tmp_path):
    # A recorded snippet plotted with its phone labels was titled "11 phones, 0 jump
    # matches (dashed)": a recording has no jump matches to count.
    from animegraph.apps.plots import phones_subtitle
    from animegraph.motion.files import read_phone_track

    (tmp_path / "hit.phones.csv").write_text("start,end,phone\n0,0.1,SIL\n0.1,0.3,AA\n")
    labels = read_phone_track(labels=tmp_path / "hit.phones.csv")
    assert phones_subtitle(labels) == "2 phones"
    explained = [{"phone": "AA", "start": 0.0, "end": 0.1, "clip_id": "a", "jump": False},
                 {"phone": "B", "start": 0.1, "end": 0.2, "clip_id": "b", "jump": True}]
    assert phones_subtitle(explained) == "2 phones, 1 jump match (dashed)"  # not "matches"
    assert phones_subtitle([]) == ""
