"""Point motion carried onto a face mesh: vertex trajectories at a render rate (§7).

:func:`animate` turns marker or landmark motion into a :class:`FaceAnimation` with the
mesh deformer of :mod:`animegraph.face.mesh`; :mod:`.render` draws it and :mod:`.gltf`
stores it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from animegraph.face.mesh import Deformer, Mesh, motion_points
from animegraph.motion.files import Motion
from db.errors import DataError
from ingest.motion import fill_gaps

#: Bytes of vertex positions an animation may hold (its head-frame and world copies,
#: float64; the whole animation is held at once, the peak about 1.8 times these). A
#: scanned head of 10^6 vertices would take 8.6 GB a copy for 12 s at 30 fps, and the
#: kernel kills the process instead of a one-line error (measured: 115,233 vertices, 120
#: frames, 1.2 GB peak); the canonical face (468 vertices) renders 3 hours at 30 fps.
MAX_ANIMATION_BYTES = 8 << 30


@dataclass(frozen=True, eq=False)
class FaceAnimation:
    """Vertex trajectories of a mesh, sampled at the render rate.

    Attributes
    ----------
    vertices : np.ndarray, shape (n_frames, n_vertices, 3)
        World positions (motion units, mm).
    local : np.ndarray, shape (n_frames, n_vertices, 3)
        The same in the head's frame (rigid head motion removed).
    rotation : np.ndarray, shape (n_frames, 3, 3)
    translation : np.ndarray, shape (n_frames, 3)
        ``vertices = rotation @ local + translation`` frame by frame.
    displacement : np.ndarray, shape (n_frames, n_markers, 3)
        Marker displacements from the rest frame, in the head's frame.
    operator : np.ndarray, shape (n_vertices, n_markers)
        ``local = mesh.vertices + operator @ displacement``.
    fps : float
    """

    mesh: Mesh
    vertices: np.ndarray
    local: np.ndarray
    displacement: np.ndarray
    operator: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    fps: float

    @property
    def n_frames(self) -> int:
        return len(self.vertices)


def resampled_length(n_frames: int, fps: float, target_fps: float) -> int:
    """Frames :func:`resample` makes of ``n_frames`` at ``fps``: the same duration."""
    return max(1, int(np.floor(n_frames * target_fps / fps + 1e-9)))


def resample(values: np.ndarray, fps: float, target_fps: float) -> np.ndarray:
    """Values (n_frames, ...) at ``target_fps``, linearly interpolated, same duration."""
    n_out = resampled_length(len(values), fps, target_fps)
    t = np.arange(n_out) / target_fps * fps
    i0 = np.clip(np.floor(t).astype(int), 0, len(values) - 1)
    i1 = np.minimum(i0 + 1, len(values) - 1)
    frac = (t - i0).reshape((-1,) + (1,) * (values.ndim - 1))
    return values[i0] * (1 - frac) + values[i1] * frac


def animate(motion: Motion, deformer: Deformer, *, fps: float | None = None,
            rigid: bool = True) -> FaceAnimation:
    """Carry point motion onto the deformer's mesh, at ``fps`` (default the motion's).

    Raises
    ------
    DataError
        If the motion lacks markers of the map (one line naming them), or its vertex
        positions would take more than :data:`MAX_ANIMATION_BYTES`.
    """
    fps = motion.fps if fps is None else float(fps)
    n_out = resampled_length(len(motion.values), motion.fps, fps)
    need = 2 * n_out * deformer.mesh.n_vertices * 3 * 8
    if need > MAX_ANIMATION_BYTES:
        raise DataError(f"{n_out} frames of the {deformer.mesh.n_vertices}-vertex mesh "
                        f"{deformer.mesh.name} would take {need / 2**30:.1f} GiB (at most "
                        f"{MAX_ANIMATION_BYTES / 2**30:g}): decimate the mesh or render the "
                        f"motion in parts")
    points = motion_points(motion.names, motion.values, deformer.markers.labels)
    if np.isnan(points).any():
        filled, _ = fill_gaps(points.reshape(len(points), -1))
        points = filled.reshape(points.shape)
    points = resample(points, motion.fps, fps)
    local, rotation, translation = deformer.local_frames(points, rigid=rigid)
    n = len(points)
    if rotation is None:
        rotation = np.tile(np.eye(3), (n, 1, 1))
        translation = np.zeros((n, 3))
    displacement = local - deformer.rest[None]
    verts_local = deformer.mesh.vertices[None] + np.matmul(deformer.operator, displacement)
    world = np.matmul(verts_local, np.transpose(rotation, (0, 2, 1))) + translation[:, None]
    return FaceAnimation(mesh=deformer.mesh, vertices=world, local=verts_local,
                         displacement=displacement, operator=deformer.operator,
                         rotation=rotation, translation=translation, fps=fps)


def animation_bounds(animation: FaceAnimation) -> np.ndarray:
    """(2, 3) lowest and highest coordinates over the animation."""
    v = animation.vertices
    return np.stack([v.min(axis=(0, 1)), v.max(axis=(0, 1))])
