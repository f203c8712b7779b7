"""The documentation site builds with warnings as errors, and its checks catch what they
should: a reference to an object the code does not have, a command the CLI reference
leaves out."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"

pytest.importorskip("sphinx", reason="sphinx is not installed (pip install -e '.[docs]')")
for _extension in ("numpydoc", "sphinx_gallery", "myst_parser", "furo"):
    pytest.importorskip(_extension, reason=f"{_extension} is not installed "
                        "(pip install -e '.[docs]')")


def _sphinx_build(source: Path, out: Path, *extra: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
    return subprocess.run(
        [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-b", "html", *extra,
         str(source), str(out)],
        cwd=ROOT, env=env, capture_output=True, text=True)


def _project(tmp_path: Path, extensions: list[str], page: str) -> Path:
    """A one-page Sphinx project using the site's own extensions and strictness."""
    source = tmp_path / "src"
    source.mkdir()
    (source / "conf.py").write_text(
        "import sys\n"
        f"sys.path.insert(0, {str(DOCS / '_ext')!r})\n"
        f"extensions = ['myst_parser', *{extensions!r}]\n"
        "nitpicky = True\n"
        "myst_heading_anchors = 3\n"
        "nitpick_ignore_regex = [(r'py:.*', r'(?!(animegraph|db|ingest)\\b).*')]\n")
    (source / "index.md").write_text(page)
    return source


def test_site_builds_without_warnings(tmp_path):
    # The whole site, gallery included (it builds a tiny database into the test's cache).
    result = _sphinx_build(DOCS, tmp_path / "html")
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-6000:]
    html = tmp_path / "html"
    for page in ("index.html", "cli.html", "api/index.html", "auto_examples/index.html",
                 "guide/index.html", "results/index.html"):
        assert (html / page).is_file(), page
    cli = (html / "cli.html").read_text(encoding="utf-8")
    # Every command's options come from the parser, e.g. synth's --k-best and batch's
    # --scheduler, and no machine's cache folder is printed.
    assert "--k-best" in cli and "--scheduler" in cli and "corpus synth" in cli
    assert "&lt;user cache&gt;/animegraph/db-default" in cli
    images = list((html / "_images").glob("sphx_glr_plot_*_001.png"))
    assert len(images) >= 4, images


def test_reference_to_missing_object_fails(tmp_path):
    page = ("# Page\n\n"
            "{func}`ingest.speech.segment.segment`, {data}`ingest.speech.engines.ENGINES`, "
            "{mod}`animegraph.face.render` exist (not documented here: shown as code).\n")
    source = _project(tmp_path, ["sphinx.ext.autodoc", "internal_refs"], page)
    ok = _sphinx_build(source, tmp_path / "ok")
    assert ok.returncode == 0, ok.stderr

    # Another name of a documented object (a re-export) links to it.
    alias = page + ("\n```{eval-rst}\n.. autoexception:: db.errors.ParameterError\n```\n\n"
                    "{class}`animegraph.ParameterError`\n")
    (source / "index.md").write_text(alias)
    linked = _sphinx_build(source, tmp_path / "alias", "-E")
    assert linked.returncode == 0, linked.stderr
    html = (tmp_path / "alias" / "index.html").read_text(encoding="utf-8")
    assert 'href="#db.errors.ParameterError"' in html

    (source / "index.md").write_text(page + "\n{data}`ingest.speech.segment.ENGINES`\n")
    stale = _sphinx_build(source, tmp_path / "stale", "-E")
    assert stale.returncode != 0
    assert "ingest.speech.segment.ENGINES" in stale.stderr


def test_broken_link_between_pages_fails(tmp_path):
    page = "# Page\n\n[the heading](other.md#a-heading)\n\n```{toctree}\nother\n```\n"
    source = _project(tmp_path, [], page)
    (source / "other.md").write_text("# Other\n\n## A heading\n")
    ok = _sphinx_build(source, tmp_path / "ok")
    assert ok.returncode == 0, ok.stderr

    (source / "other.md").write_text("# Other\n\n## A renamed heading\n")
    broken = _sphinx_build(source, tmp_path / "broken", "-E")
    assert broken.returncode != 0
    assert "a-heading" in broken.stderr


def test_cli_reference_missing_command_fails(tmp_path):
    sys.path.insert(0, str(DOCS / "_ext"))
    try:
        from cli_reference import commands
    finally:
        sys.path.remove(str(DOCS / "_ext"))
    paths = [path for path in commands() if path != "info"]
    page = "# CLI\n\n" + "".join(f"## {path or 'top'}\n\n```{{cli-command}} {path}\n```\n\n"
                                 for path in paths)
    source = _project(tmp_path, ["cli_reference"], page)
    result = _sphinx_build(source, tmp_path / "out")
    assert result.returncode != 0
    assert "not documented: info" in result.stderr

    (source / "index.md").write_text(page + "## info\n\n```{cli-command} info\n```\n")
    result = _sphinx_build(source, tmp_path / "all", "-E")
    assert result.returncode == 0, result.stderr
