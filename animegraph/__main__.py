"""``python -m animegraph``: the command line, as the ``animegraph`` command."""

import sys

from animegraph.apps.cli import main

sys.exit(main())
