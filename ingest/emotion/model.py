"""The emotion model of a database, learned at ingest (Cao et al. 2005, §5 and §6).

:func:`fit_emotion_model` learns, from the clips of a database and their independent
components:

1. the speech / emotion split of the components (§5.1.3, :mod:`ingest.emotion.components`);
2. for every ordered pair (i, j) of emotions with at least :data:`MIN_PARALLEL` sentences
   recorded in both, the mapping F_ij (§5.2, :class:`ingest.emotion.mapping.EmotionMapping`)
   from the correspondences of their emotion components, time-aligned by DTW on the speech
   components (:func:`correspondences`), and the mean offset e_j - e_i (a baseline);
3. the emotion classifier of speech (§6, the measured-best pipeline of issue #16) on the
   clips' audio, if at least two emotions have :data:`MIN_CLASSIFIER_CLIPS` usable clips
   each;
4. each emotion's mean emotion components (to guess the emotion of a motion).

:meth:`EmotionModel.to_database` turns it into model arrays (``emotion/...``), columns of the
``components`` table and a manifest entry; :meth:`EmotionModel.from_database` reads it back.
What could not be learned is said in ``notes`` (and in the manifest), never an error at
ingest: the errors come when a user asks for what is missing (:meth:`EmotionModel.mapping`).
"""

from __future__ import annotations

import logging
from collections.abc import Collection, Sequence
from dataclasses import dataclass, field
from itertools import permutations
from typing import TYPE_CHECKING

import numpy as np

from db.errors import AnimeGraphError, DataError, ParameterError
from ingest.emotion.align import sample_at
from ingest.emotion.components import (
    Aligner,
    ComponentSplit,
    parallel_groups,
    split_components,
    take_pairs,
)
from ingest.emotion.rbf import KERNEL, N_CENTRES, RbfMapping
from ingest.invariants import check_emotion

if TYPE_CHECKING:
    from ingest.emotion.classifier import EmotionClassifier, SpeechFeatures
    from ingest.emotion.mapping import EmotionMapping

logger = logging.getLogger(__name__)

#: Fewest sentences recorded in both emotions to learn a mapping between them (one
#: sentence's correspondences say nothing about other sentences; the paper has m = 10).
MIN_PARALLEL = 2
#: Prefix of the emotion model's arrays in the database.
PREFIX = "emotion/"
#: Fewest usable clips of an emotion for the classifier to learn it (its probability
#: calibration needs two per class in every out-of-fold split).
MIN_CLASSIFIER_CLIPS = 2
_CLASSIFIER_STRINGS = ("kernel", "features", "cepstrum", "normalize", "classes",
                       "norm_speakers", "class_weight")


class _StoredClassifier:
    """:attr:`EmotionModel.classifier` and ``classifier_note``, rebuilt on first read.

    A database's classifier is a scikit-learn estimator; rebuilding it imports
    scikit-learn (about a second), which a synthesis that is given its emotion never
    needs. :meth:`EmotionModel.from_database` therefore keeps the stored arrays (a
    ``dict``), and the first read of either attribute turns them into an
    :class:`~ingest.emotion.classifier.EmotionClassifier` -- or, for a classifier stored
    by an older animegraph, into None with the reason in ``classifier_note``.
    """

    def __set_name__(self, owner, name: str) -> None:
        self.name = name

    def __get__(self, model, owner=None):
        if model is None:  # the dataclass field's default
            return None if self.name == "classifier" else ""
        stored = model.__dict__["_classifier"]
        if isinstance(stored, dict):
            from ingest.emotion.classifier import EmotionClassifier

            try:
                model.__dict__["_classifier"] = EmotionClassifier.from_arrays(stored)
            except DataError as exc:  # an older format: the rest of the model still loads
                model.__dict__["_classifier"] = None
                model.__dict__["_classifier_note"] = str(exc)
        return model.__dict__["_" + self.name]

    def __set__(self, model, value) -> None:
        model.__dict__["_" + self.name] = value


class NoEmotionModel(DataError):
    """The database was built before emotion models existed (it has none)."""


@dataclass(frozen=True)
class ParallelData:
    """What mappings are learned from: clips, their components and their sentences."""

    sources: Sequence[np.ndarray]
    emotions: Sequence[str]
    sentence_ids: Sequence[str | None]
    aligner: Aligner

    def sentences(self, src: str, dst: str) -> list[str]:
        """Sentences recorded in both ``src`` and ``dst``."""
        return [s for s, g in parallel_groups(self.emotions, self.sentence_ids).items()
                if src in g and dst in g]


def correspondences(data: ParallelData, src: str, dst: str, sentences: Sequence[str],
                    split: ComponentSplit) -> tuple[np.ndarray, np.ndarray]:
    """Time-aligned emotion components of ``sentences`` in ``src`` and ``dst`` (§5.2).

    Each take in ``src`` is aligned to the matching take in ``dst`` by DTW on the speech
    components; the target's emotion components are resampled onto the source's frames.

    Returns
    -------
    (e_src, e_dst) : np.ndarray, each (T, n_emotion_components)
    """
    groups = parallel_groups(data.emotions, data.sentence_ids)
    e, s = split.emotion_components, split.speech_components
    xs, ys = [], []
    for sentence in sentences:
        g = groups[sentence]
        for a, b in take_pairs(g[src], g[dst]):
            where = data.aligner.positions(a, b, s)
            xs.append(np.asarray(data.sources[a], dtype=np.float64)[:, e])
            ys.append(sample_at(np.asarray(data.sources[b], dtype=np.float64)[:, e], where))
    return np.concatenate(xs), np.concatenate(ys)


#: A database whose clips carry no emotion label, as every message says it (an unknown
#: emotion, ``auto``, ``classify``).
NO_EMOTION_LABELS = "its clips carry no emotion labels"


def stored_model_current(manifest: dict) -> bool:
    """Whether a database's emotion model (its manifest's ``emotion``) is what ingest
    makes now: present, and its classifier, if it has one, of a format whose features
    ingest computes (one stored before the silence floor misjudged speech whose pauses
    are digital silence). If not, the next ingest learns it again from the stored clips.
    """
    from ingest.emotion.classifier_arrays import SILENCE_FLOOR_FORMAT

    emotion = manifest.get("emotion")
    if emotion is None:
        return False
    classifier = emotion.get("classifier")
    return not classifier or classifier.get("format", 0) >= SILENCE_FLOOR_FORMAT


def find_emotion(name: str, known: Collection[str]) -> str:
    """``name`` as ``known`` spells it, whatever its case.

    Ingest lowercases emotion labels (they name partition folders, one on a
    case-insensitive file system); a database written before it did may hold ``Happy``.

    Raises
    ------
    ParameterError
        No emotion of ``known`` is ``name`` (or two are, differing only in case).
    """
    if name in known:
        return name
    same = [k for k in known if k.casefold() == name.casefold()]
    if len(same) == 1:
        return same[0]
    if not set(known) - {"unknown"}:  # the label of clips without one
        raise ParameterError(f"unknown emotion {name!r}: the database has no emotions "
                             f"({NO_EMOTION_LABELS}): leave the emotion out")
    raise ParameterError(f"unknown emotion {name!r}: it is not in the database (it has "
                         f"{', '.join(sorted(known))})")


@dataclass(frozen=True, eq=False)
class EmotionModel:
    """Everything a database knows about emotion.

    Attributes
    ----------
    emotions : tuple of str
        Emotions of the database's clips (``unknown`` left out).
    split : ComponentSplit
    mappings : dict of (str, str) to RbfMapping
        F_ij by (i, j) (fitted :class:`~ingest.emotion.mapping.EmotionMapping`, or as
        restored from a database).
    offsets : dict of (str, str) to np.ndarray, shape (n_emotion_components,)
        Mean e_j - e_i over the correspondences (the offset baseline).
    centroids : dict of str to np.ndarray, shape (n_emotion_components,)
        Mean emotion components of each emotion's clips.
    parallel : dict of str to int
        Sentences recorded in both emotions, by "a/b" (sorted names).
    classifier : EmotionClassifier or None
        From a database, rebuilt on first use (:class:`_StoredClassifier`).
    notes : tuple of str
        What could not be learned and why.
    classifier_note : str
        Why there is no classifier when the database holds one that cannot be used (one
        stored by an older animegraph: re-ingest), else "".
    """

    emotions: tuple[str, ...]
    split: ComponentSplit
    mappings: dict = field(default_factory=dict)
    offsets: dict = field(default_factory=dict)
    centroids: dict = field(default_factory=dict)
    parallel: dict = field(default_factory=dict)
    classifier: EmotionClassifier | None = _StoredClassifier()
    notes: tuple[str, ...] = ()
    classifier_note: str = _StoredClassifier()

    # ------------------------------------------------------------------ use
    def check_emotion(self, name: str) -> str:
        """``name`` as the database spells it (:func:`find_emotion`)."""
        return find_emotion(name, self.emotions)

    def mapping(self, src: str, dst: str) -> RbfMapping | None:
        """F_src,dst (None when src == dst: the identity).

        Raises
        ------
        ParameterError
            Unknown emotion.
        DataError
            The database has a single emotion, or too few sentences in both to map.
        """
        if len(self.emotions) < 2:
            raise DataError(f"the database has a single emotion "
                            f"({', '.join(self.emotions) or 'none labelled'}): there is "
                            "nothing to map between")
        src, dst = self.check_emotion(src), self.check_emotion(dst)
        if src == dst:
            return None
        if (src, dst) not in self.mappings:
            n = self.parallel.get("/".join(sorted((src, dst))), 0)
            why = ("it has no emotion components" if self.split.emotion_components.size == 0
                   else f"it has {n} sentence{'s' if n != 1 else ''} recorded in both, "
                   f"a mapping needs {MIN_PARALLEL}")
            raise DataError(f"the database cannot map {src} to {dst}: {why}")
        return self.mappings[(src, dst)]

    def map_components(self, ics: np.ndarray, src: str, dst) -> np.ndarray:
        """Independent components ``ics`` (n_frames, n_ics) of a motion in emotion ``src``
        with their emotion components mapped into ``dst``.

        ``dst`` is an emotion name or a dict of weights ({"happy": 0.7, "neutral": 0.3}):
        the mapped emotion components are blended with the weights (normalised to sum 1).
        Speech and other components are unchanged.
        """
        weights = {dst: 1.0} if isinstance(dst, str) else dict(dst)
        total = sum(weights.values())
        out = np.array(ics, dtype=np.float64, copy=True)
        e = self.split.emotion_components
        if e.size == 0:
            for name in weights:
                self.mapping(src, name)  # raises why
            return out
        source = out[:, e]
        mixed = np.zeros_like(source)
        for name, w in weights.items():
            f = self.mapping(src, name)
            mixed += (w / total) * (source if f is None else f.transform(source))
        out[:, e] = mixed
        return out

    def nearest(self, target: str, available: Sequence[str]) -> str:
        """The emotion of ``available`` whose mean emotion components are closest to
        ``target``'s (``target`` itself if available)."""
        if target in available:
            return target
        mappable = [a for a in available if (a, target) in self.mappings]
        pool = mappable or list(available)
        if target not in self.centroids:
            return pool[0]
        c = self.centroids[target]
        return min(pool, key=lambda a: float(np.linalg.norm(self.centroids[a] - c))
                   if a in self.centroids else np.inf)

    def guess_emotion(self, ics: np.ndarray) -> str:
        """The emotion whose mean emotion components are nearest to those of ``ics``."""
        e = self.split.emotion_components
        if e.size == 0 or not self.centroids:
            raise DataError("the database has no emotion components to tell a motion's "
                            "emotion by: give it (--from E)")
        mean = np.asarray(ics, dtype=np.float64)[:, e].mean(axis=0)
        return min(self.centroids, key=lambda k: float(np.linalg.norm(self.centroids[k] - mean)))

    # ------------------------------------------------------------------ storage
    def to_database(self) -> tuple[dict[str, np.ndarray], dict, dict[str, list]]:
        """(model arrays, manifest entry, ``components`` table columns)."""
        arrays: dict[str, np.ndarray] = {
            PREFIX + "emotion_components": self.split.emotion_components.astype(float),
        }
        for (src, dst), f in self.mappings.items():
            for key, value in f.to_arrays().items():
                arrays[f"{PREFIX}map/{src}/{dst}/{key}"] = value
            arrays[f"{PREFIX}offset/{src}/{dst}"] = self.offsets[(src, dst)]
        for name, c in self.centroids.items():
            arrays[f"{PREFIX}centroid/{name}"] = c
        classifier = None
        if self.classifier is not None:
            stored, classifier = classifier_entry(self.classifier)
            arrays.update(stored)
        manifest = {
            "emotions": list(self.emotions),
            "emotion_components": self.split.emotion_components.tolist(),
            "speech_components": [k for k, lab in enumerate(self.split.labels)
                                  if lab == "speech"],
            "parallel_sentences": dict(self.parallel),
            "mappings": [f"{s}->{d}" for s, d in sorted(self.mappings)],
            "classifier": classifier,
            "notes": list(self.notes),
        }
        return arrays, manifest, self.split.columns()

    @classmethod
    def from_database(cls, db, arrays: dict | None = None) -> EmotionModel:
        """Read the emotion model of ``db`` (a :class:`db.store.Database`); ``arrays``:
        its model arrays if the caller has read them already (``db.arrays()``).

        Raises
        ------
        NoEmotionModel
            If the database was built before emotion models existed.
        DataError
            If its arrays contradict each other (:func:`ingest.invariants.check_emotion`).
        """
        entry = db.manifest.get("emotion")
        rows = db.table("components").to_pylist()
        if entry is None or not rows or "label" not in rows[0]:
            raise NoEmotionModel(f"database {db.root} has no emotion model (it was built by "
                                 f"an older animegraph): run 'animegraph ingest SRC --db "
                                 f"{db.root}' once to learn it")
        arrays = db.arrays() if arrays is None else arrays
        split = ComponentSplit.from_columns(rows)
        frames: dict[str, int] = {}
        try:
            for clip in db.table("clips", columns=["emotion", "n_frames"]).to_pylist():
                frames[clip["emotion"]] = frames.get(clip["emotion"], 0) + int(clip["n_frames"])
            check_emotion(arrays, entry, split.emotion_components, len(rows), frames)
        except (AttributeError, KeyError, TypeError, ValueError) as exc:
            what = f"no array {exc}" if isinstance(exc, KeyError) else str(exc)
            raise db.damaged("model_arrays", f"emotion model: {what}") from None
        mappings, offsets, centroids = {}, {}, {}
        for pair in entry["mappings"]:
            src, dst = pair.split("->")
            prefix = f"{PREFIX}map/{src}/{dst}/"
            mappings[(src, dst)] = RbfMapping.from_arrays(
                {k[len(prefix):]: v for k, v in arrays.items() if k.startswith(prefix)})
            offsets[(src, dst)] = arrays[f"{PREFIX}offset/{src}/{dst}"]
        for name in entry["emotions"]:
            key = f"{PREFIX}centroid/{name}"
            if key in arrays:
                centroids[name] = arrays[key]
        classifier = None
        if entry.get("classifier"):
            prefix = PREFIX + "classifier/"
            stored = {k[len(prefix):]: v for k, v in arrays.items() if k.startswith(prefix)}
            stored.update({k: np.array(v) for k, v in entry["classifier"].items()
                           if k in _CLASSIFIER_STRINGS})  # (its "format" says what the arrays say)
            for key in ("support", "n_support"):
                stored[key] = stored[key].astype(np.int64)
            classifier = stored  # rebuilt on first use (_StoredClassifier)
        return cls(emotions=tuple(entry["emotions"]), split=split, mappings=mappings,
                   offsets=offsets, centroids=centroids,
                   parallel=dict(entry["parallel_sentences"]), classifier=classifier,
                   notes=tuple(entry.get("notes", ())))


def classifier_entry(classifier: EmotionClassifier) -> tuple[dict[str, np.ndarray], dict]:
    """A fitted classifier as a database stores it: its numeric arrays (named
    ``emotion/classifier/<key>``) and its manifest entry (the strings, and the format)."""
    raw = classifier.to_arrays()
    entry = {k: np.asarray(raw[k]).tolist() for k in _CLASSIFIER_STRINGS if k in raw}
    # Readable without the arrays: a cached database can tell it predates a format.
    entry["format"] = int(np.asarray(raw["format"]))
    arrays = {f"{PREFIX}classifier/{key}": np.asarray(value, dtype=np.float64)
              for key, value in raw.items() if key not in _CLASSIFIER_STRINGS}
    return arrays, entry


def fit_mapping(data: ParallelData, src: str, dst: str, sentences: Sequence[str],
                split: ComponentSplit, *, n_centres: int = N_CENTRES, kernel: str = KERNEL,
                random_state: int = 0, offset: bool = False, clusters: dict | None = None
                ) -> tuple[EmotionMapping, np.ndarray]:
    """F_src,dst and the mean offset from the parallel ``sentences`` (§5.2); ``clusters``
    shares the K-means of identical source samples between mappings
    (:meth:`EmotionMapping.fit`)."""
    from ingest.emotion.mapping import EmotionMapping

    x, y = correspondences(data, src, dst, sentences, split)
    f = EmotionMapping(n_centres=n_centres, kernel=kernel, random_state=random_state,
                       offset=offset).fit(x, y, clusters=clusters)
    return f, (y - x).mean(axis=0)


def fit_emotion_model(
    sources: Sequence[np.ndarray],
    motions: Sequence[np.ndarray],
    emotions: Sequence[str],
    sentence_ids: Sequence[str | None],
    audio: Sequence[tuple[np.ndarray, int]] | None,
    loadings: np.ndarray,
    groups: Sequence[str],
    fps: float,
    *,
    n_centres: int = N_CENTRES,
    kernel: str = KERNEL,
    random_state: int = 0,
    speakers: Sequence[str | None] | None = None,
    classifier_rows: Sequence[np.ndarray | str | None] | None = None,
) -> EmotionModel:
    """Learn a database's emotion model (see the module docstring).

    Parameters
    ----------
    sources : sequence of np.ndarray, each (n_frames_k, n_ics)
        Independent components of every clip.
    motions : sequence of np.ndarray, each (n_frames_k, n_channels)
        The clips' motion in the database's channels.
    emotions, sentence_ids : sequence of str
        Per clip.
    audio : sequence of (np.ndarray, int), optional
        Each clip's speech (samples, rate), for the classifier (None: no classifier).
    loadings : np.ndarray, shape (n_ics, n_channels)
        Channel motion of one unit of each independent component.
    groups : sequence of str, length n_channels
        Channel groups; ``lips`` are the mouth (every channel if no group is).
    fps : float
    n_centres, kernel, random_state
        Of the mappings (:class:`EmotionMapping`).
    speakers : sequence of str or None, optional
        Speaker of each clip, for the classifier's per-speaker normalisation (None: one
        speaker).
    classifier_rows : sequence of (np.ndarray or str or None), optional
        Per clip, what :func:`classifier_features` returned (computed with the clip in a
        worker), or None to compute it here.
    """
    mouth = np.array([g == "lips" for g in groups])
    if not mouth.any():
        mouth[:] = True
    aligner = Aligner(sources, fps)
    split = split_components(sources, motions, emotions, sentence_ids, loadings, mouth,
                             fps=fps, aligner=aligner)
    present = tuple(sorted({e for e in emotions if e != "unknown"}))
    notes = []
    groups_ = parallel_groups(emotions, sentence_ids)
    parallel: dict[str, int] = {}
    for g in groups_.values():
        names = sorted(g)
        for i, a in enumerate(names):
            for b in names[i + 1:]:
                parallel[f"{a}/{b}"] = parallel.get(f"{a}/{b}", 0) + 1
    e = split.emotion_components
    centroids = {}
    if e.size:
        for name in present:
            rows = [np.asarray(s)[:, e] for s, em in zip(sources, emotions, strict=True)
                    if em == name]
            centroids[name] = np.concatenate(rows).mean(axis=0)
    if len(present) < 2:
        notes.append(f"a single emotion ({', '.join(present) or 'none labelled'}): "
                     "no emotion mappings")
    elif not groups_:
        notes.append("no sentence is recorded in two emotions: no emotion components, "
                     "no mappings")
    elif e.size == 0:
        notes.append("no component differs between emotions: no mappings")
    data = ParallelData(sources, emotions, sentence_ids, aligner)
    mappings, offsets = {}, {}
    clusters: dict = {}  # a source emotion's frames are clustered once for every target
    if e.size:
        for src, dst in permutations(present, 2):
            sentences = data.sentences(src, dst)
            if len(sentences) < MIN_PARALLEL:
                notes.append(f"{src}->{dst}: {len(sentences)} parallel sentence(s), a mapping "
                             f"needs {MIN_PARALLEL}")
                continue
            mappings[(src, dst)], offsets[(src, dst)] = fit_mapping(
                data, src, dst, sentences, split, n_centres=n_centres, kernel=kernel,
                random_state=random_state, clusters=clusters)
    classifier = None
    if audio is not None:
        classifier = _fit_classifier(audio, emotions, speakers, notes, classifier_rows)
    return EmotionModel(emotions=present, split=split, mappings=mappings, offsets=offsets,
                        centroids=centroids, parallel=parallel, classifier=classifier,
                        notes=tuple(notes))


def database_classifier() -> EmotionClassifier:
    """The (unfitted) emotion classifier every database learns: the default pipeline with
    probabilities (``classify`` prints them)."""
    from ingest.emotion.classifier import EmotionClassifier  # deferred: scikit-learn

    return EmotionClassifier(probability=True)


def classifier_features(audio: np.ndarray, sample_rate: float) -> SpeechFeatures | str:
    """What :func:`database_classifier` computes from one clip before fitting, or why there
    is nothing.

    Computed per clip (in ingest's workers, :func:`ingest.prepare.prepare_clip`) so that
    :func:`fit_emotion_model` does not compute them one clip after another.

    Parameters
    ----------
    audio : np.ndarray, shape (n_samples,) or (n_samples, n_channels)
        The clip's speech.
    sample_rate : int or float
        Its rate in Hz.

    Returns
    -------
    SpeechFeatures or str
        The clip's functionals (1, n_functionals) and frame descriptors (one array of
        (n_frames, 44); the codebooks are learned from them at fit), or the one-line
        reason the audio cannot be classified (too short, silent).
    """
    try:
        return database_classifier().describe([(audio, sample_rate)])
    except AnimeGraphError as exc:  # featurize names the utterance ("utterance 0: ..."):
        return str(exc.__cause__ or exc)  # one clip here, its reason is enough


def _fit_classifier(audio, emotions, speakers, notes,
                    features=None) -> EmotionClassifier | None:
    """The default :class:`EmotionClassifier` (with probabilities) on the labelled clips.

    ``features`` (one entry per clip, optional) holds what :func:`classifier_features`
    returned for a clip, or None where it is computed here. The frame descriptors are
    held for every clip until the fit (44 float64 per 10 ms: about 130 MB per hour of
    speech); the codebooks are seeded from at most 50,000 of them drawn at random
    (:class:`ingest.emotion.boaw.BagOfAudioWords`). Clips whose audio is unusable
    (too short, silent) are left out with a note; emotions with fewer than
    :data:`MIN_CLASSIFIER_CLIPS` usable clips too. Never raises for data: what could not be
    done is a note.
    """
    from ingest.emotion.classifier import SpeechFeatures

    model = database_classifier()
    rows, labels, who, dropped = [], [], [], []
    for i, (a, sr) in enumerate(audio):
        if emotions[i] == "unknown":
            continue
        row = features[i] if features is not None else None
        if row is None:
            row = classifier_features(a, sr)
        if isinstance(row, str):
            dropped.append(f"clip {i} ({row})")
            continue
        rows.append(row)
        labels.append(emotions[i])
        who.append(speakers[i] if speakers is not None and speakers[i] else "unknown")
    if dropped:
        notes.append(f"emotion classifier: {len(dropped)} clip(s) left out: "
                     + "; ".join(dropped[:3]) + (" ..." if len(dropped) > 3 else ""))
    labels = np.array(labels, dtype=object)
    names, counts = np.unique(labels.astype(str), return_counts=True)
    usable = set(names[counts >= MIN_CLASSIFIER_CLIPS])
    if len(usable) < 2:
        have = ", ".join(f"{n} {c}" for n, c in zip(names, counts, strict=True))
        notes.append(f"no emotion classifier: it needs two emotions with at least "
                     f"{MIN_CLASSIFIER_CLIPS} usable clips each ("
                     + (f"clips per emotion: {have})" if have
                        else "it has no usable clip)" if dropped
                        else "its clips carry no emotion labels)"))
        return None
    keep = [k for k, lab in enumerate(labels) if lab in usable]
    if len(usable) < names.size:
        notes.append("emotion classifier: left out emotions with fewer than "
                     f"{MIN_CLASSIFIER_CLIPS} clips: "
                     + ", ".join(sorted(set(names) - usable)))
    frames = None if rows[0].frames is None else [rows[k].frames[0] for k in keep]
    X = SpeechFeatures(np.vstack([rows[k].functionals for k in keep]), frames)
    try:
        return model.fit(X, labels[keep].astype(str), speakers=np.array([who[k] for k in keep]))
    except AnimeGraphError as exc:
        notes.append(f"the emotion classifier could not be trained: {exc}")
        return None
