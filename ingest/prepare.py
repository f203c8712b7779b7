"""Per-clip ingest work: everything that does not need the rest of the corpus.

A clip is read, its dropouts filled, its motion brought to the database's frame rate,
its speech segmented into phones (given labels, else alignment inside the words of a
given word alignment, else forced alignment of the transcript, else phone recognition)
and its prosody curve computed (RASTA-PLP, Cao et al. §4.1), and, beyond the paper,
its phone posteriorgram (hama installed). The result, a :class:`PreparedClip`, is what
the corpus-wide steps (PCA/ICA, anime nodes, tables) work from; it is also what the
database keeps of a clip, so a later ingest can rebuild the model without re-reading
the sources.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from db.errors import DataError, ParameterError
from ingest.clip import ChannelSchema, RawClip
from ingest.formats.phones_csv import Segment
from ingest.motion import fill_gaps, resample_motion, stabilize_points
from ingest.speech.ctc import doubts
from ingest.speech.engines import check_engine, check_transcript
from ingest.speech.features import RastaPlpConfig, rasta_plp
from ingest.speech.posteriorgram import HOP_S as POSTERIOR_HOP_S
from ingest.speech.quality import is_silent
from ingest.speech.segment import segment
from ingest.speech.words import align_words

#: Emotion label of clips that come without one.
UNKNOWN_EMOTION = "unknown"
#: Smallest lip-audio lag corrected (s). Lips anticipate speech by a few tens of ms as a
#: matter of course (coarticulation); larger leads are recording offsets.
MIN_LAG_CORRECTED_S = 0.08


@dataclass(frozen=True, eq=False)
class PreparedClip:
    """A clip ready to enter the database.

    Attributes
    ----------
    motion : np.ndarray, shape (n_frames, n_channels), float32
        Gap-filled motion at ``fps``.
    missing : np.ndarray of bool, shape (n_frames, n_channels)
        Where the recording had no value (filled by interpolation).
    audio : np.ndarray, shape (n_samples,), int16
        Speech.
    phones : tuple of Segment
        ARPAbet phone segments tiling the audio.
    prosody : np.ndarray, shape (n_prosody_frames, 9), float32
        RASTA-PLP curve of the whole clip, 100 frames per second.
    emotion_features : SpeechFeatures, str or None
        What the database's emotion classifier computes from the clip before fitting
        (functionals and frame descriptors)
        (:func:`ingest.emotion.model.classifier_features`; a str: why the audio has none),
        computed with the clip so that ingest's workers do it in parallel; None: not
        computed (no emotion label, a clip read back from a database, a slice), the
        classifier computes it when it needs it. Not stored in the database.
    posteriors : np.ndarray, shape (n_posterior_frames, 39), float16, or None
        Phone posteriorgram of the whole clip, 50 frames per second
        (:mod:`ingest.speech.posteriorgram`); None when hama is not installed.
    posterior_blank : np.ndarray, shape (n_posterior_frames,), float16, or None
        hama's probability of the CTC blank in each of those frames (the posteriorgram
        leaves it out): with ``posteriors``, what ppg-ridge hears of the clip, kept so
        that its fit does not run hama over the database's speech again.
    """

    clip_id: str
    corpus: str
    source: str
    checksum: str
    schema: ChannelSchema
    fps: float
    source_fps: float
    motion: np.ndarray
    missing: np.ndarray
    audio: np.ndarray
    sample_rate: int
    phones: tuple[Segment, ...]
    segmentation: str
    prosody: np.ndarray
    emotion: str
    speaker: str | None
    sentence_id: str | None
    text: str | None
    extra: dict = field(default_factory=dict)
    emotion_features: object | str | None = None  # SpeechFeatures (ingest.emotion.classifier)
    posteriors: np.ndarray | None = None
    posterior_blank: np.ndarray | None = None

    @property
    def duration(self) -> float:
        return len(self.audio) / self.sample_rate

    @property
    def key(self) -> tuple[str, str]:
        """(corpus, clip_id): a clip's identity in the database."""
        return self.corpus, self.clip_id


def prepare_clip(
    raw: RawClip,
    *,
    fps: float | None = None,
    head_reference: np.ndarray | None = None,
    prosody_config: RastaPlpConfig | None = None,
    phones_engine: str | None = None,
    posteriorgrams: bool = True,
) -> PreparedClip:
    """Turn a clip read from disk into a :class:`PreparedClip`.

    Parameters
    ----------
    raw : RawClip
        The clip as read.
    fps : float, optional
        Frame rate of the database (default: the clip's own).
    head_reference : np.ndarray, shape (n_head_points, 3), optional
        Head-group positions of the database: points of a clip with a rigid head group
        are expressed in the head's frame (:func:`ingest.motion.stabilize_points`).
    phones_engine : str, optional
        Phone engine for clips without labels (:data:`ingest.speech.engines.ENGINES`).
    posteriorgrams : bool, optional
        Compute the clip's phone posteriorgram (when hama is installed; beyond the paper).
        Kept anyway when hama recognised the clip's phones (it has heard the clip).

    Raises
    ------
    DataError
        With a one-line reason if the clip cannot be used.
    """
    filled, missing = fill_gaps(raw.motion, raw.schema.names)
    if head_reference is not None:
        filled = stabilize_points(filled, raw.schema.groups, head_reference)
    extra = dict(raw.extra)  # the lip-audio lag is decided over many clips: ingest.lag
    target = raw.fps if fps is None else float(fps)
    if target != raw.fps:
        filled = resample_motion(filled, raw.fps, target)
        missing = resample_motion(missing.astype(np.float64), raw.fps, target) > 0.5

    audio = np.asarray(raw.audio, dtype=np.float32)
    if is_silent(audio):
        raise DataError("the audio is silent")
    fallback: list[str] = []
    text = raw.text or None  # with a word alignment: its words (ingest.readers.common)
    words = raw.words if raw.words and not raw.phones else None
    checked = False  # hama heard the clip to check its word alignment's transcript
    with doubts() as doubted:  # a transcript aligned, but perhaps another utterance's
        if words and text:
            # Word times are taken as given, but not that the words are what is said (an
            # alignment of another utterance, or one that leaves words out): the transcript
            # check that guards every alignment, with recognition as the fallback.
            try:
                check_transcript(audio, raw.sample_rate, text, phones_engine)
                checked = True
            except DataError as exc:
                fallback.append(f"word alignment failed: {exc}; fell back to phone "
                                "recognition")
                words = text = None
        if words:
            phones, n_even = align_words(audio, raw.sample_rate, words)
            method = "aligned-words"
            if n_even:
                extra["words_spread_evenly"] = n_even
        else:
            phones, method = segment(audio, raw.sample_rate, text=text,
                                     labels=list(raw.phones) if raw.phones else None,
                                     engine=phones_engine, on_fallback=fallback.append)
    # Kept (in the clips table too) and said in the clip's report row.
    if fallback:
        extra["transcript_fallback"] = fallback[0]
    elif doubted:
        extra["transcript_doubt"] = doubted[0]
    if all(p.phone == "SIL" for p in phones):
        raise DataError("no speech found in the audio (every phone is silence)")
    prosody = rasta_plp(audio, raw.sample_rate, config=prosody_config)
    # hama has already heard a clip whose phones it recognised, or whose transcript it
    # aligned or checked (ingest.speech.engines): keeping its outputs is free, and spares
    # ppg-ridge's fit (the audio-only guide) hearing it again.
    # (GRID's 800 clips come with word alignments whose transcripts hama checked: without
    # their outputs kept, ppg-ridge's fit heard every one of them again.)
    heard = ((method in ("recognized", "aligned") or checked)
             and check_engine(phones_engine) in ("auto", "hama"))
    posteriors, blank = (clip_posteriors(audio, raw.sample_rate) if posteriorgrams or heard
                         else (None, None))
    pcm = np.round(np.clip(audio, -1, 1) * 32767).astype(np.int16)
    emotion = raw.emotion or UNKNOWN_EMOTION
    features = None
    if emotion != UNKNOWN_EMOTION:  # only labelled clips train the classifier
        from ingest.emotion.model import classifier_features

        features = classifier_features(pcm, raw.sample_rate)
    return PreparedClip(
        clip_id=raw.clip_id, corpus=raw.corpus, source=str(raw.source), checksum=raw.checksum,
        schema=raw.schema, fps=target, source_fps=raw.fps,
        motion=filled.astype(np.float32), missing=missing, audio=pcm,
        sample_rate=raw.sample_rate, phones=tuple(Segment(*p) for p in phones),
        segmentation=method, prosody=prosody.astype(np.float32),
        emotion=emotion, speaker=raw.speaker, sentence_id=raw.sentence_id, text=raw.text,
        extra=extra, emotion_features=features, posteriors=posteriors,
        posterior_blank=blank,
    )


def clip_posteriors(audio: np.ndarray, sample_rate: int
                    ) -> tuple[np.ndarray, np.ndarray] | tuple[None, None]:
    """The clip's phone posteriorgram, shape (n, 39), and its CTC blank, shape (n,), as
    stored (float16); (None, None) without hama."""
    from ingest.speech import ctc, posteriorgram

    if not ctc.available():
        return None, None
    probs = ctc.posteriors(audio, sample_rate)
    return (posteriorgram.fold(probs).astype(np.float16),
            posteriorgram.blank(probs).astype(np.float16))


def slice_clip(clip: PreparedClip, start: float, end: float, *, suffix: str) -> PreparedClip:
    """The part of ``clip`` from ``start`` to ``end`` seconds, as a clip of its own.

    Phones overlapping the cut are trimmed to it; the new clip's id is the old one plus
    ``suffix``. Used to split one long recording into a database part and a test part.
    """
    from dataclasses import replace

    if not 0 <= start < end <= clip.duration + 1e-9:
        raise ParameterError(f"slice [{start}, {end}] is outside the clip (0-{clip.duration})")
    f0, f1 = int(round(start * clip.fps)), int(round(end * clip.fps))
    s0, s1 = int(round(start * clip.sample_rate)), int(round(end * clip.sample_rate))
    phones = tuple(Segment(p.phone, max(p.start, start) - start, min(p.end, end) - start)
                   for p in clip.phones if p.end > start and p.start < end)
    hop = RastaPlpConfig().hop_s  # frame period of the prosody curve (ingest uses the default)
    p0, p1 = int(round(start / hop)), int(round(end / hop)) + 1
    q0, q1 = int(round(start / POSTERIOR_HOP_S)), int(round(end / POSTERIOR_HOP_S)) + 1
    post = None if clip.posteriors is None else clip.posteriors[q0:q1]
    blank = None if clip.posterior_blank is None else clip.posterior_blank[q0:q1]
    return replace(clip, clip_id=clip.clip_id + suffix, motion=clip.motion[f0:f1],
                   missing=clip.missing[f0:f1], audio=clip.audio[s0:s1],
                   phones=tuple(p for p in phones if p.end > p.start),
                   prosody=clip.prosody[p0:p1], emotion_features=None, posteriors=post,
                   posterior_blank=blank)
