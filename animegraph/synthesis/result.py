"""The result of :func:`animegraph.synthesis.synthesize`: a synthesized utterance, its
search and what the ``--explain`` record (:mod:`animegraph.synthesis.explain`) reads."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from animegraph.emotion.control import EmotionChoice
from animegraph.search import SearchResult
from animegraph.synthesis.assemble import Phone


@dataclass(frozen=True, eq=False)
class Synthesis:
    """A synthesized utterance.

    Attributes
    ----------
    motion : np.ndarray, shape (n_frames, n_channels)
        In the database's channels, at ``fps``.
    ics : np.ndarray, shape (n_frames, n_ics)
        The same motion in independent components.
    blended : tuple of list of dict
        With ``k_best``: per phone the animes its motion averages (node, clip_id,
        position, weight), the search's pick first; empty otherwise.
    warnings : tuple of str
        What may be wrong with the input: a transcript that could not be aligned (the
        phones were recognised), and the speech (:mod:`ingest.speech.quality`):
        clipping, telephone band, music, little speech the phone engine knows.
    context_ranked : bool
        With ``k_best``: the animes were ranked by phonetic context first
        (:func:`animegraph.search.k_best` with ``context``).
    recentred : bool
        With ``k_best``: each anime entered the mean relative to its recording's mean pose
        (:func:`animegraph.synthesis.pipeline.recentres`).
    cross_faded : bool
        With ``k_best``: each phone's mean was cross-faded into its neighbours' through
        the recorded transitions (``PostOptions.blend``;
        :func:`animegraph.synthesis.blend_k_best`), not cut at its boundaries.
    guided : tuple of str
        The baselines whose predicted motion guided this one (``guide``, or
        ``recognized_guide`` after a transcript that did not fit); empty without.
    """

    motion: np.ndarray
    ics: np.ndarray
    fps: float
    phones: tuple[Phone, ...]
    segmentation: str
    result: SearchResult
    joins: list[dict]
    explain: list[dict]
    timings: dict = field(default_factory=dict)
    emotion: EmotionChoice = field(default_factory=lambda: EmotionChoice(None, None))
    notes: tuple[str, ...] = ()
    blended: tuple[list[dict], ...] = ()
    warnings: tuple[str, ...] = ()
    context_ranked: bool = False
    recentred: bool = False
    cross_faded: bool = False
    guided: tuple[str, ...] = ()
