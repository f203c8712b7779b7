"""The write path: readers, phoneme segmentation, features, decomposition, corpus generators.

``ingest`` may import ``db`` but never ``animegraph``.
"""
