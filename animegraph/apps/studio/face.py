"""The face the studio's page draws: the canonical mesh, and motion carried onto it by the
project's own deformation (:func:`animegraph.face.animation.animate` for markers and
landmarks, :func:`animegraph.face.arkit.arkit_animation` for ARKit curves), exactly as
``animegraph render`` does; the page only draws the vertices it is sent.

An animation goes to the page as one binary message (:func:`pack`): a little-endian
``uint32`` length, a JSON header (frame rate, frame count, phones, and ``blocks``: the
name and shape of each array that follows), zero padding to a multiple of 4 bytes, then
the arrays as ``float32``, one after the other:

* ``vertices`` ``(n_frames, n_vertices, 3)``: world positions, for marker and landmark
  databases (5.6 kB a frame for the canonical face's 468 vertices);
* ``arkit`` ``(n_frames, 52)``: ARKit blendshape weights, in
  :data:`ingest.formats.livelink.ARKIT_BLENDSHAPES` order. An iPhone database's own
  curves (the page applies them to the canonical mesh as morph targets,
  :func:`arkit_shapes_bytes`, instead of receiving vertices: 0.2 kB a frame); for a
  point database on the canonical mesh, the weights fitted to its motion
  (:func:`fit_arkit`), to drive the user's own glTF head;
* ``rigid`` ``(n_frames, 12)``: the head's rotation (row-major 3 x 3) and translation
  (mm), with ``arkit`` for an iPhone database: ``world = R @ local + t``.
"""

from __future__ import annotations

import json
import struct
import threading
from collections.abc import Sequence
from functools import lru_cache

import numpy as np

from animegraph.face.animation import FaceAnimation, animate
from animegraph.face.arkit import arkit_animation, arkit_shapes, arkit_weights
from animegraph.face.mesh import Mesh, canonical_mesh
from animegraph.motion.files import Motion
from db.errors import DataError
from ingest import facemesh
from ingest.formats.livelink import ARKIT_BLENDSHAPES, is_arkit

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

    def blocks(self, motion: np.ndarray, fps: float) -> dict[str, np.ndarray]:
        """The arrays the page gets for ``motion`` (see the module docstring)."""
        if self.arkit:
            values = Motion(values=np.asarray(motion, dtype=np.float64), names=self.names,
                            fps=fps)
            animation = arkit_animation(values, fps=PAGE_FPS)
            rigid = np.concatenate([animation.rotation.reshape(-1, 9),
                                    animation.translation], axis=1)
            return {"arkit": arkit_weights(values, PAGE_FPS), "rigid": rigid}
        animation = self.animation(motion, fps)
        out = {"vertices": animation.vertices}
        if animation.mesh.canonical_topology:
            out["arkit"] = fit_arkit(animation.local - animation.mesh.vertices[None])
        return out


def fit_arkit(displacement: np.ndarray) -> np.ndarray:
    """ARKit weights (n_frames, 52) whose shapes (:func:`animegraph.face.arkit.arkit_shapes`)
    best give the canonical mesh's ``displacement`` (n_frames, 468, 3) in the head's frame:
    the ridge least squares of :mod:`animegraph.live.arkit_map` over every vertex, clipped
    to [0, 1]. It drives a glTF head's ARKit morph targets from marker motion; like the
    Live Link mapping, it is a generic face's reading of the points, not a fit to the actor."""
    solve = arkit_fit_matrix()
    n = len(displacement)
    return np.clip(displacement.reshape(n, -1) @ solve.T, 0.0, 1.0)


@lru_cache(maxsize=1)
def arkit_fit_matrix() -> np.ndarray:
    from animegraph.live.arkit_map import RIDGE

    basis = arkit_shapes().reshape(len(ARKIT_BLENDSHAPES), -1).T  # (3 * 468, 52)
    gram = basis.T @ basis
    lam = RIDGE * float(np.mean(np.diag(gram)))
    return np.linalg.solve(gram + lam * np.eye(len(gram)), basis.T)  # (52, 3 * 468)


def arkit_shapes_bytes() -> bytes:
    """The 52 ARKit shapes' displacements (52, 468, 3), float32 little-endian: the
    morph targets the page applies to the canonical mesh for an iPhone database."""
    return np.ascontiguousarray(arkit_shapes(), dtype="<f4").tobytes()


def mesh_json(mesh: Mesh, arkit: bool = False) -> dict:
    """The mesh as the page builds it: rest vertices (mm), triangles in three groups
    (skin, the mouth's inside, the eye openings), the two inner-lip vertices whose
    distance the page reports as the mouth opening, the eyes' corner vertices, the inner
    lips' contours (corner to corner: the page seats teeth behind them), whether the
    page morphs the mesh by ARKit weights itself (``arkit``) and the ARKit names."""
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
        # Corner, the inner contour, corner: mediapipe's inner lip corners are 78 and 308.
        "lips": ([[78, *facemesh.UPPER_LIP_INNER, 308], [78, *facemesh.LOWER_LIP_INNER, 308]]
                 if mesh.canonical_topology else []),
        "arkit": bool(arkit),
        "arkit_names": list(ARKIT_BLENDSHAPES),
    }


def pack(blocks: dict[str, np.ndarray], n_vertices: int, header: dict) -> bytes:
    """One binary message: header length, JSON header (with ``fps``, ``n_frames``,
    ``n_vertices`` and ``blocks`` added), padding, the blocks as float32."""
    arrays = {name: np.ascontiguousarray(a, dtype="<f4") for name, a in blocks.items()}
    n_frames = len(next(iter(arrays.values())))
    head = json.dumps({**header, "fps": PAGE_FPS, "n_frames": n_frames,
                       "n_vertices": int(n_vertices),
                       "blocks": [[name, list(a.shape)] for name, a in arrays.items()]},
                      allow_nan=False).encode()
    head += b" " * (-(4 + len(head)) % 4)  # the float32 blocks start 4-byte aligned
    return struct.pack("<I", len(head)) + head + b"".join(a.tobytes() for a in arrays.values())
