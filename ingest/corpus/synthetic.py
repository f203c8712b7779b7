"""The synthetic expressive speech + facial motion-capture corpus.

Every fact of this corpus is known: the speech (eSpeak NG), the exact phone timing
(eSpeak's own phoneme events), the emotion, and the 3D marker motion, which a rig on
the canonical face mesh (:mod:`ingest.corpus.face`) derives from articulatory targets
with coarticulation (:mod:`ingest.corpus.articulation`), the emotion's expression
(:mod:`ingest.corpus.emotions`) and prosody-driven gestures
(:mod:`ingest.corpus.gestures`), with capture noise and short marker dropouts.

The corpus follows Cao et al. (2005, §3.1): five emotions, a subset of sentences
spoken in all five, three variations of each (sentence, emotion) pair, 120 frames per
second. ``scale="paper"`` reproduces the paper's size: 442 (sentence, emotion) pairs
(59 frustrated, 85 happy, 86 neutral, 100 sad, 112 angry; ten sentences in all five
emotions), 1,326 utterances.

On-disk layout (the corpus format that ``animegraph ingest`` reads)::

    DIR/corpus.json             what the corpus is: generator, seed, fps, emotions, sizes
    DIR/markers.csv             label, mesh vertex, motion group, rest x/y/z (mm)
    DIR/clips/<clip>.wav        16 kHz mono PCM speech
    DIR/clips/<clip>.c3d        marker positions (mm), labels, frame rate; dropouts invalid
    DIR/clips/<clip>.json       sentence id, text, emotion, variation, speaker, ...
    DIR/clips/<clip>.phones.csv ground-truth phone segments: start,end,phone
    DIR/clips/<clip>.controls.csv  ground-truth rig controls per frame (speech/emotion/...)
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import uuid
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from db.atomic import replace_dir
from db.errors import ParameterError
from ingest.corpus import articulation, face, gestures
from ingest.corpus.emotions import EMOTIONS, EmotionStyle, vary
from ingest.corpus.sentences import generate_sentences
from ingest.formats.c3d import MarkerData, write_c3d
from ingest.formats.phones_csv import write_phones_csv
from ingest.formats.wav import write_wav
from ingest.speech.espeak import Utterance, speak
from ingest.workers import map_in_processes

logger = logging.getLogger(__name__)

FORMAT_NAME = "animegraph-corpus"
FORMAT_VERSION = 1
GENERATOR = "animegraph.synthetic"

#: (sentence, emotion) pairs per emotion in Cao et al.'s database (§3.1).
PAPER_PAIRS: dict[str, int] = {
    "frustrated": 59, "happy": 85, "neutral": 86, "sad": 100, "angry": 112,
}
PAPER_PARALLEL = 10  # sentences performed in all five emotions


@dataclass(frozen=True)
class CorpusConfig:
    """What to generate. Defaults give the embedded default corpus (about 10 minutes)."""

    sentences: int = 40  # distinct sentences (>= 40 by default, as the foundation asks)
    parallel: int = 10  # of which spoken in all five emotions (the paper's m = 10)
    variations: int = 3  # takes of every (sentence, emotion) pair (§3.1)
    fps: float = 120.0  # marker frame rate (§3.1: 120 fps)
    sample_rate: int = 16000  # audio rate (§3.2: down-sampled to 16 kHz)
    seed: int = 0
    scale: str = "default"  # "paper": the paper's 442 pairs, overriding sentences/parallel
    speaker: str = "synth01"
    marker_noise_mm: float = 0.15  # optical capture jitter, per coordinate
    dropouts_per_second: float = 0.25  # mean rate of marker dropouts
    max_dropout_s: float = 0.25  # longest gap a dropout leaves
    noise_floor: float = 3e-4  # room noise added to the audio (about -70 dBFS)

    def validate(self) -> None:
        """Raise ParameterError on impossible sizes."""
        if self.scale not in ("default", "paper"):
            raise ParameterError(f"scale must be 'default' or 'paper', got {self.scale!r}")
        checks = [
            ("sentences", self.sentences, 1, 100_000),
            ("variations", self.variations, 1, 100),
            ("seed", self.seed, 0, 2**32 - 1),
            ("parallel", self.parallel, 0, self.sentences),
        ]
        for name, value, lo, hi in checks:
            if not (lo <= value <= hi):
                raise ParameterError(f"{name} must be in [{lo}, {hi}], got {value}")
        if not (1.0 <= self.fps <= 1000.0):
            raise ParameterError(f"fps must be in [1, 1000], got {self.fps}")
        if not (8000 <= self.sample_rate <= 96000):
            raise ParameterError(f"sample_rate must be in [8000, 96000], got {self.sample_rate}")


@dataclass(frozen=True)
class ClipSpec:
    """One utterance to generate."""

    clip_id: str
    sentence_id: str
    text: str
    emotion: str
    variation: int
    speaker: str
    seed: int


@dataclass(frozen=True)
class Clip:
    """One generated utterance.

    Attributes
    ----------
    markers : np.ndarray, shape (n_frames, n_markers, 3)
        Marker positions in millimetres, NaN during dropouts.
    controls : np.ndarray, shape (n_frames, n_controls)
        The rig controls that made them (:data:`ingest.corpus.face.CONTROLS`).
    """

    spec: ClipSpec
    utterance: Utterance
    style: EmotionStyle
    fps: float
    markers: np.ndarray
    controls: np.ndarray


def plan_corpus(config: CorpusConfig) -> list[ClipSpec]:
    """List the clips of a corpus, deterministically for ``config.seed``.

    The first ``parallel`` sentences are spoken in every emotion; each other sentence in
    one emotion, chosen so that the emotions' shares follow the paper's database.
    """
    config.validate()
    if config.scale == "paper":
        parallel = PAPER_PARALLEL
        singles = {e: PAPER_PAIRS[e] - PAPER_PARALLEL for e in EMOTIONS}
    else:
        parallel = config.parallel
        singles = _apportion(config.sentences - parallel)
    n_sentences = parallel + sum(singles.values())
    texts = generate_sentences(n_sentences, seed=config.seed)
    rng = np.random.default_rng(config.seed)
    single_emotions = [e for e in EMOTIONS for _ in range(singles[e])]
    rng.shuffle(single_emotions)

    specs = []
    width = max(4, len(str(n_sentences)))
    for k, text in enumerate(texts):
        sid = f"s{k + 1:0{width}d}"
        emotions = EMOTIONS if k < parallel else (single_emotions[k - parallel],)
        for emotion in emotions:
            for v in range(1, config.variations + 1):
                specs.append(ClipSpec(
                    clip_id=f"{sid}_{emotion}_{v}", sentence_id=sid, text=text,
                    emotion=emotion, variation=v, speaker=config.speaker,
                    seed=int(rng.integers(2**31)),
                ))
    return specs


def _apportion(n: int) -> dict[str, int]:
    """Split ``n`` single-emotion sentences in the paper's proportions (largest remainder)."""
    weights = np.array([PAPER_PAIRS[e] - PAPER_PARALLEL for e in EMOTIONS], dtype=float)
    share = n * weights / weights.sum()
    counts = np.floor(share).astype(int)
    for i in np.argsort(-(share - counts), kind="stable")[: n - counts.sum()]:
        counts[i] += 1
    return dict(zip(EMOTIONS, counts.tolist(), strict=True))


def synthesize_clip(spec: ClipSpec, config: CorpusConfig) -> Clip:
    """Speak one clip and make its facial motion.

    Parameters
    ----------
    spec : ClipSpec
        What to say, in which emotion, and the clip's random seed.
    config : CorpusConfig
        Frame rate, sample rate, noise and dropout settings.
    """
    rng = np.random.default_rng(spec.seed)
    style = vary(spec.emotion, rng)
    utt = speak(spec.text, style.voice, sample_rate=config.sample_rate)
    audio = utt.audio + rng.normal(0.0, config.noise_floor, utt.audio.shape).astype(np.float32)
    utt = Utterance(text=utt.text, audio=np.clip(audio, -1, 1), sample_rate=utt.sample_rate,
                    phones=utt.phones)

    n_frames = max(2, int(np.floor(utt.duration * config.fps)))
    times = np.arange(n_frames) / config.fps
    controls = face_controls(utt, style, times, config.fps, rng)
    rest = face.marker_rest()
    markers = face.FaceRig.for_points(rest).pose(controls)
    markers = markers + rng.normal(0.0, config.marker_noise_mm, markers.shape)
    _drop_markers(markers, config, rng)
    return Clip(spec=spec, utterance=utt, style=style, fps=config.fps, markers=markers,
                controls=controls)


def face_controls(
    utt: Utterance, style: EmotionStyle, times: np.ndarray, fps: float,
    rng: np.random.Generator,
) -> np.ndarray:
    """Rig controls (shape (n_frames, len(CONTROLS))) for an utterance in a style."""
    ctl = np.zeros((len(times), len(face.CONTROLS)))
    col = {name: i for i, name in enumerate(face.CONTROLS)}
    phones = [(p.phone, p.start, p.end) for p in utt.phones]
    speech = articulation.speech_controls(phones, times)
    for i, name in enumerate(face.SPEECH_CONTROLS):
        # Emotion scales the size of the articulation, never the lip closures.
        gain = style.articulation if name in ("jaw_open", "lip_round", "lip_spread") else 1.0
        ctl[:, col[name]] = gain * speech[:, i]

    for name, level in style.expression.items():
        ctl[:, col[name]] = level * (1 + 0.15 * gestures.slow_drift(times, rng))
    prosody = gestures.analyze_prosody(utt.audio, utt.sample_rate, times)
    ctl[:, col["brow_raise"]] += style.brow_gain * 0.6 * gestures.brow_raises(prosody, times, fps)
    ctl[:, col["blink"]] = gestures.blinks(times, style.blink_rate, rng)
    ctl[:, col["head_pitch"]] = (
        style.head_pitch + 1.5 * gestures.slow_drift(times, rng)
        + style.nod_gain * gestures.head_nods(prosody, times, fps)
    )
    ctl[:, col["head_yaw"]] = 2.0 * gestures.slow_drift(times, rng)
    ctl[:, col["head_roll"]] = 1.0 * gestures.slow_drift(times, rng)
    for axis, amp in (("head_tx", 2.0), ("head_ty", 1.5), ("head_tz", 2.0)):
        ctl[:, col[axis]] = amp * gestures.slow_drift(times, rng)
    return ctl


# Lips and lids are the markers optical capture loses most (occlusion by the lips
# themselves, by blinks); they drop out three times as often as the rest.
_DROPOUT_WEIGHT = np.array(
    [3.0 if m[0].startswith(("ulip", "llip", "lip_", "lid_")) else 1.0 for m in face.MARKERS]
)


def _drop_markers(markers: np.ndarray, config: CorpusConfig, rng: np.random.Generator) -> None:
    """Blank short random stretches of random markers (NaN), in place."""
    n_frames, n_markers, _ = markers.shape
    n_drop = rng.poisson(config.dropouts_per_second * n_frames / config.fps)
    longest = max(1, int(np.floor(config.max_dropout_s * config.fps)))
    p = _DROPOUT_WEIGHT / _DROPOUT_WEIGHT.sum()
    for _ in range(n_drop):
        m = rng.choice(n_markers, p=p)
        length = int(rng.integers(min(2, longest), longest + 1))
        start = int(rng.integers(0, max(1, n_frames - length)))
        markers[start:start + length, m, :] = np.nan


def write_clip(clip: Clip, folder: Path) -> dict:
    """Write a clip's five files into ``folder``; return its JSON metadata."""
    spec, utt = clip.spec, clip.utterance
    stem = folder / spec.clip_id
    write_wav(stem.with_suffix(".wav"), utt.audio, utt.sample_rate)
    labels = tuple(m[0] for m in face.MARKERS)
    write_c3d(stem.with_suffix(".c3d"), MarkerData(points=clip.markers, labels=labels,
                                                   rate=clip.fps))
    write_phones_csv(Path(f"{stem}.phones.csv"), [(p.phone, p.start, p.end) for p in utt.phones])
    header = "frame,time," + ",".join(face.CONTROLS)
    n = len(clip.controls)
    table = np.column_stack([np.arange(n), np.arange(n) / clip.fps, clip.controls])
    np.savetxt(f"{stem}.controls.csv", table, delimiter=",", header=header, comments="",
               fmt=["%d", "%.6f"] + ["%.5f"] * len(face.CONTROLS))
    meta = {
        "clip_id": spec.clip_id, "sentence_id": spec.sentence_id, "text": spec.text,
        "emotion": spec.emotion, "variation": spec.variation, "speaker": spec.speaker,
        "fps": clip.fps, "sample_rate": utt.sample_rate, "duration": utt.duration,
        "n_frames": n, "seed": spec.seed, "voice": asdict(clip.style.voice),
        "expression": clip.style.expression, "articulation_gain": clip.style.articulation,
        "generator": GENERATOR,
    }
    Path(f"{stem}.json").write_text(json.dumps(meta, indent=1))
    return meta


def _make_and_write(args: tuple[ClipSpec, CorpusConfig, str]) -> tuple[str, float, int]:
    spec, config, folder = args
    meta = write_clip(synthesize_clip(spec, config), Path(folder))
    return spec.clip_id, meta["duration"], meta["n_frames"]


@dataclass(frozen=True)
class CorpusSummary:
    """What :func:`generate_corpus` wrote."""

    path: Path
    n_clips: int
    n_sentences: int
    duration_s: float
    n_frames: int


def generate_corpus(
    out: str | os.PathLike,
    config: CorpusConfig | None = None,
    *,
    workers: int | None = None,
    force: bool = False,
    progress: Callable | None = None,
    say: Callable[[str], object] | None = None,
) -> CorpusSummary:
    """Generate a synthetic corpus into the folder ``out``.

    The corpus is built in a hidden staging folder beside ``out`` and moved into place
    only when complete, so an interrupted or failed run leaves nothing half-written.

    Parameters
    ----------
    out : path
        Folder to create. It must not exist, or be empty, unless ``force``.
    config : CorpusConfig, optional
        Sizes, frame rate and seed.
    workers : int, optional
        Worker processes (default: all cores).
    force : bool
        Replace an existing non-empty ``out``.
    progress : callable, optional
        Wraps the iterable of finished clips (e.g. ``functools.partial(tqdm, total=n)``).
    say : callable, optional
        Receives a line before the one-off preparation of the workers.

    Raises
    ------
    ParameterError
        On impossible sizes, or when ``out`` exists and is not empty without ``force``,
        or cannot be written.
    """
    config = config or CorpusConfig()
    specs = plan_corpus(config)
    out = Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())) and not force:
        raise ParameterError(f"--out {out} exists and is not empty (use --force to replace it)")
    if workers is None:
        workers = os.cpu_count() or 1
    if workers < 1:
        raise ParameterError(f"workers must be >= 1, got {workers}")

    staging = out.parent / f".{out.name}.partial-{uuid.uuid4().hex[:8]}"
    try:
        (staging / "clips").mkdir(parents=True)
    except OSError as exc:
        raise ParameterError(f"cannot write to --out {out}: {exc.strerror}") from exc
    try:
        jobs = [(s, config, str(staging / "clips")) for s in specs]
        if workers == 1:
            results = map(_make_and_write, jobs)
            done = list(progress(results) if progress else results)
        else:
            if say is not None:
                say(f"preparing {workers} workers (librosa's pitch kernels are compiled "
                    "once per environment) ...")
            gestures.warm_up()  # compile librosa's cached gufuncs once, before the workers
            done = map_in_processes(_make_and_write, jobs, workers=workers, chunksize=4,
                                    progress=progress)
        duration = float(sum(d for _, d, _ in done))
        frames = int(sum(f for _, _, f in done))
        n_sentences = len({s.sentence_id for s in specs})
        _write_corpus_files(staging, config, specs, duration)
        replace_dir(staging, out)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return CorpusSummary(path=out, n_clips=len(specs), n_sentences=n_sentences,
                         duration_s=duration, n_frames=frames)


def _write_corpus_files(
    folder: Path, config: CorpusConfig, specs: list[ClipSpec], duration: float
) -> None:
    rest = face.marker_rest()
    lines = ["label,vertex,group,rest_x,rest_y,rest_z"]
    for (label, vertex, group), (x, y, z) in zip(face.MARKERS, rest, strict=True):
        lines.append(f"{label},{vertex},{group},{x:.4f},{y:.4f},{z:.4f}")
    (folder / "markers.csv").write_text("\n".join(lines) + "\n")
    counts = {e: sum(1 for s in specs if s.emotion == e) for e in EMOTIONS}
    by_sentence: dict[str, set[str]] = {}
    for s in specs:
        by_sentence.setdefault(s.sentence_id, set()).add(s.emotion)
    parallel = sorted(sid for sid, emos in by_sentence.items() if emos == set(EMOTIONS))
    meta = {
        "format": FORMAT_NAME, "format_version": FORMAT_VERSION, "generator": GENERATOR,
        "config": asdict(config), "emotions": list(EMOTIONS), "clips_per_emotion": counts,
        "n_clips": len(specs), "n_sentences": len({s.sentence_id for s in specs}),
        "parallel_sentences": parallel, "duration_s": round(duration, 3),
        "markers": "markers.csv", "motion_groups": list(face.MOTION_GROUPS),
        "mesh": "canonical_face_model (mediapipe, Apache-2.0), millimetres",
        "controls": {
            "speech": list(face.SPEECH_CONTROLS), "emotion": list(face.EMOTION_CONTROLS),
            "other": ["blink", *face.HEAD_CONTROLS],
        },
    }
    (folder / "corpus.json").write_text(json.dumps(meta, indent=1))
