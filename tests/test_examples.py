"""Every example marked in README.md and docs/guide/*.md runs as shown.

A page marks an example with an HTML comment on the line before its fenced block (GitHub
and MyST show neither the comment nor anything of it):

- ``<!-- example: run -->`` before a ```` ```console ```` block: each line starting with
  ``$ `` is a command (a line ending in ``\\`` goes on with the next), the lines after it
  up to the next command are what it prints, stdout and stderr together as on a terminal,
  progress bars and the one-off notice of compiling the search kernels left out. Lines
  are compared with their runs of whitespace made one space and blank lines dropped;
  ``...`` matches any text within a line, and a line that is only ``...`` matches any
  number of lines. A command must exit 0 unless what it is shown to
  print holds an ``animegraph: error:`` line.
- ``<!-- example: run-python -->`` before a ```` ```python ```` block: the block runs as
  a script; if the next fenced block is marked ``<!-- example: output -->``, what the
  script prints must match it as above.
- ``<!-- example: run shared=PATH -->``: as ``run``, skipped when ``../shared/data/PATH``
  is absent.

The blocks of one page run in order in one working folder, so a block can use what an
earlier one made. The folder holds, before the first block (docs/guide/index.md says so
to the reader):

- ``motion.db``: a copy of the tiny database (``tests/conftest.py::tiny_db``: 34 clips
  of the synthetic corpus, 5 sentences in up to five emotions, two takes each);
- ``tiny``: the tiny corpus it was ingested from (``tiny_corpus``);
- ``speech.wav``: eSpeak NG saying :data:`SPEECH_TEXT`;
- ``../shared``: the shared data beside the project, where it exists.

``animegraph`` is this checkout's command line (``python -m animegraph.apps.cli`` with
this checkout first on ``PYTHONPATH``), whatever is installed.
"""

from __future__ import annotations

import os
import re
import shutil
import stat
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from conftest import SHARED_DATA

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs" / "guide").glob("*.md"))]
#: What ``speech.wav`` in an example's working folder says.
SPEECH_TEXT = "Bin blue at F two now."
_MARK = re.compile(r"^<!-- example: (run|run-python|output)(?: shared=(\S+))? -->\s*$")
_FENCE = re.compile(r"^(`{3,})\s*(\w*)")
#: Left out of what a command prints: a progress bar's line as tqdm writes it when stderr
#: is not a terminal, and the notice of numba's one-off compilation (once per environment).
_PROGRESS = re.compile(r"\d+%\||compiling the search kernels once")


@dataclass
class Block:
    """One marked example: where it is, its kind, its text and the output it claims."""

    page: Path
    line: int
    kind: str
    text: str
    shared: str | None = None
    output: str | None = None
    where: str = field(init=False)

    def __post_init__(self):
        self.where = f"{self.page.relative_to(ROOT)}:{self.line}"


def marked_blocks(page: Path) -> list[Block]:
    """The page's marked blocks in order (an ``output`` block joins the one before)."""
    lines = page.read_text(encoding="utf-8").splitlines()
    blocks: list[Block] = []
    i = 0
    while i < len(lines):
        mark = _MARK.match(lines[i])
        if not mark:
            i += 1
            continue
        kind, shared = mark.groups()
        fence = _FENCE.match(lines[i + 1]) if i + 1 < len(lines) else None
        expected = {"run": "console", "run-python": "python", "output": "text"}[kind]
        if not fence or fence.group(2) != expected:
            raise AssertionError(f"{page.relative_to(ROOT)}:{i + 1}: the mark {kind!r} must "
                                 f"be followed by a ```{expected} block")
        end = next(j for j in range(i + 2, len(lines)) if lines[j].strip() == fence.group(1))
        text = "\n".join(lines[i + 2:end])
        if kind == "output":
            if not blocks or blocks[-1].kind != "run-python" or blocks[-1].output is not None:
                raise AssertionError(f"{page.relative_to(ROOT)}:{i + 1}: an output block "
                                     "must follow a run-python block")
            blocks[-1].output = text
        else:
            blocks.append(Block(page, i + 3, kind, text, shared))
        i = end + 1
    return blocks


def console_steps(text: str) -> list[tuple[str, str]]:
    """``(command, expected output)`` for each ``$ `` command of a console block."""
    steps: list[tuple[list[str], list[str]]] = []
    continued = False
    for line in text.splitlines():
        if continued:
            steps[-1][0].append(line.removeprefix("> "))
        elif line.startswith("$ "):
            steps.append(([line[2:]], []))
        elif steps:
            steps[-1][1].append(line)
        else:
            raise AssertionError(f"a console block starts with output, not a command: {line!r}")
        continued = line.endswith("\\")
    return [("\n".join(command), "\n".join(output)) for command, output in steps]


def _normal_lines(text: str) -> list[str]:
    lines = []
    for line in text.splitlines():
        if "\r" in line or _PROGRESS.search(line):
            continue  # a progress bar: what a terminal shows of it is gone by the end
        line = " ".join(line.split())
        if line:
            lines.append(line)
    return lines


def output_matches(expected: str, actual: str) -> bool:
    """Whether ``actual`` is what ``expected`` claims (whitespace and ``...`` as above)."""
    pattern = "".join(
        r"(?:.*\n)*?" if line == "..." else
        ".*?".join(map(re.escape, line.split("..."))) + r"\n"
        for line in _normal_lines(expected))
    return re.fullmatch(pattern, "".join(f"{line}\n" for line in _normal_lines(actual))) \
        is not None


def _environment(bin_dir: Path) -> dict[str, str]:
    env = dict(os.environ)
    env.pop("ANIMEGRAPH_DB", None)
    env["PATH"] = f"{bin_dir}{os.pathsep}{env.get('PATH', '')}"
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    env["COLUMNS"] = "100"  # tables and help are laid out for a terminal of this width
    return env


def _command_line(bin_dir: Path) -> None:
    """An ``animegraph`` that runs this checkout, and a ``python``: both this interpreter."""
    for name, runs in (("animegraph", "-m animegraph.apps.cli "), ("python", "")):
        script = bin_dir / name
        script.write_text(f'#!/bin/sh\nexec "{sys.executable}" {runs}"$@"\n')
        script.chmod(script.stat().st_mode | stat.S_IEXEC)


def _fail(block: Block, command: str, expected: str, actual: str, status: int) -> str:
    return (f"{block.where}: the example's output changed (exit status {status})\n"
            f"$ {command}\n--- the page claims:\n{expected}\n--- it printed:\n{actual}")


def run_block(block: Block, work: Path, env: dict[str, str]) -> None:
    """Run one block in ``work``; fail with what differs from the page."""
    if block.shared and not (SHARED_DATA / block.shared).exists():
        pytest.skip(f"{block.where} needs {SHARED_DATA / block.shared}, which is absent")
    if block.kind == "run-python":
        done = subprocess.run([sys.executable, "-c", block.text], cwd=work, env=env,
                              capture_output=True, text=True, timeout=600)
        actual = done.stdout + done.stderr
        as_shown = done.returncode == 0 and (block.output is None
                                             or output_matches(block.output, actual))
        assert as_shown, _fail(block, "python", block.output or "", actual, done.returncode)
        return
    for command, expected in console_steps(block.text):
        done = subprocess.run(["bash", "-c", command], cwd=work, env=env, text=True,
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, timeout=600)
        shows_error = any(line.startswith("animegraph: error:")
                          for line in _normal_lines(expected))
        as_shown = ((done.returncode == 0) != shows_error
                    and output_matches(expected, done.stdout))
        assert as_shown, _fail(block, command, expected, done.stdout, done.returncode)


@pytest.fixture(scope="module")
def speech_wav(tmp_path_factory) -> Path:
    from ingest.formats.wav import write_wav
    from ingest.speech.espeak import speak

    utterance = speak(SPEECH_TEXT)
    path = tmp_path_factory.mktemp("speech") / "speech.wav"
    write_wav(path, utterance.audio, utterance.sample_rate)
    return path


def _pages_with_examples() -> list[Path]:
    return [page for page in PAGES if marked_blocks(page)]


@pytest.mark.parametrize("page", _pages_with_examples(),
                         ids=lambda page: str(page.relative_to(ROOT)))
def test_the_page_s_examples_run_as_shown(page, tiny_corpus, tiny_db, speech_wav, tmp_path):
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    _command_line(bin_dir)
    work = tmp_path / "work"
    work.mkdir()
    if SHARED_DATA.parent.exists():
        (tmp_path / "shared").symlink_to(SHARED_DATA.parent)
    # A copy, as ingest left it: examples fit and store models in it (and other tests may
    # have stored some in the shared one).
    shutil.copytree(tiny_db[0], work / "motion.db", ignore=shutil.ignore_patterns("baselines"))
    (work / "tiny").symlink_to(tiny_corpus)
    shutil.copy(speech_wav, work / "speech.wav")
    env = _environment(bin_dir)
    for block in marked_blocks(page):
        run_block(block, work, env)


def test_every_page_has_a_marked_example_or_says_why_not():
    """A guide page whose commands run in seconds marks them: a page with none is one
    whose examples all need the shared data or minutes (it says so in a comment)."""
    for page in PAGES[1:]:
        text = page.read_text(encoding="utf-8")
        assert marked_blocks(page) or "<!-- example: none" in text, (
            f"{page.relative_to(ROOT)} runs no example: mark one, or say why not with "
            "'<!-- example: none (the reason) -->'")


def test_the_output_check_can_fail():
    """The comparison used above tells a changed line, and ``...`` is no blank cheque."""
    assert output_matches("a  b\n...\nz", "a b\nx\ny\n\nz\n")
    assert output_matches("a ... c", "a bbb c")
    assert not output_matches("a b", "a c")
    assert not output_matches("a ... c", "a bbb d")
    assert not output_matches("a\nz", "a\nx\nz")
    assert output_matches("a\n...\nz", "a\nz")
    assert not output_matches("a", "a\nb")


def _anchor(heading: str) -> str:
    """GitHub's anchor of a heading (MyST's ``myst_heading_anchors`` makes the same)."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def _anchors(page: Path) -> set[str]:
    text = re.sub(r"^(`{3,}).*?^\1", "", page.read_text(encoding="utf-8"), flags=re.M | re.S)
    return {_anchor(h) for h in re.findall(r"^#{1,6} (.+)$", text, re.M)}


def test_the_pages_links_lead_somewhere():
    """Every relative link of README.md and the guide names a file that exists, and a
    heading of it when it names one. Pages other engineers own (the command-line
    reference, the results) are checked once they are there."""
    others = {ROOT / "docs" / "cli.md", *(ROOT / "docs" / "results").glob("*.md")}
    for page in PAGES:
        for target in re.findall(r"\]\(([^)\s]+)\)", page.read_text(encoding="utf-8")):
            if re.match(r"[a-z]+:", target):
                continue
            path, _, anchor = target.partition("#")
            file = (page.parent / path).resolve() if path else page
            where = f"{page.relative_to(ROOT)}: {target}"
            if not file.exists():
                assert "results" in file.parts or file.name == "cli.md", f"{where}: no such file"
                continue
            if anchor and file.suffix == ".md" and (file in PAGES or file in others):
                assert anchor in _anchors(file), f"{where}: no such heading"
