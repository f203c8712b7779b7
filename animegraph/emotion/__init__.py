"""Emotion in synthesis (Cao et al. 2005, §5-6): requests, mapping, evaluation, plots.

The classifier (§6) and the learned emotion model live in :mod:`ingest.emotion`: ingest
trains them, and ``ingest`` may not import ``animegraph``.
"""
