"""Emotion models learned at ingest (Cao et al. 2005, §5 and §6).

* :mod:`ingest.emotion.classifier` -- the emotion classifier of speech (§6; issue #16: one
  estimator from audio to emotion), built from
  :mod:`ingest.emotion.audio` (input checks, resampling, level, silence),
  :mod:`ingest.emotion.features` (the paper's, rich, cepstrum and openSMILE feature blocks)
  and :mod:`ingest.emotion.speakers` (per-speaker normalisation);
  :mod:`ingest.emotion.emodb` reads EmoDB for evaluation; :mod:`ingest.emotion.boaw`
  (bag-of-audio-words of frame descriptors) and
  :func:`ingest.emotion.audio.speed_perturb` are measured alternatives, not in the
  default pipeline;
* :mod:`ingest.emotion.components` -- which independent components carry speech and which
  emotion (§5.1.3);
* :mod:`ingest.emotion.mapping` -- the RBF mapping F_ij between emotion spaces (§5.2);
* :mod:`ingest.emotion.model` -- all three fitted on a database's clips and stored in it.
"""
