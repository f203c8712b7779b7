"""Landmark clips: 3D face landmarks tracked from video (mediapipe face mesh), made motion.

Layout of a clip folder (the talking-face corpus)::

    <clip>/landmarks.npy   float32 (n_frames, 478, 3): x / width, y / height in [0, 1],
                           z relative depth on the x scale; 0-467 in canonical mesh order,
                           468-477 the irises; NaN where no face was found
    <clip>/audio_16k.wav   the speech, starting at frame 0 (or audio.wav)
    <clip>/meta.json       fps (required), width/height (pixels), speaker, ...

Normalisation (:func:`normalise_landmarks`): the irises are dropped; the 468 face
points are put in a right-handed pixel frame (x right, y up, z towards the camera:
``(x W, (1 - y) H, -z W)``; the image's y points down and mediapipe's z away from the
camera, so both are flipped, which is a rotation, not a reflection); then, per frame,
the similarity transform (rotation, uniform scale, translation, no reflection:
Umeyama 1991) that best maps the :data:`STABLE_LANDMARKS` onto the canonical mesh
(:func:`ingest.facemesh.load_canonical_face`, mm) is applied to all 468 points. The
stable points are forehead, nose bridge, eye corners and temples: points the jaw,
lips, brows and lids do not move. The rigid head pose is kept as channels of its own.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from db.errors import DataError
from db.npyfile import REAL_KINDS, holds
from ingest.clip import POSE_UNITS, ChannelSchema, RawClip, checksum_files
from ingest.facemesh import (
    EYE_L,
    EYE_R,
    LIP_CORNERS,
    LOWER_LIP_INNER,
    LOWER_LIP_OUTER,
    UPPER_LIP_INNER,
    UPPER_LIP_OUTER,
    load_canonical_face,
)
from ingest.formats.wav import read_wav
from ingest.readers.common import (
    ClipSource,
    check_durations,
    check_motion,
    load_npy,
    metadata_fields,
    read_fps,
    read_json_object,
    transcript_and_labels,
)
from ingest.readers.sync import audio_envelope, estimate_lag, lag_evidence, lip_activity

logger = logging.getLogger(__name__)

#: Face landmarks kept (the canonical mesh's vertices); trackers may add 10 iris points.
N_FACE = 468
N_WITH_IRISES = 478
#: Landmarks the similarity fit uses: upper forehead (10, 109, 338, 67, 297), mid
#: forehead and glabella (151, 9, 8), nose bridge and ridge (168, 6, 197, 195, 5, 4), eye
#: corners (33, 133, 362, 263) and temples (54, 284). Silhouette points (127, 356, 234,
#: 454 ...) are left out: the tracker slides them along the face's outline as the head
#: turns (they add ~1 mm to the residual).
STABLE_LANDMARKS: tuple[int, ...] = (
    10, 151, 9, 8, 168, 6, 197, 195, 5, 4, 33, 133, 362, 263, 67, 297, 109, 338, 54, 284,
)
#: Channels of the rigid head pose (group "pose"), appended after the landmarks.
POSE_CHANNELS: tuple[str, ...] = tuple(POSE_UNITS)
#: Lever arm (mm) that turns head rotation (rad) and relative scale change into
#: millimetres, so that PCA weighs the pose channels like facial motion of a point 10 cm
#: from the head's centre: rotation in 0.01 rad, scale change in per cent
#: (:data:`ingest.clip.POSE_UNITS`).
HEAD_RADIUS_MM = 100.0
#: Audio file names tried in a clip folder, in order.
AUDIO_NAMES = ("audio_16k.wav", "audio.wav")


@dataclass(frozen=True)
class NormalisedLandmarks:
    """Landmarks with the head pose removed.

    Attributes
    ----------
    points : np.ndarray, shape (n_frames, 468, 3)
        Landmarks in canonical mesh coordinates, mm (x to the subject's left, y up, z
        out of the face); NaN in frames without a face.
    pose : np.ndarray, shape (n_frames, 7)
        Head pose per frame, :data:`POSE_CHANNELS`: the rotation vector (rad) of the
        head in the camera frame (x right, y up, z towards the camera), the position
        of the canonical origin in pixels (from the image's bottom-left corner; z in
        the same pixel scale), and the scale in pixels per mm. ``camera = scale * R @
        canonical + t``.
    residual_mm : np.ndarray, shape (n_frames,)
        RMS distance (mm) of the fitted stable landmarks from the canonical mesh.
    """

    points: np.ndarray
    pose: np.ndarray
    residual_mm: np.ndarray


def pose_motion(pose: np.ndarray) -> np.ndarray:
    """Head pose as motion channels in millimetres, relative to the clip's median pose.

    Parameters
    ----------
    pose : np.ndarray, shape (n_frames, 7)
        :attr:`NormalisedLandmarks.pose` (rotation vector in rad, position in pixels,
        scale in pixels per mm).

    Returns
    -------
    np.ndarray, shape (n_frames, 7)
        Rotation as the arc (mm) a point :data:`HEAD_RADIUS_MM` from the centre travels
        (0.01 rad), translation in mm, scale change as the change (mm) of a
        :data:`HEAD_RADIUS_MM` length (per cent). Where the camera was, how the video
        was framed and which way the head turned on average differ from clip to clip and
        say nothing about head motion, so each channel is relative to the clip's median.
    """
    scale = np.nanmedian(pose[:, 6])
    out = np.empty_like(pose)
    out[:, 0:3] = pose[:, 0:3] * HEAD_RADIUS_MM
    out[:, 3:6] = pose[:, 3:6] / scale
    out[:, 6] = (pose[:, 6] / scale - 1.0) * HEAD_RADIUS_MM
    return out - np.nanmedian(out, axis=0)


def similarity_fit(
    source: np.ndarray, target: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares similarity transforms (Umeyama 1991), one per frame, no reflection.

    Parameters
    ----------
    source : np.ndarray, shape (n_frames, n_points, 3)
        Points to move.
    target : np.ndarray, shape (n_points, 3)
        Where they should go.

    Returns
    -------
    scale : np.ndarray, shape (n_frames,)
    rotation : np.ndarray, shape (n_frames, 3, 3)
        Proper rotations (determinant +1).
    translation : np.ndarray, shape (n_frames, 3)
        Such that ``target ~ scale * rotation @ source + translation``.
    """
    mu_s = source.mean(axis=1)
    mu_t = target.mean(axis=0)
    src = source - mu_s[:, None, :]
    tgt = target - mu_t
    cov = np.einsum("kj,nki->nji", tgt, src) / source.shape[1]  # (n, 3, 3): tgt^T src
    u, sigma, vt = np.linalg.svd(cov)
    sign = np.ones((len(source), 3))
    sign[:, 2] = np.sign(np.linalg.det(u) * np.linalg.det(vt))
    sign[sign == 0] = 1.0
    rotation = u @ (sign[:, :, None] * vt)
    variance = (src ** 2).sum(axis=(1, 2)) / source.shape[1]
    scale = (sigma * sign).sum(axis=1) / variance
    translation = mu_t - scale[:, None] * np.einsum("nij,nj->ni", rotation, mu_s)
    return scale, rotation, translation


def normalise_landmarks(
    raw: np.ndarray, width: float = 1.0, height: float = 1.0
) -> NormalisedLandmarks:
    """Remove head pose and scale from tracked landmarks.

    Parameters
    ----------
    raw : np.ndarray, shape (n_frames, 468 or 478, 3)
        Normalised image coordinates as the tracker gives them (x / width, y / height,
        z on the x scale).
    width, height : float
        Image size in pixels (only their ratio matters for the shape).

    Returns
    -------
    NormalisedLandmarks
    """
    raw = np.asarray(raw, dtype=np.float64)[:, :N_FACE]
    pixels = np.stack(
        [raw[..., 0] * width, (1.0 - raw[..., 1]) * height, -raw[..., 2] * width], axis=-1
    )
    canonical = load_canonical_face().vertices
    stable = list(STABLE_LANDMARKS)
    n = len(pixels)
    points = np.full((n, N_FACE, 3), np.nan)
    pose = np.full((n, len(POSE_CHANNELS)), np.nan)
    residual = np.full(n, np.nan)
    ok = np.isfinite(pixels[:, stable]).all(axis=(1, 2))
    if ok.any():
        from scipy.spatial.transform import Rotation  # deferred: synth reads no video

        scale, rot, trans = similarity_fit(pixels[ok][:, stable], canonical[stable])
        fitted = scale[:, None, None] * np.einsum("nij,nkj->nki", rot, pixels[ok])
        fitted += trans[:, None, :]
        points[ok] = fitted
        residual[ok] = np.sqrt(((fitted[:, stable] - canonical[stable]) ** 2).sum(-1).mean(-1))
        head_rot = np.transpose(rot, (0, 2, 1))  # canonical -> camera
        pose[ok, 0:3] = Rotation.from_matrix(head_rot).as_rotvec()
        pose[ok, 3:6] = -np.einsum("nij,nj->ni", head_rot, trans) / scale[:, None]
        pose[ok, 6] = 1.0 / scale
    return NormalisedLandmarks(points=points, pose=pose, residual_mm=residual)


@lru_cache(maxsize=1)
def landmark_groups() -> tuple[str, ...]:
    """Motion group of each of the 468 face landmarks, from the canonical mesh.

    ``"lips"``: the lip contours, everything below the mouth corners (chin, jaw line)
    and the skin between the nose base and the mouth; ``"upper_face"``: everything from
    5 mm below the lower eyelids up (eyes, brows, forehead, temples, top of the nose
    bridge); ``"other"``: the rest (nose, cheeks).
    """
    v = load_canonical_face().vertices
    lip_points = set(LIP_CORNERS + UPPER_LIP_OUTER + LOWER_LIP_OUTER + UPPER_LIP_INNER
                     + LOWER_LIP_INNER)
    corner_y = v[list(LIP_CORNERS), 1].mean()
    mouth_half_width = np.abs(v[list(LIP_CORNERS), 0]).mean() + 10.0
    nose_base_y = v[2, 1]  # subnasale
    eye_y = min(v[EYE_R["lower"], 1], v[EYE_L["lower"], 1]) - 5.0
    groups = []
    for i, (x, y, _) in enumerate(v):
        if i in lip_points or y < corner_y or (y < nose_base_y - 2.0 and abs(x) < mouth_half_width):
            groups.append("lips")
        elif y >= eye_y:
            groups.append("upper_face")
        else:
            groups.append("other")
    return tuple(groups)


def _stable_jitter(points: np.ndarray) -> float:
    """Median over frames of the RMS distance (mm) of the stable landmarks from their
    mean position over the clip: tracking noise left after the fit (the residual to the
    canonical mesh also holds the difference between the speaker's face and the mesh)."""
    stable = points[:, list(STABLE_LANDMARKS)]
    mean = np.nanmean(stable, axis=0)
    return float(np.nanmedian(np.sqrt(((stable - mean) ** 2).sum(-1).mean(-1))))


@lru_cache(maxsize=1)
def landmark_schema() -> ChannelSchema:
    """Schema of a landmark clip: ``lm<i>.x/y/z`` for the 468 points, then the pose
    (built once a process; a ChannelSchema is frozen)."""
    points = ChannelSchema.for_points("landmarks", [f"lm{i}" for i in range(N_FACE)],
                                      landmark_groups(), "mm")
    return ChannelSchema(
        kind="landmarks",
        names=points.names + POSE_CHANNELS,
        groups=points.groups + ("pose",) * len(POSE_CHANNELS),
        units="mm",
    )


def load_talkingface(source: ClipSource) -> RawClip:
    """Read one landmark clip folder (see the module docstring).

    Raises
    ------
    DataError
        On a missing or bad file, landmarks of the wrong shape, no face in any frame,
        no fps in ``meta.json``, or audio and motion durations that disagree.
    """
    folder = source.source
    lm_path, audio_path, meta_path = (source.file(r) for r in ("motion", "audio", "metadata"))
    if audio_path is None:
        raise DataError(f"{folder}: no audio file ({' or '.join(AUDIO_NAMES)})")
    if meta_path is None:
        raise DataError(f"{folder}: no meta.json (it gives the frame rate)")
    meta = read_json_object(meta_path)
    fps = read_fps(meta, meta_path)
    if fps is None:
        raise DataError(f"{meta_path}: no 'fps'")
    width, height = meta.get("width", 1.0), meta.get("height", 1.0)
    for name, value in (("width", width), ("height", height)):
        if isinstance(value, bool) or not isinstance(value, int | float) or not value > 0:
            raise DataError(f"{meta_path}: {name!r} must be a number > 0, got {value!r}")

    raw = load_npy(lm_path)
    audio, sample_rate = read_wav(audio_path)
    text, phones, words = transcript_and_labels(source, len(audio) / sample_rate)
    fields = metadata_fields(meta, meta_path)
    extra: dict = {}
    sync = meta.get("lip_audio_sync_estimate")
    if isinstance(sync, dict) and isinstance(sync.get("best_lag_ms"), int | float):
        # meta.json counts "+lag = lips after audio"; here + means lips lead.
        extra["meta_lip_audio_lag_s"] = 0.0 - float(sync["best_lag_ms"]) / 1000.0
    return landmark_clip(
        source, raw, fps=fps, width=float(width), height=float(height), audio=audio,
        sample_rate=sample_rate, text=text or fields["text"], phones=phones, words=words,
        fields=fields, extra=extra, where=lm_path)


def landmark_clip(
    source: ClipSource, raw: np.ndarray, *, fps: float, width: float, height: float,
    audio: np.ndarray, sample_rate: int, text: str | None, phones, words,
    fields: dict, extra: dict, where: Path,
) -> RawClip:
    """A :class:`RawClip` from tracked landmarks and the clip's speech (any source).

    Parameters
    ----------
    source : ClipSource
        The clip (its files make the checksum).
    raw : np.ndarray, shape (n_frames, 468 or 478, 3)
        Landmarks as the tracker gives them (see the module docstring), NaN without a face.
    fps, width, height : float
        Frame rate and image size (pixels).
    audio : np.ndarray, shape (n_samples,)
        Mono speech starting at frame 0.
    sample_rate : int
        Its rate (Hz).
    text, phones, words
        Transcript, phone labels and word alignment, if the clip has them.
    fields : dict
        :func:`metadata_fields` of the clip's metadata.
    extra : dict
        Reader facts to keep (merged into the clip's ``extra``).
    where : Path
        Named in errors.

    Raises
    ------
    DataError
        Landmarks of the wrong shape, no face in any frame, audio and motion durations
        that disagree.
    """
    folder = source.source
    lm_path = where
    if raw.ndim != 3 or raw.shape[1] not in (N_FACE, N_WITH_IRISES) or raw.shape[2] != 3:
        raise DataError(
            f"{lm_path}: expected landmarks of shape (n_frames, {N_FACE} or {N_WITH_IRISES}, 3), "
            f"got {raw.shape}"
        )
    if raw.dtype.kind not in REAL_KINDS:
        raise DataError(f"{lm_path}: landmarks hold {holds(raw.dtype)}, not real numbers")
    if raw.shape[0] < 2:
        raise DataError(f"{lm_path}: {raw.shape[0]} frame(s); a clip needs at least 2")
    if np.isinf(raw).any():
        raise DataError(f"{lm_path}: infinite coordinates")
    face = np.isfinite(raw[:, :N_FACE]).all(axis=(1, 2))
    if not face.any():
        raise DataError(f"{lm_path}: no face in any frame (all NaN)")

    norm = normalise_landmarks(raw, float(width), float(height))
    n = len(raw)
    motion = np.concatenate([norm.points.reshape(n, 3 * N_FACE), pose_motion(norm.pose)],
                            axis=1)
    schema = landmark_schema()
    motion = check_motion(motion, schema.names, lm_path, "channel")

    check_durations(n, fps, len(audio) / sample_rate, folder)
    lips = lip_activity(norm.points)
    loudness = audio_envelope(audio, sample_rate, fps, n)
    lag, confidence = estimate_lag(lips, loudness, fps)

    extra = {
        **extra,
        "layout": source.layout,
        # filled as gaps; said on the clip's line of the ingest report
        "frames_without_face": int((~face).sum()),
        "lip_audio_lag_s": round(lag, 4),
        "lag_confidence": round(confidence, 4),
        # pooled per speaker at ingest (ingest.lag): whether any lag is applied is decided there
        "lag_evidence": np.round(lag_evidence(lips, loudness, fps), 4).tolist(),
        "procrustes_rms_mm": round(float(np.nanmedian(norm.residual_mm)), 3),
        "procrustes_rms_p95_mm": round(float(np.nanpercentile(norm.residual_mm, 95)), 3),
        "stable_jitter_mm": round(_stable_jitter(norm.points), 3),
        "image_size": [float(width), float(height)],
    }
    logger.info("%s: lip-audio lag %+.3f s (r %.2f); Procrustes residual %.2f mm", folder,
                lag, confidence, extra["procrustes_rms_mm"])
    return RawClip(
        clip_id=source.clip_id, corpus=source.corpus, source=folder, motion=motion, fps=fps,
        schema=schema, audio=audio, sample_rate=sample_rate,
        checksum=checksum_files(source.paths), text=text, phones=phones, words=words,
        emotion=fields["emotion"], speaker=fields["speaker"],
        sentence_id=fields["sentence_id"], extra=extra,
    )
