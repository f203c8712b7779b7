"""A source, a stream and its outputs wired together (what ``animegraph live`` runs).

The source is read on a thread of its own that only queues what it hears (an unbounded
queue: the audio path never waits for synthesis or a client); the caller's thread takes
everything queued at once, pushes it into the :class:`~animegraph.live.stream.Stream`
(audio that arrives in bursts, or while an update runs, is heard together) and hands each
frame to every output (``send(index, frame)``; the outputs never block either). Ctrl-C
(KeyboardInterrupt) stops the source and closes every output and the recording before
it goes on up.
"""

from __future__ import annotations

import bisect
import queue
import threading
import time
from dataclasses import dataclass, field

import numpy as np

from animegraph.live.stream import join


@dataclass
class Take:
    """What a live run did: frames sent, audio heard (s), when each frame was sent (wall
    clock, s from the start) and when the audio it shows had arrived."""

    frames: int = 0
    heard_s: float = 0.0
    sent_at: list[float] = field(default_factory=list)
    arrived_at: list[float] = field(default_factory=list)
    interrupted: bool = False


def run(stream, source, outputs=(), *, recorder=None, on_frames=None) -> Take:
    """Play ``source`` into ``stream`` until it ends; send every frame to ``outputs``
    (and ``recorder``). ``on_frames(frames)`` is called after each batch (progress)."""
    chunks: queue.SimpleQueue = queue.SimpleQueue()
    failure: list[BaseException] = []
    start = time.perf_counter()

    def read() -> None:
        try:
            for chunk in source:
                chunks.put((time.perf_counter() - start, chunk))
        except BaseException as exc:  # noqa: BLE001 (given to the caller's thread)
            failure.append(exc)
        finally:
            chunks.put(None)

    reader = threading.Thread(target=read, name="live-source", daemon=True)
    take = Take()
    arrivals: list[float] = []  # arrival time (s, wall) of each chunk ...
    ends: list[int] = []  # ... and the samples heard once it was
    heard = 0
    sinks = list(outputs) + ([recorder] if recorder is not None else [])
    reader.start()
    try:
        done = False
        while not done:
            batch = [chunks.get()]
            while True:  # everything queued meanwhile
                try:
                    batch.append(chunks.get_nowait())
                except queue.Empty:
                    break
            done = batch[-1] is None
            batch = [b for b in batch if b is not None]
            for at, chunk in batch:
                heard += len(chunk)
                arrivals.append(at)
                ends.append(heard)
                if recorder is not None:
                    recorder.audio(chunk)
            audio = (np.concatenate([c for _, c in batch]) if batch
                     else np.zeros(0, np.float32))
            frames = stream.push(audio)
            if done:
                frames = join([frames, stream.close()], frames)
            now = time.perf_counter() - start
            for k, frame in zip(frames.indices, frames.motion, strict=True):
                for sink in sinks:
                    sink.send(int(k), frame)
                # the frame shows the audio at k / fps: it arrived with the chunk holding it
                sample = min(int(round(k / stream.fps * stream.sample_rate)), heard - 1)
                take.arrived_at.append(arrivals[bisect.bisect_right(ends, sample)]
                                       if heard else now)
                take.sent_at.append(now)
            take.frames += len(frames)
            if on_frames is not None and len(frames):
                on_frames(frames)
        if failure:
            raise failure[0]
    except KeyboardInterrupt:
        take.interrupted = True
        raise
    finally:
        source.stop()
        take.heard_s = heard / stream.sample_rate
        for sink in sinks:
            sink.close()
    return take
