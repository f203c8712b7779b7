"""A live take kept as it was sent (``animegraph live --record DIR``), to replay and check.

:class:`Recorder` keeps every frame sent and every sample heard in memory (10 minutes at
30 fps of 61 values and 16 kHz audio: about 30 MB) and writes them when closed, also
after Ctrl-C: ``DIR/take<EXT>`` in the format that keeps the database's channels
(:func:`animegraph.motion.files.motion_suffix`: Live Link Face CSV for ARKit databases,
C3D for markers, CSV otherwise) and ``DIR/take.wav``, the audio, both starting at the
stream's first sample (frame ``k`` at ``k / fps`` s). Both files are written atomically.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from db.errors import ParameterError


class Recorder:
    """Frames and audio of a live take, written by :meth:`close`.

    Parameters
    ----------
    folder : path
        Created if missing; ``take.*`` files in it are replaced.
    names : sequence of str
    kind : str
        The database's kind (as :func:`animegraph.motion.files.motion_suffix` reads it).
    fps : float
    sample_rate : int
    """

    def __init__(self, folder, names, kind: str, fps: float, sample_rate: int) -> None:
        from animegraph.motion.files import motion_suffix

        self.folder = Path(folder)
        if self.folder.exists() and not self.folder.is_dir():
            raise ParameterError(f"--record {folder}: not a folder")
        self.folder.mkdir(parents=True, exist_ok=True)
        self.names, self.kind = tuple(names), kind
        self.fps, self.sample_rate = float(fps), int(sample_rate)
        self.motion_path = self.folder / f"take{motion_suffix(self.names, kind)}"
        self.audio_path = self.folder / "take.wav"
        self._frames: list[np.ndarray] = []
        self._audio: list[np.ndarray] = []
        self._next = 0
        self.closed = False

    def audio(self, samples: np.ndarray) -> None:
        """Keep samples heard (float, shape (n,))."""
        self._audio.append(np.asarray(samples, dtype=np.float32).copy())

    def send(self, index: int, frame: np.ndarray) -> None:
        """Keep frame ``index`` (they come in order, from 0)."""
        if index != self._next:
            raise ParameterError(f"frame {index} recorded after frame {self._next - 1}")
        self._frames.append(np.asarray(frame, dtype=np.float64))
        self._next += 1

    def close(self) -> list[Path]:
        """Write the take and its audio; the paths written (none twice)."""
        from animegraph.motion.files import write_channels
        from ingest.formats.wav import write_wav

        if self.closed:
            return []
        self.closed = True
        audio = np.concatenate(self._audio) if self._audio else np.zeros(0, np.float32)
        write_wav(self.audio_path, np.clip(audio, -1.0, 1.0), self.sample_rate)
        written = [self.audio_path]
        if self._frames:
            write_channels(np.stack(self._frames), self.fps, self.names, self.kind,
                           self.motion_path)
            written.append(self.motion_path)
        return written
