"""What users run: the command line and the work it drives.

* :mod:`.cli` -- ``animegraph``, the entry point: it runs the sub-command that
  :mod:`.cli_parser` (every option and its help) parses, and turns errors into one line;
  :mod:`.commands` -- what each sub-command does (``synth``, ``render``, ``ingest`` ...);
* :mod:`.demo` -- ``animegraph demo`` on the embedded default data; :mod:`.cache` -- where
  the default corpus and database live;
* :mod:`.batch`, :mod:`.script` -- batch synthesis of dialogue scripts on Dask;
* :mod:`.query` -- clip queries and export; :mod:`.info` -- what a database holds;
  :mod:`.tabular` -- tables printed as text, CSV or JSON;
* :mod:`.plots` -- the pictures: ``animegraph plot``, the demo's, held-out comparisons;
* :mod:`.evaluate` -- held-out lip-sync evaluation (``scripts/eval_lipsync.py``);
* :mod:`.studio` -- ``animegraph studio``, the local web app (server, API, the page).

Imports: anything below it (``db``, ``ingest`` and every other room of ``animegraph``);
nothing imports it but the scripts and tests.
"""
