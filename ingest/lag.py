"""Lip-audio lag per speaker and session: pooled, applied only where it is identifiable.

A recording's lip-audio offset belongs to the recording set-up (camera, sound chain,
encoder), not to the utterance: one speaker in one session has one lag. Estimated clip
by clip on short utterances it is not identifiable: the correlation of lip activity with
loudness has side peaks a syllable either side of the true lag that a 3 s clip cannot
tell from the true one (on GRID s1 the per-clip estimate shifted 320 of 800 clips, by
up to the +-0.5 s edge of its search, while the pooled correlation peaks at 0 ms).

So (:func:`decide_lags`):

1. clips are grouped by corpus and speaker (a corpus folder stands for a session; the
   clips of a folder that name no speaker are one speaker's);
2. each group's evidence (:func:`ingest.readers.sync.lag_evidence`, kept in the clip's
   ``extra["lag_evidence"]`` by the landmark reader, also for clips already in the
   database) is pooled (:func:`ingest.readers.sync.lag_from_evidence`);
3. the pooled estimate is used when it is identifiable
   (:meth:`~ingest.readers.sync.LagEstimate.identifiable`: enough audio, a peak that
   clearly beats its side peaks); failing that, a clip's own estimate when *it* is
   identifiable (a long clip); failing that, no lag;
4. an identifiable lag of at least :data:`ingest.prepare.MIN_LAG_CORRECTED_S` is
   applied (the motion is delayed by it, :func:`ingest.readers.sync.shift_motion`).

Every clip's ``extra`` then says what was found and done: ``lag_estimate_s``,
``lag_estimate_confidence``, ``lag_estimate_margin``, ``lag_basis`` (``"pooled over N
clips"``, ``"own"`` or ``"not identifiable"``) and ``lag_corrected_s`` (0 when not
applied). The ingest report repeats them per clip.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from ingest.prepare import MIN_LAG_CORRECTED_S, PreparedClip
from ingest.readers.sync import LAG_GRID_S, LagEstimate, lag_from_evidence, shift_motion

logger = logging.getLogger(__name__)

#: Evidence key in a clip's ``extra``.
EVIDENCE_KEY = "lag_evidence"


def _evidence(clip: PreparedClip) -> np.ndarray | None:
    value = clip.extra.get(EVIDENCE_KEY)
    if value is None:
        return None
    array = np.asarray(value, dtype=np.float64)
    return array if array.shape == (3, len(LAG_GRID_S)) else None


def group_key(clip: PreparedClip) -> tuple[str, str]:
    """The recording session a clip belongs to: (corpus, speaker); clips without a
    speaker are one session per corpus folder (GRID's ``s1/``)."""
    return clip.corpus, clip.speaker or ""


def pooled_estimates(clips: Sequence[PreparedClip]) -> dict[tuple[str, str], LagEstimate]:
    """The pooled lag estimate of each speaker/session group that has evidence."""
    groups: dict[tuple[str, str], list[tuple[np.ndarray, float]]] = {}
    for clip in clips:
        evidence = _evidence(clip)
        if evidence is not None:
            groups.setdefault(group_key(clip), []).append((evidence, clip.duration))
    return {key: lag_from_evidence([e for e, _ in items], sum(d for _, d in items))
            for key, items in groups.items()}


def decide_lags(
    new: Sequence[PreparedClip], stored: Sequence[PreparedClip] = (), *,
    correct: bool = True, pooled: bool = True,
) -> list[PreparedClip]:
    """Decide and apply the lip-audio lag of newly prepared clips.

    Parameters
    ----------
    new : sequence of PreparedClip
        Clips just prepared (motion not yet shifted). Clips without evidence (markers,
        curves) are returned unchanged.
    stored : sequence of PreparedClip
        Clips already in the database: their evidence joins their group's pool; they
        are not changed.
    correct : bool
        Apply identifiable lags (``False``: only report them).
    pooled : bool
        Pool per speaker/session (the default). ``False`` is the earlier per-clip
        behaviour: each clip's own estimate, applied whenever it reaches
        :data:`~ingest.prepare.MIN_LAG_CORRECTED_S`, identifiable or not (kept to
        measure against).

    Returns
    -------
    list of PreparedClip
        ``new`` in order, shifted where a lag was applied, with the facts in ``extra``.
    """
    estimates = pooled_estimates(list(stored) + list(new)) if pooled else {}
    out = []
    for clip in new:
        evidence = _evidence(clip)
        if evidence is None:
            out.append(clip)
            continue
        own = lag_from_evidence([evidence], clip.duration)
        group = estimates.get(group_key(clip))
        if not pooled:
            chosen, basis = own, "own (not checked)"
        elif group is not None and group.n_clips > 1 and group.identifiable():
            chosen, basis = group, f"pooled over {group.n_clips} clips"
        elif own.identifiable():
            chosen, basis = own, "own"
        else:
            chosen, basis = (group if group is not None else own), "not identifiable"
        usable = basis != "not identifiable"
        apply = correct and usable and abs(chosen.lag_s) >= MIN_LAG_CORRECTED_S
        extra = dict(clip.extra)
        extra.update(lag_estimate_s=round(chosen.lag_s, 4),
                     lag_estimate_confidence=round(chosen.confidence, 4),
                     lag_estimate_margin=round(chosen.margin, 4), lag_basis=basis,
                     lag_corrected_s=round(chosen.lag_s, 4) if apply else 0.0)
        if apply:
            clip = replace(
                clip, extra=extra,
                motion=shift_motion(clip.motion, chosen.lag_s, clip.fps).astype(np.float32),
                missing=shift_motion(clip.missing.astype(np.float64), chosen.lag_s,
                                     clip.fps) > 0.5)
        else:
            clip = replace(clip, extra=extra)
        logger.info("%s: lip-audio lag %+.3f s (r %.2f, margin %.2f, %s)%s", clip.clip_id,
                    chosen.lag_s, chosen.confidence, chosen.margin, basis,
                    " applied" if apply else "")
        out.append(clip)
    return out
