"""Bag-of-audio-words of frame-level descriptors, for emotion from speech (issue #16).

After Schmitt, Ringeval & Schuller (2016), "At the border of acoustics and linguistics:
bag-of-audio-words for the recognition of emotions in speech", INTERSPEECH, and their
toolkit openXBOW (Schmitt & Schuller 2017, JMLR 18(96)); not in Cao et al. An utterance's
frames are quantised against a codebook of frames seen in training and counted: the
histogram says *which* short-time sounds occur how often, where functionals
(:func:`ingest.emotion.features.rich_features`) say how descriptors are distributed.

* :func:`frame_descriptors` -- per 10 ms frame (16 kHz, 32 ms windows, as the ``rich``
  block): 20 MFCCs, log energy and F0 in semitones above 27.5 Hz (0 when unvoiced, as
  eGeMAPS' ``F0semitoneFrom27.5Hz``), and their deltas;
* :class:`BagOfAudioWords` -- openXBOW's recipe with its defaults where it has them:
  descriptors standardised by the training frames (``-standardizeInput``), one codebook
  for the descriptors and one for their deltas (``-attributes``), each of
  :data:`CODEBOOK_SIZE` words (openXBOW's default) picked by k-means++ seeding, one draw
  per word, without the k-means updates (openXBOW's default codebook ``-c random++``:
  "random sampling is much faster than clustering while obtaining almost the same final
  performance"; seeded here from at most 50,000 training frames), :data:`ASSIGNMENTS`
  nearest words counted per frame (multi-assignment ``-a``; 10 as in openXBOW's
  tutorial), counts per second of speech (``-norm``, utterances differ in length) and
  logarithmic term frequency ``lg(TF + 1)`` (``-log``);
* an **ensemble of codebooks** (``n_codebooks`` = K, issue #16's fifth session): K pairs
  of codebooks drawn with different seeds, their histograms concatenated.

The parameters are fixed a priori from those sources, not tuned on the evaluation data.

Why an ensemble. The random++ codebook is a random draw, and the classifier's accuracy on
EmoDB moved by up to 2.4 points with its seed alone (``docs/results.md``, "Issue 16,
fourth session"): what a user gets should not depend on a seed. With one codebook pair
the kernel the SVM sees between two utterances, ``k_c(u, v) = <h_c(u), h_c(v)>``, is one
random draw of a kernel whose randomness comes only from the codebook ``c``. Concatenating
the histograms of K independently drawn codebook pairs into **one block** (weighted as one
block against the functionals by the classifier's block weights, so that the words keep
half of the total variance whatever K) gives the linear kernel
``(1/K) sum_k k_{c_k}(u, v)``: the mean of K independent draws, whose codebook-induced
variance is ``1/K`` of one draw's (the Monte Carlo argument of random-feature kernel
approximations, Rahimi & Recht 2007, NIPS), i.e. variance reduction by averaging over
the randomisation, as bagging (Breiman 1996, Machine Learning 24(2)) -- here inside one
SVM rather than by voting K SVMs, so that there is one model to calibrate and store.
Histograms of several independently randomised codebooks, concatenated, are the
ensemble-of-codebooks representation of Moosmann, Triggs & Jurie (2007, NIPS,
"Fast discriminative visual codebooks using randomized clustering forests"); openXBOW
itself concatenates the histograms of its several codebooks (``-attributes``), which is
how the descriptor and delta codebooks are already joined. **K = 5** (:data:`ENSEMBLE`),
decided before measuring: it cuts the codebook-induced standard deviation to
``1/sqrt(5)`` = 45 % of one draw's (the 2.4-point range of three seeds to about 1 point)
at 5 times the cost of the words, which ingest's emotion step and ``classify`` can
afford (a few CPU-seconds on the demo corpus); more draws buy less and less (the
deviation falls as ``1/sqrt(K)``) at a linear cost.
"""

from __future__ import annotations

import numpy as np

from db.errors import DataError, ParameterError
from ingest.emotion.audio import prepare_audio
from ingest.emotion.frames import frame_analysis  # the ``rich`` block's frames

__all__ = ["ASSIGNMENTS", "CODEBOOK_SIZE", "ENSEMBLE", "N_DESCRIPTORS", "BagOfAudioWords",
           "codebook_seeds", "descriptors", "frame_descriptors"]

#: Words per codebook (openXBOW's default ``-size``).
CODEBOOK_SIZE = 500
#: Nearest words counted per frame (openXBOW ``-a``; its tutorial's 10).
ASSIGNMENTS = 10
#: Descriptors per frame before deltas: 20 MFCCs, log energy, F0 (semitones).
N_DESCRIPTORS = 22
#: Codebook pairs of the ensemble (module docstring: decided before measuring).
ENSEMBLE = 5
#: BLAS threads of the words' matrix products: one. They are small (an utterance's
#: frames x 22 x 500, a seeding step's frames x 22), and OpenBLAS's threads spin-waiting
#: on a loaded machine made the classifier's fit on the demo corpus 11 times as costly
#: in CPU (22 CPU-s with the default threads, 2 with one, at load 3.5; docs/results.md,
#: issue 16 fifth session), with the same results.
BLAS_THREADS = 1
_HOP_S = 0.01  # frame hop of :func:`frame_descriptors`, seconds


def frame_descriptors(audio, sample_rate) -> np.ndarray:
    """Frame-level descriptors of one utterance and their deltas.

    Parameters
    ----------
    audio : np.ndarray, shape (n_samples,) or (n_samples, n_channels)
        Speech (prepared as :func:`ingest.emotion.audio.prepare_audio`: 16 kHz,
        level-normalised; silence refused).
    sample_rate : int or float

    Returns
    -------
    np.ndarray, shape (n_frames, 2 * N_DESCRIPTORS)
        Per 10 ms frame: 20 MFCCs, log RMS energy, F0 in semitones above 27.5 Hz (0 when
        unvoiced), then the deltas of these 22 (5-frame regression), float64.
    """
    return descriptors(frame_analysis(prepare_audio(audio, sample_rate)))


def descriptors(fr: dict) -> np.ndarray:
    """:func:`frame_descriptors` from an utterance's
    :func:`ingest.emotion.frames.frame_analysis` (shared with the ``rich`` block).

    Returns
    -------
    np.ndarray, shape (n_frames, 2 * N_DESCRIPTORS)
    """
    import librosa

    mfcc, rms, f0 = fr["mfcc"], fr["rms"], fr["f0"]
    n = min(mfcc.shape[1], rms.size, f0.size)
    mfcc, rms, f0 = mfcc[:, :n], rms[:n], f0[:n]
    voiced = (rms > 0.1 * np.percentile(rms, 95)) & (f0 > 62) & (f0 < 490)
    semitones = np.where(voiced, 12.0 * np.log2(np.maximum(f0, 1.0) / 27.5), 0.0)
    lld = np.vstack([mfcc, np.log(rms + 1e-8)[None], semitones[None]]).astype(np.float64)
    delta = librosa.feature.delta(lld, width=5, mode="nearest") if n >= 5 \
        else np.zeros_like(lld)
    return np.nan_to_num(np.vstack([lld, delta]).T, nan=0.0, posinf=0.0, neginf=0.0)


def codebook_seeds(random_state: int, n_codebooks: int) -> list[int]:
    """Seeds of the ``n_codebooks`` codebook pairs of a bag seeded by ``random_state``.

    The first is ``random_state`` itself (so that the first pair is the one codebook pair
    of ``n_codebooks=1``); the others come from ``SeedSequence([random_state, k])`` (31
    bits: each pair's second codebook is seeded one above), so that ensembles with
    different ``random_state`` share no codebook.

    Returns
    -------
    list of int, length n_codebooks
    """
    return [int(random_state)] + [
        int(np.random.SeedSequence([int(random_state), k]).generate_state(1)[0] >> 1)
        for k in range(1, n_codebooks)]


def _nearest(Z: np.ndarray, words: np.ndarray, k: int) -> np.ndarray:
    """Indices (n, k) of the ``k`` nearest ``words`` (Euclidean) of each row of ``Z``."""
    d = (Z * Z).sum(1)[:, None] - 2.0 * Z @ words.T + (words * words).sum(1)[None]
    return np.argpartition(d, k - 1, axis=1)[:, :k] if k < words.shape[0] \
        else np.broadcast_to(np.arange(words.shape[0]), (Z.shape[0], words.shape[0]))


class BagOfAudioWords:
    """Codebooks of frame descriptors and the log term-frequency histograms they give.

    Parameters
    ----------
    size : int, optional
        Words per codebook (one for the descriptors, one for their deltas).
    assignments : int, optional
        Nearest words counted per frame.
    local_trials : int or None, optional
        Candidates drawn per k-means++ step, the nearest-to-optimal kept: 1 is the
        k-means++ seeding of Arthur & Vassilvitskii (2007) and openXBOW's ``random++``
        (its ``CodebookNumeric.randomSamplingPlusPlus``: one draw per word); None is
        scikit-learn's greedy default, ``2 + ln(size)`` draws (what issue #16's third
        session measured; 8 times the distance computations).
    max_frames : int, optional
        Training frames the codebooks are seeded from (a random subset when there are
        more; k-means++ seeding costs frames x words).
    n_codebooks : int, optional
        Codebook pairs drawn with different seeds (:func:`codebook_seeds`), their
        histograms concatenated (the module docstring's ensemble; 1: one pair).
    random_state : int, optional
        Seed of the first pair (the other pairs' follow from it).

    Attributes
    ----------
    mean_, scale_ : np.ndarray, shape (n_descriptors,)
        Standardisation of the training frames (shared by the pairs).
    codebooks_ : list of np.ndarray, each (size, n_descriptors / 2)
        Standardised words, ``2 * n_codebooks`` of them: descriptors, deltas of the first
        pair, then of the second, ...
    """

    def __init__(self, size: int = CODEBOOK_SIZE, assignments: int = ASSIGNMENTS,
                 local_trials: int | None = 1, max_frames: int = 50_000,
                 n_codebooks: int = 1, random_state: int = 0):
        self.size = size
        self.assignments = assignments
        self.local_trials = local_trials
        self.max_frames = max_frames
        self.n_codebooks = n_codebooks
        self.random_state = random_state

    @property
    def n_words(self) -> int:
        """Width of :meth:`transform`'s histograms, ``2 * n_codebooks * size``."""
        return 2 * self.n_codebooks * self.size

    def fit(self, frames) -> BagOfAudioWords:
        """Learn the standardisation and the codebooks.

        Parameters
        ----------
        frames : sequence of np.ndarray, each (n_frames_k, n_descriptors)
            :func:`frame_descriptors` of the training utterances.
        """
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=BLAS_THREADS, user_api="blas"):
            return self._fit(frames)

    def _fit(self, frames) -> BagOfAudioWords:
        from sklearn.cluster import kmeans_plusplus

        if not 1 <= self.assignments <= self.size:
            raise ParameterError(f"assignments must be in [1, size={self.size}], "
                                 f"got {self.assignments}")
        if isinstance(self.n_codebooks, bool) or not isinstance(
                self.n_codebooks, int | np.integer) or self.n_codebooks < 1:
            raise ParameterError(f"n_codebooks must be an integer >= 1, "
                                 f"got {self.n_codebooks!r}")
        X = np.vstack(list(frames))
        if X.shape[0] < self.size:
            raise ParameterError(
                f"a codebook of {self.size} audio words needs at least "
                f"{self.size * _HOP_S:.1f} s of training speech ({self.size} frames), got "
                f"{X.shape[0] * _HOP_S:.2f} s")
        self.mean_ = X.mean(0)
        sd = X.std(0)
        self.scale_ = np.where(sd > 0, sd, 1.0)
        half = X.shape[1] // 2
        self.codebooks_ = []
        for seed in codebook_seeds(self.random_state, int(self.n_codebooks)):
            rng = np.random.default_rng(seed)
            S = X[rng.choice(X.shape[0], self.max_frames, replace=False)] \
                if X.shape[0] > self.max_frames else X
            Z = (S - self.mean_) / self.scale_
            self.codebooks_ += [
                kmeans_plusplus(np.ascontiguousarray(part), self.size,
                                n_local_trials=self.local_trials, random_state=seed + i)[0]
                for i, part in enumerate((Z[:, :half], Z[:, half:]))]
        return self

    def transform(self, frames) -> np.ndarray:
        """Histograms, shape (n_utterances, :attr:`n_words`): ``lg(1 + counts per
        second)`` of the descriptors' words, then of the deltas' words, pair after pair."""
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=BLAS_THREADS, user_api="blas"):
            return self._transform(frames)

    def _transform(self, frames) -> np.ndarray:
        rows = []
        for F in frames:
            Z = (np.asarray(F, dtype=np.float64) - self.mean_) / self.scale_
            half = Z.shape[1] // 2
            parts = []
            for j, words in enumerate(self.codebooks_):
                part = Z[:, :half] if j % 2 == 0 else Z[:, half:]
                idx = _nearest(part, words, self.assignments)
                counts = np.bincount(idx.ravel(), minlength=words.shape[0])
                parts.append(np.log10(1.0 + counts / (max(Z.shape[0], 1) * _HOP_S)))
            rows.append(np.concatenate(parts))
        return np.vstack(rows)

    def to_arrays(self) -> dict[str, np.ndarray]:
        """``boaw_mean``, ``boaw_scale`` (n_descriptors,), ``boaw_codebook0`` ...
        ``boaw_codebook{2 n_codebooks - 1}`` (size, n_descriptors / 2),
        ``boaw_assignments`` and ``boaw_n_codebooks``."""
        out = {"boaw_mean": self.mean_.copy(), "boaw_scale": self.scale_.copy(),
               "boaw_assignments": np.array(self.assignments),
               "boaw_n_codebooks": np.array(len(self.codebooks_) // 2)}
        out.update({f"boaw_codebook{j}": book.copy()
                    for j, book in enumerate(self.codebooks_)})
        return out

    @classmethod
    def from_arrays(cls, arrays) -> BagOfAudioWords:
        """Rebuild fitted codebooks from :meth:`to_arrays` output, checked.

        Parameters
        ----------
        arrays : mapping of str to np.ndarray
            Without ``boaw_n_codebooks`` (classifier format 4) one pair is read.

        Raises
        ------
        DataError
            An array missing, of the wrong shape, or not finite (one line naming it).
        """
        n = np.asarray(arrays.get("boaw_n_codebooks", 1))
        if n.shape != () or n.dtype.kind not in "iuf" or not np.isfinite(n) \
                or float(n) != int(n) or not 1 <= int(n) <= 1000:
            raise DataError(f"stored bag-of-audio-words: boaw_n_codebooks must be an integer "
                            f"in [1, 1000], got {n.tolist()}")
        books = [f"boaw_codebook{j}" for j in range(2 * int(n))]
        try:
            a = {k: np.asarray(arrays[k]) for k in ("boaw_mean", "boaw_scale", *books,
                                                     "boaw_assignments")}
        except KeyError as exc:
            raise DataError(f"stored bag-of-audio-words lacks array {exc.args[0]!r}") from None
        for key, value in a.items():
            if value.dtype.kind not in "biuf" or not np.all(np.isfinite(value)):
                raise DataError(f"stored bag-of-audio-words: array {key!r} is not finite "
                                "numbers")
        width = a["boaw_mean"].shape
        if len(width) != 1 or width[0] < 2 or width[0] % 2 or a["boaw_scale"].shape != width:
            raise DataError(f"stored bag-of-audio-words: boaw_mean and boaw_scale must have "
                            f"one even shape (n_descriptors,), got {a['boaw_mean'].shape} "
                            f"and {a['boaw_scale'].shape}")
        if not np.all(a["boaw_scale"] > 0):
            raise DataError("stored bag-of-audio-words: boaw_scale must be positive")
        half = width[0] // 2
        size = a["boaw_codebook0"].shape[0] if a["boaw_codebook0"].ndim == 2 else -1
        for key in books:
            if a[key].shape != (size, half) or size < 1:
                raise DataError(f"stored bag-of-audio-words: {key} must have shape "
                                f"(n_words, {half}) as the other codebooks, got "
                                f"{a[key].shape}")
        k = a["boaw_assignments"]
        if k.shape != () or not 1 <= float(k) <= size or float(k) != int(k):
            raise DataError(f"stored bag-of-audio-words: boaw_assignments must be an integer "
                            f"in [1, {size}], got {k.tolist()}")
        bag = cls(size=size, assignments=int(k), n_codebooks=int(n))
        bag.mean_ = a["boaw_mean"].astype(np.float64)
        bag.scale_ = a["boaw_scale"].astype(np.float64)
        bag.codebooks_ = [a[key].astype(np.float64) for key in books]
        return bag

