"""Readers: discovery and loading of marker, curve and landmark clips, on real files."""

from __future__ import annotations

import json
import shutil
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from conftest import require_shared
from crafted import PicklePayload
from scipy.spatial.transform import Rotation

from db.errors import DataError, ParameterError
from ingest.clip import RawClip, checksum_files
from ingest.facemesh import load_canonical_face
from ingest.formats import (
    MarkerData,
    read_c3d,
    read_phones_csv,
    read_wav,
    write_c3d,
    write_htk_lab,
    write_marker_csv,
    write_textgrid,
    write_trc,
    write_wav,
)
from ingest.readers import (
    ClipSource,
    discover,
    duration_tolerance,
    estimate_lag,
    load,
    normalise_landmarks,
    shift_motion,
)
from ingest.readers.common import load_npy
from ingest.readers.curves import curve_group
from ingest.readers.landmarks import (
    HEAD_RADIUS_MM,
    POSE_CHANNELS,
    STABLE_LANDMARKS,
    landmark_clip,
    landmark_groups,
)
from ingest.readers.sync import audio_envelope, lip_activity

EMOTIONS = {"neutral", "happy", "angry", "sad", "frustrated"}


@pytest.fixture(scope="module")
def corpus(tmp_path_factory) -> Path:
    """A 6-clip synthetic corpus: sentence 1 in all five emotions, sentence 2 in one."""
    from ingest.corpus.synthetic import CorpusConfig, generate_corpus

    out = tmp_path_factory.mktemp("readers") / "c"
    generate_corpus(out, CorpusConfig(sentences=2, parallel=1, variations=1), workers=1)
    return out


def _copy_clip(corpus: Path, clip_id: str, folder: Path, *suffixes: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for suffix in suffixes:
        shutil.copy(corpus / "clips" / f"{clip_id}{suffix}", folder / f"{clip_id}{suffix}")
    return folder / clip_id


def _one(paths) -> ClipSource:
    sources = discover(paths)
    assert len(sources) == 1, sources
    return sources[0]


# --------------------------------------------------------------------------- synthetic corpus


def test_discover_synthetic_corpus(corpus):
    sources = discover([corpus])
    ids = sorted(p.name[: -len(".json")] for p in (corpus / "clips").glob("*.json"))
    assert [s.clip_id for s in sources] == ids  # sorted; controls.csv files are not clips
    assert len(sources) == 6
    assert {(s.kind, s.layout, s.corpus) for s in sources} == {("markers", "synthetic", "c")}
    first = sources[0]
    assert [role for role, _ in first.files] == [
        "motion", "audio", "labels", "metadata", "marker_table"]
    assert first.source == first.path == corpus / "clips" / f"{first.clip_id}.c3d"
    assert first.file("labels").name.endswith(".phones.csv")
    # The clips folder, a clip's side file, or the corpus twice find the same clips.
    assert discover([corpus / "clips"]) == sources
    assert discover([corpus, corpus / "clips"]) == sources
    assert discover([corpus / "clips" / f"{first.clip_id}.phones.csv"]) == [first]
    assert discover([corpus / "clips" / f"{first.clip_id}.controls.csv"]) == []


def test_a_clip_whose_name_starts_with_dots_is_read(corpus, tmp_path):
    """A clip ``..dots`` (its files ``..dots.c3d``, ``..dots.wav`` ...) was skipped as a
    hidden file: neither added nor rejected, missing from the report. macOS's own files
    beside it (``._..dots.c3d``, ``.DS_Store``) are no clip."""
    first = sorted(p.name[: -len(".json")] for p in (corpus / "clips").glob("*.json"))[0]
    folder = tmp_path / "clips"
    folder.mkdir()
    for path in (corpus / "clips").glob(f"{first}.*"):
        shutil.copy(path, folder / ("..dots" + path.name[len(first):]))
    (folder / "._..dots.c3d").write_bytes(b"\x00\x05\x16\x07 AppleDouble")
    (folder / ".DS_Store").write_bytes(b"\x00\x00\x00\x01Bud1")
    for where in ([folder], [folder / "..dots.wav"]):
        source = _one(where)
        assert source.clip_id == "..dots" and source.path == folder / "..dots.c3d"


def test_one_file_says_nothing_of_the_other_clips_around_it(corpus, tmp_path, caplog):
    """Ingesting one file reads its folder (and FACEGOOD's folder above wav/), but what
    is odd about the other clips there is not this command's business: said before of
    a neighbour with two motion files, and of a clip in the folder above."""
    import logging

    ids = sorted(p.name[: -len(".json")] for p in (corpus / "clips").glob("*.json"))
    folder = tmp_path / "take" / "day1"
    wanted = _copy_clip(corpus, ids[0], folder, ".c3d", ".wav")
    other = _copy_clip(corpus, ids[1], folder, ".c3d", ".wav")
    above = _copy_clip(corpus, ids[2], folder.parent, ".c3d", ".wav")
    for odd in (other, above):  # two motion files for one clip: the CSV is ignored
        (odd.parent / f"{odd.name}.csv").write_text("frame,time,a.x,a.y,a.z\n0,0,0,0,0\n")
    with caplog.at_level(logging.WARNING, logger="ingest.readers.discovery"):
        assert _one([wanted.with_suffix(".wav")]).clip_id == ids[0]
    assert caplog.text == ""
    with caplog.at_level(logging.WARNING, logger="ingest.readers.discovery"):
        assert len(discover([folder])) == 2  # the folder: its clips and what is odd
    assert f"{other.name}: using {other.name}.c3d, ignoring {other.name}.csv" in caplog.text


def test_a_facegood_file_is_its_clip_without_a_word(tmp_path, caplog):
    """A FACEGOOD speech file named alone was also read as a plain folder's (wav/):
    "1114_2_01.wav: no motion beside it; not a clip", and then ingested."""
    import logging

    root = tmp_path / "fg"
    (root / "bs_value").mkdir(parents=True)
    (root / "wav").mkdir()
    (root / "bsname.txt").write_text("2\njaw\nbrow_raise_c\n")
    for clip in ("c1", "c2"):
        write_wav(root / "wav" / f"{clip}.wav", np.zeros(3200, np.float32), 16000)
        np.save(root / "bs_value" / f"bs_value_{clip}.npy", np.zeros((6, 2)))
    with caplog.at_level(logging.WARNING, logger="ingest.readers.discovery"):
        found = discover([root / "wav" / "c1.wav", root / "bs_value" / "bs_value_c2.npy"])
    assert [(s.layout, s.clip_id) for s in found] == [("facegood", "c1"), ("facegood", "c2")]
    assert caplog.text == ""


def test_speech_without_its_motion_is_said(corpus, tmp_path, caplog):
    import logging

    ids = sorted(p.name[: -len(".json")] for p in (corpus / "clips").glob("*.json"))
    clip = _copy_clip(corpus, ids[0], tmp_path / "takes", ".c3d", ".wav")
    shutil.copy(clip.with_suffix(".wav"), clip.parent / "lonely.wav")
    with caplog.at_level(logging.WARNING, logger="ingest.readers.discovery"):
        assert [s.clip_id for s in discover([clip.parent])] == [ids[0]]
    assert "lonely.wav: no motion beside it (lonely.c3d" in caplog.text
    assert ids[0] not in caplog.text

def test_load_synthetic_clip(corpus):
    sources = discover([corpus])
    clips = [load(s) for s in sources]
    assert {c.emotion for c in clips} == EMOTIONS
    for source, clip in zip(sources, clips, strict=True):
        meta = json.loads((corpus / "clips" / f"{clip.clip_id}.json").read_text())
        assert isinstance(clip, RawClip)
        assert (clip.clip_id, clip.corpus, clip.source) == (source.clip_id, "c", source.source)
        assert clip.emotion == meta["emotion"] and clip.text == meta["text"]
        assert clip.speaker == "synth01" and clip.sentence_id == meta["sentence_id"]
        assert clip.phones == tuple(read_phones_csv(source.file("labels")))
        assert clip.phones[0].phone == "SIL"
        assert clip.schema.kind == "markers" and clip.schema.units == "mm"
        assert clip.schema.n_channels == 216 == clip.motion.shape[1]  # 72 markers x 3
        assert clip.motion.dtype == np.float64 and clip.fps == 120.0
        assert clip.n_frames == meta["n_frames"]
        assert clip.audio.dtype == np.float32 and clip.audio.ndim == 1
        assert clip.sample_rate == 16000
        assert abs(clip.n_frames / clip.fps - clip.duration) < 0.05
    clip = clips[0]
    groups = Counter(clip.schema.groups)
    assert set(groups) == {"head", "upper_face", "lips"} and sum(groups.values()) == 216
    assert clip.schema.names[:3] == ("lip_corner_r.x", "lip_corner_r.y", "lip_corner_r.z")
    assert clip.schema.groups[:3] == ("lips",) * 3
    points = read_c3d(sources[0].source).points
    np.testing.assert_array_equal(clip.motion, points.reshape(len(points), -1))


def test_checksum_is_stable_and_covers_the_files(corpus):
    sources = discover([corpus])
    first, again = load(sources[0]), load(discover([corpus])[0])
    assert first.checksum == again.checksum
    stem = corpus / "clips" / sources[0].clip_id
    expected = checksum_files([stem.with_suffix(".c3d"), stem.with_suffix(".wav"),
                               Path(f"{stem}.phones.csv"), stem.with_suffix(".json"),
                               corpus / "markers.csv"])
    assert first.checksum == expected
    assert len({load(s).checksum for s in sources}) == len(sources)


# --------------------------------------------------------------------------- generic markers


def test_generic_marker_folder(corpus, tmp_path):
    clip_id = "s0001_happy_1"
    stem = _copy_clip(corpus, clip_id, tmp_path / "studio", ".c3d", ".wav")
    phones = read_phones_csv(corpus / "clips" / f"{clip_id}.phones.csv")
    write_textgrid(Path(f"{stem}.TextGrid"), phones)
    Path(f"{stem}.txt").write_text("  The young boy\ntook a bag.\n")
    source = _one([tmp_path / "studio"])
    assert (source.kind, source.layout, source.corpus) == ("markers", "markers", "studio")
    assert [r for r, _ in source.files] == ["motion", "audio", "labels", "transcript"]
    clip = load(source)
    assert clip.phones == tuple(phones)
    assert clip.text == "The young boy took a bag."
    assert clip.emotion is None and clip.speaker is None
    assert set(clip.schema.groups) == {"other"}  # no markers.csv
    assert clip.schema.n_channels == 216

    # A markers.csv beside it (or one folder up) gives the groups; a json the metadata.
    shutil.copy(corpus / "markers.csv", tmp_path / "markers.csv")
    Path(f"{stem}.json").write_text(json.dumps({"emotion": "happy", "speaker": "ann",
                                                "sentence_id": 7}))
    clip2 = load(_one([tmp_path / "studio"]))
    assert Counter(clip2.schema.groups) == Counter(load(discover([corpus])[2]).schema.groups)
    assert (clip2.emotion, clip2.speaker, clip2.sentence_id) == ("happy", "ann", "7")
    assert clip2.text == clip.text  # the transcript file wins over the json
    assert clip2.checksum != clip.checksum


@pytest.mark.parametrize("suffix", [".trc", ".csv"])
def test_generic_text_marker_formats(corpus, tmp_path, suffix):
    clip_id = "s0002_angry_1"
    data = read_c3d(corpus / "clips" / f"{clip_id}.c3d")
    folder = tmp_path / "text"
    stem = _copy_clip(corpus, clip_id, folder, ".wav")
    (write_trc if suffix == ".trc" else write_marker_csv)(stem.with_suffix(suffix), data)
    phones = read_phones_csv(corpus / "clips" / f"{clip_id}.phones.csv")
    write_htk_lab(stem.with_suffix(".lab"), phones)
    clip = load(_one([folder]))
    assert clip.fps == 120.0
    np.testing.assert_allclose(clip.motion, data.points.reshape(data.n_frames, -1), atol=1e-4)
    assert [p.phone for p in clip.phones] == [p.phone for p in phones]
    np.testing.assert_allclose([p.end for p in clip.phones], [p.end for p in phones], atol=1e-6)


# --------------------------------------------------------------------------- generic curves


def _curve_clip(folder: Path, n_frames: int = 90, fps: float = 30.0) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(1)
    np.save(folder / "take1.npy", rng.uniform(0, 1, size=(n_frames, 4)))
    (folder / "take1.channels.txt").write_text("jawOpen\nbrowInnerUp\nheadYaw\nnoseSneer\n")
    write_wav(folder / "take1.wav", np.zeros(int(n_frames / fps * 16000), np.float32), 16000)
    (folder / "take1.json").write_text(json.dumps({"fps": fps, "speaker": "bo"}))
    return folder / "take1"


def test_generic_curve_clip(tmp_path):
    stem = _curve_clip(tmp_path / "rig")
    source = _one([tmp_path])
    assert (source.kind, source.layout, source.clip_id) == ("curves", "curves", "take1")
    clip = load(source)
    assert clip.motion.shape == (90, 4) and clip.fps == 30.0 and clip.speaker == "bo"
    assert clip.schema.kind == "curves" and clip.schema.units == "unit"
    assert clip.schema.names == ("jawOpen", "browInnerUp", "headYaw", "noseSneer")
    assert clip.schema.groups == ("lips", "upper_face", "head", "other")
    np.testing.assert_array_equal(clip.motion, np.load(stem.with_suffix(".npy")))

    # The same clip as CSV with a header and a time column: no fps needed.
    shutil.rmtree(tmp_path / "rig")
    folder = tmp_path / "rig"
    folder.mkdir()
    values = np.random.default_rng(2).uniform(size=(60, 2))
    rows = ["frame,time,mouthClose,eyeBlink_L"] + [
        f"{i},{i / 30:.6f},{a:.5f},{b:.5f}" for i, (a, b) in enumerate(values)]
    (folder / "t.curves.csv").write_text("\n".join(rows) + "\n")
    write_wav(folder / "t.wav", np.zeros(32000, np.float32), 16000)
    clip = load(_one([folder]))
    assert clip.fps == 30.0 and clip.schema.names == ("mouthClose", "eyeBlink_L")
    np.testing.assert_allclose(clip.motion, values, atol=1e-5)


def test_curve_groups_from_names():
    assert curve_group("jaw") == curve_group("mouth_oh_c") == curve_group("cheek_UP") == "lips"
    assert curve_group("tongue_u") == curve_group("blendShape1.lipsPucker") == "lips"
    assert curve_group("brow_raise_l") == curve_group("EyeBlinkLeft") == "upper_face"
    assert curve_group("head_pitch") == "head"
    assert curve_group("nose_wrinkle_l") == curve_group("neck") == "other"


def test_curve_clip_failures(tmp_path):
    stem = _curve_clip(tmp_path / "a")
    source = _one([tmp_path / "a"])
    stem.with_suffix(".json").write_text("{}")
    with pytest.raises(DataError, match="no frame rate"):
        load(source)
    (tmp_path / "curves.json").write_text(json.dumps({"fps": 30}))  # corpus-level rate
    assert load(_one([tmp_path / "a"])).fps == 30.0
    Path(f"{stem}.channels.txt").write_text("jawOpen\nbrowInnerUp\n")
    with pytest.raises(DataError, match="unknown channel layout: 4 columns but 2 channel"):
        load(_one([tmp_path / "a"]))
    Path(f"{stem}.channels.txt").unlink()
    with pytest.raises(DataError, match="unknown channel layout"):
        load(_one([tmp_path / "a"]))
    np.save(stem.with_suffix(".npy"), np.zeros((90, 4, 3)))
    Path(f"{stem}.channels.txt").write_text("a\nb\nc\nd\n")
    with pytest.raises(DataError, match=r"expected a 2-D \(n_frames, n_channels\)"):
        load(_one([tmp_path / "a"]))
    np.save(stem.with_suffix(".npy"), np.array([{"a": 1}], dtype=object))
    with pytest.raises(DataError, match=r"holds Python objects \(a pickle\); refused"):
        load(_one([tmp_path / "a"]))  # .npy files are never unpickled
    np.save(stem.with_suffix(".npy"), np.zeros((90, 4)))
    stem.with_suffix(".npy").write_bytes(stem.with_suffix(".npy").read_bytes()[:-100])
    with pytest.raises(DataError, match="unreadable or truncated array file"):
        load(_one([tmp_path / "a"]))


def test_facegood_layout_never_unpickles(tmp_path):
    root = tmp_path / "fg"
    (root / "bs_value").mkdir(parents=True)
    (root / "wav").mkdir()
    (root / "bsname.txt").write_text("3\njaw\nbrow_raise_c\neye_blink1_l\n")
    write_wav(root / "wav" / "c1.wav", np.zeros(32000, np.float32), 16000)
    # A crafted .npy whose unpickling would run code: it must be refused, not run.
    marker = tmp_path / "payload-ran"
    np.save(root / "bs_value" / "bs_value_c1.npy", np.array([PicklePayload(marker)], dtype=object),
            allow_pickle=True)
    source = _one([root])
    assert (source.layout, source.clip_id) == ("facegood", "c1")
    with pytest.raises(DataError, match="holds Python objects .*refused"):
        load(source)
    assert not marker.exists()
    # A pickled object array of plain numbers is refused too: nothing is unpickled.
    np.save(root / "bs_value" / "bs_value_c1.npy",
            np.array([[0.1 * i, 0.5, 0.0] for i in range(60)], dtype=object), allow_pickle=True)
    with pytest.raises(DataError, match="refused"):
        load(source)
    rows = [[0.1 * i, 0.5, 0.0] for i in range(60)]
    np.save(root / "bs_value" / "bs_value_c1.npy", np.array(rows))
    clip = load(source)
    # FACEGOOD's columns sit one after their names (see facegood_column_names).
    assert clip.schema.names == ("unnamed_0", "jaw", "brow_raise_c")
    assert clip.fps == 30.0 and clip.schema.groups == ("other", "lips", "upper_face")
    np.testing.assert_allclose(clip.motion, rows)
    (root / "bsname.txt").write_text("4\njaw\nbrow_raise_c\neye_blink1_l\n")
    with pytest.raises(DataError, match="says 4 names but lists 3"):
        load(source)


def test_shared_facegood_files_load_without_pickle():
    folder = require_shared("facegood")
    files = sorted(folder.rglob("*.npy"))
    assert files
    for path in files:
        assert not load_npy(path).dtype.hasobject, path


# --------------------------------------------------------------------------- bad input


@pytest.fixture
def clip_folder(corpus, tmp_path) -> Path:
    """A generic copy of one synthetic clip (c3d, wav, phones, json)."""
    return _copy_clip(corpus, "s0001_sad_1", tmp_path / "bad", ".c3d", ".wav", ".phones.csv",
                      ".json")


def test_truncated_wav(clip_folder):
    wav = clip_folder.with_suffix(".wav")
    wav.write_bytes(wav.read_bytes()[: wav.stat().st_size // 2])
    with pytest.raises(DataError, match=r"truncated audio file .*s0001_sad_1\.wav"):
        load(_one([clip_folder.parent]))



def test_empty_wav(clip_folder):
    clip_folder.with_suffix(".wav").write_bytes(b"")
    with pytest.raises(DataError, match=r"empty audio file .*s0001_sad_1\.wav \(0 bytes\)"):
        load(_one([clip_folder.parent]))

def test_wav_at_96k_is_ingested_at_48k(clip_folder):
    """A studio recorder's 96 kHz: read at 48 kHz (the fastest the prosody features take),
    so the clip goes in instead of being rejected for its rate."""
    import soundfile
    from scipy.signal import resample_poly

    from ingest.prepare import prepare_clip

    wav = clip_folder.with_suffix(".wav")
    audio, rate = read_wav(wav)
    soundfile.write(str(wav), resample_poly(audio, 96000, rate), 96000, subtype="PCM_24")
    raw = load(_one([clip_folder.parent]))
    assert raw.sample_rate == 48000
    assert abs(len(raw.audio) / 48000 - len(audio) / rate) < 1e-3
    clip = prepare_clip(raw, posteriorgrams=False)
    assert len(clip.phones) > 0


def test_audio_motion_length_mismatch(clip_folder):
    wav = clip_folder.with_suffix(".wav")
    audio, rate = read_wav(wav)
    duration = len(audio) / rate
    # just within the tolerance: accepted
    keep = int((duration - duration_tolerance(duration) + 0.02) * rate)
    write_wav(wav, audio[:keep], rate)
    load(_one([clip_folder.parent]))
    write_wav(wav, audio[: int(len(audio) * 0.6)], rate)
    with pytest.raises(DataError, match=r"s0001_sad_1\.c3d: motion lasts 5\.6\d\d s .* but "
                                        r"audio 3\.\d+ s \(tolerance 0\.20 s\)"):
        load(_one([clip_folder.parent]))


def test_marker_nan_throughout(clip_folder):
    c3d = clip_folder.with_suffix(".c3d")
    data = read_c3d(c3d)
    points = data.points.copy()
    points[:, data.labels.index("chin_tip")] = np.nan
    write_c3d(c3d, MarkerData(points=points, labels=data.labels, rate=data.rate))
    with pytest.raises(DataError, match=r"s0001_sad_1\.c3d: marker chin_tip missing \(NaN\) "
                                        r"in every frame"):
        load(_one([clip_folder.parent]))


def test_empty_transcript(clip_folder):
    Path(f"{clip_folder}.txt").write_text(" \n\n")
    with pytest.raises(DataError, match=r"empty transcript file: .*s0001_sad_1\.txt"):
        load(_one([clip_folder.parent]))


def test_other_bad_clips(clip_folder):
    folder = clip_folder.parent
    c3d = clip_folder.with_suffix(".c3d")
    original = c3d.read_bytes()
    c3d.write_bytes(original[: len(original) // 2])
    with pytest.raises(DataError, match=r"truncated C3D file"):
        load(_one([folder]))
    c3d.write_bytes(original)
    clip_folder.with_suffix(".json").write_text("{not json")
    with pytest.raises(DataError, match=r"corrupt JSON in .*s0001_sad_1\.json"):
        load(_one([folder]))
    clip_folder.with_suffix(".json").write_text("[]")
    with pytest.raises(DataError, match="expected a JSON object"):
        load(_one([folder]))
    clip_folder.with_suffix(".json").unlink()
    Path(f"{clip_folder}.phones.csv").write_text("start,end,phone\n0,9,AA\n")
    with pytest.raises(DataError, match="phone labels end at 9.000 s, after the audio"):
        load(_one([folder]))
    Path(f"{clip_folder}.phones.csv").unlink()
    clip_folder.with_suffix(".wav").unlink()
    source = _one([folder])  # a marker file without audio is still found ...
    assert source.file("audio") is None
    with pytest.raises(DataError, match=r"no audio file s0001_sad_1\.wav"):
        load(source)  # ... and rejected with the reason


def test_discover_and_load_arguments(tmp_path):
    with pytest.raises(ParameterError, match="does not exist"):
        discover([tmp_path / "nope"])
    with pytest.raises(ParameterError, match="sequence of paths"):
        discover(tmp_path)
    with pytest.raises(ParameterError, match="ClipSource"):
        load(str(tmp_path))
    assert discover([tmp_path]) == []


# --------------------------------------------------------------------------- landmarks


def _mediapipe_view(points_mm: np.ndarray, rotvec, scale, shift, size=256.0) -> np.ndarray:
    """Points in canonical mm -> mediapipe's normalised image coordinates."""
    rot = Rotation.from_rotvec(rotvec).as_matrix()
    camera = scale * points_mm @ rot.T + shift  # x right, y up, z towards the camera
    return np.stack([camera[..., 0] / size, 1.0 - camera[..., 1] / size,
                     -camera[..., 2] / size], axis=-1)


def test_normalise_landmarks_recovers_pose():
    canonical = load_canonical_face().vertices
    rotvecs = np.array([[0.0, 0.0, 0.0], [0.15, -0.3, 0.05], [-0.2, 0.25, -0.1]])
    raw = np.stack([_mediapipe_view(canonical, r, 0.9 + 0.1 * i, [120 + i, 130, -40])
                    for i, r in enumerate(rotvecs)])
    raw = np.concatenate([raw, np.zeros((3, 10, 3))], axis=1)  # irises: dropped
    raw[1, 100] = np.nan  # a lost non-stable landmark stays lost in its frame only
    norm = normalise_landmarks(raw, 256.0, 256.0)
    assert norm.points.shape == (3, 468, 3) and norm.pose.shape == (3, len(POSE_CHANNELS))
    np.testing.assert_allclose(np.delete(norm.points, 100, axis=1),
                               np.delete(np.broadcast_to(canonical, (3, 468, 3)), 100, axis=1),
                               atol=1e-9)
    assert np.isnan(norm.points[1, 100]).all() and np.isfinite(norm.points[2, 100]).all()
    np.testing.assert_allclose(norm.pose[:, :3], rotvecs, atol=1e-9)
    np.testing.assert_allclose(norm.pose[:, 3:6], [[120, 130, -40], [121, 130, -40],
                                                   [122, 130, -40]], atol=1e-9)
    np.testing.assert_allclose(norm.pose[:, 6], [0.9, 1.0, 1.1])
    np.testing.assert_allclose(norm.residual_mm, 0.0, atol=1e-9)


def test_landmark_groups_follow_the_face():
    groups = landmark_groups()
    assert len(groups) == 468
    for i in (13, 14, 61, 291, 0, 17, 152, 175):  # lips, chin
        assert groups[i] == "lips", i
    for i in (10, 151, 33, 263, 159, 386, 105, 334):  # forehead, eyes, brows
        assert groups[i] == "upper_face", i
    for i in (1, 4, 234, 454):  # nose tip, cheeks
        assert groups[i] == "other", i
    assert not {groups[i] for i in STABLE_LANDMARKS} & {"lips"}


def test_lag_estimate_on_a_known_offset(rng):
    fps, rate, n = 30.0, 16000, 900
    # A mouth opening that opens and closes a few times a second ...
    opening = np.convolve(rng.uniform(0, 12, n), np.ones(5) / 5, mode="same")
    points = np.zeros((n, 468, 3))
    points[:, 14, 1] = -opening
    points[:, 291, 0] = 50 + 0.3 * opening
    activity = lip_activity(points)
    # ... and speech whose loudness follows the lip activity 6 frames (200 ms) later.
    lag_frames = 6
    loud = np.concatenate([np.full(lag_frames, activity.min()), activity[:-lag_frames]])
    envelope = np.repeat(0.02 + loud / loud.max(), int(rate / fps))
    audio = (rng.normal(size=len(envelope)) * envelope * 0.3).astype(np.float32)
    lag, confidence = estimate_lag(activity, audio_envelope(audio, rate, fps, n), fps)
    assert lag == pytest.approx(0.2, abs=0.5 / fps)
    assert confidence > 0.5
    # reversed roles: the audio leads
    lag, _ = estimate_lag(np.concatenate([activity[lag_frames:], np.zeros(lag_frames)]),
                          audio_envelope(audio, rate, fps, n), fps)
    assert lag == pytest.approx(0.4, abs=0.5 / fps)


def test_shift_motion():
    motion = np.arange(10.0)[:, None] * [1.0, 10.0]
    shifted = shift_motion(motion, 0.2, 10.0)  # delay by 2 frames
    np.testing.assert_array_equal(shifted[:, 0], [0, 0, 0, 1, 2, 3, 4, 5, 6, 7])
    np.testing.assert_array_equal(shift_motion(motion, -0.3, 10.0)[:, 0],
                                  [3, 4, 5, 6, 7, 8, 9, 9, 9, 9])
    np.testing.assert_allclose(shift_motion(motion[:, 0], 0.05, 10.0),
                               [0, 0.5, 1.5, 2.5, 3.5, 4.5, 5.5, 6.5, 7.5, 8.5])
    gap = motion.copy()
    gap[5] = np.nan
    out = shift_motion(gap, 0.1, 10.0)
    assert np.isnan(out[6]).all() and np.isfinite(np.delete(out, 6, axis=0)).all()
    np.testing.assert_array_equal(shift_motion(motion, 0.0, 10.0), motion)
    for bad in (dict(lag_s=np.nan, fps=10.0), dict(lag_s=0.1, fps=0.0)):
        with pytest.raises(ParameterError):
            shift_motion(motion, **bad)
    with pytest.raises(ParameterError):
        shift_motion(np.zeros((0, 3)), 0.1, 10.0)


def test_landmark_clip_failures(tmp_path):
    canonical = load_canonical_face().vertices
    folder = tmp_path / "lm" / "clip1"
    folder.mkdir(parents=True)
    raw = np.stack([_mediapipe_view(canonical, [0, 0.1 * np.sin(i / 5), 0], 1.0,
                                     [128, 128, 0]) for i in range(50)]).astype(np.float32)
    np.save(folder / "landmarks.npy", raw)
    write_wav(folder / "audio_16k.wav", np.zeros(32000, np.float32), 16000)
    (folder / "meta.json").write_text(json.dumps({"fps": 25, "width": 256, "height": 256,
                                                  "speaker": "x"}))
    source = _one([tmp_path / "lm"])
    assert (source.kind, source.layout, source.corpus, source.clip_id) == (
        "landmarks", "talkingface", "lm", "clip1")
    clip = load(source)
    assert clip.motion.shape == (50, 468 * 3 + 7) and clip.schema.kind == "landmarks"
    assert clip.schema.names[-7:] == POSE_CHANNELS and clip.schema.groups[-1] == "pose"
    # Rotations are not millimetres (the channels table says each channel's units).
    assert clip.schema.channel_units[-8:] == ("mm",) + ("0.01 rad",) * 3 + ("mm",) * 3 + ("%",)
    assert clip.extra["procrustes_rms_mm"] < 1e-3
    assert clip.extra["frames_without_face"] == 0
    gaps = raw.copy()
    gaps[[3, 4, 20]] = np.nan  # frames the tracker found no face in
    np.save(folder / "landmarks.npy", gaps)
    clip = load(source)
    assert clip.extra["frames_without_face"] == 3
    np.save(folder / "landmarks.npy", raw)
    (folder / "meta.json").write_text(json.dumps({"width": 256}))
    with pytest.raises(DataError, match="meta.json: no 'fps'"):
        load(source)
    (folder / "meta.json").write_text(json.dumps({"fps": 50}))
    with pytest.raises(DataError, match="motion lasts 1.000 s"):
        load(source)
    (folder / "meta.json").write_text(json.dumps({"fps": 25}))
    np.save(folder / "landmarks.npy", raw[:, :400])
    with pytest.raises(DataError, match=r"expected landmarks of shape \(n_frames, 468 or 478"):
        load(source)
    np.save(folder / "landmarks.npy", np.full_like(raw, np.nan))
    with pytest.raises(DataError, match="no face in any frame"):
        load(source)
    # Landmarks come from a .npy (checked as it is read) or the video tracker's cache.
    with pytest.raises(DataError, match=r"landmarks hold complex numbers \(complex64\), not "
                                        r"real numbers"):
        landmark_clip(source, raw.astype(np.complex64), fps=25, width=256, height=256,
                      audio=np.zeros(32000, np.float32), sample_rate=16000, text=None,
                      phones=None, words=None, fields={}, extra={},
                      where=folder / "landmarks.npy")


# --------------------------------------------------------------------------- real data


@pytest.mark.shared
def test_facegood_clips():
    root = require_shared("facegood")
    sources = discover([root])
    assert [s.clip_id for s in sources] == [f"1114_2_0{i}" for i in range(1, 6)]
    names = [n.strip() for n in (root / "bsname.txt").read_text().splitlines()[1:] if n.strip()]
    for source in sources:
        assert (source.kind, source.layout, source.corpus) == ("curves", "facegood", "facegood")
        clip = load(source)
        assert clip.fps == 30.0 and clip.motion.shape[1] == 116 == clip.schema.n_channels
        assert list(clip.schema.names) == ["unnamed_0", *names[:-1]]
        assert clip.sample_rate == 16000
        # frames / 30 = audio duration (measured: within 30 ms, i.e. one frame)
        assert abs(clip.n_frames / clip.fps - clip.duration) < 0.035
        assert 0.0 <= clip.motion.min() and clip.motion.max() <= 1.0
        assert clip.phones is None and clip.text is None
    groups = Counter(clip.schema.groups)
    assert groups["lips"] > 60 and groups["upper_face"] > 20


@pytest.fixture(scope="module")
def talkingface():
    root = require_shared("talkingface")
    sources = discover([root])
    return {s.clip_id: (s, load(s)) for s in sources}


@pytest.mark.shared
def test_talkingface_clips(talkingface):
    assert len(talkingface) == 13
    canonical = load_canonical_face().vertices
    for clip_id, (source, clip) in talkingface.items():
        meta = json.loads(source.file("metadata").read_text())
        assert (source.kind, clip.schema.kind, clip.schema.units) == (
            "landmarks", "landmarks", "mm")
        assert clip.fps == meta["fps"] and clip.n_frames == meta["frames"]
        assert clip.motion.shape == (meta["frames"], 468 * 3 + 7)
        assert clip.schema.names[-7:] == POSE_CHANNELS
        assert Counter(clip.schema.groups)["pose"] == 7
        assert np.isfinite(clip.motion).all()
        # Procrustes: stable points within 1.9-3.0 mm of the canonical mesh (the speaker's
        # face is not the mesh); frame-to-frame jitter of those points 0.4-1.0 mm.
        assert clip.extra["procrustes_rms_mm"] < 3.5, clip_id
        assert clip.extra["stable_jitter_mm"] < 1.5, clip_id
        points = clip.motion[:, :1404].reshape(-1, 468, 3)
        mean_shape = points.mean(axis=0)
        # the clip's mean face is the mesh's, give or take the speaker (measured 2.9-7.5 mm)
        assert np.sqrt(((mean_shape - canonical) ** 2).sum(-1).mean()) < 10.0, clip_id
        # the mouth opens and closes: 13-14 distance, 5th percentile 0.4-2.1 mm, 95th
        # 8.8-19.9 mm
        opening = np.linalg.norm(points[:, 13] - points[:, 14], axis=1)
        p5, p95 = np.percentile(opening, [5, 95])
        assert p5 < 2.5 and p95 > 8.0 and p95 - p5 > 7.0, clip_id
        # the head moves; its pose is kept
        pose = clip.motion[:, -7:]
        # rotation as mm of arc at 10 cm from the clip's median pose: under 45 degrees
        rotation_deg = np.degrees(pose[:, :3] / HEAD_RADIUS_MM)
        assert np.abs(rotation_deg).max() < 45 and rotation_deg.std(0).max() > 0.5
        assert np.abs(np.median(pose, axis=0)).max() < 1e-6  # relative to the median
        assert abs(clip.n_frames / clip.fps - clip.duration) < 0.1


@pytest.mark.shared
def test_talkingface_lip_audio_lag(talkingface):
    leading = 0
    for clip_id, (_, clip) in talkingface.items():
        ours, theirs = clip.extra["lip_audio_lag_s"], clip.extra["meta_lip_audio_lag_s"]
        assert -0.5 <= ours <= 0.5 and 0.0 < clip.extra["lag_confidence"] <= 1.0
        if theirs >= 0.1:  # meta.json: lips lead by 120-300 ms (Obama x3, KristiNoem, pose2)
            leading += 1
            assert ours > 0.1, clip_id  # same sign, same order (measured 0.125-0.237 s)
            assert abs(ours - theirs) < 0.2, clip_id  # KristiNoem: 0.136 vs 0.300
            if clip_id.startswith("styletalk_Obama"):
                assert abs(ours - theirs) < 0.025, clip_id  # within a frame
        else:  # meta.json: in sync within 67 ms; ours within 50 ms of 0
            assert abs(ours) < 0.06, clip_id
    assert leading == 5


@pytest.mark.shared
def test_shift_motion_brings_a_leading_clip_in_sync(talkingface):
    _, clip = talkingface["styletalk_Obama_clip1"]
    points = clip.motion[:, :1404].reshape(-1, 468, 3)
    loudness = audio_envelope(clip.audio, clip.sample_rate, clip.fps, clip.n_frames)
    lag = clip.extra["lip_audio_lag_s"]
    shifted = shift_motion(clip.motion, lag, clip.fps)[:, :1404].reshape(-1, 468, 3)
    after, _ = estimate_lag(lip_activity(shifted), loudness, clip.fps)
    assert abs(after) < 1 / clip.fps < abs(estimate_lag(lip_activity(points), loudness,
                                                        clip.fps)[0])


@pytest.mark.shared
def test_discover_the_shared_data():
    root = require_shared()
    sources = discover([root])  # EmoDB has no motion and the mesh folder no clips
    assert Counter(s.layout for s in sources) == {"talkingface": 13, "facegood": 5,
                                                  "livelink": 1,
                                                  "video": 800}  # GRID s1
    assert discover([root / "facegood" / "wav" / "1114_2_03.wav"]) == [
        s for s in sources if s.clip_id == "1114_2_03"]


def test_facegood_names_line_up_with_their_columns():
    """Left/right curve pairs move together, and the jaw curve follows the speech."""
    root = require_shared("facegood")
    clips = [load(s) for s in discover([root])]
    names = list(clips[0].schema.names)
    motion = np.concatenate([c.motion for c in clips])
    assert names[0] == "unnamed_0" and np.ptp(motion[:, 0]) == 0

    def col(name):
        return motion[:, names.index(name)]

    for left in ("mouth_lipCornerPull_l", "mouth_pucker_l", "mouth_press_l"):
        right = left[:-1] + "r"
        assert np.corrcoef(col(left), col(right))[0, 1] > 0.95, left


def _claiming(shape, dtype="<f8") -> bytes:
    """A ``.npy`` whose header claims ``shape`` over 64 bytes of data."""
    import io

    buffer = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        buffer, {"descr": dtype, "fortran_order": False, "shape": shape})
    return buffer.getvalue() + bytes(64)


def test_an_array_header_claiming_more_than_its_file_is_refused_unallocated(tmp_path):
    """A 200-byte .npy claiming (10**12, 2) float64 asked numpy for 14.6 TiB: a
    MemoryError traceback that lost the whole ingest (or minutes of swapping)."""
    import zipfile

    from animegraph.motion.files import read_motion
    from db.npyfile import check_npz

    bomb = tmp_path / "c1.npy"
    bomb.write_bytes(_claiming((10**12, 2)))
    with pytest.raises(DataError, match="declares 16000000000000 bytes of data, the file "
                                        "holds 64"):
        load_npy(bomb)
    fine = tmp_path / "fine.npy"
    fine.write_bytes(_claiming((4, 2)))
    assert load_npy(fine).shape == (4, 2)
    motion = tmp_path / "bomb.npz"
    with zipfile.ZipFile(motion, "w") as archive:
        archive.writestr("motion.npy", _claiming((10**12, 216)))
        archive.writestr("fps.npy", _claiming(()))
        archive.writestr("channels.npy", _claiming((1,), "<U3"))
    with pytest.raises(DataError, match="motion.npy declares"):
        read_motion(motion)
    with pytest.raises(DataError, match="unpacks to more than"):
        check_npz(motion, max_bytes=100)


@pytest.mark.parametrize(("dtype", "holds"), [
    ("complex128", "complex numbers"), ("bool", "booleans"), ("datetime64[s]", "dates"),
    ("f8,f8,f8,f8", "records")])
def test_an_array_of_other_than_real_numbers_is_refused_not_cast(tmp_path, dtype, holds):
    """A complex .npy was cast to its real part without a word (booleans to 0 and 1,
    dates to numbers), in a clip and in a motion file."""
    from animegraph.motion.files import read_motion
    from ingest.readers.common import check_motion

    stem = _curve_clip(tmp_path / "rig")
    values = np.load(stem.with_suffix(".npy"))
    odd = (np.rec.fromarrays(values.T, dtype=dtype) if "," in dtype
           else (values + 1j * values if dtype.startswith("complex") else values)
           .astype(dtype))
    np.save(stem.with_suffix(".npy"), odd)
    refused = f"holds {holds} .*; refused: only arrays of real numbers or of text are read"
    with pytest.raises(DataError, match=refused):
        load(_one([tmp_path / "rig"]))
    motion = tmp_path / "motion.npz"
    np.savez(motion, motion=odd, fps=30.0, channels=np.array(["a", "b", "c", "d"]))
    with pytest.raises(DataError, match=rf"motion.npz:motion.npy {refused}"):
        read_motion(motion)
    if "," not in dtype:  # what any reader's motion goes through, from a .npy or not
        with pytest.raises(DataError, match=f"motion holds {holds} .*, not real numbers"):
            check_motion(odd, list("abcd"), stem)


def test_a_motion_file_holds_numbers_and_names_or_is_refused(tmp_path):
    from animegraph.motion.files import read_motion

    path = tmp_path / "m.npz"
    values, names = np.ones((5, 2)), np.array(["jaw", "lip"])
    for arrays, refused in (
            ({"motion": values.astype(str)}, r"motion holds text \(<U32\), not real numbers"),
            ({"channels": np.array([1, 2])}, r"channels holds integers \(int64\), not text"),
            ({"fps": np.array(["30"])}, r"fps holds text \(<U2\), not real numbers"),
            ({"fps": np.array([30.0, 25.0])}, r"needs one fps \(got 2\)")):
        np.savez(path, **{"motion": values, "fps": 30.0, "channels": names, **arrays})
        with pytest.raises(DataError, match=refused):
            read_motion(path)
    np.savez(path, motion=values.astype(np.int16), fps=np.float32(30), channels=names)
    assert read_motion(path).values.dtype == np.float64


def test_a_side_file_linked_to_a_file_outside_the_clip_is_refused(clip_folder, tmp_path):
    """A clip from someone else carried any file the user could read (a key) into the
    database as its transcript; a link inside the clip's folder still reads."""
    secret = tmp_path / "secret_key"
    secret.write_text("-----BEGIN OPENSSH PRIVATE KEY-----")
    transcript = clip_folder.with_suffix(".txt")
    transcript.symlink_to(secret)
    with pytest.raises(DataError, match="is a symbolic link to .*secret_key, outside the "
                                        "clip's folder"):
        load(_one([clip_folder.parent]))
    transcript.unlink()
    inside = clip_folder.parent / "words.txt"
    inside.write_text("the words")
    transcript.symlink_to(inside)
    assert load(_one([clip_folder.parent])).text == "the words"
