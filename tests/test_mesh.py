"""§7 mesh deformation against the synthetic face rig evaluated on every vertex."""

from __future__ import annotations

import json

import numpy as np
import pytest
from crafted import gltf_drawing, gltf_reaching, quad_bin
from scipy.spatial.transform import Rotation

from animegraph.face.mesh import (
    REGIONS,
    Deformer,
    canonical_mesh,
    canonical_regions,
    default_marker_map,
    load_mesh,
    motion_points,
    read_marker_map,
)
from db.errors import DataError
from ingest.corpus import face
from ingest.facemesh import canonical_mesh_path


@pytest.fixture(scope="module")
def setup():
    mesh = canonical_mesh()
    markers = default_marker_map([m[0] for m in face.MARKERS])
    # Ground truth: the corpus' own rig posed on every vertex and on the markers.
    controls = np.zeros((4, len(face.CONTROLS)))
    col = face.CONTROLS.index
    controls[1, col("jaw_open")] = 1.0
    controls[2, col("smile")] = 1.0
    controls[2, col("brow_raise")] = 1.0
    controls[3, col("jaw_open")] = 0.7
    controls[3, col("head_pitch")] = 8.0
    controls[3, col("head_yaw")] = 15.0
    truth = face.FaceRig.for_points(mesh.vertices).pose(controls)
    points = face.FaceRig.for_points(mesh.vertices[markers.vertices]).pose(controls)
    return mesh, markers, truth, points


def _gap(vertices, frame):
    # Inner lips between the markers (82 upper, 87 lower): only interpolation moves them.
    return np.linalg.norm(vertices[frame, 82] - vertices[frame, 87])


def test_regions_follow_the_paper(setup):
    _, markers, _, _ = setup
    regions = dict(zip(markers.labels, markers.regions, strict=True))
    assert regions["ulip_in_c"] == ("upper_jaw",) and regions["llip_in_c"] == ("lower_jaw",)
    assert set(regions["lip_corner_r"]) == {"lower_jaw", "upper_jaw"}
    assert regions["lid_up_r"] == ("eyelid_r",) and regions["lid_up_l"] == ("eyelid_l",)
    assert regions["brow_l3"] == ("upper_face",) and regions["nose_tip"] == ("anchor",)
    assert {r for rs in markers.regions for r in rs} == set(REGIONS) | {"anchor"}


def test_rbf_with_regions_matches_the_rig_and_parts_the_lips(setup):
    mesh, markers, truth, points = setup
    deformer = Deformer.build(mesh, markers)
    assert deformer.operator.shape == (468, 72)
    assert np.allclose(deformer.region_weights.sum(axis=1), 1.0)
    out = deformer.deform(points)
    # Markers are interpolated exactly; the rest of the face within a millimetre RMS.
    assert np.abs(out[:, markers.vertices] - points).max() < 1e-9
    err = np.linalg.norm(out - truth, axis=-1)
    assert np.sqrt((err[1:] ** 2).mean()) < 1.0
    # The lips part as the rig parts them (frame 1: jaw wide open; 3: with a head turn).
    for frame in (1, 3):
        assert abs(_gap(out, frame) - _gap(truth, frame)) < 1.0
    # One interpolant through every marker smears the lips together: the paper's reason
    # for regions.
    single = Deformer.build(mesh, markers, regions=False).deform(points)
    assert _gap(truth, 1) - _gap(single, 1) > 3.0


def test_rigid_head_motion_moves_the_mesh_rigidly(setup):
    mesh, markers, _, _ = setup
    deformer = Deformer.build(mesh, markers)
    rot = Rotation.from_euler("xyz", [10, 25, -5], degrees=True).as_matrix()
    shift = np.array([3.0, -4.0, 5.0])
    moved = deformer.rest @ rot.T + shift
    out = deformer.deform(moved[None])[0]
    assert np.abs(out - (mesh.vertices @ rot.T + shift)).max() < 1e-9


def test_landmarks_map_one_to_one():
    mesh = canonical_mesh()
    markers = default_marker_map([f"lm{i}" for i in range(468)])
    deformer = Deformer.build(mesh, markers)
    rng = np.random.default_rng(0)
    points = mesh.vertices[None] + rng.normal(0, 0.5, (2, 468, 3))
    assert np.abs(deformer.deform(points) - points).max() < 1e-6


def test_custom_mesh_and_marker_map(tmp_path, setup):
    import trimesh

    mesh, markers, truth, points = setup
    keep = np.setdiff1d(np.arange(len(mesh.faces)), mesh.mouth)  # a mesh with an open mouth
    path = tmp_path / "face.ply"
    trimesh.Trimesh(mesh.vertices, mesh.faces[keep], process=False).export(path)
    rows = ["label,vertex,region"] + [f"{lab},{v},{'|'.join(r)}" for lab, v, r in zip(
        markers.labels, markers.vertices, markers.regions, strict=True)]
    (tmp_path / "map.csv").write_text("\n".join(rows) + "\n")
    custom = load_mesh(path)
    assert custom.n_vertices == 468 and len(custom.mouth) == 0
    mapped = read_marker_map(tmp_path / "map.csv", custom)
    out = Deformer.build(custom, mapped).deform(points)
    reference = Deformer.build(mesh, markers).deform(points)
    assert np.abs(out - reference).max() < 1e-3  # PLY stores float32


@pytest.mark.parametrize("text, needle", [
    ("label,vertex\nlip_corner_r,9999\n", "names vertex 9999"),
    ("label,vertex\nlip_corner_r,x\n", "not a whole number"),
    ("label,vertex,region\na,1,cheek\n", "region of 'a'"),
    ("label,vertex\na,1\na,2\n", "listed twice"),
    ("name,index\na,1\n", "'label' and 'vertex'"),
])
def test_bad_marker_maps(tmp_path, text, needle):
    path = tmp_path / "map.csv"
    path.write_text(text)
    with pytest.raises(DataError, match=needle):
        read_marker_map(path, canonical_mesh())


def test_custom_mesh_needs_regions(tmp_path):
    import trimesh

    mesh = canonical_mesh()
    trimesh.Trimesh(mesh.vertices, mesh.faces[:-1], process=False).export(tmp_path / "m.obj")
    (tmp_path / "map.csv").write_text("label,vertex\na,1\nb,2\n")
    with pytest.raises(DataError, match="no 'region' column"):
        read_marker_map(tmp_path / "map.csv", load_mesh(tmp_path / "m.obj"))


def test_a_mesh_file_of_the_canonical_triangles_is_known_as_canonical(tmp_path):
    # The shipped canonical mesh given as --mesh (or a face sculpted on its triangles)
    # was refused a marker map without regions, and drew its mouth closed
    import trimesh

    mesh = canonical_mesh()
    sculpt = tmp_path / "sculpt.obj"
    trimesh.Trimesh(mesh.vertices * 1.1, mesh.faces, process=False).export(sculpt)
    (tmp_path / "map.csv").write_text("label,vertex\na,13\nb,14\nc,6\n")
    expected = read_marker_map(tmp_path / "map.csv", mesh)
    for path in (canonical_mesh_path(), sculpt):
        loaded = load_mesh(path)
        assert loaded.canonical_topology
        np.testing.assert_array_equal(loaded.mouth, mesh.mouth)
        np.testing.assert_array_equal(loaded.eyes, mesh.eyes)
        assert read_marker_map(tmp_path / "map.csv", loaded).regions == expected.regions


def test_unreadable_mesh(tmp_path):
    bad = tmp_path / "bad.obj"
    bad.write_bytes(b"\x00\x01 not a mesh at all \xff")
    with pytest.raises(DataError, match="cannot read mesh"):
        load_mesh(bad)
    with pytest.raises(DataError, match="does not exist"):
        load_mesh(tmp_path / "missing.ply")


def test_motion_must_carry_the_maps_markers():
    names = ("a.x", "a.y", "a.z")
    with pytest.raises(DataError, match="do not match the mesh's marker map"):
        motion_points(names, np.zeros((2, 3)), ["a", "b"])


def test_canonical_regions_split_the_lips():
    verts = canonical_mesh().vertices
    regions = canonical_regions(verts[[13, 14, 159, 386, 151]])
    assert regions == (("upper_jaw",), ("lower_jaw",), ("eyelid_r",), ("eyelid_l",),
                       ("upper_face",))


def test_corpus_markers_csv_is_a_map_for_the_canonical_mesh(tmp_path):
    rest = face.marker_rest()
    lines = ["label,vertex,group,rest_x,rest_y,rest_z"] + [
        f"{lab},{v},{g},{x},{y},{z}" for (lab, v, g), (x, y, z) in zip(face.MARKERS, rest,
                                                                       strict=True)]
    (tmp_path / "markers.csv").write_text("\n".join(lines) + "\n")
    mapped = read_marker_map(tmp_path / "markers.csv", canonical_mesh())
    expected = default_marker_map([m[0] for m in face.MARKERS])
    assert mapped.regions == expected.regions
    assert np.array_equal(mapped.vertices, expected.vertices)


@pytest.mark.parametrize("nested", [True, False])
def test_a_gltf_drawing_its_pieces_at_too_many_places_is_refused_at_once(tmp_path, nested):
    # 5,000 nested nodes (a 200 KB file) kept load_mesh for minutes (1,000: 5 s); nodes drawing a
    # large piece many times would make billions of vertices from a small file
    (tmp_path / "quad.bin").write_bytes(quad_bin())
    for n, fits in [(256, True), (1000, False)]:
        path = tmp_path / f"n{n}.gltf"
        path.write_text(json.dumps(gltf_drawing("quad.bin", n, nested=nested)))
        if fits:
            assert load_mesh(path).vertices.shape == (4 * n, 3)
        else:
            with pytest.raises(DataError, match=f"draws its pieces at {n} places"):
                load_mesh(path)


def test_a_gltf_reads_no_buffer_outside_its_folder(tmp_path):
    # A shared mesh.gltf whose buffer is another file (../secret.bin, an absolute path, a
    # symlink beside it) would put that file's bytes in the rendered face: refused, while
    # a buffer beside the glTF is read
    quad = (np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 1]], np.float32).tobytes()
            + np.array([0, 1, 2, 0, 2, 3], np.uint32).tobytes())
    secret = tmp_path / "elsewhere" / "secret.bin"
    secret.parent.mkdir()
    secret.write_bytes(quad)
    folder = tmp_path / "mesh"
    folder.mkdir()
    (folder / "quad.bin").write_bytes(quad)
    (folder / "link.bin").symlink_to(secret)
    (folder / "ok.gltf").write_text(json.dumps(gltf_reaching("quad.bin")))
    assert load_mesh(folder / "ok.gltf").vertices.shape == (4, 3)
    for uri in ("../elsewhere/secret.bin", str(secret), secret.as_uri(), "link.bin"):
        (folder / "bad.gltf").write_text(json.dumps(gltf_reaching(uri)))
        with pytest.raises(DataError, match=r"cannot read mesh .*bad\.gltf"):
            load_mesh(folder / "bad.gltf")
