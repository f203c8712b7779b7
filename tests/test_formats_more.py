"""Round trips and failure modes of the TextGrid, HTK label, TRC and marker-CSV formats."""

from __future__ import annotations

import numpy as np
import pytest

from db.errors import DataError, ParameterError
from ingest.formats import (
    MOTION_READERS,
    MarkerData,
    Segment,
    read_htk_lab,
    read_marker_csv,
    read_textgrid,
    read_trc,
    to_arpabet,
    write_htk_lab,
    write_marker_csv,
    write_textgrid,
    write_trc,
)
from ingest.formats.phones_csv import read_phones_csv
from ingest.formats.textgrid import read_tiers
from ingest.formats.words import read_grid_align

SEGMENTS = [
    Segment("SIL", 0.0, 0.12),
    Segment("HH", 0.12, 0.185),
    Segment("AH", 0.185, 0.31),
    Segment("L", 0.31, 0.4),
    Segment("OW", 0.4, 0.62),
    Segment("SIL", 0.62, 0.9),
]


def _markers(n_frames: int = 60, n_markers: int = 5, rate: float = 120.0, seed: int = 0):
    rng = np.random.default_rng(seed)
    points = rng.normal(scale=80.0, size=(n_frames, n_markers, 3))
    points[5:12, 1] = np.nan  # a gap
    points[-3:, n_markers - 1] = np.nan  # the last marker lost at the end (rows cut short)
    labels = tuple(f"M{i}" for i in range(n_markers - 1)) + ("lip.corner_l",)
    return MarkerData(points=points, labels=labels, rate=rate)


# --------------------------------------------------------------------------- labels


@pytest.mark.parametrize(
    ("label", "phone"),
    [("AH0", "AH"), ("ah1", "AH"), (" ey2 ", "EY"), ("SIL", "SIL"), ("sil", "SIL"),
     ("sp", "SIL"), ("<sil>", "SIL"), ("spn", "SIL"), ("", "SIL"), ("  ", "SIL"),
     ("pau", "SIL"), ("h#", "SIL"), ("ax", "AH"), ("AXR", "ER"), ("zh", "ZH"), ("NG", "NG")],
)
def test_to_arpabet(label, phone):
    assert to_arpabet(label) == phone


def test_to_arpabet_rejects_unknown_labels():
    for bad in ("xyz", "a:", "ʃ", "1"):
        # MFA's IPA and WebMAUS' SAMPA were refused without saying what is read
        with pytest.raises(DataError, match=r"unknown phone label .* are ARPAbet.*not IPA"):
            to_arpabet(bad)
    with pytest.raises(ParameterError):
        to_arpabet(3)


# --------------------------------------------------------------------------- TextGrid

PRAAT_LONG = '''File type = "ooTextFile"
Object class = "TextGrid"

xmin = 0
xmax = 0.9
tiers? <exists>
size = 3
item []:
    item [1]:
        class = "IntervalTier"
        name = "words"
        xmin = 0
        xmax = 0.9
        intervals: size = 2
        intervals [1]:
            xmin = 0
            xmax = 0.4
            text = "say ""hello"""
        intervals [2]:
            xmin = 0.4
            xmax = 0.9
            text = ""
    item [2]:
        class = "IntervalTier"
        name = "Phones"
        xmin = 0
        xmax = 0.9
        intervals: size = 4
        intervals [1]:
            xmin = 0
            xmax = 0.1
            text = ""
        intervals [2]:
            xmin = 0.1
            xmax = 0.25
            text = "S"
        intervals [3]:
            xmin = 0.25
            xmax = 0.4
            text = "EY1"
        intervals [4]:
            xmin = 0.4
            xmax = 0.9
            text = "spn"
    item [3]:
        class = "TextTier"
        name = "events"
        xmin = 0
        xmax = 0.9
        points: size = 1
        points [1]:
            number = 0.3
            mark = "click"
'''


def test_textgrid_long_round_trip(tmp_path):
    path = tmp_path / "a.TextGrid"
    write_textgrid(path, SEGMENTS)
    assert path.read_text().startswith('File type = "ooTextFile"\nObject class = "TextGrid"')
    assert "intervals [6]:" in path.read_text()
    assert read_textgrid(path) == SEGMENTS


def test_textgrid_short_round_trip_utf16(tmp_path):
    path = tmp_path / "a.TextGrid"
    write_textgrid(path, SEGMENTS, short=True, encoding="utf-16", tier="Phönes")
    raw = path.read_bytes()
    assert raw[:2] in (b"\xff\xfe", b"\xfe\xff")  # UTF-16 with a byte-order mark
    assert "intervals" not in raw.decode("utf-16")
    assert read_textgrid(path) == SEGMENTS  # the only interval tier
    assert read_textgrid(path, tier="Phönes") == SEGMENTS


def test_textgrid_utf16_big_endian_without_bom(tmp_path):
    path = tmp_path / "a.TextGrid"
    write_textgrid(path, SEGMENTS)
    path.write_bytes(path.read_text().encode("utf-16-be"))
    assert read_textgrid(path) == SEGMENTS


def test_textgrid_gaps_become_silence(tmp_path):
    path = tmp_path / "gaps.TextGrid"
    write_textgrid(path, [("AA", 0.1, 0.2), ("B", 0.3, 0.4)], xmax=0.5)
    assert read_textgrid(path) == [
        Segment("SIL", 0.0, 0.1), Segment("AA", 0.1, 0.2), Segment("SIL", 0.2, 0.3),
        Segment("B", 0.3, 0.4), Segment("SIL", 0.4, 0.5),
    ]


def test_textgrid_praat_file_with_several_tiers(tmp_path):
    path = tmp_path / "praat.TextGrid"
    path.write_text(PRAAT_LONG)
    tiers = read_tiers(path)
    assert [(t.kind, t.name) for t in tiers] == [
        ("IntervalTier", "words"), ("IntervalTier", "Phones"), ("TextTier", "events")]
    assert tiers[0].items[0][2] == 'say "hello"'  # doubled quotes
    # "Phones" is found case-insensitively; stress digits go, "" and spn are silence
    assert read_textgrid(path) == [
        Segment("SIL", 0.0, 0.1), Segment("S", 0.1, 0.25), Segment("EY", 0.25, 0.4),
        Segment("SIL", 0.4, 0.9),
    ]
    with pytest.raises(DataError, match=r"praat\.TextGrid:18: unknown phone label 'say"):
        read_textgrid(path, tier="words")  # words are not phones: named with their line
    with pytest.raises(DataError, match="point tier"):
        read_textgrid(path, tier="events")
    with pytest.raises(DataError, match=r"no tier named 'nope' \(tiers: \['words'"):
        read_textgrid(path, tier="nope")


def test_textgrid_without_phone_tier_uses_the_last_interval_tier(tmp_path):
    path = tmp_path / "t.TextGrid"
    write_textgrid(path, SEGMENTS, tier="mau")
    assert read_textgrid(path) == SEGMENTS


def test_textgrid_unknown_label_names_line(tmp_path):
    path = tmp_path / "bad.TextGrid"
    write_textgrid(path, SEGMENTS)
    text = path.read_text().replace('text = "OW"', 'text = "QQ"')
    path.write_text(text)
    line = text.splitlines().index('            text = "QQ" ') + 1
    with pytest.raises(DataError, match=rf"bad\.TextGrid:{line}: unknown phone label 'QQ'"):
        read_textgrid(path)


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"", "empty"),
        (b"ooBinaryFile\x08TextGrid", "binary TextGrid"),
        (b'File type = "ooTextFile"\nObject class = "Sound"\n', "not 'TextGrid'"),
        (b"hello", "not a Praat TextGrid"),
        (b'"ooTextFile" 3', r"c\.TextGrid:1: expected the object class"),
        (b"\xff\xff\xfe\x00 not text", "neither UTF-8 nor UTF-16"),
    ],
)
def test_textgrid_corrupt_files(tmp_path, content, message):
    path = tmp_path / "c.TextGrid"
    path.write_bytes(content)
    with pytest.raises(DataError, match=message):
        read_textgrid(path)


def test_textgrid_truncated_and_malformed(tmp_path):
    path = tmp_path / "t.TextGrid"
    write_textgrid(path, SEGMENTS)
    full = path.read_text()
    path.write_text(full[: len(full) * 2 // 3])
    with pytest.raises(DataError, match="truncated TextGrid|unterminated string"):
        read_textgrid(path)
    path.write_text(full[: full.rindex("xmax")])
    with pytest.raises(DataError, match=r"truncated TextGrid .*interval xmax"):
        read_textgrid(path)
    path.write_text(full.replace("xmax = 0.185", "xmax = 0.1"))
    with pytest.raises(DataError, match="interval start 0.12 is not before end 0.1"):
        read_textgrid(path)
    with pytest.raises(DataError, match="not found"):
        read_textgrid(tmp_path / "missing.TextGrid")


def test_write_textgrid_rejects_bad_segments(tmp_path):
    with pytest.raises(ParameterError, match="unknown phone"):
        write_textgrid(tmp_path / "x.TextGrid", [("sp", 0.0, 1.0)])
    with pytest.raises(ParameterError, match="overlaps"):
        write_textgrid(tmp_path / "x.TextGrid", [("AA", 0.0, 1.0), ("B", 0.5, 1.5)])
    with pytest.raises(ParameterError, match="xmax"):
        write_textgrid(tmp_path / "x.TextGrid", SEGMENTS, xmax=0.5)
    assert not (tmp_path / "x.TextGrid").exists()


# --------------------------------------------------------------------------- HTK lab


def test_htk_lab_round_trip(tmp_path):
    path = tmp_path / "a.lab"
    write_htk_lab(path, SEGMENTS)
    assert path.read_text().splitlines()[1] == "1200000 1850000 HH"
    assert read_htk_lab(path) == SEGMENTS


def test_htk_lab_variants(tmp_path):
    path = tmp_path / "v.lab"
    # extra columns (score, word), stress digits, silence names, a second transcription
    path.write_text("0 1000000 sil -12.5\n1000000 2500000 hh -3.1 hello\n"
                    "2500000 4000000 ah0\n4000000 5000000 sp\n///\n0 5000000 AA\n")
    assert read_htk_lab(path) == [Segment("SIL", 0.0, 0.1), Segment("HH", 0.1, 0.25),
                                  Segment("AH", 0.25, 0.4), Segment("SIL", 0.4, 0.5)]
    path.write_text("0.0 0.25 sil\n0.25 0.5 AA1\n")  # seconds (WaveSurfer style)
    assert read_htk_lab(path) == [Segment("SIL", 0.0, 0.25), Segment("AA", 0.25, 0.5)]
    path.write_text("0 500000 xx^pau-pau+hh=ax@x_x\n500000 1500000 pau^pau-hh+ax=l@1_1\n")
    assert read_htk_lab(path) == [Segment("SIL", 0.0, 0.05), Segment("HH", 0.05, 0.15)]


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("0 100 AA\n100 200 QX\n", r"bad\.lab:2: unknown phone label 'QX'"),
        ("0 100 AA\n100\n", r"bad\.lab:2: expected 'start end label'"),
        ("0 100 AA\n50 200 B\n", r"bad\.lab:2: start .* overlaps"),
        ("0 100 AA\n200 100 B\n", r"bad\.lab:2: start .* not before end"),
        ("0 100 AA\n0.1 0.2 B\n", r"bad\.lab:2: mixes integer"),
        ("0 x AA\n", r"bad\.lab:1: bad time"),
        ("\n\n", "has no labels"),
    ],
)
def test_htk_lab_bad_files(tmp_path, content, message):
    path = tmp_path / "bad.lab"
    path.write_text(content)
    with pytest.raises(DataError, match=message):
        read_htk_lab(path)


# --------------------------------------------------------------------------- TRC


def test_trc_round_trip_with_gaps(tmp_path):
    data = _markers()
    path = tmp_path / "m.trc"
    write_trc(path, data)
    lines = path.read_text().splitlines()
    assert lines[0].startswith("PathFileType\t4")
    assert lines[2].split("\t")[:5] == ["120.0", "120.0", "60", "5", "mm"]
    assert lines[-1].endswith("\t\t\t")  # the last marker is missing: empty cells
    back = read_trc(path)
    assert back.labels == data.labels
    assert back.rate == 120.0
    np.testing.assert_allclose(back.points, data.points, atol=1e-5)
    assert np.array_equal(back.missing, data.missing)
    # Some writers cut rows short after the last marker seen: the rest is missing.
    path.write_text("\n".join(line.rstrip("\t") for line in lines) + "\n")
    np.testing.assert_allclose(read_trc(path).points, data.points, atol=1e-5)
    assert MOTION_READERS[".trc"] is read_trc


def test_trc_units_converted_to_mm(tmp_path):
    path = tmp_path / "m.trc"
    path.write_text(
        "PathFileType\t4\t(X/Y/Z)\tm.trc\n"
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\n"
        "60\t60\t2\t2\tm\n"
        "Frame#\tTime\tA\t\t\tB\n"
        "\t\tX1\tY1\tZ1\tX2\tY2\tZ2\n"
        "1\t0\t0.1\t0.2\t0.3\t1\t2\t3\n"
        "2\t0.016667\t0.1\t\t0.3\t1\t2\t3\n"
    )
    data = read_trc(path)
    assert data.rate == 60.0 and data.labels == ("A", "B")
    np.testing.assert_allclose(data.points[0], [[100, 200, 300], [1000, 2000, 3000]])
    assert data.missing.tolist() == [[False, False], [True, False]]


def test_trc_bad_files(tmp_path):
    data = _markers()
    path = tmp_path / "m.trc"
    write_trc(path, data)
    full = path.read_text()
    lines = full.splitlines()
    path.write_text("\n".join(lines[:-10]) + "\n")
    with pytest.raises(DataError, match="truncated TRC file .*NumFrames is 60, found 50"):
        read_trc(path)
    path.write_text(full.replace(lines[8].split("\t")[3], "abc", 1))
    with pytest.raises(DataError, match=r"m\.trc:9: coordinate 2 is not a number"):
        read_trc(path)
    path.write_text(full.replace("\tmm\t", "\tinches\t", 1))
    with pytest.raises(DataError, match="unknown Units"):
        read_trc(path)
    path.write_text(full.replace("\t5\tmm", "\t6\tmm", 1))
    with pytest.raises(DataError, match="NumMarkers is 6 but 5 names"):
        read_trc(path)
    path.write_text("frame,time\n1,0\n")
    with pytest.raises(DataError, match="not a TRC file"):
        read_trc(path)


# --------------------------------------------------------------------------- marker CSV


def test_marker_csv_round_trip(tmp_path):
    data = _markers()
    path = tmp_path / "m.csv"
    write_marker_csv(path, data)
    assert path.read_text().splitlines()[0].startswith("frame,time,M0.x,M0.y,M0.z,M1.x")
    back = read_marker_csv(path)
    assert back.labels == data.labels  # "lip.corner_l" keeps its dot
    assert back.rate == 120.0
    np.testing.assert_allclose(back.points, data.points, atol=1e-5)
    assert MOTION_READERS[".csv"] is read_marker_csv


@pytest.mark.parametrize("rate", [120.0, 100.0, 30000 / 1001, 59.94, 25.0])
def test_marker_csv_infers_rate(tmp_path, rate):
    data = _markers(n_frames=40, rate=rate)
    path = tmp_path / "m.csv"
    write_marker_csv(path, data)
    assert read_marker_csv(path).rate == pytest.approx(rate, rel=2e-5)


def test_marker_csv_two_frames_snap_to_whole_rate(tmp_path):
    path = tmp_path / "m.csv"
    write_marker_csv(path, _markers(n_frames=2, rate=120.0))
    assert read_marker_csv(path).rate == 120.0


def test_marker_csv_skipped_frames_are_missing(tmp_path):
    path = tmp_path / "m.csv"
    path.write_text("frame,time,a.x,a.y,a.z\n10,0.1,1,2,3\n11,0.11,1,2,3\n13,0.13,4,5,6\n")
    data = read_marker_csv(path)
    assert data.rate == 100.0 and data.n_frames == 4
    assert data.missing[:, 0].tolist() == [False, False, True, False]


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("", "empty"),
        ("frame,t,a.x,a.y,a.z\n", "expected header"),
        ("frame,time,a.x,a.y,b.z\n", r"not '<label>\.x"),
        ("frame,time,a.x,a.y,a.z\n0,0,1,2,3\n", "fewer than 2 frames"),
        ("frame,time,a.x,a.y,a.z\n0,0,1,2,3\n1,0.01,1,2\n", r"m\.csv:3: expected 5 fields"),
        ("frame,time,a.x,a.y,a.z\n0,0,1,2,3\n1,0.01,1,x,3\n", r"m\.csv:3: a value is not"),
        ("frame,time,a.x,a.y,a.z\n1,0,1,2,3\n1,0.01,1,2,3\n", r"m\.csv:3: frame 1 does not"),
        ("frame,time,a.x,a.y,a.z\n0,0,1,2,3\n1,0.01,1,2,3\n2,0.02,1,2,3\n3,0.1,1,2,3\n",
         "irregular times"),
        ("frame,time,a.x,a.y,a.z\n0,0.1,1,2,3\n1,0.1,1,2,3\n", "times do not increase"),
    ],
)
def test_marker_csv_bad_files(tmp_path, content, message):
    path = tmp_path / "m.csv"
    path.write_text(content)
    with pytest.raises(DataError, match=message):
        read_marker_csv(path)


def test_text_writers_reject_bad_data(tmp_path):
    data = _markers()
    cm = MarkerData(points=data.points, labels=data.labels, rate=data.rate, units="cm")
    for write in (write_trc, write_marker_csv):
        with pytest.raises(ParameterError, match="units"):
            write(tmp_path / "x", cm)
        with pytest.raises(ParameterError, match="MarkerData"):
            write(tmp_path / "x", data.points)
    comma = MarkerData(points=data.points[:, :1], labels=("a,b",), rate=data.rate)
    with pytest.raises(ParameterError, match="CSV column"):
        write_marker_csv(tmp_path / "x.csv", comma)
    assert list(tmp_path.iterdir()) == []


def test_side_files_past_the_bound_are_refused_before_they_are_parsed(tmp_path):
    # Parsed, a label costs ~80 bytes however short it is written (a TextGrid of 17.5 MB of
    # two-byte values took 1.4 GB and 27 s): side files stop at MAX_SIDE_FILE_BYTES
    from animegraph.face.mesh import canonical_mesh, read_marker_map
    from ingest.formats.text import MAX_SIDE_FILE_BYTES
    from ingest.readers.common import read_transcript

    big = tmp_path / "big"  # not text either: without the bound, refused as such at once
    big.write_bytes(b"\x80" * (MAX_SIDE_FILE_BYTES + 1))
    readers = {"x.TextGrid": read_tiers, "x.align": read_grid_align, "x.lab": read_htk_lab,
               "x.phones.csv": read_phones_csv, "x.txt": read_transcript,
               "x.csv": lambda p: read_marker_map(p, canonical_mesh())}
    for name, read in readers.items():
        (tmp_path / name).hardlink_to(big)
        with pytest.raises(DataError, match=rf"{name} is larger than 16,777,216 bytes$"):
            read(tmp_path / name)


def _tg(rows) -> str:
    """A TextGrid (Praat's long text format) of one interval tier ``phones``."""
    items = "".join(f"        intervals [{k}]:\n            xmin = {a}\n            xmax = {b}\n"
                    f"            text = \"{p}\"\n" for k, (p, a, b) in enumerate(rows, 1))
    return ('File type = "ooTextFile"\nObject class = "TextGrid"\n\nxmin = 0\nxmax = 1\n'
            'tiers? <exists>\nsize = 1\nitem []:\n    item [1]:\n        class = '
            '"IntervalTier"\n        name = "phones"\n        xmin = 0\n        xmax = 1\n'
            f"        intervals: size = {len(rows)}\n{items}")


@pytest.mark.parametrize(("rows", "problem"), [
    ([("AA", 0.0, 0.2), ("B", 0.1, 0.3)], "start 0.1 overlaps the previous segment ending 0.2"),
    ([("AA", 0.0, 0.2), ("B", 0.3, 0.25)], "start 0.3 is not before end 0.25"),
    ([("AA", 0.0, 0.2), ("QQ", 0.2, 0.3)], "unknown phone label 'QQ'"),
])
def test_the_phone_readers_say_the_same_of_the_same_fault(tmp_path, rows, problem):
    """The phones CSV, TextGrid and HTK label readers check a segment one way
    (``ingest.formats.phones_csv.append_read``): the same fault, the same words, each
    after the file and line it is on; an overlap within ORDER_TOLERANCE is forgiven."""
    files = {
        "p.csv": ("start,end,phone\n" + "".join(f"{a},{b},{p}\n" for p, a, b in rows),
                  read_phones_csv, 3),
        "p.lab": ("".join(f"{round(a * 1e7)} {round(b * 1e7)} {p}\n" for p, a, b in rows),
                  read_htk_lab, 2),
        "p.TextGrid": (_tg(rows), read_textgrid, None),
    }
    for name, (text, read, line) in files.items():
        path = tmp_path / name
        path.write_text(text)
        with pytest.raises(DataError) as caught:
            read(path)
        message = str(caught.value)
        assert message.startswith(f"{path}:{line or ''}") and problem in message, message
    close = [("AA", 0.0, 0.2), ("B", 0.2 - 1e-10, 0.3)]
    path = tmp_path / "close.csv"
    path.write_text("start,end,phone\n" + "".join(f"{a!r},{b},{p}\n" for p, a, b in close))
    assert [s.phone for s in read_phones_csv(path)] == ["AA", "B"]
