"""Where live speech comes from: a file played at real-time pace, raw PCM on stdin or from
a WebSocket client, or the microphone. Each source is an iterable of chunks (float32,
shape (n,), in [-1, 1]) with its ``sample_rate``; :meth:`stop` ends it early (from another thread).
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


class WebSocketSource:
    """Raw PCM from a WebSocket client: a server at ``ws://HOST:PORT/`` that takes one
    client, whose binary messages are 16-bit signed little-endian mono samples at
    ``sample_rate`` (any length; a sample split between messages waits for its other
    byte). The stream ends when that client closes. Text messages are refused (counted in
    :attr:`refused`), as are clients while one is connected (the ``websockets`` package:
    ``pip install 'animegraph[live]'``).

    Parameters
    ----------
    port : int
        0 picks a free one (:attr:`port` says which).
    sample_rate : int
    host : str
    """

    def __init__(self, port: int, sample_rate: int, *, host: str = "127.0.0.1") -> None:
        import queue

        try:
            from websockets.sync.server import serve
        except ImportError:
            raise DataError("--source ws:PORT needs the websockets package: pip install "
                            "'animegraph[live]'") from None
        self.sample_rate = int(sample_rate)
        self.refused = 0
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._busy = threading.Lock()
        self._stop = threading.Event()
        try:
            self._server = serve(self._client, host, int(port), max_size=2**22)
        except OSError as exc:
            raise DataError(f"--source ws:{port}: cannot listen there ({exc})") from None
        self.port = self._server.socket.getsockname()[1]
        threading.Thread(target=self._server.serve_forever, daemon=True,
                         name="live-ws-source").start()

    def _client(self, ws) -> None:  # the server's thread for this client
        from websockets.exceptions import ConnectionClosed

        if not self._busy.acquire(blocking=False):
            self.refused += 1
            ws.close(1013, "another client is sending")
            return
        odd = b""
        try:
            for message in ws:
                if isinstance(message, str):
                    self.refused += 1
                    continue
                data = odd + message
                cut = len(data) - len(data) % 2
                odd = data[cut:]
                if cut:
                    self._queue.put(np.frombuffer(data[:cut], dtype="<i2").astype(np.float32)
                                    / 32768.0)
        except ConnectionClosed:
            pass
        finally:
            self._queue.put(None)  # the stream ends with its client

    def __iter__(self):
        import queue

        try:
            while not self._stop.is_set():
                try:
                    chunk = self._queue.get(timeout=0.1)
                except queue.Empty:
                    continue
                if chunk is None:
                    return
                yield chunk
        finally:
            self._server.shutdown()

    def stop(self) -> None:
        self._stop.set()
