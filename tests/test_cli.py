"""The command-line tool: commands work, user errors are one line and a non-zero exit."""

from __future__ import annotations

import json
import shutil
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
    (["classify", "a.wav", "b.wav"],
     "classify: unrecognized arguments: b.wav (see 'animegraph classify --help')"),
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
