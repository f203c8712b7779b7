"""The command-line tool: commands work, user errors are one line and a non-zero exit."""

from __future__ import annotations

import json
import os
import shutil
import stat
import subprocess
import sys

import pytest

from animegraph.apps.cli import main


def _one_line_error(capsys, code, expected_code):
    captured = capsys.readouterr()
    assert code == expected_code
    lines = [line for line in captured.err.splitlines() if line.strip()]
    assert len(lines) == 1, captured.err
    assert "Traceback" not in captured.err
    return lines[0]


def test_console_script_is_installed():
    exe = shutil.which("animegraph")
    assert exe, "the animegraph console script is not on PATH"
    out = subprocess.run([exe, "--version"], capture_output=True, text=True, check=True)
    assert out.stdout.startswith("animegraph ")


def test_module_entry_point_reports_errors_in_one_line():
    out = subprocess.run([sys.executable, "-m", "animegraph.apps.cli", "corpus", "synth"],
                         capture_output=True, text=True)
    assert out.returncode == 2
    assert len(out.stderr.strip().splitlines()) == 1
    assert "--out" in out.stderr


@pytest.mark.parametrize("argv, code, needle", [
    ([], 2, "choose a command"),
    (["frobnicate"], 2, "invalid choice"),
    (["corpus"], 2, "choose an action"),
    (["corpus", "synth", "--out", "x", "--bogus"], 2, "unrecognized arguments"),
    (["corpus", "synth", "--out", "x", "--sentences", "many"], 2, "whole number"),
    (["corpus", "synth", "--out", "x", "--sentences", "0"], 1, "sentences"),
    (["corpus", "synth", "--out", "x", "--fps", "0"], 1, "fps"),
    (["corpus", "synth", "--out", "x", "--scale", "paper", "--sentences", "5"], 2, "--scale"),
    (["demo", "--emotion", "bored"], 1, "emotion"),
])
def test_user_errors(capsys, tmp_path, monkeypatch, argv, code, needle):
    monkeypatch.chdir(tmp_path)
    line = _one_line_error(capsys, main(argv), code)
    assert needle in line
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize("argv, said", [
    (["synth", "x.wav", "-o", "y.c3d", "--emotin", "happy"],
     "synth: unrecognized arguments: --emotin happy; did you mean --emotion? "
     "(see 'animegraph synth --help')"),
    (["map-emotion", "a.c3d", "b.c3d", "--to", "happy", "-o", "y.c3d"],  # classify takes many
     "map-emotion: unrecognized arguments: b.c3d (see 'animegraph map-emotion --help')"),
    (["emotion", "fit", "d", "--preset", "tess", "-o", "m.npz", "--emotionz", "sad"],
     "emotion fit: unrecognized arguments: --emotionz sad; did you mean --emotions? "
     "(see 'animegraph emotion fit --help')"),
    (["corpus", "synth", "--out", "x", "--sentense", "3"],
     "corpus synth: unrecognized arguments: --sentense 3; did you mean --sentences? "
     "(see 'animegraph corpus synth --help')"),
    (["batch", "s.csv", "--out", "x", "--format", "csv"],  # nothing close: no guess
     "batch: unrecognized arguments: --format csv (see 'animegraph batch --help')"),
    (["--bogus", "info"], "unrecognized arguments: --bogus (see 'animegraph --help')"),
])
def test_an_unknown_option_names_its_command(capsys, tmp_path, monkeypatch, argv, said):
    # The top parser said it, "(see 'animegraph --help')", whose page lists no option of
    # the command.
    monkeypatch.chdir(tmp_path)
    assert _one_line_error(capsys, main(argv), 2) == f"animegraph: error: {said}"


def test_unwritable_output_folder(capsys, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    argv = ["corpus", "synth", "--out", str(blocker / "corpus"), "--sentences", "1",
            "--parallel", "0", "--variations", "1", "--quiet"]
    line = _one_line_error(capsys, main(argv), 1)
    assert "cannot write" in line


def test_corpus_synth_command(capsys, tmp_path):
    out = tmp_path / "corpus"
    argv = ["corpus", "synth", "--out", str(out), "--sentences", "2", "--parallel", "1",
            "--variations", "1", "--fps", "60", "--seed", "3", "--workers", "1", "--quiet"]
    assert main(argv) == 0
    assert "wrote 6 clips of 2 sentences" in capsys.readouterr().out
    meta = json.loads((out / "corpus.json").read_text())
    assert meta["config"]["fps"] == 60.0 and meta["n_clips"] == 6
    # A second run into the same folder is refused, and --force replaces it.
    line = _one_line_error(capsys, main(argv), 1)
    assert "--force" in line
    assert main([*argv, "--force"]) == 0


def test_a_bug_gives_the_caller_its_ctrl_c_handler_back(monkeypatch):
    """main sets its own SIGINT handler; an unexpected exception (a bug, with its
    traceback) must not leave it installed in the process that called main."""
    import signal

    import animegraph.apps.cli as cli

    def bug(argv):
        raise RuntimeError("a bug")

    before = signal.getsignal(signal.SIGINT)
    monkeypatch.setattr(cli, "_main", bug)
    with pytest.raises(RuntimeError, match="a bug"):
        cli.main(["info"])
    assert signal.getsignal(signal.SIGINT) is before


def test_help_says_what_the_commands_do():
    # --exact was "the global optimum (default)" (the default is k-best 20, and --exact
    # turns it off); --audio-cost posteriorgram "needs a database ingested with hama" (the
    # error asks for --posteriorgrams); --k-best gave no default.
    from animegraph.apps.cli_parser import build_parser

    sub = next(a for a in build_parser()._actions if a.dest == "command")
    helps = {a.dest: a.help for a in sub.choices["synth"]._actions}
    assert "(default)" not in helps["exact"] and "one anime a phone" in helps["exact"]
    assert "--posteriorgrams" in helps["audio_cost"]
    assert "default 20" in helps["k_best"]
    # plot --audio said "(WAV)"; it reads a video's sound track as render does.
    plot = {a.dest: a.help for a in sub.choices["plot"]._actions}
    assert "video" in plot["audio"]
    # classify's description left out the bag of audio words, half of its features.
    assert "bag of audio words" in sub.choices["classify"].description
    # ingest's description named neither the iPhone's Live Link CSV nor videos.
    assert "Live Link" in sub.choices["ingest"].description


def _places_no_output_may_take(tmp_path):
    """name -> (path, its bytes or None for a folder, a FIFO): each must be there, as it
    was, after a command was told to write its output to it."""
    (tmp_path / "kept.txt").write_text("kept")
    (tmp_path / "kept").mkdir()
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    db = tmp_path / "db"
    (db / "v000001").mkdir(parents=True)
    (db / "CURRENT").write_text("v000001")
    (tmp_path / "file_link").symlink_to(tmp_path / "kept.txt")
    (tmp_path / "folder_link").symlink_to(tmp_path / "kept")
    return {"fifo": fifo, "file symlink": tmp_path / "file_link",
            "folder symlink": tmp_path / "folder_link", "database CURRENT": db / "CURRENT",
            "inside a database": db / "v000001" / "out.csv", "a database": db,
            "through ..": db / "v000001" / ".." / "CURRENT"}


#: Every option naming an output file (OUT: where it goes); the inputs need not exist,
#: the output is refused before they are read.
OUTPUT_FILES = {
    "sql -o": ["sql", "SELECT 1", "--db", "nodb", "-o", "OUT"],
    "synth -o": ["synth", "x.wav", "--db", "nodb", "-o", "OUT"],
    "synth --explain-json": ["synth", "x.wav", "--db", "nodb", "-o", "y.c3d",
                             "--explain-json", "OUT"],
    "render -o": ["render", "x.c3d", "-o", "OUT"],
    "plot -o": ["plot", "x.c3d", "-o", "OUT"],
    "map-emotion -o": ["map-emotion", "x.c3d", "--db", "nodb", "--to", "happy", "-o", "OUT"],
}
#: Every option naming an output folder.
OUTPUT_FOLDERS = {
    "query --export": ["query", "--db", "nodb", "--export", "OUT", "--force"],
    "batch --out": ["batch", "x.csv", "--db", "nodb", "--out", "OUT"],
    "corpus synth --out": ["corpus", "synth", "--out", "OUT"],
    "demo --out": ["demo", "--out", "OUT"],
}


@pytest.mark.parametrize("option", [*OUTPUT_FILES, *OUTPUT_FOLDERS])
def test_an_output_never_replaces_what_is_not_an_output(capsys, tmp_path, monkeypatch,
                                                         option):
    # The write is a rename into place: '-o /dev/full' (as root) replaced the device node
    # with a regular file, a FIFO or a symbolic link became a file, and '-o DB/CURRENT'
    # overwrote the database's pointer (every later command said it was damaged).
    monkeypatch.chdir(tmp_path)
    places = _places_no_output_may_take(tmp_path)
    argv = {**OUTPUT_FILES, **OUTPUT_FOLDERS}[option]
    for name, path in places.items():
        if option in OUTPUT_FOLDERS and name in ("database CURRENT", "file symlink"):
            continue  # not folders: refused as such, tried above for the files
        line = _one_line_error(capsys, main([str(path) if a == "OUT" else a for a in argv]),
                               2)
        assert str(path) in line, (name, line)
        assert ("inside the database" in line or "a database folder" in line
                or "symbolic link" in line or "FIFO" in line), (name, line)
    assert stat.S_ISFIFO(os.lstat(places["fifo"]).st_mode)
    assert os.readlink(tmp_path / "file_link") == str(tmp_path / "kept.txt")
    assert (tmp_path / "kept.txt").read_text() == "kept"
    assert (tmp_path / "db" / "CURRENT").read_text() == "v000001"
    assert sorted(p.name for p in (tmp_path / "db").iterdir()) == ["CURRENT", "v000001"]
    assert not list((tmp_path / "db" / "v000001").iterdir())


def test_a_library_write_replaces_only_a_regular_file(tmp_path):
    from db.atomic import atomic_write
    from db.errors import DataError

    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    (tmp_path / "link").symlink_to(tmp_path / "elsewhere")
    for path in (fifo, tmp_path / "link"):
        with pytest.raises(DataError, match="not a regular file"), atomic_write(path) as out:
            out.write(b"x")
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode) and (tmp_path / "link").is_symlink()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fifo", "link"]  # no temporary
    with atomic_write(tmp_path / "new.csv") as out:  # a new path, and a file, still are
        out.write(b"1")
    with atomic_write(tmp_path / "new.csv") as out:
        out.write(b"2")
    assert (tmp_path / "new.csv").read_bytes() == b"2"


def test_query_help_lists_every_export_format_the_export_writes(capsys):
    # The help said "C3D for marker databases, CSV otherwise": no word of .livelink.csv.
    from animegraph.motion.files import motion_suffix
    from animegraph.motion.suffixes import EXPORT_FORMATS
    from ingest.formats.livelink import ARKIT_BLENDSHAPES

    with pytest.raises(SystemExit):
        main(["query", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    for suffix in EXPORT_FORMATS:
        assert f"{suffix}:" in text, suffix
    written = {motion_suffix(list(ARKIT_BLENDSHAPES), "curves"),
               motion_suffix(["a.x", "a.y", "a.z"], "markers"),
               motion_suffix(["a.x", "a.y", "a.z", "head.yaw"], "landmarks")}
    assert written == set(EXPORT_FORMATS)
