"""The canonical face mesh shipped with the package, and named regions of it.

The mesh is mediapipe's canonical face model (468 vertices, Apache-2.0; the licence
sits beside it in ``ingest/assets``). Its vertex order is the landmark order of
mediapipe's face-mesh tracker, so landmark tracks from video map onto it one to one,
and the synthetic corpus places its markers on its vertices.

Coordinates are converted to millimetres on load: x towards the subject's left,
y up, z out of the face (towards the camera).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from importlib import resources
from pathlib import Path

import numpy as np

from db.errors import DataError

#: The mesh file is in centimetres; everything in the project is in millimetres.
MESH_UNITS_TO_MM = 10.0

#: Landmark indices of named places on the canonical mesh (mediapipe numbering).
#: "_r" is the subject's right (negative x), "_l" the subject's left.
LIP_CORNERS = (61, 291)
UPPER_LIP_OUTER = (185, 40, 39, 37, 0, 267, 269, 270, 409)
LOWER_LIP_OUTER = (146, 91, 181, 84, 17, 314, 405, 321, 375)
UPPER_LIP_INNER = (191, 80, 81, 82, 13, 312, 311, 310, 415)
LOWER_LIP_INNER = (95, 88, 178, 87, 14, 317, 402, 318, 324)
#: Inner-lip midpoints: their distance is the mouth opening.
UPPER_LIP_MID, LOWER_LIP_MID = 13, 14
EYE_R = {"upper": 159, "lower": 145, "outer": 33, "inner": 133}
#: The lid margins around each eye opening (mediapipe's eye contours), right then left:
#: the triangles between them fill the opening (the mesh has no eyeballs).
EYE_RING_R = (33, 7, 163, 144, 145, 153, 154, 155, 133, 173, 157, 158, 159, 160, 161, 246)
EYE_RING_L = (263, 249, 390, 373, 374, 380, 381, 382, 362, 398, 384, 385, 386, 387, 388, 466)
EYE_L = {"upper": 386, "lower": 374, "outer": 263, "inner": 362}


@dataclass(frozen=True)
class FaceMesh:
    """A triangle mesh of a face in millimetres.

    Attributes
    ----------
    vertices : np.ndarray, shape (n_vertices, 3)
        Rest positions in millimetres.
    faces : np.ndarray, shape (n_faces, 3)
        Vertex indices of each triangle.
    """

    vertices: np.ndarray
    faces: np.ndarray


def canonical_mesh_path() -> Path:
    """Return the path of the canonical face mesh OBJ shipped with the package."""
    return Path(str(resources.files("ingest") / "assets" / "canonical_face_model.obj"))


@lru_cache(maxsize=1)
def load_canonical_face() -> FaceMesh:
    """Load the canonical face mesh (cached), in millimetres.

    Returns
    -------
    FaceMesh
        468 vertices and 898 triangles.
    """
    return _read_obj(canonical_mesh_path())


def _read_obj(path: Path) -> FaceMesh:
    # A tiny reader for the vertex and face lines is all this mesh needs; reading it
    # without trimesh keeps the corpus generator's start-up light in worker processes.
    vertices, faces = [], []
    try:
        text = path.read_text()
    except OSError as exc:
        raise DataError(f"cannot read mesh {path}: {exc.strerror}") from exc
    for line in text.splitlines():
        if line.startswith("v "):
            vertices.append([float(v) for v in line.split()[1:4]])
        elif line.startswith("f "):
            faces.append([int(tok.split("/")[0]) - 1 for tok in line.split()[1:4]])
    if not vertices or not faces:
        raise DataError(f"mesh {path} has no vertices or no faces")
    verts = np.asarray(vertices, dtype=np.float64) * MESH_UNITS_TO_MM
    verts.setflags(write=False)
    tris = np.asarray(faces, dtype=np.int64)
    tris.setflags(write=False)
    return FaceMesh(vertices=verts, faces=tris)
