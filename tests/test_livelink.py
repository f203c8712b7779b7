"""iPhone face capture in and out: Live Link Face CSV (ARKit-52) as a clip and as an output."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
from conftest import require_shared

from db.errors import DataError, ParameterError
from ingest.formats.livelink import (
    ARKIT_BLENDSHAPES,
    ARKIT_CHANNELS,
    format_timecode,
    livelink_column,
    parse_timecode,
    read_livelink,
    sniff_livelink,
    timecode_frames,
    write_livelink,
)
from ingest.formats.wav import write_wav
from ingest.readers import discover, load


def _take_values(n: int, seed: int = 0) -> np.ndarray:
    """(n, 61) plausible ARKit curves: jaw and lips moving, rotations small."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 60.0
    values = np.clip(rng.uniform(0, 0.1, (n, len(ARKIT_CHANNELS))), 0, 1)
    values[:, ARKIT_CHANNELS.index("jawOpen")] = 0.3 + 0.3 * np.sin(2 * np.pi * 3 * t)
    values[:, len(ARKIT_BLENDSHAPES):] = rng.normal(0, 0.05, (n, 9))
    return np.round(values, 10)


def _write_take(folder: Path, stem: str = "take", n: int = 180, *, rows=None,
                audio_s: float | None = None, header=None) -> Path:
    """A Live Link CSV (60 fps timecode with Live Link's sub-frame drift) and a WAV."""
    values = _take_values(n)
    path = folder / f"{stem}.csv"
    names = header or ["Timecode", "BlendshapeCount"] + [livelink_column(c) for c in
                                                         ARKIT_CHANNELS]
    with open(path, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(names)
        for k in rows if rows is not None else range(n):
            frame = 36000 * 60 + k * 1.0017
            writer.writerow([format_timecode(frame, 60.0), len(names) - 2]
                            + [f"{v:.10f}" for v in values[k][: len(names) - 2]])
    seconds = n / 60.0 if audio_s is None else audio_s
    rng = np.random.default_rng(1)
    sr = 16000
    t = np.arange(int(seconds * sr)) / sr
    audio = (0.3 * np.sin(2 * np.pi * 150 * t) * (0.5 + 0.5 * np.sin(2 * np.pi * 3 * t))
             + 0.01 * rng.normal(size=len(t))).astype(np.float32)
    write_wav(folder / f"{stem}.wav", audio, sr)
    return path


def _set_cell(path: Path, line: int, column: int, text: str) -> None:
    """Overwrite one cell of a CSV (``line`` 0 = the header)."""
    lines = path.read_text().splitlines()
    cells = lines[line].split(",")
    cells[column] = text
    lines[line] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")


def _load_one(folder: Path):
    sources = discover([folder])
    assert len(sources) == 1
    assert sources[0].layout == "livelink" and sources[0].kind == "curves"
    return load(sources[0])


# --- the format -----------------------------------------------------------------------


def test_timecode_parse_and_format():
    assert parse_timecode("10:13:39:01.936") == (10, 13, 39, 1.936)
    assert format_timecode(((10 * 60 + 13) * 60 + 39) * 60 + 1.936, 60) == "10:13:39:01.936"
    assert format_timecode(59.9999, 60) == "00:00:01:00.000"  # rounding carries over
    for bad in ("10:13:39", "1:2:3:4:5", "25:00:00:00", "aa:bb:cc:dd"):
        with pytest.raises(ValueError):
            parse_timecode(bad)


def test_read_fixture(tmp_path):
    path = _write_take(tmp_path)
    assert sniff_livelink(path)
    take = read_livelink(path)
    assert take.names == ARKIT_CHANNELS
    assert take.values.shape == (180, 61)
    assert take.timecode_rate == 60.0
    np.testing.assert_allclose(np.diff(take.frames), 1.0017, atol=1e-3)
    np.testing.assert_array_equal(take.values, _take_values(180))


def test_write_round_trip_is_lossless(tmp_path):
    values = _take_values(100)
    out = write_livelink(tmp_path / "a.livelink.csv", values, ARKIT_CHANNELS, 60.0,
                         start="01:02:03:04")
    take = read_livelink(out)
    np.testing.assert_array_equal(take.values, values)
    assert take.names == ARKIT_CHANNELS
    assert format_timecode(take.frames[0], 60) == "01:02:03:04.000"
    np.testing.assert_allclose(np.diff(take.frames), 1.0)  # continuous, no gap
    # Written again from what was read: the same bytes.
    again = write_livelink(tmp_path / "b.livelink.csv", take.values, take.names, 60.0,
                           start="01:02:03:04")
    assert again.read_bytes() == out.read_bytes()


def test_write_clamps_blendshapes_not_rotations(tmp_path):
    values = _take_values(10)
    values[:, 0] = 1.7
    values[:, 1] = -0.2
    values[:, -1] = -0.5  # a rotation
    take = read_livelink(write_livelink(tmp_path / "c.csv", values, ARKIT_CHANNELS, 30.0))
    assert (take.values[:, 0] == 1.0).all() and (take.values[:, 1] == 0.0).all()
    assert (take.values[:, -1] == -0.5).all()
    # 30 fps written on a 30 fps timecode: whole frames.
    np.testing.assert_allclose(np.diff(take.frames), 1.0)


def test_timecode_rate_is_found_from_the_rollover(tmp_path):
    from ingest.readers.livelink import frame_steps

    for fps in (24.0, 25.0, 30.0, 60.0):
        path = write_livelink(tmp_path / "r.csv", _take_values(int(2 * fps)), ARKIT_CHANNELS,
                              fps, start="00:00:00:10")
        take = read_livelink(path)
        assert take.timecode_rate == fps
        assert frame_steps(take.frames, take.timecode_rate, path)[0] == fps


def test_writer_rejects_non_arkit_motion(tmp_path):
    with pytest.raises(ParameterError, match="not ARKit motion"):
        write_livelink(tmp_path / "d.csv", np.zeros((3, 2)), ("jaw", "lips"), 60.0)
    with pytest.raises(ParameterError, match="start"):
        write_livelink(tmp_path / "d.csv", _take_values(3), ARKIT_CHANNELS, 60.0,
                       start="noon")
    assert not (tmp_path / "d.csv").exists()


# --- the clip reader ------------------------------------------------------------------


def test_clip_from_fixture(tmp_path):
    _write_take(tmp_path)
    clip = _load_one(tmp_path)
    assert clip.schema.names == ARKIT_CHANNELS
    groups = dict(zip(clip.schema.names, clip.schema.groups, strict=True))
    assert groups["jawOpen"] == groups["mouthPucker"] == groups["tongueOut"] == "lips"
    assert groups["browInnerUp"] == groups["cheekSquintLeft"] == groups["eyeBlinkLeft"] \
        == "upper_face"
    assert groups["headYaw"] == groups["leftEyePitch"] == "head"
    # The channels table said "unit" of the head and eye angles, which are radians.
    units = dict(zip(clip.schema.names, clip.schema.channel_units, strict=True))
    assert units["headYaw"] == units["rightEyeRoll"] == "rad" and units["jawOpen"] == "unit"
    assert clip.fps == pytest.approx(60 / 1.0017, abs=0.01)
    assert clip.extra["dropped_frames"] == 0
    assert clip.extra["timecode_start"] == "10:00:00:00.000"
    assert "lip_audio_lag_s" in clip.extra and "lag_confidence" in clip.extra


def test_dropped_frames_are_reported_and_filled(tmp_path):
    rows = [k for k in range(180) if k not in (50, 51, 52, 120)]
    _write_take(tmp_path, rows=rows)
    clip = _load_one(tmp_path)
    assert clip.n_frames == 180
    assert clip.extra["dropped_frames"] == 4 and clip.extra["gaps"] == 2
    assert np.isnan(clip.motion[[50, 51, 52, 120]]).all()
    assert not np.isnan(clip.motion[[49, 53, 119, 121]]).any()
    from ingest.motion import fill_gaps

    filled, missing = fill_gaps(clip.motion)
    assert missing[50:53].all() and np.isfinite(filled).all()


@pytest.mark.parametrize("case, needle", [
    ("other_app", "not a Live Link Face CSV"),
    ("missing_column", "missing ARKit blendshape column"),
    ("duplicate", "timecode repeats"),
    ("backwards", "timecode goes back"),
    ("nan", "NaN"),
    ("percent", "an ARKit weight lies in"),
    # rotations in degrees that were within the old bound of a full turn (2 pi)
    ("eye_degrees", r"LeftEyeYaw is 5; its angles are radians, within ±1.571"),
    ("head_degrees", r"HeadYaw is 4; its angles are radians, within ±3.142"),
    ("pitch_degrees", r"HeadPitch is -2; its angles are radians, within ±1.571"),
    ("huge_angle", r"HeadRoll is 1e\+09; its angles are radians"),
    ("short_audio", "but audio"),
    ("two_takes", "more than one take"),
    ("no_audio", "no take.wav"),
])
def test_bad_takes_fail_with_one_reason(tmp_path, case, needle):
    names = ["Timecode", "BlendshapeCount"] + [livelink_column(c) for c in ARKIT_CHANNELS]
    if case == "other_app":
        path = _write_take(tmp_path, header=["Timecode", "Frame"] + names[2:])
        # Another app's CSV is not taken for a Live Link clip at all; loaded directly it
        # is refused with its reason.
        assert not sniff_livelink(path)
        with pytest.raises(DataError, match=needle):
            read_livelink(path)
        return
    if case == "missing_column":
        _write_take(tmp_path, header=[n for n in names if n != "MouthClose"])
    elif case == "duplicate":
        _write_take(tmp_path, rows=[*range(0, 60), 59, *range(60, 180)])
    elif case == "backwards":
        _write_take(tmp_path, rows=[*range(0, 60), 58, *range(61, 180)])
    elif case == "nan":
        _set_cell(_write_take(tmp_path), 5, 20, "nan")
    elif case == "percent":
        _set_cell(_write_take(tmp_path), 7, 2, "35.0")
    elif case.endswith(("_degrees", "_angle")):
        column, value = {"eye": ("leftEyeYaw", "5.0"), "head": ("headYaw", "4.0"),
                         "pitch": ("headPitch", "-2.0"), "huge": ("headRoll", "1e9")}[
                             case.split("_")[0]]
        _set_cell(_write_take(tmp_path), 9, 2 + ARKIT_CHANNELS.index(column), value)
    elif case == "short_audio":
        _write_take(tmp_path, n=600, audio_s=4.0)
    elif case == "two_takes":
        _write_take(tmp_path, rows=[*range(0, 60), *range(120, 180)])
    elif case == "no_audio":
        _write_take(tmp_path)
        (tmp_path / "take.wav").unlink()
    with pytest.raises(DataError, match=needle) as info:
        _load_one(tmp_path)
    assert "\n" not in str(info.value)


def test_speech_from_the_takes_video(tmp_path):
    """Live Link Face keeps the speech in the take's .mov: read through ffmpeg."""
    import subprocess

    import imageio_ffmpeg

    from ingest.formats.media import read_audio
    from ingest.formats.wav import read_wav

    _write_take(tmp_path)
    wav = tmp_path / "take.wav"
    subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-nostdin", "-loglevel", "error",
                    "-f", "lavfi", "-i", "color=black:s=64x64:r=30", "-i", str(wav),
                    "-shortest", "-c:v", "libx264", "-c:a", "aac", "-b:a", "96k",
                    str(tmp_path / "take.mov")], check=True)
    original, sr = read_wav(wav)
    wav.unlink()
    clip = _load_one(tmp_path)
    assert clip.sample_rate == sr
    assert abs(clip.duration - len(original) / sr) < 0.1
    n = min(len(original), len(clip.audio))
    # The same speech, through AAC: correlated sample by sample once aligned.
    lag = int(np.argmax(np.correlate(clip.audio[:4000], original[:2000], "valid")))
    assert np.corrcoef(clip.audio[lag:n], original[: n - lag])[0, 1] > 0.9
    (tmp_path / "empty.mov").write_bytes(b"not a video")
    with pytest.raises(DataError, match="empty.mov"):
        read_audio(tmp_path / "empty.mov")


def test_marker_csv_is_not_taken_for_livelink(tmp_path):
    (tmp_path / "m.csv").write_text("frame,time,a.x,a.y,a.z\n0,0,1,2,3\n")
    assert not sniff_livelink(tmp_path / "m.csv")


# --- the face -------------------------------------------------------------------------


def test_arkit_shapes_mean_what_arkit_says():
    from animegraph.face.arkit import arkit_shapes
    from animegraph.face.mesh import canonical_mesh
    from ingest.facemesh import EYE_L, EYE_R, LIP_CORNERS, LOWER_LIP_MID, UPPER_LIP_MID

    shapes = arkit_shapes()
    rest = canonical_mesh().vertices
    assert shapes.shape == (52, 468, 3)

    def d(name):
        return shapes[ARKIT_BLENDSHAPES.index(name)]

    assert d("jawOpen")[LOWER_LIP_MID, 1] < -15 and abs(d("jawOpen")[UPPER_LIP_MID, 1]) < 1
    # Lips forward for pucker and funnel; the mouth narrower for pucker.
    assert d("mouthPucker")[UPPER_LIP_MID, 2] > 3
    right, left = LIP_CORNERS
    assert d("mouthPucker")[left, 0] < 0 < d("mouthPucker")[right, 0]
    # A left smile lifts the subject's left corner (+x) and leaves the right one.
    assert d("mouthSmileLeft")[left, 1] > 3 and abs(d("mouthSmileLeft")[right, 1]) < 0.1
    # A left blink closes the left eye only; blinks close the lid gap.
    gap = rest[EYE_L["upper"], 1] - rest[EYE_L["lower"], 1]
    closed = gap + d("eyeBlinkLeft")[EYE_L["upper"], 1] - d("eyeBlinkLeft")[EYE_L["lower"], 1]
    assert closed < 0.3 * gap
    assert np.abs(d("eyeBlinkLeft")[EYE_R["upper"]]).max() < 0.05
    assert d("browInnerUp")[:, 1].max() > 3
    assert not d("tongueOut").any()  # no tongue in the mesh: said, not faked


def test_render_and_gltf_of_arkit_curves(tmp_path):
    import pygltflib

    from animegraph.face.arkit import arkit_animation
    from animegraph.face.gltf import read_glb_frames
    from animegraph.face.render import render_motion
    from animegraph.motion.files import read_motion

    path = _write_take(tmp_path, n=60)
    motion = read_motion(path)
    assert motion.names == ARKIT_CHANNELS
    png = render_motion(motion, tmp_path / "take.png")
    assert png.stat().st_size > 1000
    glb = render_motion(motion, tmp_path / "take.glb")
    gltf = pygltflib.GLTF2().load(str(glb))
    assert gltf.meshes[0].extras["targetNames"] == list(ARKIT_BLENDSHAPES)
    assert len(gltf.meshes[0].primitives[0].targets) == 52
    times, vertices, _ = read_glb_frames(glb)
    animation = arkit_animation(motion)
    np.testing.assert_allclose(vertices, animation.vertices, atol=0.01)  # mm, float32


# --- the real capture (../shared) -----------------------------------------------------


@pytest.fixture(scope="module")
def capture() -> Path:
    return require_shared("livelink", "neurosync_testset.csv")


def test_real_capture_reads(capture):
    clip = load(discover([capture])[0])
    assert clip.n_frames == 1218 and clip.schema.n_channels == 61
    assert clip.fps == pytest.approx(59.9, abs=0.05)
    assert clip.extra["dropped_frames"] == 0
    assert clip.extra["timecode_start"] == "10:13:39:01.936"
    # The README: in sync with the audio from row 0.
    assert abs(clip.extra["lip_audio_lag_s"]) < 0.08
    assert clip.extra["lag_confidence"] > 0.2
    assert np.nanmax(clip.motion[:, :52]) <= 1.0


def test_real_capture_round_trip(capture, tmp_path):
    from ingest.readers.livelink import frame_steps

    take = read_livelink(capture)
    fps, _ = frame_steps(take.frames, take.timecode_rate, capture)
    out = write_livelink(tmp_path / "rt.livelink.csv", take.values, take.names, fps,
                         start=format_timecode(take.frames[0], 60))
    again = read_livelink(out)
    np.testing.assert_array_equal(again.values, take.values)
    # The value cells are the capture's, character for character.
    original = [line.split(",", 2)[2] for line in capture.read_text().splitlines()[1:]]
    written = [line.split(",", 2)[2] for line in out.read_text().splitlines()[1:]]
    assert written == original
    # The timecode runs at the capture's rate: within a millisecond-frame of the original.
    np.testing.assert_allclose(again.frames, take.frames, atol=0.01)


def _first_seconds(capture: Path, folder: Path, seconds: float) -> Path:
    """The capture's first ``seconds`` as a take of its own (CSV rows and WAV cut)."""
    from ingest.formats.wav import read_wav

    folder.mkdir(parents=True)
    lines = capture.read_text().splitlines()
    n = int(seconds * 59.9)
    (folder / "part.csv").write_text("\n".join(lines[: n + 1]) + "\n")
    audio, sr = read_wav(capture.with_suffix(".wav"))
    write_wav(folder / "part.wav", audio[: int(n / 59.9 * sr)], sr)
    return folder


def test_ingest_and_synthesize_from_a_few_seconds(capture, tmp_path, capsys):
    from animegraph.apps.cli import main
    from ingest.formats.wav import read_wav
    from ingest.pipeline import ingest

    corpus = _first_seconds(capture, tmp_path / "corpus", 8.0)
    # A bad take beside it is rejected with its reason; the good one goes in.
    _write_take(corpus, stem="broken", rows=[*range(0, 60), 59, *range(60, 180)])
    report = ingest([corpus], tmp_path / "db")
    status = {c.clip_id: (c.status, c.reason) for c in report.clips}
    assert status["part"][0] == "added"
    assert status["broken"][0] == "rejected" and "timecode repeats" in status["broken"][1]

    # New speech: the capture's last 6 s (not in the database).
    audio, sr = read_wav(capture.with_suffix(".wav"))
    write_wav(tmp_path / "line.wav", audio[-6 * sr:], sr)
    out = tmp_path / "line.livelink.csv"
    assert main(["synth", str(tmp_path / "line.wav"), "--db", str(tmp_path / "db"), "-o",
                 str(out), "--timecode", "01:00:00:00"]) == 0
    take = read_livelink(out)
    assert take.names == ARKIT_CHANNELS
    assert format_timecode(take.frames[0], 60) == "01:00:00:00.000"
    capsys.readouterr()
    # C3D holds points, not blendshapes: said in one line before anything is synthesized.
    assert main(["synth", str(tmp_path / "line.wav"), "--db", str(tmp_path / "db"), "-o",
                 str(tmp_path / "line.c3d")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "C3D holds 3D points" in err[0], err
    assert not (tmp_path / "line.c3d").exists()
    assert len(take.values) / (60 / np.median(np.diff(take.frames))) == pytest.approx(6.0,
                                                                                       abs=0.1)
    assert take.values[:, :52].min() >= 0 and take.values[:, :52].max() <= 1
    assert take.values[:, ARKIT_CHANNELS.index("jawOpen")].std() > 0.01  # it talks

    # query --export writes Live Link CSV for an ARKit database's hits.
    capsys.readouterr()
    assert main(["query", "--db", str(tmp_path / "db"), "--limit", "2", "--export",
                 str(tmp_path / "hits")]) == 0
    exported = sorted((tmp_path / "hits").glob("*.livelink.csv"))
    assert len(exported) == 2 and read_livelink(exported[0]).names == ARKIT_CHANNELS
    # A hit carries the take's timecode at its start (it counted from 00:00:00:00).
    with open(tmp_path / "hits" / "index.csv") as handle:
        first = next(csv.DictReader(handle))
    expected = timecode_frames("10:13:39:01.936", 60) + float(first["snippet_start"]) * 60
    assert read_livelink(tmp_path / "hits" / first["motion"]).frames[0] \
        == pytest.approx(expected, abs=0.01)

    # render draws the face of a synthesized take.
    assert main(["render", str(out), "-o", str(tmp_path / "line.png")]) == 0

    # batch writes Live Link CSV for an ARKit database too.
    script = tmp_path / "lines.csv"
    script.write_text('id,text\nhello,"Hello there, how are you?"\n')
    assert main(["batch", str(script), "--db", str(tmp_path / "db"), "--out",
                 str(tmp_path / "batch"), "--workers", "1", "--quiet"]) == 0
    assert read_livelink(tmp_path / "batch" / "hello" / "motion.livelink.csv").names \
        == ARKIT_CHANNELS


def test_labels_beside_a_livelink_take_are_found(tmp_path):
    # 'query --export' writes hit.livelink.csv with hit.phones.csv; render and plot looked
    # for hit.livelink.phones.csv and drew no phones.
    from animegraph.apps.commands.common import sidecar_labels

    (tmp_path / "hit.phones.csv").write_text("start,end,phone\n0.0,0.1,AA\n")
    assert sidecar_labels(tmp_path / "hit.livelink.csv") == tmp_path / "hit.phones.csv"
    assert sidecar_labels(tmp_path / "hit.csv") == tmp_path / "hit.phones.csv"
    assert sidecar_labels(tmp_path / "other.livelink.csv") is None


def test_output_formats_are_checked_before_the_work():
    from animegraph.motion.files import check_output

    points = ["a.x", "a.y", "a.z"]
    for name, kind in (("m.c3d", "markers"), ("m.c3d", "landmarks"), ("m.csv", "curves"),
                       ("m.NPZ", "curves")):
        check_output(Path(name), points, kind)
    check_output(Path("m.livelink.csv"), ARKIT_CHANNELS, "curves")
    for name, names, kind, needle in (
            ("m.c3d", ARKIT_CHANNELS, "curves", "C3D holds 3D points"),
            ("m.livelink.csv", points, "markers", "needs a database of ARKit"),
            ("m.txt", points, "markers", "must end in .c3d, .csv or .npz")):
        with pytest.raises(ParameterError, match=needle):
            check_output(Path(name), names, kind)
    with pytest.raises(ParameterError, match="timecode goes only"):
        check_output(Path("m.csv"), points, "markers", timecode="01:00:00:00")


def test_synth_livelink_needs_an_arkit_database(capsys, tiny_db, tmp_path):
    from animegraph.apps.cli import main

    write_wav(tmp_path / "a.wav", np.zeros(1600, dtype=np.float32), 16000)
    code = main(["synth", str(tmp_path / "a.wav"), "--db", str(tiny_db[0]), "-o",
                 str(tmp_path / "a.livelink.csv")])
    err = capsys.readouterr().err
    assert code != 0 and "needs a database of ARKit blendshapes" in err
    assert len(err.strip().splitlines()) == 1
    assert not (tmp_path / "a.livelink.csv").exists()


def test_a_baseline_reads_the_kind_from_the_channels_not_the_manifest(capsys, tiny_db,
                                                                     tmp_path):
    # synth --method mu-mlp read the kind from the manifest's summary: a database whose
    # manifest lacks it (shared, older or edited) was a KeyError traceback.
    import json
    import shutil

    from animegraph.apps.cli import main

    db = tmp_path / "db"
    shutil.copytree(tiny_db[0], db, ignore=shutil.ignore_patterns("baselines"))
    manifest = sorted(db.glob("v*/manifest.json"))[-1]
    info = json.loads(manifest.read_text())
    del info["kind"]
    manifest.write_text(json.dumps(info))
    write_wav(tmp_path / "a.wav", np.zeros(1600, dtype=np.float32), 16000)
    code = main(["synth", str(tmp_path / "a.wav"), "--db", str(db), "--method", "mu-mlp",
                 "-o", str(tmp_path / "a.livelink.csv")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "needs a database of ARKit blendshapes" in err[0]


def test_synth_timecode_needs_a_livelink_output(capsys, tmp_path):
    from animegraph.apps.cli import main

    write_wav(tmp_path / "a.wav", np.zeros(1600, dtype=np.float32), 16000)
    code = main(["synth", str(tmp_path / "a.wav"), "--db", str(tmp_path / "db"), "-o",
                 str(tmp_path / "a.csv"), "--timecode", "01:00:00:00"])
    err = capsys.readouterr().err
    assert code != 0 and "--timecode needs -o NAME.livelink.csv" in err
    assert len(err.strip().splitlines()) == 1


def test_a_take_is_refused_by_a_marker_database_before_its_phones(tiny_db, tmp_path,
                                                                   monkeypatch):
    # Its channels were compared only once it was prepared: 16 s of phone recognition
    # for a 112 s FACEGOOD clip that was then rejected.
    import shutil

    import ingest.per_clip as per_clip
    import ingest.pipeline as pipeline
    from db.store import Database

    db = tmp_path / "db"
    shutil.copytree(tiny_db[0], db)
    before = Database.open(db).version_dir.name
    take = tmp_path / "take"
    take.mkdir()
    _write_take(take)
    prepared = []
    monkeypatch.setattr(per_clip, "prepare_clip",
                        lambda raw, **kw: prepared.append(raw.clip_id))  # must not be reached
    with pytest.raises(ParameterError, match="its motion is curves, the database's markers"):
        pipeline.ingest([take], db)
    assert prepared == [] and Database.open(db).version_dir.name == before
