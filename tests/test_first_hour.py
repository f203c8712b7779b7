"""A new user's first hour (issue 17): the default database, the sidecar phones, true
messages, one error style, labelled progress, the one-off compilation announced."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from animegraph.apps.cache import DB_ENV, default_db_dir
from animegraph.apps.cli import build_parser, main
from animegraph.apps.demo import DemoResult
from ingest.clip import ChannelSchema


def _err_lines(capsys) -> list[str]:
    return [line for line in capsys.readouterr().err.splitlines() if line.strip()]


def _subparsers(parser, prefix=""):
    for action in parser._actions:  # argparse keeps its sub-commands here
        if action.__class__.__name__ == "_SubParsersAction":
            for name, sub in action.choices.items():
                yield prefix + name, sub
                yield from _subparsers(sub, prefix + name + " ")


# ------------------------------------------------------------------ the default database


def test_info_uses_the_database_named_by_the_environment(tiny_db, monkeypatch, capsys):
    monkeypatch.setenv(DB_ENV, str(tiny_db[0]))
    assert main(["info"]) == 0
    out = capsys.readouterr().out
    assert str(tiny_db[0]) in out and f"named by ${DB_ENV}" in out


def test_without_db_the_demos_database_is_used(tiny_db, monkeypatch, capsys):
    monkeypatch.delenv(DB_ENV, raising=False)
    target = default_db_dir()
    target.parent.mkdir(parents=True, exist_ok=True)
    shutil.copytree(tiny_db[0], target, dirs_exist_ok=True)
    try:
        assert main(["info"]) == 0
        out = capsys.readouterr().out
        assert str(target) in out
        assert "the demo's database, the default (no --db given, $ANIMEGRAPH_DB not set)" in out
    finally:
        shutil.rmtree(target)


@pytest.mark.parametrize("argv", [["info"], ["synth", "x.wav", "-o", "y.c3d"],
                                  ["sql", "SELECT 1"], ["query", "--phoneme", "AA"]])
def test_a_missing_default_database_says_how_to_make_it(monkeypatch, capsys, argv):
    monkeypatch.delenv(DB_ENV, raising=False)
    assert not default_db_dir().exists()
    assert main(argv) == 1
    lines = _err_lines(capsys)
    assert len(lines) == 1 and lines[0].startswith("animegraph: error: no --db given")
    assert "animegraph demo" in lines[0] and str(default_db_dir()) in lines[0]


def test_a_missing_environment_database_says_so(monkeypatch, capsys, tmp_path):
    monkeypatch.setenv(DB_ENV, str(tmp_path / "nowhere"))
    assert main(["info"]) == 1
    (line,) = _err_lines(capsys)
    assert f"${DB_ENV}" in line and "nowhere" in line and "animegraph ingest" in line


def test_help_names_the_default_database_and_no_issue_numbers():
    parser = build_parser()
    top = parser.format_help()
    assert DB_ENV in top and str(default_db_dir()) in " ".join(top.split()).replace("- ", "-")
    for name, sub in _subparsers(parser):
        text = sub.format_help()
        assert not re.search(r"issue\s*#?\d", text), name
        assert sub.description, f"'{name} --help' has no description"
        # ingest and emotion fit write where --db says (no default); render reads none
        if any("--db" in a.option_strings for a in sub._actions) and name not in (
                "ingest", "render", "emotion fit"):
            assert DB_ENV in text, name


# ------------------------------------------------------------------ the phones beside the speech


def test_synth_uses_the_phones_beside_the_speech(tiny_db, tiny_corpus, tmp_path, capsys):
    clip = sorted((tiny_corpus / "clips").glob("*_happy_1.wav"))[0]
    wav = tmp_path / "speech.wav"
    shutil.copy(clip, wav)
    shutil.copy(clip.with_name(clip.stem + ".phones.csv"), tmp_path / "speech.phones.csv")
    out = tmp_path / "out.npz"
    assert main(["synth", str(wav), "--db", str(tiny_db[0]), "-o", str(out)]) == 0
    err = capsys.readouterr().err
    assert "using the phone labels beside the speech" in err
    assert "speech.phones.csv" in err and "phones (labels)" in err
    # And the search's kernels are now compiled and cached: nothing to announce.
    from animegraph.search.kernels import compile_notice, kernel_caches, uncompiled_kernels

    assert kernel_caches("exact") and kernel_caches("paper")  # the check sees the kernels
    assert uncompiled_kernels("exact") == [] and compile_notice("exact") is None


def test_explicit_text_wins_over_the_sidecar(tiny_db, tiny_corpus, tmp_path, capsys):
    import json

    clip = sorted((tiny_corpus / "clips").glob("*_happy_1.wav"))[0]
    wav = tmp_path / "speech.wav"
    shutil.copy(clip, wav)
    shutil.copy(clip.with_name(clip.stem + ".phones.csv"), tmp_path / "speech.phones.csv")
    text = json.loads(clip.with_suffix(".json").read_text())["text"]
    assert main(["synth", str(wav), "--db", str(tiny_db[0]), "--text", text,
                 "-o", str(tmp_path / "o.npz")]) == 0
    err = capsys.readouterr().err
    assert "beside the speech" not in err and "phones (labels)" not in err


# ------------------------------------------------------------------ true messages


def test_schema_difference_says_what_differs():
    a = ChannelSchema.for_points("markers", ["m1", "m2"], ["head", "lips"], "mm")
    assert a.difference(a) == ""
    no_groups = ChannelSchema.for_points("markers", ["m1", "m2"], ["other", "other"], "mm")
    why = a.difference(no_groups)
    assert "motion groups" in why and "markers.csv" in why and "216" not in why
    assert "order" in ChannelSchema.for_points("markers", ["m2", "m1"], ["head", "lips"],
                                               "mm").difference(a)
    other = ChannelSchema.for_points("markers", ["m1", "m9"], ["head", "lips"], "mm")
    assert "m9" in other.difference(a) and "m2" in other.difference(a)
    assert "3 " in ChannelSchema.for_points("markers", ["m1"], ["head"], "mm").difference(a)
    curves = ChannelSchema("curves", ("a",) * 0 + tuple(f"c{i}" for i in range(6)),
                           ("other",) * 6, "unit")
    assert "curves" in curves.difference(a) and "markers" in curves.difference(a)


def test_a_clip_without_markers_csv_is_rejected_for_its_motion_groups(
        tiny_db, tiny_corpus, tmp_path, capsys):
    db = tmp_path / "db"
    shutil.copytree(tiny_db[0], db)
    folder = tmp_path / "loose"
    folder.mkdir()
    clip = sorted((tiny_corpus / "clips").glob("*_sad_1.c3d"))[0]
    for path in clip.parent.glob(clip.stem + ".*"):
        shutil.copy(path, folder / path.name)
    assert main(["ingest", str(folder), "--db", str(db)]) == 1
    err = capsys.readouterr().err
    assert "motion groups" in err and "markers.csv" in err
    assert "differ from the database's (markers, 216)" not in err


def test_demo_report_counts_phones_one_way():
    result = DemoResult(corpus=Path("c"), corpus_created=False, corpus_clips=3, text="t",
                        emotion="happy", candidates=[("SIL", 5, 1), ("AA", 3, 1),
                                                     ("B", 2, 0), ("SIL", 5, 1)])
    line = next(x for x in result.report() if x.startswith("search nodes"))
    assert line.startswith("search nodes: 4 phones (2 besides silence)")


# ------------------------------------------------------------------ one error style


@pytest.mark.parametrize("argv, code", [
    (["synth", "x.wav", "--db", "nowhere", "-o", "y.txt"], 2),
    (["synth", "x.wav", "--db", "nowhere", "-o", "y.c3d", "--window", "0"], 2),
    (["synth", "x.wav", "--db", "nowhere", "-o", "y.c3d", "--bogus"], 2),
    (["info", "--db", "nowhere"], 1),
    ([], 2),
])
def test_every_error_has_one_style(capsys, argv, code):
    assert main(argv) == code
    (line,) = _err_lines(capsys)
    assert line.startswith("animegraph: error: ") and "animegraph: error: animegraph" not in line


# ------------------------------------------------------------------ speech formats


def test_mp3_speech_is_read_as_documented(tmp_path):
    import soundfile

    from ingest.formats.wav import read_wav

    if "MP3" not in soundfile.available_formats():
        pytest.skip("this libsndfile cannot write MP3")
    t = np.arange(16000) / 16000
    soundfile.write(tmp_path / "s.mp3", 0.3 * np.sin(2 * np.pi * 220 * t), 16000,
                    format="MP3")
    audio, rate = read_wav(tmp_path / "s.mp3")
    assert rate == 16000 and abs(len(audio) - 16000) < 2000
    help_text = build_parser().format_help()
    assert help_text  # the synth help names the formats:
    synth = dict(_subparsers(build_parser()))["synth"].format_help()
    assert "MP3" in synth and "WAV" in synth


# ------------------------------------------------------------------ tables and plots


def test_a_cut_text_column_ends_in_an_ellipsis():
    import pyarrow as pa

    from animegraph.apps.tabular import format_table

    text = format_table(pa.table({"text": ["x" * 100, "short"]}), "table", max_rows=5)
    first = text.splitlines()[2]
    assert first.endswith("…") and len(first) == 60 and "short" in text


def test_query_export_shows_its_progress(tiny_db, tmp_path, capsys):
    out = tmp_path / "export"
    assert main(["query", "--db", str(tiny_db[0]), "--phoneme", "AA", "--limit", "2",
                 "--export", str(out)]) == 0
    err = capsys.readouterr().err
    assert "exporting" in err and "2/2" in err


def test_head_pitch_from_markers_follows_the_rig():
    from animegraph.apps.plots import head_pitch
    from ingest.corpus import face

    rest = np.repeat(face.marker_rest()[None], 50, axis=0)
    pitch = 4.0 * np.sin(np.linspace(0, 3, 50))
    zero = np.zeros(50)
    moved = face.rigid_transform(rest, {"head_pitch": pitch, "head_yaw": 2 + zero,
                                        "head_roll": -1 + zero, "head_tx": 3 + zero,
                                        "head_ty": zero, "head_tz": zero})
    assert np.allclose(head_pitch(moved), pitch, atol=0.05)
    moved[7, [i for i, m in enumerate(face.MARKERS) if m[2] == "head"][0]] = np.nan
    est = head_pitch(moved)
    assert np.isnan(est[7]) and np.isfinite(np.delete(est, 7)).all()


# ------------------------------------------------------------------ no silent minutes


def test_corpus_generation_labels_its_steps(tmp_path, capsys):
    assert main(["corpus", "synth", "--out", str(tmp_path / "c"), "--sentences", "2",
                 "--parallel", "0", "--variations", "1", "--workers", "2"]) == 0
    err = capsys.readouterr().err
    assert "preparing 2 workers" in err and "generating the corpus" in err
    assert "2/2" in err


def test_a_kernel_that_moved_in_its_file_counts_as_cached(tmp_path, monkeypatch):
    from animegraph.search import kernels

    index = tmp_path / "problem.row_dist-586.py311.nbi"
    monkeypatch.setattr(kernels, "kernel_caches", lambda method="exact": [
        ("problem.row_dist", index)])
    assert kernels.uncompiled_kernels() == ["problem.row_dist"]
    (tmp_path / "problem.row_dist-501.py311.nbi").write_bytes(b"")  # before an edit above it
    assert kernels.uncompiled_kernels() == [] and kernels.compile_notice() is None
    (tmp_path / "problem.other-586.py311.nbi").write_bytes(b"")
    (tmp_path / "problem.row_dist-501.py312.nbi").write_bytes(b"")
    (tmp_path / "problem.row_dist-501.py311.nbi").unlink()
    assert kernels.uncompiled_kernels() == ["problem.row_dist"]  # another kernel, Python



def test_the_kernels_announced_are_the_ones_synthesis_compiles(tiny_db, tiny_corpus,
                                                               monkeypatch):
    """A kernel synthesis never calls is never cached by it, so counting it made every
    ``synth`` announce a minute's compilation that never came."""
    from animegraph.search import dtw, kernels
    from animegraph.synthesis import Model, synthesize
    from ingest.formats.phones_csv import read_phones_csv
    from ingest.formats.wav import read_wav

    names = {name for method in ("exact", "paper") for name, _ in kernels.kernel_caches(method)}
    assert names and not kernels.NOT_IN_SYNTHESIS & names

    def untouched(*args):
        raise AssertionError("synthesis called a kernel said not to be its own")

    monkeypatch.setattr(dtw, "_dtw_path", untouched)
    clip = sorted((tiny_corpus / "clips").glob("*_happy_1.wav"))[0]
    audio, rate = read_wav(clip)
    labels = read_phones_csv(clip.with_name(clip.stem + ".phones.csv"))
    model = Model.load(tiny_db[0])
    for k_best in (None, 20):  # the paper's one anime a phone, and k-best
        assert synthesize(model, audio, rate, labels=labels, k_best=k_best).motion.size
    with pytest.raises(AssertionError, match="said not to be its own"):
        dtw.dtw(audio[:40, None], audio[:30, None])  # the check above can fail
