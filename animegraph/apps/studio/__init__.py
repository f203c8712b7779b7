"""The studio: a local web app over a motion database (``animegraph studio``).

It sits in :mod:`animegraph.apps` (what users run): it serves what the commands do
(``info``, ``query``, ``sql``, ``render``'s deformation, ``synth``) to a browser.

* :mod:`.server` -- the aiohttp application, its token guard and error format, and
  :func:`~.server.serve`;
* :mod:`.api` -- overview, clips, a clip's face and speech, SQL (the command line's own
  functions behind each);
* :mod:`.synth` -- a recording uploaded, synthesized, its outputs downloaded;
* :mod:`.live` -- ``animegraph live``'s WebSocket frames relayed to the page as faces;
* :mod:`.face` -- motion carried onto the canonical face as ``render`` does (and ARKit
  weights for the page's morph targets), packed for the page;
* ``static/`` -- the page: plain ES modules, three.js shipped in ``static/vendor`` with
  its licence (one module minified from npm's r187 by ``scripts/build_studio_three.sh``).
"""
