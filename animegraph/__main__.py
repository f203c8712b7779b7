"""``python -m animegraph``: the command line, as the ``animegraph`` command."""

from animegraph.apps.cli import entry

entry()
