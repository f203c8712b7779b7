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

import io
import logging
import os
import re
import subprocess
from pathlib import Path

import numpy as np
import soundfile

from db.errors import DataError
from ingest.formats.wav import MAX_SPEECH_SAMPLES, check_speech_size, read_wav, speech_samples

logger = logging.getLogger(__name__)

#: Video containers (lower case, with the dot): their sound track is speech, and ingest
#: tracks the face in their pictures (:mod:`ingest.readers.video`).
VIDEO_SUFFIXES = (".mp4", ".mov", ".avi", ".mpg", ".mpeg", ".mkv", ".webm")
#: Everything read through ffmpeg: videos and audio-only MPEG-4 (``.m4a``).
MEDIA_SUFFIXES = VIDEO_SUFFIXES + (".m4a",)
#: The demuxers ffmpeg may use for a file of :data:`MEDIA_SUFFIXES` (``-format_whitelist``):
#: the containers those suffixes name (QuickTime/MP4, Matroska/WebM, AVI, MPEG program and
#: transport streams, raw MPEG video). Left to itself ffmpeg picks the demuxer by the
#: file's content, and some demuxers open other files: a DASH manifest (XML) named
#: ``speech.mp4`` makes ffmpeg read any local file its ``BaseURL`` names.
MEDIA_DEMUXERS = ("mov", "matroska", "avi", "mpeg", "mpegts", "mpegvideo")
#: The demuxers for any other sound file (a WAV, or another format libsndfile reads, as
#: :func:`ingest.formats.wav.read_wav` does), when ffmpeg reads it (``render`` muxing the
#: speech in).
SOUND_DEMUXERS = ("wav", "w64", "aiff", "au", "caf", "flac", "ogg", "mp3")
#: A line ffmpeg logs at level error or fatal (``-loglevel level+...`` tags each line).
_ERROR_LEVEL = re.compile(r"\[(error|fatal|panic)\] ")
#: The container's declared duration, as ffmpeg describes the input.
_DURATION = re.compile(r"^\[info\]\s+Duration: (\d+):(\d\d):(\d\d(?:\.\d+)?)")
#: What :func:`read_audio` gives for a file, as a number that changes whenever that
#: changes: caches of decoded sound tracks are keyed by it, so a new way of reading never
#: meets the old one's copies. 2: channels in opposite phase not averaged away, and a
#: truncated track refused.
DECODING_VERSION = 2
#: Seconds a complete sound track may fall short of the declared duration: codec priming
#: and padding (AAC's 1024 samples, Opus's 312) and the rounding of the duration to 10 ms
#: move its end by tens of milliseconds; a file cut short loses far more.
TRUNCATION_SLACK = 0.2


def read_audio(path: str | os.PathLike[str],
               sample_rate: int | None = None) -> tuple[np.ndarray, int]:
    """Mono float32 audio in [-1, 1] and its rate: a WAV, or a video's sound track.

    Parameters
    ----------
    path : path
        A WAV (read by :func:`ingest.formats.wav.read_wav`) or a file of
        :data:`MEDIA_SUFFIXES` (its first sound track, decoded by ffmpeg).
    sample_rate : int, optional
        Decode a sound track at this rate (default: its own, limited as a WAV's). WAV
        files keep theirs.

    Returns
    -------
    audio : np.ndarray, float32, shape (n_samples,)
        The channels mixed as a WAV's are, the rate limited as a WAV's is
        (:func:`ingest.formats.wav.speech_samples`).
    sample_rate : int

    Raises
    ------
    DataError
        One line naming the file if it is missing, has no sound track, ffmpeg cannot
        read it, it is truncated (:func:`_check_complete`), or it holds more than
        :data:`ingest.formats.wav.MAX_SPEECH_SAMPLES`.
    """
    path = Path(path)
    if path.suffix.lower() not in MEDIA_SUFFIXES:
        return read_wav(path)
    if not path.is_file():
        raise DataError(f"audio file not found: {path}")
    import imageio_ffmpeg

    # A WAV on the pipe rather than raw samples: its header gives the rate and the channel
    # count, so the channels are mixed here, by the WAV's rule, not by ffmpeg's downmix
    # (which sums stereo at -3 dB each and cancels opposite phases). The log, each line
    # tagged with its level, gives the declared duration and any decoding error. -fs stops
    # the WAV just past MAX_SPEECH_SAMPLES (a header's length is not to be trusted): a few
    # kilobytes of compressed silence would otherwise decode to gigabytes in memory.
    cmd = [imageio_ffmpeg.get_ffmpeg_exe(), "-nostdin", "-hide_banner", "-nostats",
           "-loglevel", "level+info", *input_args(path), "-vn", "-map", "0:a:0",
           *(("-ar", str(int(sample_rate))) if sample_rate else ()),
           "-f", "wav", "-acodec", "pcm_f32le", "-fs", str(4 * MAX_SPEECH_SAMPLES + 4096), "-"]
    proc = subprocess.run(cmd, capture_output=True, check=False)
    log = proc.stderr.decode(errors="replace").splitlines()
    errors = [_message(ln) for ln in log if _ERROR_LEVEL.search(ln)]
    if proc.returncode != 0:
        raise _read_error(path, "audio", errors, proc.returncode)
    try:
        audio, rate = soundfile.read(io.BytesIO(proc.stdout), dtype="float32", always_2d=True)
    except (soundfile.SoundFileError, RuntimeError, ValueError) as exc:
        raise DataError(f"cannot read the audio track of {path}: {exc}") from exc
    check_speech_size(*audio.shape, rate, path)
    if len(audio):  # no samples at all is speech_samples' error
        _check_complete(path, len(audio) / rate, log, errors)
    # Lossy codecs overshoot full scale near loud peaks (GRID's AAC by up to 40 %): not a
    # fault of the file to warn about; clipped quietly (synth warns of flat tops).
    np.clip(audio, -1.0, 1.0, out=audio)
    return speech_samples(audio, int(rate), path)


def input_args(path: str | os.PathLike[str]) -> list[str]:
    """ffmpeg's arguments to read ``path``, a file from others, and nothing else.

    Only the ``file`` protocol, and only the demuxers of what the file's suffix claims
    (:data:`MEDIA_DEMUXERS`, else :data:`SOUND_DEMUXERS`): a playlist or manifest
    disguised as a video (HLS, DASH, concat) cannot make ffmpeg open other files or URLs.
    The path is made absolute, so a name like ``concat:a|b`` is a file's, not a protocol's.

    Parameters
    ----------
    path : path

    Returns
    -------
    list of str
        Input options, then ``-i`` and the path (the last two items).
    """
    demuxers = (MEDIA_DEMUXERS if Path(path).suffix.lower() in MEDIA_SUFFIXES
                else SOUND_DEMUXERS)
    return ["-protocol_whitelist", "file", "-format_whitelist", ",".join(demuxers),
            "-i", os.path.abspath(path)]


def read_frames(path: str | os.PathLike[str], **kwargs):
    """``imageio_ffmpeg.read_frames`` of a file from others, restricted as
    :func:`input_args` (its generator: the metadata, then the frames' bytes)."""
    import imageio_ffmpeg

    *options, _, absolute = input_args(path)
    return imageio_ffmpeg.read_frames(absolute, input_params=options, **kwargs)


def _message(line: str) -> str:
    """An ffmpeg log line without its ``[component @ 0x...]`` and ``[level]`` tags."""
    return re.sub(r"^(\[[^\]]*\]\s*)+", "", line).strip()


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
           *input_args(path), "-map", "0:v:0", "-f", "null", "-progress", "pipe:1", "-"]
    proc = subprocess.run(cmd, capture_output=True, check=False)
    totals = dict(line.partition("=")[::2]
                  for line in proc.stdout.decode(errors="replace").splitlines())
    frames = totals.get("frame", "").strip()
    if proc.returncode != 0 or not frames.isdigit() or int(frames) == 0:
        lines = [ln for ln in proc.stderr.decode(errors="replace").splitlines() if ln.strip()]
        raise _read_error(path, "video", lines, proc.returncode)
    try:
        return int(totals["out_time_us"]) / 1e6
    except (KeyError, ValueError):
        raise DataError(f"cannot read the video track of {path}: ffmpeg gave no "
                        "duration") from None


def _read_error(path: Path, track: str, errors: list[str], returncode: int) -> DataError:
    """The one line for a failed ffmpeg read of ``path``'s ``track`` (``"audio"`` or
    ``"video"``), from ffmpeg's error lines."""
    # "Stream map '' matches no streams." need not be the last line (ffmpeg 7 adds more)
    if any("matches no streams" in ln for ln in errors):
        return DataError(f"{path}: no {track} track")
    if any("not on whitelist" in ln for ln in errors):  # input_args' demuxers
        return DataError(f"cannot read the {track} track of {path}: not a container its "
                         f"suffix names (a playlist or manifest named like a video?)")
    return DataError(f"cannot read the {track} track of {path}: "
                     f"{errors[-1] if errors else returncode}")


def _check_complete(path: Path, decoded_s: float, log: list[str], errors: list[str]) -> None:
    """Refuse a sound track cut short: ffmpeg reads what is there, says so at level error
    ("partial file", "File ended prematurely"), and exits 0.

    The sound is truncated when ffmpeg reported an error and decoded more than
    :data:`TRUNCATION_SLACK` s less than the container declares. Without an error the
    shortfall is a sound track that ends before the pictures (``-shortest`` leaves a
    second of them), which is no fault: it is only logged. A read error with no
    shortfall, a damaged packet inside the file, is ffmpeg's to conceal.

    Raises
    ------
    DataError
        One line naming the file, like a truncated WAV's.
    """
    match = next((m for m in map(_DURATION.match, log) if m), None)
    if match is None:  # a stream with no declared duration ("N/A"): nothing to compare
        return
    hours, minutes, seconds = match.groups()
    declared = 3600 * int(hours) + 60 * int(minutes) + float(seconds)
    if decoded_s >= declared - TRUNCATION_SLACK:
        return
    if errors:
        raise DataError(f"truncated audio file {path}: {decoded_s:.2f} s of sound decoded, "
                        f"the file declares {declared:.2f} s ({errors[0]})")
    logger.info("%s: the sound track ends at %.2f s, %.2f s before the file's declared "
                "duration", path, decoded_s, declared - decoded_s)
