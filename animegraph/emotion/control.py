"""Emotion under control in synthesis (Cao et al. 2005, §5.2 Fig. 6, and §6).

* :func:`parse_emotion` -- an emotion request: ``None``, ``"auto"`` (classify the speech,
  §6), a name (``"happy"``) or a mix (``"happy=0.7,neutral=0.3"`` or a dict; beyond the
  paper);
* :func:`classify_speech` -- class probabilities of an utterance from the database's
  classifier;
* :func:`resolve_emotion` -- the request made concrete for one database and utterance;
* :func:`map_frames` -- the motion found by the search moved into the wanted emotion: the
  frames that came from animes of another emotion X get their emotion components mapped
  by F_X,E (Fig. 6); a mix blends the mapped emotion components with its weights;
* :func:`map_motion` -- a whole motion file's emotion changed (``animegraph map-emotion``).
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from db.errors import DataError, ParameterError
from ingest.emotion.model import NO_EMOTION_LABELS, EmotionModel, find_emotion
from ingest.lowpass import smooth
from ingest.motion import unstabilize_points

AUTO = "auto"
_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_-]*$")


def parse_emotion(spec) -> str | dict[str, float] | None:
    """Normalise an emotion request.

    Parameters
    ----------
    spec : None, str or mapping of str to float
        ``None`` (no preference), ``"auto"``, an emotion name, ``"happy=0.7,neutral=0.3"``
        or ``{"happy": 0.7, "neutral": 0.3}``.

    Returns
    -------
    None, str or dict of str to float
        A mix comes back as a dict whose weights sum to 1; a one-emotion mix as its name.

    Raises
    ------
    ParameterError
        Malformed text, a negative or non-numeric weight, weights summing to 0.
    """
    if spec is None:
        return None
    if isinstance(spec, Mapping):
        items = [(str(k), v) for k, v in spec.items()]
    elif isinstance(spec, str):
        text = spec.strip()
        if not text:
            raise ParameterError("emotion must not be empty")
        if "=" not in text and "," not in text:
            if not _NAME.match(text):
                raise ParameterError(f"not an emotion name: {text!r}")
            return text.lower() if text.lower() == AUTO else text
        items = []
        for part in text.split(","):
            name, sep, weight = part.partition("=")
            if not sep:
                raise ParameterError(f"emotion mix {text!r}: write name=weight, e.g. "
                                     "happy=0.7,neutral=0.3")
            items.append((name.strip(), weight.strip()))
    else:
        raise ParameterError(f"emotion must be a name, 'auto' or a mix, got {spec!r}")
    mix: dict[str, float] = {}
    for name, weight in items:
        if not _NAME.match(name) or name == AUTO:
            raise ParameterError(f"not an emotion name in the mix: {name!r}")
        try:
            w = float(weight)
        except (TypeError, ValueError):
            raise ParameterError(f"emotion weight of {name} is not a number: {weight!r}") from None
        if not np.isfinite(w):  # 1e999 parses, as inf: it is no weight
            raise ParameterError(f"emotion weight of {name} is not a finite number: "
                                 f"{weight!r}")
        if w < 0:
            raise ParameterError(f"emotion weight of {name} must be >= 0, got {weight}")
        mix[name] = mix.get(name, 0.0) + w
    total = sum(mix.values())
    if not total > 0:
        raise ParameterError("emotion mix weights sum to 0")
    mix = {k: v / total for k, v in mix.items() if v > 0}
    return next(iter(mix)) if len(mix) == 1 else mix


def no_classifier(model: EmotionModel | None, *, auto: bool = True) -> str:
    """Why the database cannot classify speech, and what to do: the one wording of
    ``classify`` (``auto=False``) and of the emotion ``auto`` (synthesis, ``batch``)."""
    if model is None:
        return ("the database has no emotion model: give the emotion instead of 'auto'"
                if auto else "the database has no emotion model (it was built by an older "
                "animegraph): re-ingest it (animegraph ingest SRC --db DB) to learn one")
    if model.classifier_note:  # one stored by an older animegraph: re-ingest
        return model.classifier_note
    if not model.emotions:
        return (f"the database has no emotion classifier ({NO_EMOTION_LABELS}): "
                + ("leave the emotion out instead of 'auto'" if auto else
                   "classifying needs a database of clips labelled with two emotions or more"))
    from ingest.emotion.model import MIN_CLASSIFIER_CLIPS

    n = len(model.emotions)
    return (f"the database has no emotion classifier (its clips carry {n} emotion "
            f"label{'s' * (n != 1)}, {', '.join(model.emotions)}; it needs two emotions with "
            f"at least {MIN_CLASSIFIER_CLIPS} usable clips each): "
            + ("give the emotion instead of 'auto'" if auto else
               "re-ingest with more labelled clips to classify"))


def classify_speech(model: EmotionModel, audio: np.ndarray, sample_rate: int, *,
                    auto: bool = True) -> dict[str, float]:
    """Probabilities of the database's emotions for an utterance (§6), most likely first.

    ``auto``: asked for by the emotion ``auto`` (the error says to name the emotion
    instead), else by ``classify``.

    Speech only: noise, tones and music are refused with the reason
    (:func:`ingest.emotion.audio.check_speech`). A recording longer than
    :data:`ingest.emotion.timeline.MAX_UTTERANCE_S` is classified window by window
    (bounded memory, linear time); its probabilities are the mean of its speech windows'.

    Raises
    ------
    DataError
        No classifier in the database (:func:`no_classifier`); audio too short (< 0.25 s),
        silent, not speech, or non-finite.
    """
    from ingest.emotion.timeline import utterance_probabilities

    if model.classifier is None:
        raise DataError(no_classifier(model, auto=auto))
    return utterance_probabilities(model.classifier, audio, sample_rate)


def classify_timeline(model: EmotionModel, audio: np.ndarray, sample_rate: int, *,
                      auto: bool = True, window: float | None = None,
                      hop: float | None = None) -> list:
    """The recording's windows (:func:`ingest.emotion.timeline.classify_windows`; ``window``
    and ``hop`` in seconds, None: its defaults), each classified, or why it is not (silence,
    not speech)."""
    from ingest.emotion.timeline import HOP_S, WINDOW_S, classify_windows

    if model.classifier is None:
        raise DataError(no_classifier(model, auto=auto))
    return classify_windows(model.classifier, audio, sample_rate,
                            window=WINDOW_S if window is None else window,
                            hop=HOP_S if hop is None else hop)


@dataclass(frozen=True)
class EmotionTimeline:
    """The emotion of a long line over time: its windows' probabilities
    (:func:`ingest.emotion.timeline.classify_windows`), which ``synth --emotion auto``
    follows (:func:`map_frames_over_time`)."""

    windows: tuple

    def weights(self, times) -> tuple[list[str], np.ndarray]:
        """(names, weights of shape (len(times), n_names)) at ``times`` in seconds:
        :func:`ingest.emotion.timeline.weights_over_time`."""
        from ingest.emotion.timeline import weights_over_time

        return weights_over_time(list(self.windows), times)

    def describe(self) -> str:
        """The leading emotion of each speech window, runs joined: ``angry 0-6 s, sad 6-12 s``."""
        runs: list[list] = []
        for w in self.windows:
            if w.probabilities is None:
                continue
            top = next(iter(w.probabilities))
            if runs and runs[-1][0] == top:
                runs[-1][2] = w.end
            else:
                runs.append([top, w.start, w.end])
        return ", ".join(f"{name} {a:.0f}-{b:.0f} s" for name, a, b in runs)


@dataclass(frozen=True)
class EmotionChoice:
    """An emotion request made concrete.

    Attributes
    ----------
    target : str or dict of str to float or None
        The emotion (or mix) the motion should show; None: whatever the search finds.
    search : str or None
        Emotion whose animes the search prefers (the mix's heaviest, or the nearest one
        the database has animes of).
    probabilities : dict of str to float or None
        The classifier's output for ``"auto"`` (over a long line, its windows' mean).
    timeline : EmotionTimeline or None
        For ``"auto"`` on speech longer than a window: the emotion over time, which the
        motion follows instead of ``target``.
    """

    target: str | dict | None
    search: str | None
    probabilities: dict | None = None
    timeline: EmotionTimeline | None = None

    def describe(self) -> str:
        if self.target is None:
            return "none"
        if isinstance(self.target, dict):
            return ",".join(f"{k}={v:.2f}" for k, v in self.target.items())
        return self.target


def check_names(spec, model: EmotionModel | None, graph_emotions: Sequence[str]):
    """A parsed request in the database's spelling of its emotions.

    Names match whatever their case (:func:`ingest.emotion.model.find_emotion`).

    Returns
    -------
    None, str or dict of str to float
        ``spec`` with each name as the database writes it.

    Raises
    ------
    ParameterError
        A name the database lacks.
    """
    if spec is None or spec == AUTO:
        return spec
    known = set(graph_emotions) | set(model.emotions if model is not None else ())
    if isinstance(spec, str):
        return find_emotion(spec, known)
    mix: dict[str, float] = {}
    for name, weight in spec.items():
        name = find_emotion(name, known)
        mix[name] = mix.get(name, 0.0) + weight
    return mix


def resolve_emotion(spec, model: EmotionModel | None, graph_emotions: Sequence[str],
                    audio: np.ndarray | None = None, sample_rate: int | None = None, *,
                    timeline: bool = False) -> EmotionChoice:
    """Make an emotion request concrete for a database (and the speech, for ``"auto"``).

    With ``timeline`` (what a synthesis asks; a check or the live loop, which use only the
    target, need not), ``"auto"`` on speech longer than one window
    (:data:`ingest.emotion.timeline.WINDOW_S`) with two speech windows or more gives an
    :class:`EmotionTimeline` too; ``spec`` may be an :class:`EmotionChoice` already made
    (returned as it is).

    Raises
    ------
    ParameterError
        An emotion the database does not know.
    DataError
        ``"auto"`` without a classifier or with unusable audio.
    """
    if isinstance(spec, EmotionChoice):
        return spec
    spec = check_names(parse_emotion(spec), model, graph_emotions)
    if spec is None:
        return EmotionChoice(None, None)
    follow, probabilities, timeline = timeline, None, None
    if spec == AUTO:
        if model is None:
            raise DataError(no_classifier(None))
        if audio is None or sample_rate is None:
            raise ParameterError("emotion 'auto' needs the speech to classify")
        timeline = _timeline(model, audio, sample_rate) if follow else None
        if timeline is None:
            probabilities = classify_speech(model, audio, sample_rate)
        else:
            from ingest.emotion.timeline import mean_probabilities

            probabilities = mean_probabilities(list(timeline.windows))
        spec = next(iter(probabilities))
    spec = check_names(spec, model, graph_emotions)
    names = [spec] if isinstance(spec, str) else list(spec)
    heaviest = spec if isinstance(spec, str) else max(spec, key=spec.get)
    search = heaviest
    if heaviest not in graph_emotions and model is not None:
        search = model.nearest(heaviest, list(graph_emotions))
    if isinstance(spec, dict) and model is not None:
        for name in names:  # every part of a mix must be reachable from the search's emotion
            model.mapping(search, name)
    return EmotionChoice(spec, search, probabilities, timeline)


def _timeline(model: EmotionModel, audio, sample_rate) -> EmotionTimeline | None:
    """The emotion over time of speech longer than one window with two speech windows or
    more, else None (one label for all of it)."""
    from ingest.emotion.timeline import MAX_RECORDING_S, WINDOW_S

    seconds = np.shape(audio)[0] / float(sample_rate)
    if seconds <= WINDOW_S or seconds > MAX_RECORDING_S:
        return None
    windows = classify_timeline(model, audio, sample_rate)
    if sum(w.probabilities is not None for w in windows) < 2:
        return None
    return EmotionTimeline(tuple(windows))


def map_frames(model: EmotionModel, ics: np.ndarray, frame_emotions: Sequence[str],
               target) -> tuple[np.ndarray, list[str]]:
    """Move every frame's emotion components from its own emotion into ``target``.

    Parameters
    ----------
    model : EmotionModel
    ics : np.ndarray, shape (n_frames, n_ics)
    frame_emotions : sequence of str, length n_frames
        Emotion of the anime each frame came from.
    target : str or dict of str to float
        Emotion or mix.

    Returns
    -------
    (ics, notes)
        Mapped components; notes on frames that could not be mapped (left as found).
    """
    out = np.array(ics, dtype=np.float64, copy=True)
    frame_emotions = np.asarray(frame_emotions)
    notes = []
    weights = {target: 1.0} if isinstance(target, str) else dict(target)
    for source in dict.fromkeys(frame_emotions.tolist()):
        rows = frame_emotions == source
        if list(weights) == [source]:
            continue
        try:
            out[rows] = model.map_components(out[rows], source, weights)
        except (DataError, ParameterError) as exc:
            notes.append(f"{int(rows.sum())} frames of {source} animes kept as found: {exc}")
    return out, notes


def map_frames_over_time(model: EmotionModel, ics: np.ndarray, frame_emotions: Sequence[str],
                         names: Sequence[str], weights: np.ndarray
                         ) -> tuple[np.ndarray, list[str]]:
    """:func:`map_frames` with a mix whose weights change from frame to frame (an
    :class:`EmotionTimeline`'s): frame t's emotion components are the blend, with
    ``weights[t]``, of their mappings into each of ``names``.

    Parameters
    ----------
    model : EmotionModel
    ics : np.ndarray, shape (n_frames, n_ics)
    frame_emotions : sequence of str, length n_frames
        Emotion of the anime each frame came from.
    names : sequence of str, length n_names
        Emotions (the database's; others are left out, the rest renormalised).
    weights : np.ndarray, shape (n_frames, n_names)

    Returns
    -------
    (ics, notes)
    """
    out = np.array(ics, dtype=np.float64, copy=True)
    weights = np.asarray(weights, dtype=np.float64)
    notes: list[str] = []
    known = [k for k, n in enumerate(names) if n in model.emotions]
    if len(known) < len(names):
        notes.append("emotions the database lacks are left out of the timeline: "
                     + ", ".join(n for k, n in enumerate(names) if k not in known))
    if not known:
        return out, notes
    w = weights[:, known]
    w = w / np.maximum(w.sum(axis=1, keepdims=True), 1e-12)
    e = model.split.emotion_components
    frame_emotions = np.asarray(frame_emotions)
    for source in dict.fromkeys(frame_emotions.tolist()):
        rows = frame_emotions == source
        mixed = np.zeros((int(rows.sum()), e.size))
        for j, k in enumerate(known):
            try:
                f = model.mapping(source, names[k])
            except (DataError, ParameterError) as exc:
                notes.append(f"{int(rows.sum())} frames of {source} animes kept as found "
                             f"for {names[k]}: {exc}")
                f = None
            part = out[rows][:, e]
            mixed += w[rows, j:j + 1] * (part if f is None else f.transform(part))
        out[np.ix_(rows, e)] = mixed
    return out, notes


def map_motion(synth_model, motion: np.ndarray, source: str, target, *,
               fps: float | None = None) -> np.ndarray:
    """A recorded or synthesized motion with its emotion changed (Fig. 6).

    The motion (in the database's channels, world coordinates) is brought into the
    database's head frame, decomposed, its emotion components mapped from ``source`` to
    ``target`` (a name or a mix) and low-passed at the database's per-component cutoffs
    (§4.3; the interpolant is not smooth between its centres) when ``fps`` is given, and
    the change is added back on the input's own head motion; the rigid head group is left
    as it was.

    Parameters
    ----------
    synth_model : animegraph.synthesis.Model
    motion : np.ndarray, shape (n_frames, n_channels)
    source : str
    target : str or dict of str to float
    fps : float, optional
        Frame rate of ``motion`` (for the smoothing; None: no smoothing).

    Returns
    -------
    np.ndarray, shape (n_frames, n_channels)
    """
    model = synth_model.emotion_model
    if model is None:
        raise DataError("the database has no emotion model (built by an older animegraph): "
                        "run 'animegraph ingest SRC --db DB' once to learn it")
    groups = synth_model.groups
    rigid = synth_model.rigid_head
    local = synth_model.to_local(motion)
    dec = synth_model.decomposer
    ics = dec.transform(local)
    mapped = model.map_components(ics, source, target)
    e = model.split.emotion_components
    if fps is not None and e.size and not np.array_equal(mapped, ics):
        mapped[:, e] = smooth(mapped[:, e], synth_model.cutoffs[e], fps)
    delta = dec.inverse_transform(mapped) - dec.inverse_transform(ics)
    if rigid:
        delta[:, np.asarray(groups) == "head"] = 0.0
        return unstabilize_points(local + delta, groups, synth_model.head_reference)
    return local + delta
