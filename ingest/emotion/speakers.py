"""Per-speaker feature normalisation for emotion classification (issue #16; not in the paper).

A speaker's voice (pitch level, timbre, speaking rate) moves utterance features more
than the emotion does. Z-normalising each feature over a speaker's own utterances removes
it, with no labels: on EmoDB it lifts leave-one-speaker-out accuracy by 13 points (69.1 to
82.4 % with rich + cepstrum features; ``docs/results/emotion.md``, "EmoDB: the default and the
alternatives").

:class:`SpeakerNormalizer` is fitted on training features and their speakers; at
prediction, a speaker with at least :data:`MIN_SPEAKER_UTTERANCES` utterances in the batch
is normalised by their own statistics (a training speaker by the statistics stored at
fit), and any other utterance (a lone utterance of an unknown speaker, the ``classify``
case) by the *fallback*: the training population's statistics. The alternative, a second
SVM trained on unnormalised features for such utterances, measured no better on EmoDB
leave-one-speaker-out with one utterance at a time (70.3 % against 69.3 %, within the
spread between speakers; docs/results/emotion.md, "EmoDB: the default and the alternatives"), so
one model is kept -- but it learns from both normalisations: the classifier's default
(``normalize="speaker+population"``) trains its SVM on every utterance normalised by its
speaker's statistics and by the population's, so that a lone utterance is no stranger to
it (on RAVDESS, unseen actors, one utterance at a time: 52.4 to 58.1 % on 8 emotions;
docs/results/emotion.md, "RAVDESS: unseen actors").
"""

from __future__ import annotations

import numpy as np

from db.errors import ParameterError

__all__ = ["MIN_SPEAKER_UTTERANCES", "SpeakerNormalizer", "speaker_normalize"]

#: Fewest utterances of a speaker to normalise by their own statistics; fewer use the
#: fallback (a standard deviation of two or three utterances says little).
MIN_SPEAKER_UTTERANCES = 5


def _zscore(F: np.ndarray) -> np.ndarray:
    sd = F.std(axis=0)
    return (F - F.mean(axis=0)) / np.where(sd > 0, sd, 1.0)


def _moments(F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    sd = F.std(axis=0)
    return F.mean(axis=0), np.where(sd > 0, sd, 1.0)


def _check(F, speakers) -> tuple[np.ndarray, np.ndarray]:
    F = np.asarray(F, dtype=np.float64)
    if F.ndim != 2:
        raise ParameterError(f"features must have shape (n, n_features), got {F.shape}")
    speakers = np.asarray(speakers)
    if speakers.shape != (F.shape[0],):
        raise ParameterError(f"speakers must have shape ({F.shape[0]},), one per utterance, "
                             f"got {speakers.shape}")
    return F, speakers


def speaker_normalize(features: np.ndarray, speakers) -> np.ndarray:
    """Z-normalise each feature within each speaker (label-free).

    Parameters
    ----------
    features : np.ndarray, shape (n, n_features)
        Feature matrix.
    speakers : array-like, shape (n,)
        Speaker of each row.

    Returns
    -------
    np.ndarray, shape (n, n_features)
        Zero mean, unit variance per speaker (constant features become 0).
    """
    F, speakers = _check(features, speakers)
    out = np.empty_like(F)
    for s in np.unique(speakers):
        m = speakers == s
        out[m] = _zscore(F[m])
    return out


class SpeakerNormalizer:
    """Per-speaker z-normalisation with a population fallback (arrays only, no pickles).

    Parameters
    ----------
    min_utterances : int, optional
        Fewest utterances of a speaker normalised by their own statistics.

    Attributes
    ----------
    speakers_ : np.ndarray of str, shape (n_speakers,)
        Training speakers with at least ``min_utterances`` utterances.
    means_, scales_ : np.ndarray, shape (n_speakers, n_features)
        Their feature means and standard deviations (1 where 0).
    mean_, scale_ : np.ndarray, shape (n_features,)
        The training population's: the fallback for speakers heard too little.
    """

    def __init__(self, min_utterances: int = MIN_SPEAKER_UTTERANCES):
        self.min_utterances = min_utterances

    def fit(self, features: np.ndarray, speakers=None) -> SpeakerNormalizer:
        """Learn the population's and each training speaker's statistics.

        Parameters
        ----------
        features : np.ndarray, shape (n, n_features)
            Raw training features.
        speakers : array-like, shape (n,), optional
            Speaker of each row (None: no speaker is known).
        """
        F = np.asarray(features, dtype=np.float64)
        self.mean_, self.scale_ = _moments(F)
        names, means, scales = [], [], []
        if speakers is not None:
            F, speakers = _check(F, speakers)
            speakers = speakers.astype(str)
            for s in np.unique(speakers):
                m = speakers == s
                if np.count_nonzero(m) >= self.min_utterances:
                    names.append(s)
                    mean, scale = _moments(F[m])
                    means.append(mean)
                    scales.append(scale)
        self.speakers_ = np.array(names, dtype=str)
        self.means_ = np.array(means).reshape(len(names), F.shape[1])
        self.scales_ = np.array(scales).reshape(len(names), F.shape[1])
        return self

    def transform(self, features: np.ndarray, speakers=None) -> np.ndarray:
        """Normalised features, shape (n, n_features).

        ``speakers`` (shape (n,), optional) groups the rows by speaker. A training speaker
        is normalised by their stored statistics; another speaker with at least
        ``min_utterances`` rows here by those rows' own statistics (label-free); every
        other row, and every row when ``speakers`` is None, by the population's.
        """
        F = np.asarray(features, dtype=np.float64)
        out = (F - self.mean_) / self.scale_
        if speakers is None:
            return out
        F, speakers = _check(F, speakers)
        speakers = speakers.astype(str)
        known = {s: k for k, s in enumerate(self.speakers_)}
        for s in np.unique(speakers):
            m = speakers == s
            if s in known:
                out[m] = (F[m] - self.means_[known[s]]) / self.scales_[known[s]]
            elif np.count_nonzero(m) >= self.min_utterances:
                out[m] = _zscore(F[m])
        return out

    def to_arrays(self) -> dict[str, np.ndarray]:
        """``norm_mean``, ``norm_scale`` (n_features,), ``norm_speakers`` (n_speakers,),
        ``norm_means``, ``norm_scales`` (n_speakers, n_features), ``norm_min_utterances``."""
        return {"norm_mean": self.mean_.copy(), "norm_scale": self.scale_.copy(),
                "norm_speakers": self.speakers_.copy(), "norm_means": self.means_.copy(),
                "norm_scales": self.scales_.copy(),
                "norm_min_utterances": np.array(self.min_utterances)}

    @classmethod
    def from_arrays(cls, arrays) -> SpeakerNormalizer:
        """Rebuild from :meth:`to_arrays` output."""
        norm = cls(int(arrays["norm_min_utterances"]))
        norm.mean_ = np.asarray(arrays["norm_mean"], dtype=np.float64)
        norm.scale_ = np.asarray(arrays["norm_scale"], dtype=np.float64)
        norm.speakers_ = np.asarray(arrays["norm_speakers"]).astype(str).reshape(-1)
        shape = (norm.speakers_.size, norm.mean_.size)
        norm.means_ = np.asarray(arrays["norm_means"], dtype=np.float64).reshape(shape)
        norm.scales_ = np.asarray(arrays["norm_scales"], dtype=np.float64).reshape(shape)
        return norm
