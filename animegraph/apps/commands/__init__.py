"""What each ``animegraph`` sub-command does, once :mod:`animegraph.apps.cli` has parsed
its command line (:mod:`animegraph.apps.cli_parser`) and chosen it.

* :mod:`.synth` -- ``synth`` (the Anime Graph, or a fitted baseline) and ``batch``;
  :mod:`.synth_plan` -- which path ``synth`` takes (k-best or the paper's search, the
  guiding baseline) and the path line that says so;
* :mod:`.render` -- ``render`` and ``plot``;
* :mod:`.emotion` -- ``classify`` and ``map-emotion``; :mod:`.emotion_fit` -- ``emotion fit``;
* :mod:`.corpus` -- ``corpus synth`` and ``demo``;
* :mod:`.database` -- ``ingest``, ``sql``, ``query``, ``fit`` and ``info``;
* :mod:`.studio` -- ``studio`` (the web app, :mod:`animegraph.apps.studio`);
* :mod:`.common` -- what they share: :class:`~.common.UsageError`, progress bars and
  lines, the phone labels beside a file.

Every command is a function of the parsed arguments that returns the exit status,
``cmd_<command>`` (``cmd_synth``, ``cmd_map_emotion``). What crosses a module
boundary has a public name; a leading underscore stays in its own module. Heavy
modules are imported inside the functions, so that ``animegraph --help`` starts quickly;
nothing here imports :mod:`animegraph.apps.cli`.
"""
