"""Round trips and failure modes of the C3D, WAV and phones-CSV readers and writers."""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass

import numpy as np
import pytest
import soundfile

from db.errors import DataError, ParameterError
from ingest.formats import (
    MOTION_READERS,
    MarkerData,
    Segment,
    read_c3d,
    read_phones_csv,
    read_wav,
    write_c3d,
    write_phones_csv,
    write_wav,
)

# --------------------------------------------------------------------------- helpers


def _markers(n_frames: int = 240, n_markers: int = 100, rate: float = 120.0, seed: int = 0):
    rng = np.random.default_rng(seed)
    points = rng.normal(scale=250.0, size=(n_frames, n_markers, 3))
    points[10:40, 3 % n_markers] = np.nan  # a gap of 30 frames
    points[5 % n_frames, 7 % n_markers, 2] = np.nan  # one coordinate lost: marker missing
    if n_markers > 11:
        points[:, 11] = np.nan  # a marker never seen
    points[-1, :5] = np.nan  # gaps up to the last frame
    labels = tuple(f"MK{i:03d}" for i in range(n_markers))
    return MarkerData(points=points, labels=labels, rate=rate)


def _tone(n: int, rate: int, freq: float = 220.0, amp: float = 0.5) -> np.ndarray:
    t = np.arange(n) / rate
    return (amp * np.sin(2 * np.pi * freq * t)).astype(np.float32)


def _leftovers(folder) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".tmp"))


def _fail(*args, **kwargs):
    raise OSError(28, "No space left on device")


# --------------------------------------------------------------------------- C3D


def test_c3d_round_trip_with_gaps(tmp_path):
    data = _markers()
    path = tmp_path / "clip.c3d"
    write_c3d(path, data)
    back = read_c3d(path)

    assert back.labels == data.labels
    assert back.rate == 120.0
    assert back.units == "mm"
    assert back.points.shape == (240, 100, 3)
    assert back.points.dtype == np.float64
    missing = np.isnan(data.points).any(axis=2)
    assert missing[5, 7] and missing[20, 3] and missing[:, 11].all()
    np.testing.assert_array_equal(np.isnan(back.points), np.repeat(missing[:, :, None], 3, 2))
    expected = data.points.astype(np.float32).astype(np.float64)
    np.testing.assert_array_equal(back.points[~missing], expected[~missing])
    assert _leftovers(tmp_path) == []


def test_a_c3d_of_one_marker_is_read_in_a_few_times_its_size(tmp_path):
    """Frames were kept as a list of per-frame arrays, ~100 bytes each of their own: a
    one-marker file (16 bytes a frame) took 22 times its size to read (a 16 MB file
    414 MB); now 6."""
    import tracemalloc

    n = 100_000
    path = tmp_path / "long.c3d"
    write_c3d(path, MarkerData(points=np.zeros((n, 1, 3)) + np.arange(n)[:, None, None],
                               labels=("m1",), rate=120.0))
    tracemalloc.start()
    try:
        back = read_c3d(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert back.points.shape == (n, 1, 3) and back.points[-1, 0, 0] == n - 1
    assert peak < 10 * os.path.getsize(path)


def test_c3d_missing_markers_use_invalid_point_convention(tmp_path):
    import c3d

    data = _markers(n_frames=50, n_markers=12)
    path = tmp_path / "gaps.c3d"
    write_c3d(path, data)
    with open(path, "rb") as handle, warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "No analog data found in file."
        frames = [p for _, p, _ in c3d.Reader(handle).read_frames(check_nan=False)]
    raw = np.stack(frames)  # (n_frames, n_markers, 5)
    missing = data.missing
    assert (raw[missing, 3] == -1).all()
    assert (raw[missing, :3] == 0).all()  # not the marker's last valid position
    assert (raw[~missing, 3] >= 0).all()


def test_c3d_small_and_odd_rates(tmp_path):
    points = np.array([[[1.5, -2.25, 3.0]]])
    write_c3d(tmp_path / "one.c3d", MarkerData(points, ("A",), 59.94))
    back = read_c3d(tmp_path / "one.c3d")
    assert back.points.tolist() == [[[1.5, -2.25, 3.0]]]
    assert back.rate == pytest.approx(59.94, rel=1e-6)
    assert back.labels == ("A",)


def test_c3d_long_labels_and_many_markers(tmp_path):
    labels = tuple(f"upper_lip_marker_{i:03d}_left_side"[:32] for i in range(255))
    assert len(set(labels)) == 255
    data = MarkerData(np.zeros((3, 255, 3)), labels, 120)
    write_c3d(tmp_path / "wide.c3d", data)
    assert read_c3d(tmp_path / "wide.c3d").labels == labels


def test_c3d_with_more_markers_than_one_label_parameter_holds(tmp_path):
    """A face tracked from video (468 landmarks) in one file: the labels past 255 go in
    POINT:LABELS2, LABELS3 ... as C3D.org's manual has it; read back by this reader and by
    ezc3d (the C++ reference implementation), marker for marker."""
    import ezc3d

    rng = np.random.default_rng(3)
    labels = tuple(f"lm{i:03d}" for i in range(600))
    points = rng.normal(0, 50, size=(4, 600, 3))
    points[1, 300] = np.nan  # a gap past the first parameter's markers
    write_c3d(tmp_path / "face.c3d", MarkerData(points, labels, 30))
    back = read_c3d(tmp_path / "face.c3d")
    assert back.labels == labels
    np.testing.assert_allclose(back.points, points.astype(np.float32), equal_nan=True)
    other = ezc3d.c3d(str(tmp_path / "face.c3d"))
    params = other["parameters"]["POINT"]
    assert params["USED"]["value"][0] == 600
    assert [*params["LABELS"]["value"], *params["LABELS2"]["value"],
            *params["LABELS3"]["value"]] == list(labels)
    xyz = np.moveaxis(other["data"]["points"][:3], (0, 1, 2), (2, 1, 0))  # -> frames first
    valid = ~np.isnan(points[:, :, 0])
    np.testing.assert_allclose(xyz[valid], points.astype(np.float32)[valid], rtol=1e-6)


def test_c3d_registry():
    assert MOTION_READERS[".c3d"] is read_c3d


@pytest.mark.parametrize(
    ("kwargs", "word"),
    [
        ({"points": np.zeros((4, 2))}, "points"),
        ({"points": np.zeros((4, 2, 2))}, "points"),
        ({"points": np.zeros((0, 2, 3))}, "points"),
        ({"points": np.full((4, 2, 3), np.inf)}, "points"),
        ({"labels": ("A",)}, "labels"),
        ({"labels": ("A", "A")}, "labels"),
        ({"labels": ("A", "")}, "labels"),
        ({"labels": ("A", " B")}, "labels"),
        ({"labels": ("A", "B" * 33)}, "labels"),
        ({"labels": ("A", "é")}, "labels"),
        ({"labels": "AB"}, "labels"),
        ({"rate": 0.0}, "rate"),
        ({"rate": -120.0}, "rate"),
        ({"rate": float("nan")}, "rate"),
        ({"rate": float("inf")}, "rate"),
        ({"rate": "120"}, "rate"),
    ],
)
def test_marker_data_validation(kwargs, word):
    args = {"points": np.zeros((4, 2, 3)), "labels": ("A", "B"), "rate": 120.0} | kwargs
    with pytest.raises(ParameterError, match=word):
        MarkerData(**args)


def test_write_c3d_bad_arguments(tmp_path):
    with pytest.raises(ParameterError, match="data"):
        write_c3d(tmp_path / "x.c3d", np.zeros((4, 2, 3)))
    with pytest.raises(ParameterError, match="units"):
        write_c3d(tmp_path / "x.c3d", MarkerData(np.zeros((2, 1, 3)), ("A",), 100, units="m"))
    with pytest.raises(ParameterError, match="32768"):
        labels = tuple(f"M{i}" for i in range(32768))
        write_c3d(tmp_path / "x.c3d", MarkerData(np.zeros((1, 32768, 3)), labels, 100))
    with pytest.raises(ParameterError, match="float32"):
        write_c3d(tmp_path / "x.c3d", MarkerData(np.full((2, 1, 3), 1e300), ("A",), 100))
    assert list(tmp_path.iterdir()) == []


@pytest.fixture
def good_c3d(tmp_path):
    path = tmp_path / "good.c3d"
    write_c3d(path, _markers(n_frames=100, n_markers=30))
    return path


@pytest.mark.parametrize(
    "mangle",
    [
        pytest.param(lambda b: b"", id="empty"),
        pytest.param(lambda b: os.urandom(len(b)), id="random-bytes"),
        pytest.param(lambda b: bytes([b[0], 0x50]) + os.urandom(3000), id="random-after-key"),
        pytest.param(lambda b: b[: len(b) // 2], id="cut-in-half"),
        pytest.param(lambda b: b[:600], id="cut-in-parameters"),
        pytest.param(lambda b: b[:100], id="cut-in-header"),
        pytest.param(lambda b: b[: len(b) - 700], id="last-frames-missing"),
        pytest.param(lambda b: b"\0" * len(b), id="zeros"),
    ],
)
def test_read_c3d_corrupt(tmp_path, good_c3d, mangle):
    bad = tmp_path / "bad.c3d"
    bad.write_bytes(mangle(good_c3d.read_bytes()))
    with pytest.raises(DataError, match="bad.c3d"):
        read_c3d(bad)


@pytest.mark.parametrize("cut", [100, 600, 700])
def test_a_c3d_cut_short_is_said_truncated_in_words(tmp_path, good_c3d, cut):
    # It read "corrupt C3D file ...: struct.error: unpack requires a buffer of 1 bytes".
    bad = tmp_path / "bad.c3d"
    bad.write_bytes(good_c3d.read_bytes()[:cut])
    with pytest.raises(DataError) as err:
        read_c3d(bad)
    message = str(err.value)
    assert str(bad) in message and "\n" not in message
    assert "truncated" in message and "struct" not in message and "unpack" not in message


def test_read_c3d_wav_renamed(tmp_path):
    wav = tmp_path / "speech.wav"
    write_wav(wav, _tone(8000, 16000), 16000)
    fake = tmp_path / "speech.c3d"
    os.replace(wav, fake)
    with pytest.raises(DataError, match="speech.c3d"):
        read_c3d(fake)


def test_read_c3d_missing(tmp_path):
    with pytest.raises(DataError, match="nope.c3d"):
        read_c3d(tmp_path / "nope.c3d")
    with pytest.raises(DataError):
        read_c3d(tmp_path)  # a folder


def test_c3d_interrupted_write_keeps_old_file(tmp_path, monkeypatch):
    path = tmp_path / "clip.c3d"
    old = _markers(n_frames=20, n_markers=4, seed=1)
    write_c3d(path, old)
    before = path.read_bytes()

    monkeypatch.setattr(os, "replace", _fail)
    with pytest.raises(DataError, match="clip.c3d"):
        write_c3d(path, _markers(n_frames=30, n_markers=6, seed=2))
    monkeypatch.undo()
    monkeypatch.setattr(os, "fsync", _fail)  # fails after the data went to the temp file
    with pytest.raises(DataError, match="clip.c3d"):
        write_c3d(path, _markers(n_frames=30, n_markers=6, seed=2))
    monkeypatch.undo()

    assert path.read_bytes() == before
    assert _leftovers(tmp_path) == []
    assert read_c3d(path).n_frames == old.n_frames


def test_write_into_missing_folder(tmp_path):
    with pytest.raises(DataError, match="missing"):
        write_c3d(tmp_path / "missing" / "clip.c3d", _markers(n_frames=2, n_markers=1))


# --------------------------------------------------------------------------- WAV


@pytest.mark.parametrize("rate", [16000, 22050])
def test_wav_round_trip(tmp_path, rate):
    audio = _tone(rate // 2, rate)
    write_wav(tmp_path / "a.wav", audio, rate)
    back, back_rate = read_wav(tmp_path / "a.wav")
    assert back_rate == rate
    assert back.dtype == np.float32 and back.shape == audio.shape
    np.testing.assert_allclose(back, audio, atol=1.0 / 32768 + 1e-7)
    assert soundfile.info(str(tmp_path / "a.wav")).subtype == "PCM_16"
    assert _leftovers(tmp_path) == []


def test_wav_stereo_to_mono(tmp_path):
    left, right = _tone(8000, 16000, 200.0, 0.6), _tone(8000, 16000, 310.0, 0.3)
    write_wav(tmp_path / "st.wav", np.stack([left, right], axis=1), 16000)
    mono, _ = read_wav(tmp_path / "st.wav")
    both, _ = read_wav(tmp_path / "st.wav", mono=False)
    assert mono.shape == (8000,) and both.shape == (8000, 2)
    np.testing.assert_allclose(mono, (left + right) / 2, atol=2.0 / 32768)
    np.testing.assert_allclose(both[:, 1], right, atol=1.0 / 32768 + 1e-7)


@pytest.mark.parametrize("subtype", ["PCM_16", "PCM_24", "PCM_32", "FLOAT"])
def test_wav_reads_other_subtypes(tmp_path, subtype):
    audio = _tone(4410, 44100, amp=0.9)
    soundfile.write(str(tmp_path / "s.wav"), audio, 44100, subtype=subtype)
    back, rate = read_wav(tmp_path / "s.wav")
    assert rate == 44100 and back.dtype == np.float32
    np.testing.assert_allclose(back, audio, atol=1.0 / 32768 + 1e-7)


def test_wav_float_file_is_clipped(tmp_path):
    soundfile.write(str(tmp_path / "loud.wav"), np.array([0.5, 1.5, -2.0], np.float32), 8000,
                    subtype="FLOAT")
    back, _ = read_wav(tmp_path / "loud.wav")
    assert back.tolist() == [0.5, 1.0, -1.0]


@pytest.fixture
def good_wav(tmp_path):
    path = tmp_path / "good.wav"
    write_wav(path, _tone(16000, 16000), 16000)
    return path


@pytest.mark.parametrize(
    "mangle",
    [
        pytest.param(lambda b: b"", id="empty"),
        pytest.param(lambda b: os.urandom(len(b)), id="random-bytes"),
        pytest.param(lambda b: b[: len(b) // 2], id="cut-in-half"),
        pytest.param(lambda b: b[: len(b) // 2 + 1], id="cut-mid-sample"),
        pytest.param(lambda b: b[:30], id="cut-in-header"),
        pytest.param(lambda b: b[:44], id="header-only"),
    ],
)
def test_read_wav_corrupt(tmp_path, good_wav, mangle):
    bad = tmp_path / "bad.wav"
    bad.write_bytes(mangle(good_wav.read_bytes()))
    with pytest.raises(DataError, match="bad.wav"):
        read_wav(bad)


def test_read_wav_no_samples_and_missing(tmp_path):
    soundfile.write(str(tmp_path / "silent.wav"), np.zeros(0, np.float32), 16000)
    with pytest.raises(DataError, match="silent.wav"):
        read_wav(tmp_path / "silent.wav")
    with pytest.raises(DataError, match="nope.wav"):
        read_wav(tmp_path / "nope.wav")
    c3d_file = tmp_path / "m.c3d"
    write_c3d(c3d_file, _markers(n_frames=5, n_markers=2))
    with pytest.raises(DataError, match="m.c3d"):
        read_wav(c3d_file)


@pytest.mark.parametrize(
    ("audio", "rate", "word"),
    [
        (np.zeros(0, np.float32), 16000, "audio"),
        (np.zeros((10, 0), np.float32), 16000, "audio"),
        (np.zeros((2, 2, 2), np.float32), 16000, "audio"),
        (np.array([0.0, np.nan], np.float32), 16000, "audio"),
        (np.zeros(10, np.int32), 16000, "audio"),
        (np.zeros(10, np.float32), 0, "sample_rate"),
        (np.zeros(10, np.float32), 16000.0, "sample_rate"),
        (np.zeros(10, np.float32), True, "sample_rate"),
    ],
)
def test_write_wav_bad_arguments(tmp_path, audio, rate, word):
    with pytest.raises(ParameterError, match=word):
        write_wav(tmp_path / "x.wav", audio, rate)
    assert list(tmp_path.iterdir()) == []


def test_wav_interrupted_write_keeps_old_file(tmp_path, monkeypatch):
    path = tmp_path / "take.wav"
    write_wav(path, _tone(1600, 16000), 16000)
    before = path.read_bytes()
    for name in ("replace", "fsync"):
        monkeypatch.setattr(os, name, _fail)
        with pytest.raises(DataError, match="take.wav"):
            write_wav(path, _tone(3200, 16000, 440.0), 16000)
        monkeypatch.undo()
    assert path.read_bytes() == before
    assert _leftovers(tmp_path) == []


# --------------------------------------------------------------------------- phones CSV


@dataclass(frozen=True)
class _Labelled:
    phone: str
    start: float
    end: float
    stress: int = 0


def test_phones_csv_round_trip(tmp_path):
    segments = [
        _Labelled("SIL", 0.0, 0.1234567),
        ("HH", 0.1234567, 0.2),
        Segment("AH", 0.2, 0.25),
        ["L", 0.3, 0.41],  # a gap before it is fine
        _Labelled("OW", 0.41, 0.7, stress=1),
    ]
    path = tmp_path / "clip.phones.csv"
    write_phones_csv(path, segments)
    lines = path.read_text().splitlines()
    assert lines[0] == "start,end,phone"
    assert lines[1] == "0.000000,0.123457,SIL"
    back = read_phones_csv(path)
    assert [s.phone for s in back] == ["SIL", "HH", "AH", "L", "OW"]
    assert all(isinstance(s, Segment) for s in back)
    assert back[1] == ("HH", pytest.approx(0.123457), pytest.approx(0.2))
    assert back[4].duration == pytest.approx(0.29)
    assert _leftovers(tmp_path) == []


def test_phones_csv_empty_list(tmp_path):
    write_phones_csv(tmp_path / "e.phones.csv", [])
    assert read_phones_csv(tmp_path / "e.phones.csv") == []


@pytest.mark.parametrize(
    ("body", "line"),
    [
        ("0.0,0.1,SIL\n0.1,0.2,XX\n", 3),  # unknown phone
        ("0.0,0.1,SIL\n0.1,0.2,a\u0251\n", 3),  # IPA
        ("0.0,0.1,SIL\n0.2,0.2,AA\n", 3),  # start == end
        ("0.0,0.1,SIL\n0.3,0.2,AA\n", 3),  # start > end
        ("0.2,0.3,SIL\n0.0,0.1,AA\n", 3),  # unsorted
        ("0.0,0.2,SIL\n0.1,0.3,AA\n", 3),  # overlap
        ("0.0,0.1,SIL\n0.1,0.2\n", 3),  # missing field
        ("0.0,0.1,SIL,extra\n", 2),
        ("0.0,abc,SIL\n", 2),
        ("0.0,nan,SIL\n", 2),
        ("-0.1,0.1,SIL\n", 2),
    ],
)
def test_read_phones_csv_bad_lines(tmp_path, body, line):
    path = tmp_path / "bad.phones.csv"
    path.write_text("start,end,phone\n" + body)
    with pytest.raises(DataError, match=rf"bad\.phones\.csv:{line}:"):
        read_phones_csv(path)


def test_read_phones_csv_reads_labels_as_the_other_readers_do(tmp_path):
    # It wanted bare upper-case phones where a TextGrid or an HTK .lab may say ah0, sp.
    path = tmp_path / "clip.phones.csv"
    path.write_bytes("\ufeff Start , END,phone\n0,0.1,sp\n0.1,0.2, ah0\n0.2,0.3,HH\n"
                     "0.3,0.4,ax\n".encode())
    assert read_phones_csv(path) == [Segment("SIL", 0.0, 0.1), Segment("AH", 0.1, 0.2),
                                     Segment("HH", 0.2, 0.3), Segment("AH", 0.3, 0.4)]


def test_read_phones_csv_bad_files(tmp_path):
    path = tmp_path / "bad.phones.csv"
    for content in (b"", b"phone,start,end\n0.0,0.1,SIL\n", b"\xff\xfe\x00garbage",
                    b"start;end;phone\n0.0;0.1;SIL\n", b"0.0,0.1,SIL\n"):
        path.write_bytes(content)
        with pytest.raises(DataError, match="bad.phones.csv"):
            read_phones_csv(path)
    with pytest.raises(DataError, match="nope.phones.csv"):
        read_phones_csv(tmp_path / "nope.phones.csv")


@pytest.mark.parametrize(
    ("segments", "word"),
    [
        ([("XX", 0.0, 0.1)], "phone"),
        ([("AA", 0.2, 0.1)], "segments"),
        ([("AA", 0.0, 0.2), ("B", 0.1, 0.3)], "overlaps"),
        ([("AA", 0.5, 0.6), ("B", 0.1, 0.3)], "before"),
        ([("AA", -1.0, 0.1)], "start"),
        ([("AA", 0.0, float("inf"))], "end"),
        ([("AA", 0.0, "x")], "end"),
        ([("AA", 0.0)], "segments"),
        ([42], "segments"),
        ("AA", "segments"),
    ],
)
def test_write_phones_csv_bad_arguments(tmp_path, segments, word):
    with pytest.raises(ParameterError, match=word):
        write_phones_csv(tmp_path / "x.phones.csv", segments)
    assert list(tmp_path.iterdir()) == []


def test_phones_csv_interrupted_write_keeps_old_file(tmp_path, monkeypatch):
    path = tmp_path / "clip.phones.csv"
    write_phones_csv(path, [("SIL", 0.0, 0.5)])
    before = path.read_bytes()
    for name in ("replace", "fsync"):
        monkeypatch.setattr(os, name, _fail)
        with pytest.raises(DataError, match="clip.phones.csv"):
            write_phones_csv(path, [("SIL", 0.0, 0.2), ("AA", 0.2, 0.4)])
        monkeypatch.undo()
    assert path.read_bytes() == before
    assert _leftovers(tmp_path) == []


def test_a_motion_goes_to_the_file_type_that_keeps_every_channel(tmp_path, caplog):
    """C3D for points alone; a landmark database's head pose goes to CSV (batch, query
    --export); ``-o x.c3d`` asked for all the same says what it leaves out."""
    import logging

    from animegraph.motion.files import (
        LIVELINK_SUFFIX,
        check_output,
        motion_suffix,
        write_channels,
    )
    from ingest.formats.livelink import ARKIT_BLENDSHAPES

    points = [f"m{i}.{a}" for i in range(3) for a in "xyz"]
    pose = ["pose.rx", "pose.ry", "pose.rz", "pose.tx", "pose.ty", "pose.tz", "pose.scale"]
    assert motion_suffix(points, "markers") == ".c3d"
    assert motion_suffix(points, "landmarks") == ".c3d"
    assert motion_suffix(points + pose, "landmarks") == ".csv"
    assert motion_suffix(["jaw_open", "mouth_oh"], "curves") == ".csv"
    assert motion_suffix(list(ARKIT_BLENDSHAPES), "curves") == LIVELINK_SUFFIX
    motion = np.random.default_rng(0).normal(size=(5, len(points) + len(pose)))
    with caplog.at_level(logging.WARNING, logger="animegraph.motion.files"):
        check_output(tmp_path / "face.c3d", points + pose, "landmarks")  # before the work
    assert "the 7 channels that are not a point's (pose.rx, pose.ry, pose.rz, pose.tx ...)" \
        " are left out" in caplog.text
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="animegraph.motion.files"):
        # not again as it is written (batch's workers wrote it amid the progress bar)
        write_channels(motion, 30.0, points + pose, "landmarks", tmp_path / "face.c3d")
    assert caplog.text == ""
    back = read_c3d(tmp_path / "face.c3d")
    assert back.labels == ("m0", "m1", "m2")
    np.testing.assert_allclose(back.points.reshape(5, -1), motion[:, :9], rtol=1e-5)
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="animegraph.motion.files"):
        check_output(tmp_path / "markers.c3d", points, "markers")
        write_channels(motion[:, :9], 30.0, points, "markers", tmp_path / "markers.c3d")
    assert caplog.text == ""


def test_read_phones_csv_forgives_the_rounding_other_tools_leave(tmp_path):
    """A neighbour overlapping by less than ORDER_TOLERANCE (a float written by another
    tool) is read, as the .lab and TextGrid readers read it; more is an error."""
    from ingest.formats.phones_csv import read_phones_csv

    path = tmp_path / "a.phones.csv"
    path.write_text("start,end,phone\n0,0.30000000001,AA\n0.3,0.5,B\n")
    assert [s.phone for s in read_phones_csv(path)] == ["AA", "B"]
    path.write_text("start,end,phone\n0,0.301,AA\n0.3,0.5,B\n")
    with pytest.raises(DataError, match=":3: start 0.3 overlaps"):
        read_phones_csv(path)
