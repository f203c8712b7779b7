"""Marker motion on a face mesh by scattered-data interpolation (Cao et al. 2005, §7).

Each marker sits on a vertex of the mesh. One frame of the motion (the *rest frame*,
the expression the mesh was modelled in) gives the "mapping at rest"; every other frame
is a displacement of the markers from it. Radial basis functions extend the
displacement from the markers to every vertex. Smooth interpolation would drag the
upper and lower lips together, so, as in the paper, the face is split into regions that
move independently — lower jaw, upper jaw, right eyelid, left eyelid, upper face
(forehead and brows) — each interpolating only its own markers, and the regions are
blended smoothly at their borders.

* **Interpolation**: per region, a polyharmonic RBF (``scipy.interpolate.RBFInterpolator``,
  kernel ``r`` in 3-D with a linear polynomial) through the region's markers and the
  rigid *anchor* markers (head group, which do not move in the head's frame). The
  interpolant is linear in the marker displacements, so it is precomputed once as a
  matrix: interpolating the identity gives each vertex's weights on each marker.
* **Regions and blending**: each vertex's weight on a region falls from 1 to 0 as its
  geodesic distance (along mesh edges, Dijkstra) to the region's nearest marker exceeds
  the nearest region's by up to ``band_mm``. The triangles that close the mouth are
  left out of the edge graph, so the upper and lower lips, a millimetre apart in space,
  are far apart along the surface and follow their own jaws.
* **Rigid head motion**: with three or more anchor markers, each frame's rigid head
  pose is fitted (Kabsch) and removed before interpolation and put back afterwards, so
  a head turn moves the whole mesh rigidly instead of bending it.

The result is one ``(n_vertices, n_markers)`` operator: a frame costs one matrix
product.
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.interpolate import RBFInterpolator
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from db.errors import DataError, ParameterError
from ingest import facemesh
from ingest.formats.text import read_csv_records
from ingest.motion import rigid_fit

logger = logging.getLogger(__name__)

#: The paper's five regions (§7), in this order in every array.
REGIONS = ("lower_jaw", "upper_jaw", "eyelid_r", "eyelid_l", "upper_face")
#: Region name of rigid markers: fixed in the head's frame, in every region's interpolant.
ANCHOR = "anchor"
#: Width (mm of geodesic distance) of the blend between neighbouring regions.
BAND_MM = 6.0
#: Most places a mesh file (a glTF scene) may draw its pieces at, and most vertices it
#: may make: trimesh walks every place's chain of parents, so a 200 KB glTF of 5,000
#: nested nodes took minutes (1,000: 5 s), and 10,000 nodes drawing one 100,000-vertex
#: piece would make 10^9 vertices. A face has a few pieces (head, eyes, teeth).
MAX_MESH_INSTANCES = 256
MAX_MESH_VERTICES = 5_000_000
#: Inner-lip ring of the canonical mesh, right corner to left corner.
_INNER_UPPER = (78,) + facemesh.UPPER_LIP_INNER + (308,)
_INNER_LOWER = (78,) + facemesh.LOWER_LIP_INNER + (308,)


@dataclass(frozen=True)
class Mesh:
    """A triangle mesh.

    Attributes
    ----------
    vertices : np.ndarray, shape (n_vertices, 3)
        Rest positions (the motion's units, millimetres for the project's data).
    faces : np.ndarray, shape (n_faces, 3)
        Vertex indices of each triangle, counter-clockwise seen from outside.
    mouth : np.ndarray, shape (n_mouth,)
        Indices into ``faces`` of the triangles that close the mouth (drawn as the
        mouth's inside, left out of the region graph). Empty for a mesh with an open
        mouth.
    name : str
        Where it came from.
    eyes : np.ndarray, shape (n_eyes,)
        Indices into ``faces`` of the triangles that fill the eye openings (drawn dark,
        so lids opening and closing show). Empty if unknown.
    canonical_topology : bool
        Whether its triangles are the canonical mesh's (vertex ``i`` is the canonical
        vertex ``i``): its mouth, eyes and markers' regions are then known.
    """

    vertices: np.ndarray
    faces: np.ndarray
    mouth: np.ndarray
    name: str
    eyes: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=np.int64))
    canonical_topology: bool = False

    @property
    def n_vertices(self) -> int:
        return len(self.vertices)


@dataclass(frozen=True)
class MarkerMap:
    """Which mesh vertex each marker sits on, and which region it drives.

    Attributes
    ----------
    labels : tuple of str, length n_markers
    vertices : np.ndarray of int, shape (n_markers,)
    regions : tuple of tuple of str, length n_markers
        Regions of :data:`REGIONS` each marker drives (several for a marker on a border,
        e.g. a lip corner), or ``("anchor",)`` for a rigid marker.
    """

    labels: tuple[str, ...]
    vertices: np.ndarray
    regions: tuple[tuple[str, ...], ...]

    @property
    def n_markers(self) -> int:
        return len(self.labels)

    @property
    def anchors(self) -> np.ndarray:
        """Indices of the rigid markers."""
        return np.array([i for i, r in enumerate(self.regions) if r == (ANCHOR,)], dtype=int)


def canonical_mesh() -> Mesh:
    """The canonical face mesh shipped with the package (mm), mouth triangles marked."""
    face = facemesh.load_canonical_face()
    ring = set(_INNER_UPPER) | set(_INNER_LOWER)
    mouth = np.array([i for i, tri in enumerate(face.faces) if set(tri.tolist()) <= ring])
    lids = (set(facemesh.EYE_RING_R), set(facemesh.EYE_RING_L))
    eyes = np.array([i for i, tri in enumerate(face.faces)
                     if any(set(tri.tolist()) <= ring for ring in lids)], dtype=np.int64)
    return Mesh(vertices=np.asarray(face.vertices, dtype=np.float64),
                faces=np.asarray(face.faces, dtype=np.int64), mouth=mouth,
                name="canonical face mesh", eyes=eyes, canonical_topology=True)


def load_mesh(path: str | os.PathLike) -> Mesh:
    """Read any mesh trimesh reads (OBJ, PLY, STL, OFF, glTF ...), as triangles.

    The mesh is taken as it is (no merging or reordering of vertices, so a marker map's
    vertex numbers stay valid) and is assumed to have its mouth open (no triangles
    across the lips) — the canonical mesh's closing triangles are known and handled.

    Raises
    ------
    DataError
        If the file is missing, trimesh cannot read a triangle mesh from it, a coordinate
        is not finite or a face names a vertex the mesh does not have.
    """
    import trimesh

    path = Path(path)
    if not path.is_file():
        raise DataError(f"mesh {path} does not exist")
    try:
        scene = trimesh.load_scene(path, process=False)
        pieces = scene.graph.geometry_nodes  # piece -> the nodes drawing it
        places = sum(len(nodes) for nodes in pieces.values())
        made = sum(len(getattr(scene.geometry.get(name), "vertices", ())) * len(nodes)
                   for name, nodes in pieces.items())
        if places > MAX_MESH_INSTANCES or made > MAX_MESH_VERTICES:
            raise DataError(f"mesh {path} draws its pieces at {places} places into {made:,} "
                            f"vertices (at most {MAX_MESH_INSTANCES} and "
                            f"{MAX_MESH_VERTICES:,})")
        loaded = scene.to_mesh()
    except DataError:
        raise
    except Exception as exc:  # trimesh raises many kinds on a bad file
        raise DataError(f"cannot read mesh {path}: {_first_line(exc)}") from None
    vertices = np.asarray(getattr(loaded, "vertices", np.empty((0, 3))), dtype=np.float64)
    faces = np.asarray(getattr(loaded, "faces", np.empty((0, 3))), dtype=np.int64)
    if vertices.ndim != 2 or len(vertices) < 4 or faces.ndim != 2 or len(faces) < 1:
        raise DataError(f"cannot read mesh {path}: no triangles in it")
    if not np.isfinite(vertices).all():
        raise DataError(f"mesh {path} has non-finite vertex coordinates")
    # PLY faces come as written: a vertex past the end would fail deep in the render, a
    # negative one would silently take a vertex from the end
    outside = (faces < 0) | (faces >= len(vertices))
    if outside.any():
        row = int(np.flatnonzero(outside.any(axis=1))[0])
        raise DataError(f"mesh {path}: face {row} names vertex "
                        f"{int(faces[row][outside[row]][0])}, but it has vertices "
                        f"0-{len(vertices) - 1}")
    canonical = canonical_mesh()
    if np.array_equal(faces, canonical.faces):
        # The canonical mesh's triangles (the shipped file itself, or a face sculpted on
        # it): its closing mouth triangles, eyelids and marker regions are known.
        return Mesh(vertices=vertices, faces=faces, mouth=canonical.mouth,
                    name=path.name, eyes=canonical.eyes, canonical_topology=True)
    return Mesh(vertices=vertices, faces=faces, mouth=np.empty(0, dtype=np.int64),
                name=path.name)


def _first_line(exc: Exception) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def canonical_regions(points: np.ndarray, groups=None) -> tuple[tuple[str, ...], ...]:
    """Regions of points on the canonical face, from where they are.

    Parameters
    ----------
    points : np.ndarray, shape (n, 3)
        Rest positions on the canonical mesh (mm).
    groups : sequence of str, optional
        Motion group of each point; ``"head"`` makes it an anchor.

    Returns
    -------
    tuple of tuple of str
        Eyelid regions inside an ellipse around each eye (the eye corners also upper
        face), upper face above the eyes, and below them the upper jaw above the line
        between the lips and the lower jaw under it (the lip corners both).
    """
    v = facemesh.load_canonical_face().vertices
    up, low = v[list(_INNER_UPPER)], v[list(_INNER_LOWER)]
    line_x = 0.5 * (up[:, 0] + low[:, 0])
    line_y = 0.5 * (up[:, 1] + low[:, 1])
    corner_x = np.abs(v[list(facemesh.LIP_CORNERS), 0]).mean()
    eyes = {}
    for name, eye in (("eyelid_r", facemesh.EYE_R), ("eyelid_l", facemesh.EYE_L)):
        centre = 0.5 * (v[eye["inner"]] + v[eye["outer"]])
        half = 0.5 * abs(v[eye["outer"], 0] - v[eye["inner"], 0])
        eyes[name] = (centre, half)
    brow_y = max(v[facemesh.EYE_R["upper"], 1], v[facemesh.EYE_L["upper"], 1]) + 3.0
    out = []
    for i, (x, y, _z) in enumerate(np.asarray(points, dtype=np.float64)):
        if groups is not None and groups[i] == "head":
            out.append((ANCHOR,))
            continue
        regions = ()
        for name, (centre, half) in eyes.items():
            r2 = ((x - centre[0]) / (half + 1.0)) ** 2 + ((y - centre[1]) / 6.0) ** 2
            if r2 <= 1.0:
                regions = (name, "upper_face") if r2 > 0.8 else (name,)
        if not regions:
            if y >= brow_y:
                regions = ("upper_face",)
            else:
                mouth_y = float(np.interp(x, line_x, line_y))
                if abs(abs(x) - corner_x) < 2.5 and abs(y - mouth_y) < 1.5:
                    regions = ("lower_jaw", "upper_jaw")
                elif y < mouth_y:
                    regions = ("lower_jaw",)
                else:
                    regions = ("upper_jaw",)
        out.append(regions)
    return tuple(out)


def default_marker_map(labels) -> MarkerMap:
    """The marker map for motion on the canonical mesh, from its marker labels.

    Markers of the synthetic corpus (:data:`ingest.corpus.face.MARKERS`) and landmarks
    ``lm<i>`` (vertex ``i``, mediapipe order) are known; regions come from
    :func:`canonical_regions`.

    Raises
    ------
    DataError
        If the labels are neither.
    """
    from ingest.corpus.face import MARKERS

    labels = tuple(labels)
    known = {name: (vertex, group) for name, vertex, group in MARKERS}
    if labels and all(lab in known for lab in labels):
        chosen = [(lab, *known[lab]) for lab in labels]
    elif labels and all(_landmark_vertex(lab) is not None for lab in labels):
        chosen = [(lab, _landmark_vertex(lab), "other") for lab in labels]
    else:
        unknown = [lab for lab in labels if lab not in known and _landmark_vertex(lab) is None]
        raise DataError(f"the motion's markers are not the corpus' markers or lm<i> landmarks "
                        f"({', '.join(unknown[:4])}{' ...' if len(unknown) > 4 else ''}): "
                        "give --mesh and --marker-map")
    vertices = np.array([v for _, v, _ in chosen], dtype=np.int64)
    rest = facemesh.load_canonical_face().vertices[vertices]
    regions = canonical_regions(rest, [g for _, _, g in chosen])
    return MarkerMap(labels=labels, vertices=vertices, regions=regions)


def _landmark_vertex(label: str) -> int | None:
    if label.startswith("lm") and label[2:].isdigit() and int(label[2:]) < 468:
        return int(label[2:])
    return None


def read_marker_map(path: str | os.PathLike, mesh: Mesh) -> MarkerMap:
    """Read a marker map CSV: ``label,vertex[,region][,group]``.

    ``region`` is one of :data:`REGIONS`, several joined by ``|`` (a marker on a border),
    or ``anchor`` (rigid); without a ``region`` column, a ``group`` column of ``head``
    marks anchors and the regions are read off the canonical face's geometry, which only
    makes sense for the canonical mesh. The synthetic corpus' ``markers.csv`` is such a
    file.

    Raises
    ------
    DataError
        On a malformed file, a vertex the mesh does not have, an unknown region, a label
        listed twice, or a custom mesh without a ``region`` column.
    """
    path = Path(path)
    fields, rows = read_csv_records(path, "marker map", ("label", "vertex"))
    labels, vertices, regions, groups = [], [], [], []
    for where, row in rows:
        label = row["label"]
        if not label:
            continue
        if label in labels:
            raise DataError(f"{where}: marker {label!r} listed twice")
        try:
            vertex = int(row["vertex"])
        except ValueError:
            raise DataError(f"{where}: vertex of {label!r} is not a whole number: "
                            f"{row['vertex']!r}") from None
        if not 0 <= vertex < mesh.n_vertices:
            raise DataError(f"{where}: marker {label!r} names vertex {vertex}, but the "
                            f"mesh ({mesh.name}) has vertices 0-{mesh.n_vertices - 1}")
        if "region" in fields:
            names = tuple(r.strip() for r in row["region"].split("|") if r.strip())
            bad = [r for r in names if r not in REGIONS + (ANCHOR,)]
            if not names or bad or (ANCHOR in names and len(names) > 1):
                raise DataError(f"{where}: region of {label!r} must be one of "
                                f"{', '.join(REGIONS)} (several joined by '|') or "
                                f"{ANCHOR}, got {row['region']!r}")
            regions.append(names)
        labels.append(label)
        vertices.append(vertex)
        groups.append(row.get("group", ""))
    if not labels:
        raise DataError(f"marker map {path} lists no markers")
    vertices = np.asarray(vertices, dtype=np.int64)
    if "region" not in fields:
        if not mesh.canonical_topology:
            raise DataError(f"marker map {path} has no 'region' column: for a mesh other than "
                            f"the canonical one, name each marker's region "
                            f"({', '.join(REGIONS)} or {ANCHOR})")
        # regions by where each vertex sits on the canonical face, in any sculpt of it
        regions = list(canonical_regions(canonical_mesh().vertices[vertices], groups))
    return MarkerMap(labels=tuple(labels), vertices=vertices, regions=tuple(regions))


@dataclass(frozen=True, eq=False)
class Deformer:
    """Precomputed §7 deformation of one mesh by one marker set.

    Build with :meth:`build`; :meth:`deform` turns marker trajectories into vertex
    trajectories.

    Attributes
    ----------
    mesh : Mesh
    markers : MarkerMap
    rest : np.ndarray, shape (n_markers, 3)
        Marker positions of the rest frame, in the motion's coordinates.
    operator : np.ndarray, shape (n_vertices, n_markers)
        Vertex displacement = ``operator @`` marker displacement (per axis).
    region_weights : np.ndarray, shape (n_vertices, n_regions)
        Blend weights of :data:`REGIONS` (rows sum to 1).
    """

    mesh: Mesh
    markers: MarkerMap
    rest: np.ndarray
    operator: np.ndarray
    region_weights: np.ndarray

    @classmethod
    def build(cls, mesh: Mesh, markers: MarkerMap, rest: np.ndarray | None = None, *,
              band_mm: float = BAND_MM, regions: bool = True,
              kernel: str = "linear") -> Deformer:
        """Precompute the interpolation operator.

        Parameters
        ----------
        mesh, markers : Mesh, MarkerMap
        rest : np.ndarray, shape (n_markers, 3), optional
            The rest frame; default the mesh's own vertices under the markers.
        band_mm : float
            Width of the blend between regions (geodesic mm).
        regions : bool
            False: one interpolant through every marker (what the paper avoids; for
            comparison).
        kernel : str
            ``RBFInterpolator`` kernel; ``linear`` (``-r``, the 3-D polyharmonic spline).
        """
        if band_mm <= 0:
            raise ParameterError(f"band_mm must be > 0, got {band_mm}")
        verts = mesh.vertices
        at = verts[markers.vertices]
        rest = at.copy() if rest is None else np.asarray(rest, dtype=np.float64)
        if rest.shape != (markers.n_markers, 3):
            raise ParameterError(f"rest must have shape ({markers.n_markers}, 3), "
                                 f"got {rest.shape}")
        if len(np.unique(markers.vertices)) != markers.n_markers:
            raise DataError("two markers of the map sit on the same vertex")
        anchors = markers.anchors
        if not regions:
            weights = np.ones((mesh.n_vertices, 1))
            members = [np.arange(markers.n_markers)]
        else:
            owned = [np.array([i for i, r in enumerate(markers.regions) if name in r],
                              dtype=int) for name in REGIONS]
            used = [k for k, idx in enumerate(owned) if len(idx)]
            if not used:
                raise DataError("the marker map has no marker outside the rigid anchors")
            # Distances are to the markers a region owns alone: a marker shared by two
            # regions (a lip corner) is in both interpolants but draws no border.
            alone = [np.array([i for i in owned[k] if len(markers.regions[i]) == 1], dtype=int)
                     for k in used]
            sources = [a if len(a) else owned[k] for a, k in zip(alone, used, strict=True)]
            weights_used = _region_weights(mesh, markers.vertices, sources, band_mm)
            weights = np.zeros((mesh.n_vertices, len(REGIONS)))
            weights[:, used] = weights_used
            # A marker's vertex follows its own regions only: interpolation stays exact
            # there even where another region's marker is closer than the blend band.
            for vertex, names in zip(markers.vertices, markers.regions, strict=True):
                if names != (ANCHOR,):
                    weights[vertex] = 0.0
                    weights[vertex, [REGIONS.index(n) for n in names]] = 1.0 / len(names)
            members = [np.union1d(idx, anchors) if len(idx) else idx for idx in owned]
        operator = np.zeros((mesh.n_vertices, markers.n_markers))
        for k, idx in enumerate(members):
            if not len(idx):
                continue
            w = weights[:, k]
            rows = np.flatnonzero(w > 1e-9)
            basis = _rbf_basis(at[idx], verts[rows], kernel)
            operator[np.ix_(rows, idx)] += w[rows, None] * basis
        if not regions:
            weights = np.tile(np.eye(len(REGIONS))[4], (mesh.n_vertices, 1))
        return cls(mesh=mesh, markers=markers, rest=rest, operator=operator,
                   region_weights=weights)

    def deform(self, points: np.ndarray, *, rigid: bool = True) -> np.ndarray:
        """Vertex positions for marker positions.

        Parameters
        ----------
        points : np.ndarray, shape (n_frames, n_markers, 3)
            Marker positions in the order of :attr:`markers`, no NaN.
        rigid : bool
            Remove and restore the rigid head pose fitted to the anchors (needs >= 3).

        Returns
        -------
        np.ndarray, shape (n_frames, n_vertices, 3)
        """
        local, rotation, translation = self.local_frames(points, rigid=rigid)
        out = self.mesh.vertices[None] + np.matmul(self.operator, local - self.rest[None])
        if rotation is not None:
            out = np.matmul(out, np.transpose(rotation, (0, 2, 1))) + translation[:, None]
        return out

    def local_frames(self, points: np.ndarray, *, rigid: bool = True):
        """Markers in the head's frame, and the head pose (None without anchors).

        Returns
        -------
        local : np.ndarray, shape (n_frames, n_markers, 3)
        rotation : np.ndarray, shape (n_frames, 3, 3) or None
        translation : np.ndarray, shape (n_frames, 3) or None
            ``world = rotation @ local + translation``.
        """
        pts = np.asarray(points, dtype=np.float64)
        if pts.ndim != 3 or pts.shape[1:] != (self.markers.n_markers, 3):
            raise ParameterError(f"points must have shape (n_frames, {self.markers.n_markers}, "
                                 f"3), got {pts.shape}")
        if not np.isfinite(pts).all():
            raise DataError("the motion has missing (NaN) marker positions; fill them first")
        anchors = self.markers.anchors
        if not rigid or len(anchors) < 3:
            return pts, None, None
        # rigid_fit maps frame -> rest; its inverse puts the rest frame on the moving head.
        to_rest, shift = rigid_fit(pts[:, anchors], self.rest[anchors])
        local = np.matmul(pts, np.transpose(to_rest, (0, 2, 1))) + shift[:, None]
        rotation = np.transpose(to_rest, (0, 2, 1))
        translation = -np.einsum("fij,fj->fi", rotation, shift)
        return local, rotation, translation


def _rbf_basis(centres: np.ndarray, at: np.ndarray, kernel: str) -> np.ndarray:
    """Weights (len(at), len(centres)) of the RBF interpolant through ``centres``."""
    n = len(centres)
    if n == 1:
        return np.ones((len(at), 1))
    degree = 1 if n >= 4 else 0
    try:
        rbf = RBFInterpolator(centres, np.eye(n), kernel=kernel, degree=degree)
    except (ValueError, np.linalg.LinAlgError) as exc:
        # Coplanar or collinear markers make the linear term singular: drop it.
        logger.info("RBF with a linear term failed (%s); using a constant term", exc)
        rbf = RBFInterpolator(centres, np.eye(n), kernel=kernel, degree=0)
    return rbf(at)


def _region_weights(mesh: Mesh, vertices: np.ndarray, owned: list[np.ndarray],
                    band_mm: float) -> np.ndarray:
    """Blend weights (n_vertices, len(owned)) from geodesic distances to each region."""
    dist = np.stack([_geodesic(mesh, vertices[idx]) for idx in owned], axis=1)
    unreachable = ~np.isfinite(dist)
    if unreachable.all(axis=1).any():
        # Pieces of the mesh with no marker: fall back on straight-line distances.
        lost = np.flatnonzero(unreachable.all(axis=1))
        for k, idx in enumerate(owned):
            d = np.linalg.norm(mesh.vertices[lost, None] - mesh.vertices[vertices[idx]][None],
                               axis=-1)
            dist[lost, k] = d.min(axis=1)
    excess = dist - dist.min(axis=1, keepdims=True)
    t = np.clip(1.0 - excess / band_mm, 0.0, 1.0)
    w = t * t * (3.0 - 2.0 * t)
    w[~np.isfinite(w)] = 0.0
    return w / w.sum(axis=1, keepdims=True)


def _geodesic(mesh: Mesh, sources: np.ndarray) -> np.ndarray:
    """Shortest distance along mesh edges (mouth triangles excluded) to any source."""
    keep = np.ones(len(mesh.faces), dtype=bool)
    keep[mesh.mouth] = False
    tris = mesh.faces[keep]
    edges = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    length = np.linalg.norm(mesh.vertices[edges[:, 0]] - mesh.vertices[edges[:, 1]], axis=1)
    n = mesh.n_vertices
    graph = coo_matrix((length, (edges[:, 0], edges[:, 1])), shape=(n, n)).tocsr()
    return dijkstra(graph, directed=False, indices=np.asarray(sources), min_only=True)


def motion_points(names, motion: np.ndarray, labels) -> np.ndarray:
    """Marker trajectories of ``labels`` from channel motion.

    Parameters
    ----------
    names : sequence of str
        Channel names (``<marker>.x/.y/.z``).
    motion : np.ndarray, shape (n_frames, n_channels)
    labels : sequence of str
        Markers wanted.

    Returns
    -------
    np.ndarray, shape (n_frames, len(labels), 3)

    Raises
    ------
    DataError
        If the motion lacks any of the markers.
    """
    index = {n: i for i, n in enumerate(names)}
    missing = [lab for lab in labels if any(f"{lab}.{a}" not in index for a in "xyz")]
    if missing:
        raise DataError(f"the motion's channels do not match the mesh's marker map: "
                        f"{len(missing)} of its {len(labels)} markers are missing "
                        f"({', '.join(missing[:4])}{' ...' if len(missing) > 4 else ''})")
    cols = [index[f"{lab}.{a}"] for lab in labels for a in "xyz"]
    return np.asarray(motion, dtype=np.float64)[:, cols].reshape(len(motion), len(labels), 3)
