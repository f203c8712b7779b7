"""The command-line reference, read from ``animegraph``'s argument parser at build time.

``docs/cli.md`` gives each command a Markdown heading (so that ``cli.md#animegraph-synth``
links work) followed by the directive::

    ```{cli-command} synth
    ```

which writes the command's usage, description, arguments and options as
:func:`animegraph.apps.cli_parser.build_parser` defines them: the page cannot drift from
the parser. A command of the parser that no directive shows, or a directive naming a
command the parser lacks, is a build warning (an error under ``-W``).
"""

from __future__ import annotations

import argparse
import os
from contextlib import contextmanager

from docutils import nodes
from sphinx.application import Sphinx
from sphinx.util import logging
from sphinx.util.docutils import SphinxDirective

logger = logging.getLogger(__name__)

#: Printed instead of this machine's cache folder in help that names it.
_CACHE_SHOWN = "<user cache>/animegraph"
#: Width of the usage lines (argparse wraps at the terminal's width).
_COLUMNS = "88"


@contextmanager
def _environ(**values: str):
    old = {key: os.environ.get(key) for key in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for key, value in old.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


def _parser() -> argparse.ArgumentParser:
    """The parser, built with a cache folder that names no one's home directory."""
    from animegraph.apps.cli_parser import build_parser

    with _environ(ANIMEGRAPH_CACHE=_CACHE_SHOWN, COLUMNS=_COLUMNS):
        return build_parser()


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:  # argparse keeps them nowhere public
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def commands(parser: argparse.ArgumentParser | None = None, prefix: str = ""
             ) -> dict[str, argparse.ArgumentParser]:
    """Every command path (``""`` for the top level, ``"synth"``, ``"corpus synth"``)."""
    parser = parser or _parser()
    found = {prefix: parser}
    for name, sub in _subcommands(parser).items():
        found.update(commands(sub, f"{prefix} {name}".strip()))
    return found


def _paragraph(text: str) -> nodes.paragraph:
    return nodes.paragraph(text, text)


def _arguments(parser: argparse.ArgumentParser, title: str,
               actions: list[argparse.Action]) -> list[nodes.Node]:
    """A definition list: the argument as argparse's help shows it, and its help."""
    if not actions:
        return []
    formatter = parser._get_formatter()
    items = nodes.definition_list()
    for action in actions:
        invocation = formatter._format_action_invocation(action)
        help_text = action.help or ""
        if "%" in help_text:
            help_text = formatter._expand_help(action)
        term = nodes.term("", "", nodes.literal(invocation, invocation))
        definition = nodes.definition("", _paragraph(help_text or "(no help)"))
        items += nodes.definition_list_item("", term, definition)
    return [nodes.rubric(title, title), items]


class CliCommand(SphinxDirective):
    """One command's usage, description, arguments, options and epilogue."""

    required_arguments = 0
    optional_arguments = 100  # the words of the command path
    has_content = False

    def run(self) -> list[nodes.Node]:
        path = " ".join(self.arguments)
        with _environ(ANIMEGRAPH_CACHE=_CACHE_SHOWN, COLUMNS=_COLUMNS):
            found = commands()
            if path not in found:
                logger.warning("cli-command: the parser has no command %r", path,
                               location=self.get_location(), type="cli", subtype="unknown")
                return []
            parser = found[path]
            usage = parser.format_usage().strip()
        # Which page shows which command, for _check_every_command.
        self.env.cli_documented = getattr(self.env, "cli_documented", {})
        self.env.cli_documented.setdefault(self.env.docname, set()).add(path)

        out: list[nodes.Node] = [nodes.literal_block(usage, usage, language="text")]
        if parser.description:
            out.append(_paragraph(parser.description))
        positionals, optionals, subs = [], [], None
        for action in parser._actions:
            if action.help == argparse.SUPPRESS:
                continue
            if isinstance(action, argparse._SubParsersAction):
                subs = action
            elif action.option_strings:
                optionals.append(action)
            else:
                positionals.append(action)
        out += _arguments(parser, "Arguments", positionals)
        out += _arguments(parser, "Options", optionals)
        if subs is not None:
            helps = {choice.dest: choice.help for choice in subs._choices_actions}
            rows = nodes.definition_list()
            for name in subs.choices:
                term = nodes.term("", "", nodes.literal(name, name))
                rows += nodes.definition_list_item(
                    "", term, nodes.definition("", _paragraph(helps.get(name) or "")))
            out += [nodes.rubric("Commands", "Commands"), rows]
        if parser.epilog:
            out.append(_paragraph(parser.epilog))
        return out


def _merge(app, env, docnames, other) -> None:
    env.cli_documented = getattr(env, "cli_documented", {})
    env.cli_documented.update(getattr(other, "cli_documented", {}))


def _purge(app, env, docname) -> None:
    getattr(env, "cli_documented", {}).pop(docname, None)


def _check_every_command(app: Sphinx, env) -> None:
    """Warn about commands of the parser that no page documents."""
    shown = set().union(*getattr(env, "cli_documented", {}).values())
    if not shown:
        return  # a build without the reference page (e.g. one page alone)
    missing = [path or "(top level)" for path in commands() if path not in shown]
    if missing:
        logger.warning("cli-command: not documented: %s", ", ".join(missing),
                       type="cli", subtype="missing")


def setup(app: Sphinx) -> dict:
    app.add_directive("cli-command", CliCommand)
    app.connect("env-purge-doc", _purge)
    app.connect("env-merge-info", _merge)
    app.connect("env-check-consistency", _check_every_command)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
