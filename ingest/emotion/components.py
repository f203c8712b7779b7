"""Which independent components carry speech and which carry emotion (Cao et al. 2005, §5.1.3).

The paper (after Cao et al. 2003) classifies each independent component u_k:

* **emotion** -- its time series differ significantly between two recordings of the
  same sentence in different emotions, once the recordings are aligned in time;
* **speech** -- among the others, those whose single-component reconstruction (Eq. 9,
  M'_k = A [0 .. u_k .. 0]^T) captures much of the mouth motion.

The paper compares "visually and numerically" and leaves the numbers to Cao et al.
(2003). Here both decisions are numeric and automatic:

speech score (Eq. 9)
    The share of the mouth motion -- the ``lips`` channel group, each clip's mean
    removed so that a held expression (a smile) does not count as mouth *motion* --
    that the component's single-component reconstruction captures,
    ``1 - ||X - M'_k||^2 / ||X||^2`` over every clip (clipped at 0). Speech components
    score at least :data:`SPEECH_MIN_SHARE`.
emotion score
    Two recordings a, b of one sentence are aligned by DTW on the speech candidates
    (components with a speech score of at least :data:`SPEECH_MIN_SHARE`, each clip's
    mean removed). For each component the RMS difference along the path, divided by the
    component's own RMS variation within the two clips, measures how much more it
    differs than it moves. The score of a component is the largest, over the pairs of
    emotions that share sentences, of the mean of this ratio over those sentences (an
    emotion component need only separate *some* emotions: a smile separates happy from
    the others, not angry from sad). The **baseline** is the same ratio between two takes
    of one sentence in one emotion.
    A component is an emotion component if its score is at least
    :data:`EMOTION_MIN_DIFFERENCE` (it differs more than it moves) and at least
    :data:`EMOTION_MIN_RATIO` times its baseline (significantly more than between takes;
    skipped when no sentence has two takes in one emotion).

Components neither emotion nor speech are labelled ``other`` (blinks, noise); emotion
mapping leaves them unchanged, like the speech components.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from itertools import combinations

import numpy as np

from ingest.emotion.align import dtw_path, sample_at, warp_positions

#: Least share of the mouth motion a speech component's reconstruction captures (Eq. 9).
SPEECH_MIN_SHARE = 0.05
#: Least ratio of cross-emotion difference to within-utterance variation of an emotion
#: component.
EMOTION_MIN_DIFFERENCE = 1.0
#: Least ratio of an emotion component's score to its same-emotion baseline.
EMOTION_MIN_RATIO = 2.0
#: Frame rate (about) at which recordings are aligned by DTW.
ALIGN_FPS = 30.0
#: Component labels.
LABELS = ("speech", "emotion", "other")


@dataclass(frozen=True)
class ComponentSplit:
    """Scores and labels of the independent components.

    Attributes
    ----------
    speech_score : np.ndarray, shape (n_ics,)
        Share of the mouth motion the single-component reconstruction captures.
    emotion_score : np.ndarray, shape (n_ics,)
        Cross-emotion difference ratio (NaN without parallel recordings).
    emotion_baseline : np.ndarray, shape (n_ics,)
        The same ratio between takes in one emotion (NaN without repeated takes).
    emotion_pair : tuple of str
        The pair of emotions ("happy/neutral") that gave each component its score ("" if
        none).
    labels : tuple of str
        ``speech``, ``emotion`` or ``other``.
    """

    speech_score: np.ndarray
    emotion_score: np.ndarray
    emotion_baseline: np.ndarray
    emotion_pair: tuple[str, ...]
    labels: tuple[str, ...]

    @property
    def emotion_components(self) -> np.ndarray:
        """Indices of the emotion components e."""
        return np.array([k for k, lab in enumerate(self.labels) if lab == "emotion"], dtype=int)

    @property
    def speech_components(self) -> np.ndarray:
        """Indices of the speech components s (DTW of parallel recordings runs on these)."""
        speech = [k for k, lab in enumerate(self.labels) if lab == "speech"]
        if not speech:  # nothing looks like speech: align on every non-emotion component
            speech = [k for k, lab in enumerate(self.labels) if lab != "emotion"]
        return np.array(speech, dtype=int)

    def columns(self) -> dict[str, list]:
        """Columns for the database's ``components`` table."""
        return {
            "label": list(self.labels),
            "speech_score": self.speech_score.tolist(),
            "emotion_score": self.emotion_score.tolist(),
            "emotion_baseline": self.emotion_baseline.tolist(),
            "emotion_pair": list(self.emotion_pair),
        }

    @classmethod
    def from_columns(cls, rows: Sequence[dict]) -> ComponentSplit:
        """Inverse of :meth:`columns` (rows of the ``components`` table, in order)."""
        def col(name):
            return np.array([np.nan if r[name] is None else r[name] for r in rows], dtype=float)

        return cls(speech_score=col("speech_score"), emotion_score=col("emotion_score"),
                   emotion_baseline=col("emotion_baseline"),
                   emotion_pair=tuple(r["emotion_pair"] or "" for r in rows),
                   labels=tuple(r["label"] for r in rows))


class Aligner:
    """Time alignment of two clips by DTW on chosen components, computed once and cached.

    DTW runs on every ``step``-th frame (about :data:`ALIGN_FPS` frames per second: facial
    motion has little above 10 Hz) and each clip's mean is removed first; the path is
    brought back to the full frame rate by interpolation.

    Parameters
    ----------
    sources : sequence of np.ndarray, each (n_frames_k, n_ics)
        Independent components of every clip.
    fps : float
        Their frame rate.
    """

    def __init__(self, sources: Sequence[np.ndarray], fps: float):
        self.sources = sources
        self.step = max(1, int(round(fps / ALIGN_FPS)))
        self._cache: dict = {}

    def _features(self, clip: int, components: np.ndarray) -> np.ndarray:
        u = np.asarray(self.sources[clip], dtype=np.float64)[:, components]
        return (u - u.mean(axis=0))[::self.step]

    def positions(self, a: int, b: int, components: np.ndarray) -> np.ndarray:
        """Fractional frame of clip b matched to every frame of clip a, shape (n_a,)."""
        comps = tuple(int(c) for c in components)
        if (a, b, comps) in self._cache:
            path = self._cache[(a, b, comps)]
        elif (b, a, comps) in self._cache:
            path = self._cache[(b, a, comps)][:, ::-1]
        else:
            path = dtw_path(self._features(a, components), self._features(b, components))
            self._cache[(a, b, comps)] = path
        path = path[np.lexsort((path[:, 1], path[:, 0]))]
        return warp_positions(path, len(self.sources[a]), len(self.sources[b]), self.step)


def parallel_groups(emotions: Sequence[str], sentence_ids: Sequence[str | None]
                    ) -> dict[str, dict[str, list[int]]]:
    """Sentences recorded in at least two emotions: sentence -> emotion -> clip indices."""
    groups: dict[str, dict[str, list[int]]] = {}
    for i, (emotion, sentence) in enumerate(zip(emotions, sentence_ids, strict=True)):
        if sentence is None or emotion == "unknown":
            continue
        groups.setdefault(sentence, {}).setdefault(emotion, []).append(i)
    return {s: g for s, g in sorted(groups.items()) if len(g) >= 2}


def take_pairs(a: Sequence[int], b: Sequence[int]) -> list[tuple[int, int]]:
    """Matched takes of one sentence in two emotions: the k-th take of each (takes carry no
    meaning across emotions; pairing every take with every other would only repeat the
    alignments)."""
    return list(zip(a, b, strict=False))


def pair_name(a: str, b: str) -> str:
    return "/".join(sorted((a, b)))


def speech_scores(sources: Sequence[np.ndarray], motions: Sequence[np.ndarray],
                  loadings: np.ndarray, mouth: np.ndarray) -> np.ndarray:
    """Share of the mouth motion each single-component reconstruction captures (Eq. 9).

    Parameters
    ----------
    sources : sequence of np.ndarray, each (n_frames_k, n_ics)
    motions : sequence of np.ndarray, each (n_frames_k, n_channels)
        The clips' motion in the database's channels.
    loadings : np.ndarray, shape (n_ics, n_channels)
        Motion of one unit of each component (row k: A's column k taken to the channels).
    mouth : np.ndarray of bool, shape (n_channels,)
        The mouth channels.

    Returns
    -------
    np.ndarray, shape (n_ics,)
        In [0, 1].
    """
    L = loadings[:, mouth]
    total, xtu, uu = 0.0, np.zeros((L.shape[1], L.shape[0])), np.zeros(L.shape[0])
    for u, x in zip(sources, motions, strict=True):
        u = np.asarray(u, dtype=np.float64)
        x = np.asarray(x, dtype=np.float64)[:, mouth]
        u = u - u.mean(axis=0)
        x = x - x.mean(axis=0)
        total += float((x * x).sum())
        xtu += x.T @ u
        uu += (u * u).sum(axis=0)
    if total <= 0:
        return np.zeros(L.shape[0])
    residual = total - 2 * np.einsum("kc,ck->k", L, xtu) + uu * (L * L).sum(axis=1)
    return np.clip(1.0 - residual / total, 0.0, 1.0)


def _ratio(ua: np.ndarray, ub: np.ndarray, positions: np.ndarray) -> np.ndarray:
    diff = ua - sample_at(ub, positions)
    rms = np.sqrt((diff * diff).mean(axis=0))
    spread = np.sqrt(0.5 * (ua.var(axis=0) + ub.var(axis=0)))
    return rms / np.maximum(spread, 1e-9)


def split_components(
    sources: Sequence[np.ndarray],
    motions: Sequence[np.ndarray],
    emotions: Sequence[str],
    sentence_ids: Sequence[str | None],
    loadings: np.ndarray,
    mouth: np.ndarray,
    *,
    speech_min: float = SPEECH_MIN_SHARE,
    emotion_min: float = EMOTION_MIN_DIFFERENCE,
    ratio_min: float = EMOTION_MIN_RATIO,
    fps: float = 120.0,
    aligner: Aligner | None = None,
) -> ComponentSplit:
    """Score and label every independent component (§5.1.3; see the module docstring).

    Parameters
    ----------
    sources : sequence of np.ndarray, each (n_frames_k, n_ics)
        Independent components of every clip.
    motions : sequence of np.ndarray, each (n_frames_k, n_channels)
        The clips' motion.
    emotions, sentence_ids : sequence of str
        Each clip's emotion and sentence.
    loadings : np.ndarray, shape (n_ics, n_channels)
        Channel motion of one unit of each component.
    mouth : np.ndarray of bool, shape (n_channels,)
        Mouth channels (the ``lips`` group; every channel if there is none).
    fps : float
        Frame rate of the clips.
    aligner : Aligner, optional
        Cache of DTW paths (shared with the mapping fit).

    Returns
    -------
    ComponentSplit
    """
    n_ics = loadings.shape[0]
    speech = speech_scores(sources, motions, loadings, mouth)
    candidates = np.flatnonzero(speech >= speech_min)
    if candidates.size == 0:
        candidates = np.arange(n_ics)
    aligner = aligner or Aligner(sources, fps)
    groups = parallel_groups(emotions, sentence_ids)
    cross: dict[str, list[np.ndarray]] = {}
    same: list[np.ndarray] = []
    for by_emotion in groups.values():
        for ea, eb in combinations(sorted(by_emotion), 2):
            for a, b in take_pairs(by_emotion[ea], by_emotion[eb]):
                where = aligner.positions(a, b, candidates)
                cross.setdefault(pair_name(ea, eb), []).append(
                    _ratio(sources[a], sources[b], where))
        for takes in by_emotion.values():
            for a, b in zip(takes[:-1], takes[1:], strict=True):
                same.append(_ratio(sources[a], sources[b], aligner.positions(a, b, candidates)))
    score = np.full(n_ics, np.nan)
    pair = [""] * n_ics
    if cross:
        names = sorted(cross)
        means = np.array([np.mean(cross[n], axis=0) for n in names])
        best = means.argmax(axis=0)
        score = means[best, np.arange(n_ics)]
        pair = [names[b] for b in best]
    baseline = np.mean(same, axis=0) if same else np.full(n_ics, np.nan)
    is_emotion = score >= emotion_min
    if same:
        is_emotion &= score >= ratio_min * baseline
    labels = tuple("emotion" if is_emotion[k] else "speech" if speech[k] >= speech_min
                   else "other" for k in range(n_ics))
    return ComponentSplit(speech_score=speech, emotion_score=score, emotion_baseline=baseline,
                          emotion_pair=tuple(pair), labels=labels)
