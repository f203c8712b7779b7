"""JSON frames to any number of WebSocket clients (the browser, or any program).

Each client that connects to ``ws://HOST:PORT/`` first gets a ``hello`` message (the
channel names and frame rate), then one message per frame, in order::

    {"type": "hello", "fps": 30.0, "channels": ["jawOpen", ...]}
    {"type": "frame", "index": 12, "time": 0.4, "values": [0.01, ...]}

and ``{"type": "end", "frames": N}`` when the stream ends. The server runs its own event
loop on a thread; :meth:`FrameServer.send` never blocks the audio path: each client has a
queue of :data:`QUEUE_FRAMES` frames, and a frame that finds it full (a client reading
too slowly) is dropped for that client and counted. A client that disconnects is counted
and forgotten.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import threading

import numpy as np

from db.errors import DataError

#: Frames waiting per client before new ones are dropped (about 2 s at 30 fps).
QUEUE_FRAMES = 64
#: Decimals of the values sent.
DECIMALS = 5


class FrameServer:
    """A WebSocket server sending frames (see the module docstring).

    Parameters
    ----------
    port : int
        0 picks a free one (:attr:`port` says which).
    names : sequence of str
        The channels.
    fps : float
    host : str
    """

    def __init__(self, port: int, names, fps: float, *, host: str = "127.0.0.1") -> None:
        try:
            import websockets  # noqa: F401 (an optional extra: say so before starting)
        except ImportError:
            raise DataError("--websocket needs the websockets package: pip install "
                            "'animegraph[live]'") from None
        self.names = [str(n) for n in names]
        self.fps = float(fps)
        self.dropped = 0
        self.sent = 0
        self.disconnected = 0
        self.connected = 0
        self._clients: dict[object, asyncio.Queue] = {}
        self._loop = asyncio.new_event_loop()
        self._ready = threading.Event()
        self._stop: asyncio.Event | None = None
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, args=(host, port), daemon=True,
                                        name="live-websocket")
        self._thread.start()
        self._ready.wait()
        if self._error is not None:
            raise DataError(f"--websocket {port}: cannot listen there ({self._error})")

    def _run(self, host: str, port: int) -> None:
        asyncio.set_event_loop(self._loop)
        self._loop.run_until_complete(self._main(host, port))

    async def _main(self, host: str, port: int) -> None:
        from websockets.asyncio.server import serve

        self._stop = asyncio.Event()
        try:
            server = await serve(self._client, host, port)
        except OSError as exc:
            self._error = exc
            self._ready.set()
            return
        self.port = server.sockets[0].getsockname()[1]
        self._ready.set()
        async with server:
            await self._stop.wait()
            for queue in self._clients.values():  # let every client have its end
                queue.put_nowait(None)
            await asyncio.sleep(0)
            with contextlib.suppress(asyncio.TimeoutError):
                await asyncio.wait_for(self._drain(), timeout=2.0)

    async def _drain(self) -> None:
        while any(not q.empty() for q in self._clients.values()):
            await asyncio.sleep(0.01)

    async def _client(self, ws) -> None:
        from websockets.exceptions import ConnectionClosed

        queue: asyncio.Queue = asyncio.Queue(QUEUE_FRAMES)
        self._clients[ws] = queue
        self.connected += 1
        try:
            await ws.send(json.dumps({"type": "hello", "fps": self.fps,
                                      "channels": self.names}))
            while True:
                message = await queue.get()
                if message is None:
                    break
                await ws.send(message)
        except ConnectionClosed:
            self.disconnected += 1
        finally:
            self._clients.pop(ws, None)

    def _offer(self, message: str) -> None:  # on the server's loop
        for queue in list(self._clients.values()):
            try:
                queue.put_nowait(message)
                self.sent += 1
            except asyncio.QueueFull:
                self.dropped += 1

    def send(self, index: int, frame: np.ndarray) -> None:
        """Queue frame ``index`` (n_channels,) for every client; never blocks."""
        message = json.dumps({"type": "frame", "index": int(index),
                              "time": round(index / self.fps, 6),
                              "values": np.round(np.asarray(frame, dtype=np.float64),
                                                 DECIMALS).tolist()})
        self._loop.call_soon_threadsafe(self._offer, message)

    @property
    def clients(self) -> int:
        """Clients connected now."""
        return len(self._clients)

    def close(self, frames: int | None = None) -> None:
        """Send ``end`` to every client, let their queues drain (2 s at most), stop."""
        if self._stop is None or not self._thread.is_alive():
            return
        if frames is not None:
            end = json.dumps({"type": "end", "frames": int(frames)})
            self._loop.call_soon_threadsafe(self._offer, end)
        self._loop.call_soon_threadsafe(self._stop.set)
        self._thread.join(timeout=5.0)
