"""Scores of a phone segmentation against a reference: matched onset errors and the phone
error rate (``scripts/eval_segmentation.py`` uses them on eSpeak-synthesised speech)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from db.errors import ParameterError
from ingest.formats.phones_csv import Segment
from ingest.speech.phones import SILENCE
from ingest.speech.tiling import check_label

__all__ = ["boundary_errors", "edit_alignment", "matched_onsets", "phone_error_rate"]


def edit_alignment(
    reference: Sequence[str], hypothesis: Sequence[str]
) -> list[tuple[int | None, int | None]]:
    """Minimum edit-distance alignment of two label sequences.

    Parameters
    ----------
    reference, hypothesis : sequence of str
        Labels.

    Returns
    -------
    list of (int or None, int or None)
        Pairs of indices in order: ``(i, j)`` a match or substitution, ``(i, None)`` a
        deletion, ``(None, j)`` an insertion. Ties prefer matches, then substitutions.
    """
    n, m = len(reference), len(hypothesis)
    cost = np.zeros((n + 1, m + 1), dtype=np.int64)
    cost[:, 0] = np.arange(n + 1)
    cost[0, :] = np.arange(m + 1)
    hyp = np.asarray(hypothesis, dtype=object)
    for i in range(1, n + 1):
        diff = (hyp != reference[i - 1]).astype(np.int64)
        row = np.minimum(cost[i - 1, 1:] + 1, cost[i - 1, :-1] + diff)
        # insertions run along the row: a cumulative minimum resolves them
        current = np.empty(m + 1, dtype=np.int64)
        current[0] = cost[i, 0]
        current[1:] = row
        current = np.minimum.accumulate(current - np.arange(m + 1)) + np.arange(m + 1)
        cost[i] = current
    pairs: list[tuple[int | None, int | None]] = []
    i, j = n, m
    while i > 0 or j > 0:
        if i > 0 and j > 0:
            same = reference[i - 1] == hypothesis[j - 1]
            if cost[i, j] == cost[i - 1, j - 1] + (0 if same else 1):
                pairs.append((i - 1, j - 1))
                i, j = i - 1, j - 1
                continue
        if i > 0 and cost[i, j] == cost[i - 1, j] + 1:
            pairs.append((i - 1, None))
            i -= 1
        else:
            pairs.append((None, j - 1))
            j -= 1
    pairs.reverse()
    return pairs


def _phones_of(segments: Sequence[Segment], name: str) -> list[Segment]:
    if isinstance(segments, str | bytes) or not isinstance(segments, Sequence):
        raise ParameterError(f"{name}: expected a sequence of segments, got {segments!r}")
    return [check_label(item, k) for k, item in enumerate(segments)]


def boundary_errors(
    reference: Sequence[Segment], hypothesis: Sequence[Segment], *, signed: bool = False
) -> np.ndarray:
    """Absolute differences (seconds) between matched phone onsets of two segmentations.

    The two phone sequences (``SIL`` included) are aligned by minimum edit distance
    (:func:`edit_alignment`), so that differing pronunciations ("family" as F AE M AH L IY
    or F AE M L IY) or an extra pause on one side do not shift the comparison. Each pair
    of *matched* segments (same phone) whose reference onset is not the start of the
    clip contributes ``|reference.start - hypothesis.start|``: the boundary in front of
    that phone. Substituted, inserted and deleted phones contribute nothing, so the
    number of values tells how many boundaries were compared.

    Parameters
    ----------
    reference, hypothesis : sequence of Segment
        Segmentations of the same audio, in time order.
    signed : bool, optional
        Return ``hypothesis.start - reference.start`` instead of its absolute value (to
        see a bias).

    Returns
    -------
    numpy.ndarray, shape (n_matched,), float64
        Onset errors in seconds, in reference order.

    Raises
    ------
    ParameterError
        A bad segment.
    """
    errors = matched_onsets(reference, hypothesis)[1]
    return errors if signed else np.abs(errors)


def matched_onsets(reference: Sequence[Segment],
                   hypothesis: Sequence[Segment]) -> tuple[np.ndarray, np.ndarray]:
    """The reference phones :func:`boundary_errors` compares, and their signed errors.

    Returns
    -------
    index : numpy.ndarray, shape (n_matched,), int64
        Each matched phone's position in ``reference``: two hypotheses can then be
        compared on the phones both matched.
    errors : numpy.ndarray, shape (n_matched,), float64
        ``hypothesis.start - reference.start`` (s).
    """
    ref = _phones_of(reference, "reference")
    hyp = _phones_of(hypothesis, "hypothesis")
    pairs = [(i, j) for i, j in edit_alignment([s.phone for s in ref], [s.phone for s in hyp])
             if i is not None and j is not None and ref[i].phone == hyp[j].phone
             and ref[i].start > 0]
    return (np.asarray([i for i, _ in pairs], dtype=np.int64),
            np.asarray([hyp[j].start - ref[i].start for i, j in pairs], dtype=np.float64))


def phone_error_rate(reference: Sequence[Segment], hypothesis: Sequence[Segment]) -> float:
    """Phone error rate: edit distance of the phone sequences over the reference length.

    ``SIL`` is left out of both sequences (pauses are not phones), as usual for phone
    recognition scores.

    Parameters
    ----------
    reference, hypothesis : sequence of Segment
        Segmentations (or any items with ``.phone``, ``.start``, ``.end``).

    Returns
    -------
    float
        (substitutions + deletions + insertions) / reference phones; may exceed 1.

    Raises
    ------
    ParameterError
        A bad segment, or a reference without phones.
    """
    ref = [s.phone for s in _phones_of(reference, "reference") if s.phone != SILENCE]
    hyp = [s.phone for s in _phones_of(hypothesis, "hypothesis") if s.phone != SILENCE]
    if not ref:
        raise ParameterError("reference: has no phones other than SIL")
    pairs = edit_alignment(ref, hyp)
    errors = sum(1 for i, j in pairs if i is None or j is None or ref[i] != hyp[j])
    return errors / len(ref)
