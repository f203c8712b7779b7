"""Point motion (markers, landmarks) as ARKit's 52 blendshape weights, for Live Link.

Live Link Face carries 52 ARKit blendshape weights, not points. A marker or landmark
database's frames are mapped onto them by the geometry the project already gives each
shape (:func:`animegraph.face.arkit.arkit_shapes`: every shape's displacement, mm, of
every vertex of the canonical face mesh at weight 1) and the vertex each point sits on
(:func:`animegraph.face.mesh.default_marker_map`: the synthetic corpus' markers, or
``lm<i>`` landmarks):

1. a frame is taken into the database's head-stabilised space
   (:meth:`animegraph.synthesis.Model.to_local`) and its displacement from the database's
   rest pose (:func:`animegraph.live.stream.rest_pose`) is taken, point by point;
2. the database's units are brought to the mesh's millimetres by one scale: the ratio of
   the RMS spread of the canonical mesh's vertices under the points to that of the rest
   pose's points (both centred);
3. the weights are the ridge least-squares fit of the 52 shapes' displacements at those
   vertices to the frame's (:data:`RIDGE` relative to the mean squared norm of the shape
   columns), clipped to [0, 1]: one precomputed (52, 3 n_points) matrix, so a frame costs
   one product. The clip, rather than a bounded solve, keeps it that cheap; shapes that
   move none of the points (gaze, ``tongueOut``) come out 0 by the ridge.

Head and eye rotations are sent as 0. What this is not: a fit to the actor's own face
(the shapes are a generic face's, :mod:`animegraph.face.arkit`), nor a check that a
MetaHuman rig reads the weights as the points meant; it is measured only by
``tests/test_live.py`` (a pure shape's displacement maps back to that shape).
"""

from __future__ import annotations

import numpy as np

from db.errors import DataError
from ingest.formats.livelink import ARKIT_BLENDSHAPES, ARKIT_CHANNELS

#: Ridge penalty, relative to the mean squared norm of a shape's displacement column.
RIDGE = 1e-3


class PointsToArkit:
    """Maps frames of a point database (n_channels,) to ARKit channel values (61,), in
    :data:`ingest.formats.livelink.ARKIT_CHANNELS` order (see the module docstring).

    Raises
    ------
    DataError
        If the database's points are not ones the canonical mesh knows.
    """

    names = ARKIT_CHANNELS

    def __init__(self, model) -> None:
        from animegraph.face.arkit import arkit_shapes
        from animegraph.face.mesh import canonical_mesh, default_marker_map
        from animegraph.live.stream import rest_pose
        from animegraph.motion.files import point_labels

        labels = point_labels(model.names)
        if not labels:
            raise DataError("Live Link needs ARKit blendshapes or points on a face; this "
                            "database has neither")
        try:
            markers = default_marker_map(labels)
        except DataError as exc:
            raise DataError(f"no mapping of this database's points to ARKit's shapes: "
                            f"{exc}") from None
        index = {n: i for i, n in enumerate(model.names)}
        self.columns = np.array([index[f"{lab}.{a}"] for lab in labels for a in "xyz"])
        self.model = model
        self.rest = model.to_local(rest_pose(model)[None])[0][self.columns]
        mesh_points = canonical_mesh().vertices[markers.vertices]
        rest_points = self.rest.reshape(-1, 3)
        spread = np.sqrt(np.mean((rest_points - rest_points.mean(0)) ** 2))
        self.scale = float(np.sqrt(np.mean((mesh_points - mesh_points.mean(0)) ** 2))
                           / spread) if spread > 0 else 1.0
        basis = arkit_shapes()[:, markers.vertices, :].reshape(len(ARKIT_BLENDSHAPES), -1).T
        gram = basis.T @ basis
        lam = RIDGE * float(np.mean(np.diag(gram)))
        self.solve = np.linalg.solve(gram + lam * np.eye(len(gram)), basis.T)  # (52, 3n)

    def weights(self, frames: np.ndarray) -> np.ndarray:
        """The 52 blendshape weights of frames (n, n_channels), shape (n, 52)."""
        local = self.model.to_local(np.atleast_2d(frames))[:, self.columns]
        return np.clip((self.scale * (local - self.rest)) @ self.solve.T, 0.0, 1.0)

    def __call__(self, frame: np.ndarray) -> np.ndarray:
        """One frame (n_channels,) as the 61 ARKit channels (rotations 0)."""
        out = np.zeros(len(ARKIT_CHANNELS))
        out[:len(ARKIT_BLENDSHAPES)] = self.weights(frame)[0]
        return out
