"""The face the studio's page draws: the canonical mesh, and motion carried onto it by the
project's own deformation (:func:`animegraph.face.animation.animate` for markers and
landmarks, :func:`animegraph.face.arkit.arkit_animation` for ARKit curves), exactly as
``animegraph render`` does; the page only draws the vertices it is sent.

An animation goes to the page as one binary message (:func:`pack`): a little-endian
``uint32`` length, a JSON header (frame rate, frame count, phones ...), zero padding to
a multiple of 4 bytes, then the world vertex positions as ``float32`` of shape
``(n_frames, n_vertices, 3)``: 5.6 kB a frame for the canonical face's 468 vertices.
"""

from __future__ import annotations

import json
import struct
import threading
from collections.abc import Sequence

import numpy as np

from animegraph.face.animation import FaceAnimation, animate
from animegraph.face.arkit import arkit_animation
from animegraph.face.mesh import Mesh, canonical_mesh
from animegraph.motion.files import Motion
from db.errors import DataError
from ingest import facemesh
from ingest.formats.livelink import is_arkit

#: Frames per second of the vertices sent to the page; the page interpolates between
#: them at its own display rate (a 120 fps capture would otherwise be four times the bytes).
PAGE_FPS = 30.0


class FaceBuilder:
    """Turns motion of one database's channels into page animations.

    The deformer (RBF systems per face region, :meth:`animegraph.face.mesh.Deformer.build`)
    is built once, on first use, and shared by every request.

    Parameters
    ----------
    names : sequence of str
        The database's channels.
    """

    def __init__(self, names: Sequence[str]):
        self.names = tuple(names)
        self.arkit = is_arkit(self.names)
        self._deformer = None
        self._lock = threading.Lock()

    @property
    def mesh(self) -> Mesh:
        return self.deformer().mesh if not self.arkit else canonical_mesh()

    def deformer(self):
        """The database's deformer (None for ARKit curves).

        Raises
        ------
        DataError
            If the motion has no point channels the canonical mesh can carry.
        """
        from animegraph.face.render import deformer_for

        if self.arkit:
            return None
        with self._lock:
            if self._deformer is None:
                deformer = deformer_for(self.names)
                if deformer is None:
                    raise DataError("this database's motion is curves without geometry (not "
                                    "ARKit blendshapes): there is no face to show it on")
                self._deformer = deformer
        return self._deformer

    def animation(self, motion: np.ndarray, fps: float) -> FaceAnimation:
        """``motion`` (n_frames, n_channels) at ``fps`` on the canonical face, at
        :data:`PAGE_FPS`."""
        values = Motion(values=np.asarray(motion, dtype=np.float64), names=self.names, fps=fps)
        if self.arkit:
            return arkit_animation(values, fps=PAGE_FPS)
        return animate(values, self.deformer(), fps=PAGE_FPS)


def mesh_json(mesh: Mesh) -> dict:
    """The mesh as the page builds it: rest vertices (mm), triangles in three groups
    (skin, the mouth's inside, the eye openings), the two inner-lip vertices whose
    distance the page reports as the mouth opening, and the eyes' corner vertices."""
    special = np.zeros(len(mesh.faces), dtype=np.int8)
    special[mesh.mouth] = 1
    special[mesh.eyes] = 2
    middle = len(facemesh.UPPER_LIP_INNER) // 2
    return {
        "n_vertices": int(mesh.n_vertices),
        "vertices": np.round(mesh.vertices, 3).ravel().tolist(),
        "skin": mesh.faces[special == 0].ravel().tolist(),
        "mouth": mesh.faces[special == 1].ravel().tolist(),
        "eyes": mesh.faces[special == 2].ravel().tolist(),
        "lip_pair": [facemesh.UPPER_LIP_INNER[middle], facemesh.LOWER_LIP_INNER[middle]],
        # Each eye's corners and lids (outer, inner, upper, lower): the page seats an
        # eyeball behind each opening and moves it with them. Only the canonical mesh
        # has them (the vertices are its own).
        "eye_corners": ([[eye[k] for k in ("outer", "inner", "upper", "lower")]
                         for eye in (facemesh.EYE_R, facemesh.EYE_L)]
                        if mesh.canonical_topology else []),
    }


def pack(animation: FaceAnimation, header: dict) -> bytes:
    """One binary message: header length, JSON header (with ``fps``, ``n_frames``,
    ``n_vertices`` added), padding, float32 vertices (n_frames, n_vertices, 3)."""
    vertices = np.ascontiguousarray(animation.vertices, dtype="<f4")
    head = json.dumps({**header, "fps": animation.fps, "n_frames": int(animation.n_frames),
                       "n_vertices": int(vertices.shape[1])}, allow_nan=False).encode()
    head += b" " * (-(4 + len(head)) % 4)  # the float32 block starts 4-byte aligned
    return struct.pack("<I", len(head)) + head + vertices.tobytes()
