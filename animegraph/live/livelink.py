"""The Live Link Face UDP packet: what Epic Games' iPhone app sends to Unreal's Live Link
(and MetaHuman), encoded and decoded, and a sender that never blocks.

One datagram per frame, every number big-endian (Unreal's ``AppleARKitLiveLinkSource``,
packet version 6, the version pylivelinkface 0.1 and the think-biq serializer also use)::

    uint8    version (6)
    int32    length, then that many UTF-8 bytes: the device id (a 36-character UUID)
    int32    length, then that many UTF-8 bytes: the subject name
    int32    frame number  }  FQualifiedFrameTime: the frame time ...
    float32  sub-frame     }
    int32    rate numerator    } ... and its rate (e.g. 60 / 1)
    int32    rate denominator  }
    uint8    count (61)
    float32  x 61: the 52 ARKit blendshapes in Unreal's EARFaceBlendShape order, then
             head yaw, pitch, roll and the left and right eyes' yaw, pitch, roll

The packet's blendshape order is Unreal's enum's (:data:`PACKET_ORDER`: ``JawLeft``
before ``JawRight``, ``MouthLeft`` before ``MouthRight``), not the app's CSV column order
(:data:`ingest.formats.livelink.ARKIT_BLENDSHAPES`, right before left): values are placed
by name.

An ARKit database's channels are sent as they are; a marker or landmark database's frames
are first mapped onto the 52 shapes (:mod:`animegraph.live.arkit_map`).
"""

from __future__ import annotations

import socket
import struct
import uuid as uuid_module
from dataclasses import dataclass

import numpy as np

from db.errors import DataError, ParameterError
from ingest.formats.livelink import ARKIT_BLENDSHAPES, ROTATIONS

#: The packet version written (Unreal's BLEND_SHAPE_PACKET_VER).
PACKET_VERSION = 6
#: Values per packet.
N_VALUES = 61
#: Unreal's EARFaceBlendShape order differs from Live Link Face's CSV columns (the
#: project's order, :data:`ARKIT_BLENDSHAPES`) in two pairs only.
_UNREAL_SWAPS = {"jawRight": "jawLeft", "jawLeft": "jawRight",
                 "mouthRight": "mouthLeft", "mouthLeft": "mouthRight"}
#: Unreal's order of the 61 values of a packet: the 52 shapes, then the rotations.
PACKET_ORDER: tuple[str, ...] = tuple(
    _UNREAL_SWAPS.get(name, name) for name in ARKIT_BLENDSHAPES) + ROTATIONS
#: Largest packet accepted by :func:`decode` (Unreal's limit).
MAX_PACKET = 774


@dataclass(frozen=True)
class Packet:
    """A decoded packet: ``values`` (61,) in :data:`PACKET_ORDER`."""

    version: int
    device_id: str
    subject: str
    frame: int
    sub_frame: float
    rate: tuple[int, int]
    values: np.ndarray

    def value(self, name: str) -> float:
        """The value of a blendshape or rotation by its (lower camel case) name."""
        return float(self.values[PACKET_ORDER.index(name)])


def _string(text: str) -> bytes:
    data = text.encode("utf-8")
    return struct.pack(">i", len(data)) + data


def encode(values: np.ndarray, *, frame: int, fps: float, device_id: str,
           subject: str, sub_frame: float = 0.0) -> bytes:
    """One packet.

    Parameters
    ----------
    values : np.ndarray, shape (61,)
        In :data:`PACKET_ORDER`.
    frame : int
        Frame number at ``fps`` (the frame time).
    fps : float
        Frame rate, written as a fraction (``30000/1001`` for 29.97).
    device_id, subject : str
    """
    values = np.asarray(values, dtype=">f4").reshape(-1)
    if values.shape != (N_VALUES,):
        raise ParameterError(f"a Live Link packet holds {N_VALUES} values, got {values.size}")
    num, den = _rate(fps)
    return (struct.pack(">B", PACKET_VERSION) + _string(device_id) + _string(subject)
            + struct.pack(">ifiiB", int(frame), float(sub_frame), num, den, N_VALUES)
            + values.tobytes())


def _rate(fps: float) -> tuple[int, int]:
    if abs(fps - round(fps)) < 1e-6:
        return int(round(fps)), 1
    if abs(fps * 1.001 - round(fps * 1.001)) < 1e-3:
        return int(round(fps * 1.001)) * 1000, 1001
    return int(round(fps * 1000)), 1000


def decode(data: bytes) -> Packet:
    """A packet read back (DataError on a malformed one: someone else's bytes)."""
    if not 0 < len(data) <= MAX_PACKET:
        raise DataError(f"a Live Link packet of {len(data)} bytes (at most {MAX_PACKET})")
    try:
        pos = 1
        version = data[0]
        strings = []
        for _ in range(2):
            (n,) = struct.unpack_from(">i", data, pos)
            if not 0 <= n <= len(data) - pos - 4:
                raise DataError(f"a Live Link packet with a string of {n} bytes")
            strings.append(data[pos + 4: pos + 4 + n].decode("utf-8"))
            pos += 4 + n
        frame, sub, num, den, count = struct.unpack_from(">ifiiB", data, pos)
        pos += 17
        if len(data) - pos != 4 * count:
            raise DataError(f"a Live Link packet says {count} values and holds "
                            f"{(len(data) - pos) / 4:g}")
        values = np.frombuffer(data, dtype=">f4", count=count, offset=pos).astype(np.float64)
    except (struct.error, UnicodeDecodeError) as exc:
        raise DataError(f"a malformed Live Link packet ({exc})") from None
    return Packet(version, strings[0], strings[1], frame, sub, (num, den), values)


def arkit_columns(names) -> np.ndarray:
    """For each of the 61 packet values, the database channel that holds it (-1: none,
    sent as 0), shape (61,).

    Raises
    ------
    DataError
        If the channels are not ARKit blendshapes (map points first:
        :mod:`animegraph.live.arkit_map`).
    """
    lower = {str(n).lower(): i for i, n in enumerate(names)}
    cols = np.array([lower.get(n.lower(), -1) for n in PACKET_ORDER], dtype=np.int64)
    if (cols[:52] < 0).sum() > 0:
        missing = [n for n, c in zip(PACKET_ORDER[:52], cols[:52], strict=True) if c < 0]
        raise DataError(f"Live Link sends ARKit's 52 blendshapes; these channels lack "
                        f"{len(missing)} of them ({', '.join(missing[:3])}, ...)")
    return cols


def packet_values(frame: np.ndarray, columns: np.ndarray) -> np.ndarray:
    """A frame (n_channels,) as the 61 packet values: blendshapes clamped to [0, 1]."""
    out = np.where(columns >= 0, np.asarray(frame)[np.maximum(columns, 0)], 0.0)
    out[:52] = np.clip(out[:52], 0.0, 1.0)
    return out


class LiveLinkSender:
    """Sends frames to a Live Link receiver over UDP, one datagram each.

    Never blocks: the socket is non-blocking, and a datagram the system will not take now
    (or one refused by the receiver's host: no one listening there) is dropped and
    counted (:attr:`dropped`, :attr:`errors` by kind).

    Parameters
    ----------
    target : str
        ``HOST:PORT`` (Unreal's Live Link Face source listens on 11111 by default).
    names : sequence of str
        The database's channels (ARKit: :func:`arkit_columns`).
    fps : float
    subject : str
        The subject name Unreal lists.
    convert : callable, optional
        Maps a frame to ARKit channel values named ``convert.names`` (a point database:
        :class:`animegraph.live.arkit_map.PointsToArkit`).
    """

    def __init__(self, target: str, names, fps: float, *, subject: str = "animegraph",
                 convert=None) -> None:
        host, port = parse_target(target)
        self.convert = convert  # frame -> ARKit channel values (its ``names``), or None
        self.columns = arkit_columns(names if convert is None else convert.names)
        self.fps = fps
        self.subject = subject
        self.device_id = str(uuid_module.uuid4()).upper()  # 36 characters, as the app's
        try:
            info = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)[0]
        except socket.gaierror as exc:
            raise DataError(f"--livelink {target}: cannot resolve {host!r} ({exc.strerror})") \
                from None
        self.sock = socket.socket(info[0], socket.SOCK_DGRAM)
        self.sock.setblocking(False)
        self.address = info[4]
        self.sent = 0
        self.dropped = 0
        self.errors: dict[str, int] = {}

    def send(self, index: int, frame: np.ndarray) -> None:
        """Send frame ``index`` (n_channels,)."""
        if self.convert is not None:
            frame = self.convert(frame)
        data = encode(packet_values(frame, self.columns), frame=index, fps=self.fps,
                      device_id=self.device_id, subject=self.subject)
        try:
            self.sock.sendto(data, self.address)
            self.sent += 1
        except OSError as exc:  # full buffer, or ICMP port unreachable from an earlier one
            self.dropped += 1
            kind = exc.strerror or type(exc).__name__
            self.errors[kind] = self.errors.get(kind, 0) + 1

    def close(self) -> None:
        self.sock.close()


def parse_target(text: str) -> tuple[str, int]:
    """``HOST:PORT`` -> (host, port); ParameterError on anything else."""
    host, sep, port = str(text).rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ParameterError(f"--livelink wants HOST:PORT (e.g. 127.0.0.1:11111), got {text!r}")
    return host.strip("[]"), int(port)
