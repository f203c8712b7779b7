"""Live: speech in as it is spoken, facial motion out in real time.

* :mod:`.stream` -- :class:`~.stream.Stream`: push audio chunks, get motion frames with
  their times (the offline default re-run on a bounded sliding window, sent with a
  look-ahead the caller chooses);
* :mod:`.livelink` -- the Live Link Face UDP packet (what Unreal's Live Link and MetaHuman
  receive from the iPhone app), encoded and decoded, and a sender;
* :mod:`.websocket` -- JSON frames to any number of WebSocket clients;
* :mod:`.record` -- what was sent, kept as a Live Link CSV (or the database's motion
  format) with the audio;
* :mod:`.sources` -- audio from a file played at real-time pace, raw PCM on stdin, or the
  microphone; :mod:`.run` wires a source to a stream and its outputs (``animegraph live``).
"""

from animegraph.live.stream import Frames, Stream, stored_guide

__all__ = ["Frames", "Stream", "stored_guide"]
