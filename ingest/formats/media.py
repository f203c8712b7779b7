"""The sound track of a video (``.mp4``, ``.mov``, ``.mkv`` ..., ``.m4a``), through ffmpeg.

Live Link Face saves each take's speech only inside the take's video (``<take>.mov``
beside ``<take>.csv``); :func:`read_audio` reads it as mono float32, so an iPhone take
ingests as it comes off the phone. The ffmpeg binary is the one ``imageio-ffmpeg`` ships
(a dependency, used for rendering too). The same reads the speech of a video clip
(:mod:`ingest.readers.video`) and a video given to ``synth``. WAV files go through
:func:`ingest.formats.wav.read_wav` as everywhere else. :func:`video_length` says how much
of a video's picture ffmpeg can decode (``render --beside`` checks the actor's video with it).
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import numpy as np

from db.errors import DataError
from ingest.formats.wav import read_wav

#: Video containers (lower case, with the dot): their sound track is speech, and ingest
#: tracks the face in their pictures (:mod:`ingest.readers.video`).
VIDEO_SUFFIXES = (".mp4", ".mov", ".avi", ".mpg", ".mpeg", ".mkv", ".webm")
#: Everything read through ffmpeg: videos and audio-only MPEG-4 (``.m4a``).
MEDIA_SUFFIXES = VIDEO_SUFFIXES + (".m4a",)


def read_audio(path: str | os.PathLike[str],
               sample_rate: int | None = None) -> tuple[np.ndarray, int]:
    """Mono float32 audio in [-1, 1] and its rate: a WAV, or a video's sound track.

    Parameters
    ----------
    path : path
        A WAV (read by :func:`ingest.formats.wav.read_wav`) or a file of
        :data:`MEDIA_SUFFIXES` (its first sound track, decoded by ffmpeg).
    sample_rate : int, optional
        Decode a sound track at this rate (default: its own). WAV files keep theirs.

    Raises
    ------
    DataError
        One line naming the file if it is missing, has no sound track, or ffmpeg cannot
        read it.
    """
    path = Path(path)
    if path.suffix.lower() not in MEDIA_SUFFIXES:
        return read_wav(path)
    if not path.is_file():
        raise DataError(f"audio file not found: {path}")
    import imageio_ffmpeg

    rate = int(sample_rate) if sample_rate else _sample_rate(path)
    cmd = [imageio_ffmpeg.get_ffmpeg_exe(), "-nostdin", "-loglevel", "error", "-i", str(path),
           "-vn", "-map", "0:a:0", "-ac", "1", "-ar", str(rate), "-f", "f32le",
           "-acodec", "pcm_f32le", "-"]
    proc = subprocess.run(cmd, capture_output=True, check=False)
    if proc.returncode != 0 or not proc.stdout:
        raise _read_error(path, "audio", proc, nothing_read=not proc.stdout)
    audio = np.frombuffer(proc.stdout, dtype="<f4").astype(np.float32)
    return np.clip(audio, -1.0, 1.0), rate


def video_length(path: str | os.PathLike[str]) -> float:
    """Seconds of picture that ffmpeg decodes from a file's first video track.

    Every frame is decoded (to no output), so a file cut short gives the length it
    holds, not the one its header declares.

    Parameters
    ----------
    path : path
        A video (any container ffmpeg reads).

    Returns
    -------
    float
        From the first decoded frame to the end of the last one.

    Raises
    ------
    DataError
        One line naming the file if it is missing, has no video track, or ffmpeg decodes
        no frame of it (ffmpeg's last line).
    """
    path = Path(path)
    if not path.is_file():
        raise DataError(f"video not found: {path}")
    import imageio_ffmpeg

    # -progress writes key=value lines (the last frame= and out_time_us= are the totals);
    # ffmpeg's human-readable statistics line is not meant to be parsed.
    cmd = [imageio_ffmpeg.get_ffmpeg_exe(), "-nostdin", "-loglevel", "error", "-nostats",
           "-i", str(path), "-map", "0:v:0", "-f", "null", "-progress", "pipe:1", "-"]
    proc = subprocess.run(cmd, capture_output=True, check=False)
    totals = dict(line.partition("=")[::2]
                  for line in proc.stdout.decode(errors="replace").splitlines())
    frames = totals.get("frame", "").strip()
    if proc.returncode != 0 or not frames.isdigit() or int(frames) == 0:
        raise _read_error(path, "video", proc, nothing_read=True)
    try:
        return int(totals["out_time_us"]) / 1e6
    except (KeyError, ValueError):
        raise DataError(f"cannot read the video track of {path}: ffmpeg gave no "
                        "duration") from None


def _read_error(path: Path, track: str, proc: subprocess.CompletedProcess,
                nothing_read: bool) -> DataError:
    """The one line for a failed ffmpeg read of ``path``'s ``track`` (audio or video)."""
    lines = [ln for ln in proc.stderr.decode(errors="replace").splitlines() if ln.strip()]
    # ffmpeg 7 follows "Stream map '' matches no streams." with more lines
    if nothing_read and (not lines or any("matches no streams" in ln for ln in lines)):
        return DataError(f"{path}: no {track} track")
    return DataError(f"cannot read the {track} track of {path}: "
                     f"{lines[-1] if lines else proc.returncode}")


def _sample_rate(path: Path) -> int:
    """The first sound track's sample rate, from ffmpeg's description of the file."""
    import re

    import imageio_ffmpeg

    proc = subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-nostdin", "-hide_banner", "-i",
                           str(path)], capture_output=True, check=False)
    info = proc.stderr.decode(errors="replace")
    match = re.search(r"Stream #\S+.*?Audio: .*?(\d+) Hz", info)
    if not match:
        raise DataError(f"{path}: no audio track")
    return int(match.group(1))
