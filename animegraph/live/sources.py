"""Where live speech comes from: a file played at real-time pace, raw PCM on stdin, or the
microphone. Each source is an iterable of chunks (float32, shape (n,), in [-1, 1]) with
its ``sample_rate``; :meth:`stop` ends it early (from another thread).
"""

from __future__ import annotations

import sys
import threading
import time

import numpy as np

from db.errors import DataError

#: Samples per chunk (ms of audio) read from a source.
CHUNK_MS = 20.0


class FileSource:
    """A WAV, or a video's sound track (:func:`ingest.formats.media.read_audio`), given in
    chunks at the pace it was spoken (``fast``: as fast as it is taken)."""

    def __init__(self, path, *, fast: bool = False, chunk_ms: float = CHUNK_MS) -> None:
        from ingest.formats.media import read_audio

        audio, self.sample_rate = read_audio(path)
        self.audio = np.asarray(audio, dtype=np.float32)
        self.fast = fast
        self.chunk = max(1, int(round(chunk_ms / 1000 * self.sample_rate)))
        self._stop = threading.Event()

    def __iter__(self):
        start = time.perf_counter()
        for k in range(0, len(self.audio), self.chunk):
            if self._stop.is_set():
                return
            end = min(len(self.audio), k + self.chunk)
            if not self.fast:  # a chunk is there once its last sample has been spoken
                wait = start + end / self.sample_rate - time.perf_counter()
                if wait > 0 and self._stop.wait(wait):
                    return
            yield self.audio[k:end]

    def stop(self) -> None:
        self._stop.set()


class PcmSource:
    """Raw PCM, 16-bit signed little-endian mono at ``sample_rate``, from a binary stream
    (stdin by default), in chunks as they come."""

    def __init__(self, sample_rate: int, *, stream=None, chunk_ms: float = CHUNK_MS) -> None:
        self.sample_rate = int(sample_rate)
        self.stream = stream if stream is not None else sys.stdin.buffer
        self.chunk_bytes = 2 * max(1, int(round(chunk_ms / 1000 * self.sample_rate)))
        self._stop = threading.Event()

    def __iter__(self):
        odd = b""
        while not self._stop.is_set():
            data = self.stream.read1(self.chunk_bytes) if hasattr(self.stream, "read1") \
                else self.stream.read(self.chunk_bytes)
            if not data:
                return
            data = odd + data
            cut = len(data) - len(data) % 2  # a sample split between reads waits for its half
            odd = data[cut:]
            if cut:
                yield np.frombuffer(data[:cut], dtype="<i2").astype(np.float32) / 32768.0

    def stop(self) -> None:
        self._stop.set()


class MicSource:
    """The default microphone through PortAudio (``sounddevice``: ``pip install
    'animegraph[live]'`` and the system's PortAudio library, ``apt install libportaudio2``
    on Debian and Ubuntu)."""

    def __init__(self, sample_rate: int, *, chunk_ms: float = CHUNK_MS) -> None:
        self.sample_rate = int(sample_rate)
        try:
            import sounddevice
        except ImportError:
            raise DataError("the microphone needs the sounddevice package: pip install "
                            "'animegraph[live]'") from None
        except OSError:  # sounddevice loads PortAudio when imported
            raise DataError("the microphone needs the PortAudio library: apt install "
                            "libportaudio2 (Debian, Ubuntu), brew install portaudio "
                            "(macOS)") from None
        import queue

        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self.overflows = 0

        def heard(data, frames, when, status) -> None:  # PortAudio's thread: never block
            if status.input_overflow:
                self.overflows += 1
            self._queue.put(data[:, 0].copy())

        try:
            self._stream = sounddevice.InputStream(
                samplerate=self.sample_rate, channels=1, dtype="float32",
                blocksize=max(1, int(round(chunk_ms / 1000 * self.sample_rate))),
                callback=heard)
        except Exception as exc:  # PortAudioError: no device, a rate it cannot take
            raise DataError(f"cannot open the microphone at {self.sample_rate} Hz: "
                            f"{exc}") from None
        self._stop = threading.Event()

    def __iter__(self):
        import queue

        with self._stream:
            while not self._stop.is_set():
                try:
                    yield self._queue.get(timeout=0.1)
                except queue.Empty:
                    continue

    def stop(self) -> None:
        self._stop.set()
