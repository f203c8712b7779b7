"""Motion as it enters and leaves the tool, and what is measured on it.

* :mod:`.files` -- :class:`~.files.Motion` (``(n_frames, n_channels)`` with channel names
  and a frame rate) read from and written to C3D, channel CSV and NPZ; phone tracks;
* :mod:`.measures` -- mouth opening and the other facial measures, and the errors of
  synthesized motion against the truth (RMSE, lip vertex error, Pearson R, and the
  baselines' own measures).

Imports: ``db`` and ``ingest`` only -- the bottom room of ``animegraph``.
"""
