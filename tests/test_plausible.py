"""Plausibility checks at ingest: one bad clip never poisons a database (issue #18)."""

from __future__ import annotations

import json
import shutil
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

from db.errors import DataError
from db.store import Database
from ingest.clip import ChannelSchema, RawClip
from ingest.formats import Segment
from ingest.formats.c3d import MarkerData, read_c3d, write_c3d
from ingest.plausible import Limits, check_clip, check_label
from ingest.readers import discover, load


def _clip(motion, *, fps=100.0, kind="markers", names=None, **fields) -> RawClip:
    n_points = motion.shape[1] // 3
    schema = (ChannelSchema.for_points(kind, [f"m{i}" for i in range(n_points)],
                                       ["lips"] * n_points, "mm")
              if names is None else ChannelSchema(kind, tuple(names), ("other",) * len(names),
                                                   "unit"))
    audio = np.zeros(int(16000 * len(motion) / fps), np.float32)
    return RawClip(clip_id=fields.pop("clip_id", "c1"), corpus="k", source=Path("c1.c3d"),
                   motion=motion, fps=fps, schema=schema, audio=audio, sample_rate=16000,
                   checksum="0", **fields)


def _walk(rng, n=300, points=4):
    # Smooth face-like tracks: ~100 mm from the origin, moving a few mm.
    t = np.arange(n)[:, None] / 100.0
    base = rng.normal(0, 50, size=(1, 3 * points)) + 100
    return base + 3 * np.sin(2 * np.pi * (0.5 + rng.random((1, 3 * points))) * t)


@pytest.mark.parametrize("value, what", [
    ("__HIVE_DEFAULT_PARTITION__", "reserves"), ("NULL", "reserves"), ("x" * 300, "300 char"),
    ("x" * 1_000_000, "1000000 char"), ("hap\x00py", "control"), ("a/b", "separator"),
    ("..", "separator"), ("happy\n", "control"), ("__x", "reserves"), ("h=appy", "letters"),
])
def test_bad_emotions_are_refused_in_one_short_line(value, what):
    with pytest.raises(DataError, match=what) as err:
        check_label(value, "emotion", emotion=True)
    assert "\n" not in str(err.value) and len(str(err.value)) < 200


def test_good_labels_pass():
    for value in ("happy", "Neutral", "angry-2", "fear+surprise", "wütend"[:0] + "sad"):
        check_label(value, "emotion", emotion=True)
    check_label("US senator (not named), from a public speech", "speaker")


def test_emotion_labels_are_lowercased(rng):
    """``Happy`` and ``happy`` are one emotion (and one partition folder on macOS)."""
    clip, _ = check_clip(_clip(_walk(rng), emotion="Happy"))
    assert clip.emotion == "happy"
    assert check_clip(_clip(_walk(rng)))[0].emotion is None


def test_absurd_phones_are_rejected(rng):
    motion = _walk(rng)
    tiny = tuple(Segment("AA", i * 4e-6, (i + 1) * 4e-6) for i in range(1000))
    with pytest.raises(DataError, match="shorter than one analysis frame"):
        check_clip(_clip(motion, phones=tiny))
    many = tuple(Segment("AA", i * 0.011, (i + 1) * 0.011) for i in range(272))
    with pytest.raises(DataError, match="per second"):
        check_clip(_clip(motion, phones=many))
    fine = (Segment("SIL", 0.0, 0.5), Segment("AA", 0.5, 0.6), Segment("SIL", 0.6, 3.0))
    assert check_clip(_clip(motion, phones=fine))[1] == ""
    # eSpeak NG's occasional 6 ms phone among normal ones is speech, not an attack.
    speech = tuple(Segment("AA", 0.1 * i, 0.1 * i + (0.006 if i == 5 else 0.1))
                   for i in range(20))
    assert check_clip(_clip(motion, phones=speech))[1] == ""
    one_us = speech[:5] + (Segment("B", 0.5, 0.500001),) + speech[6:]
    with pytest.raises(DataError, match="shorter than one analysis frame"):
        check_clip(_clip(motion, phones=one_us))


@pytest.mark.parametrize("value", [4.4e6, 3e38, -2e5])
def test_a_one_frame_spike_becomes_a_dropout(rng, value):
    motion = _walk(rng)
    spiked = motion.copy()
    spiked[120, 4] = value
    out, note = check_clip(_clip(spiked))
    assert "1 implausible sample" in note and "m1" in note and "dropout" in note
    assert np.isnan(out.motion[120, 3:6]).all()
    np.testing.assert_array_equal(np.delete(out.motion, 120, axis=0),
                                  np.delete(motion, 120, axis=0))


def test_a_jump_faster_than_the_limit_is_a_dropout_or_rejects(rng):
    motion = _walk(rng)
    jumped = motion.copy()
    jumped[50:53, 0] += 80.0  # 80 mm in 10 ms: 8 m/s
    _, note = check_clip(_clip(jumped))
    assert "3 implausible" in note and "mm/s" in note
    _, note = check_clip(_clip(jumped), Limits(max_speed_mm_s=10_000))  # configurable
    assert note == ""
    jumped[50:200, 0] += 80.0  # a step that lasts: a swapped label, not a dropout
    with pytest.raises(DataError, match="m0 implausible .*more than a dropout"):
        check_clip(_clip(jumped))


def test_dead_constant_and_infinite_tracks_reject_the_clip(rng):
    motion = _walk(rng)
    dead = motion.copy()
    dead[:, 6:9] = 0.0
    with pytest.raises(DataError, match="m2 never moves"):
        check_clip(_clip(dead))
    with pytest.raises(DataError, match="never moves"):
        check_clip(_clip(np.ones_like(motion)))
    inf = motion.copy()
    inf[3, 3] = np.inf
    with pytest.raises(DataError, match="infinite"):
        check_clip(_clip(inf))
    far = motion.copy()
    far[:, 0] = 3e38
    with pytest.raises(DataError, match="beyond 10000 mm"):
        check_clip(_clip(far))


def test_curves_are_range_checked_and_may_hold_still_channels(rng):
    curves = np.clip(rng.random((100, 3)), 0, 1)
    curves[:, 2] = 0.0  # an unused blendshape: fine for curves
    assert check_clip(_clip(curves, kind="curves", names=["a", "b", "c"]))[1] == ""
    curves[10, 1] = 1e9
    out, note = check_clip(_clip(curves, kind="curves", names=["a", "b", "c"]))
    assert "b" in note and np.isnan(out.motion[10, 1])


# --------------------------------------------------------------------------- through ingest


def _copy(corpus: Path, stem: str, dest: Path, new_stem: str | None = None) -> Path:
    new_stem = new_stem or stem
    for suffix in (".c3d", ".wav", ".phones.csv", ".json"):
        shutil.copy(corpus / "clips" / f"{stem}{suffix}", dest / "clips" / f"{new_stem}{suffix}")
    return dest / "clips" / f"{new_stem}.c3d"


def _poison(path: Path, frames: slice, marker: int, value: float, axes=1) -> None:
    data = read_c3d(path)
    points = data.points.copy()
    points[frames, marker, axes] = value
    write_c3d(path, MarkerData(points, data.labels, data.rate, data.units))


def _folder(corpus: Path, dest: Path) -> Path:
    (dest / "clips").mkdir(parents=True)
    for name in ("corpus.json", "markers.csv"):
        shutil.copy(corpus / name, dest / name)
    return dest


def test_bad_clips_do_not_change_the_model_of_the_good_ones(tiny_corpus, tmp_path):
    from ingest.pipeline import ingest

    stems = sorted(p.stem for p in (tiny_corpus / "clips").glob("*.c3d"))
    good = [s for s in stems if s.startswith("s0001_")][:4]
    spares = [s for s in stems if s.startswith("s0002_")][:2]
    clean = _folder(tiny_corpus, tmp_path / "clean")
    for s in good:
        _copy(tiny_corpus, s, clean)
    dirty = _folder(tiny_corpus, tmp_path / "dirty")
    for s in good:
        _copy(tiny_corpus, s, dirty)
    _poison(dirty / "clips" / f"{good[0]}.c3d", slice(40, 41), 30, 4.4e6)  # a flipped byte
    _poison(dirty / "clips" / f"{good[1]}.c3d", slice(70, 71), 10, 3e38)
    _poison(_copy(tiny_corpus, spares[0], dirty, "zz_dead"), slice(None), 5, 0.0, axes=slice(None))
    _poison(_copy(tiny_corpus, spares[1], dirty, "zz_far"), slice(10, 200), 3, 3e38)
    meta = dirty / "clips" / "zz_deep.json"
    _copy(tiny_corpus, spares[1], dirty, "zz_deep")
    meta.write_text("[" * 100_000 + "]" * 100_000)
    _copy(tiny_corpus, spares[1], dirty, "zz_label")
    label = json.loads((dirty / "clips" / "zz_label.json").read_text())
    (dirty / "clips" / "zz_label.json").write_text(
        json.dumps({**label, "emotion": "__HIVE_DEFAULT_PARTITION__"}))

    clean_report = ingest([clean], tmp_path / "clean.db")
    report = ingest([dirty], tmp_path / "dirty.db")
    by_id = {c.clip_id: c for c in report.clips}
    assert {k for k, c in by_id.items() if c.status == "rejected"} == {
        "zz_dead", "zz_far", "zz_deep", "zz_label"}
    assert "never moves" in by_id["zz_dead"].reason
    assert "more than a dropout" in by_id["zz_far"].reason
    assert "nested too deeply" in by_id["zz_deep"].reason
    assert "reserves" in by_id["zz_label"].reason
    assert "filled as dropouts" in by_id[good[0]].note
    assert "filled as dropouts" in by_id[good[1]].note
    assert clean_report.summary["n_pcs"] == report.summary["n_pcs"]
    a, b = Database.open(tmp_path / "clean.db"), Database.open(tmp_path / "dirty.db")
    mean_a, mean_b = a.arrays()["channel_mean"], b.arrays()["channel_mean"]
    assert np.abs(mean_a - mean_b).max() < 0.5  # mm: the spikes were filled, not fitted
    assert abs(clean_report.summary["variance_kept"] - report.summary["variance_kept"]) < 0.01
    frames = b.table("frames")
    values = np.column_stack([frames.column(n).to_numpy() for n in frames.column_names
                              if n.endswith((".x", ".y", ".z"))])
    assert np.abs(values).max() < 1000


def test_discovered_clips_of_the_tiny_corpus_all_pass(tiny_corpus):
    for source in discover([tiny_corpus])[:8]:
        assert check_clip(load(source))[1] == ""


def test_the_speed_limit_is_an_option_and_checked():
    from animegraph.apps.cli import build_parser
    from db.errors import ParameterError

    args = build_parser().parse_args(["ingest", "src", "--db", "db", "--max-speed", "800",
                                      "--wait", "5"])
    assert (args.max_speed, args.wait) == (800.0, 5.0)
    with pytest.raises(ParameterError, match="max_speed_mm_s"):
        Limits(max_speed_mm_s=-1)


@pytest.mark.parametrize("name", [f.name for f in fields(Limits)])
def test_every_limit_has_a_ceiling(name):
    """A limit was any finite number above 0: a manifest (someone else's data) could set
    1e30 and wave its own damaged clips, and the next ones, into the model."""
    from db.errors import ParameterError
    from ingest.plausible import _CEILINGS

    ceiling = _CEILINGS[name]
    assert getattr(Limits(**{name: ceiling}), name) == ceiling  # the ceiling itself is fine
    for value in (ceiling * 1.01, 1e30):
        with pytest.raises(ParameterError, match=f"{name} must be .* at most {ceiling:g}"):
            Limits(**{name: value})


def test_max_speed_beyond_its_ceiling_is_one_line(capsys, tmp_path):
    from animegraph.apps.cli import main

    assert main(["ingest", str(tmp_path), "--db", str(tmp_path / "db"), "--max-speed",
                 "1e30"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--max-speed must be above 0 and at most 100000" in err
    assert not (tmp_path / "db").exists()


def test_a_database_checks_its_clips_with_the_limits_they_went_in_with(tiny_corpus, tmp_path):
    """A database built with a looser --max-speed was 'damaged' to the next ingest (and
    to fit) unless the flag was given again: its stored clips were checked with the
    defaults."""
    from ingest.pipeline import IngestConfig, ingest
    from ingest.tables import prepared_from_database, stored_limits

    stems = sorted(p.stem for p in (tiny_corpus / "clips").glob("*.c3d"))
    fast, more = _folder(tiny_corpus, tmp_path / "fast"), _folder(tiny_corpus, tmp_path / "more")
    data = read_c3d(_copy(tiny_corpus, stems[0], fast))
    points = data.points.copy()
    steps = np.arange(int(data.rate)) % 2 * 2 - 1  # 1 s of +-1 a frame
    points[10:10 + len(steps), 0, 0] += 8000 / data.rate / 2 * steps  # 8,000 mm/s
    write_c3d(fast / "clips" / f"{stems[0]}.c3d",
              MarkerData(points, data.labels, data.rate, data.units))
    _copy(tiny_corpus, stems[1], more)
    path = tmp_path / "db"

    loose = Limits(max_speed_mm_s=20_000)
    ingest([fast], path, IngestConfig(limits=loose))
    assert stored_limits(Database.open(path)) == loose
    report = ingest([more], path)  # no flag: the database's limits, for the new clip too
    assert report.count("added") == 1 and report.written
    db = Database.open(path)
    assert db.manifest["limits"]["max_speed_mm_s"] == 20_000
    assert len(prepared_from_database(db)) == 2  # as fit reads them

    # A stricter flag later is for the new clips: the database keeps what its clips passed.
    assert Limits(max_speed_mm_s=3000).loosest(loose) == loose
    # A database written before it kept its limits: its clips are checked with the flag
    # given again, else the defaults.
    old = db.version_dir / "manifest.json"
    old.write_text(json.dumps({k: v for k, v in db.manifest.items() if k != "limits"}))
    db = Database.open(path)
    assert stored_limits(db) == Limits() and stored_limits(db, loose) == loose
    with pytest.raises(DataError, match="is damaged: .*above 5000 mm/s"):
        prepared_from_database(db)
    old.write_text(json.dumps({**db.manifest, "limits": {"max_speed_mm_s": "fast"}}))
    with pytest.raises(DataError, match=r"manifest.json: limits: max_speed_mm_s must be a "
                                        r"number, got str"):
        prepared_from_database(Database.open(path))
    # A crafted manifest loosening the checks beyond any face (a marker 1 km away, moving
    # at 1e30 mm/s) is damage too, not limits.
    for name in ("max_speed_mm_s", "max_coordinate_mm"):
        old.write_text(json.dumps({**db.manifest, "limits": {name: 1e30}}))
        with pytest.raises(DataError, match=f"manifest.json: limits: {name} must be .* at "
                                            "most 100000 .*, got 1e[+]30$"):
            ingest([more], path)
