"""Emotion in synthesis (Cao et al. 2005, §5-6): requests, mapping, evaluation, plots.

The classifier (§6) and the learned emotion model live in :mod:`ingest.emotion`: ingest
trains them, and ``ingest`` may not import ``animegraph``.

* :mod:`.control` -- emotion requests (a name, ``auto``, a mix) resolved for a database
  and mapped onto synthesized or recorded motion;
* :mod:`.evaluate`, :mod:`.plots` -- how well the speech/emotion split and the mappings
  hold (``scripts/eval_emotion_mapping.py``).

Imports: ``db`` and ``ingest`` only -- nothing else of ``animegraph``.
"""
