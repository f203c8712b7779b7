"""glTF 2.0 binary (.glb) of a face animation: morph targets plus rigid head motion.

:func:`write_glb` stores the mesh at rest, the principal components of its non-rigid
vertex motion as morph targets with per-frame weights, and the head's rotation and
translation as node animation, in metres, through ``pygltflib``; :func:`write_arkit_glb`
does the same with the 52 ARKit blendshapes as morph targets named by ARKit (the names
are in the mesh's ``extras.targetNames``, where Blender and three.js read them);
:func:`read_glb_frames` reads such a file back into vertex positions (for checking round
trips).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from animegraph.face.animation import FaceAnimation


def write_glb(animation: FaceAnimation, path: Path, *, max_targets: int = 64,
              tolerance_mm: float = 0.01) -> Path:
    """glTF 2.0 binary: the mesh, morph targets and an animation (atomic).

    Non-rigid motion becomes morph targets: the principal components of the vertex
    displacements (in the head's frame), as many as needed for ``tolerance_mm`` (at
    most ``max_targets``), with their weights animated per frame; rigid head motion
    animates the node's rotation and translation. Units are metres (glTF's), so
    Blender imports a life-size head.

    Returns
    -------
    Path
    """
    n = animation.n_frames
    # Vertex motion is the fixed operator times the marker motion, so the principal
    # components of the (small) marker displacements carry over to the vertices.
    disp = animation.displacement.reshape(n, -1)
    u, s, vt = np.linalg.svd(disp, full_matrices=False)
    op = animation.operator
    k = 1
    for k in range(1, min(max_targets, len(s)) + 1):
        recon = (u[:, :k] * s[:k]) @ vt[:k]
        resid = (recon - disp).reshape(n, -1, 3)
        if np.abs(np.matmul(op, resid)).max() <= tolerance_mm:
            break
    scale = s[:k] / np.sqrt(n)
    targets = np.matmul(op, (vt[:k] * scale[:, None]).reshape(k, -1, 3))
    weights = u[:, :k] * np.sqrt(n)
    return _write_gltf(animation, targets, [f"pc{i}" for i in range(k)], weights, path)


def write_arkit_glb(animation: FaceAnimation, weights: np.ndarray, path: Path) -> Path:
    """glTF 2.0 binary with the 52 ARKit blendshapes as morph targets named by ARKit (atomic).

    Blender (shape keys) and three.js (``morphTargetDictionary``) bind the animation to
    any ARKit-rigged head by these names; the canonical mesh carries the shapes of
    :func:`animegraph.face.arkit.arkit_shapes` so the file also plays on its own.

    Parameters
    ----------
    animation : FaceAnimation
        From :func:`animegraph.face.arkit.arkit_animation` (gives mesh, head motion, fps).
    weights : np.ndarray, shape (n_frames, 52)
        Blendshape weights at the animation's frames, in
        :data:`ingest.formats.livelink.ARKIT_BLENDSHAPES` order.
    path : Path
    """
    from animegraph.face.arkit import arkit_shapes
    from ingest.formats.livelink import ARKIT_BLENDSHAPES

    return _write_gltf(animation, np.asarray(arkit_shapes()), list(ARKIT_BLENDSHAPES),
                       np.asarray(weights, dtype=np.float64), path)


def _write_gltf(animation: FaceAnimation, targets: np.ndarray, names: list[str],
                weights: np.ndarray, path: Path) -> Path:
    """The mesh at rest, ``targets`` (k, n_vertices, 3) mm named ``names`` with
    ``weights`` (n_frames, k) animated, and the head's rigid motion, as .glb (atomic)."""
    import pygltflib as gl

    from db.atomic import atomic_write

    mm = 0.001
    n = animation.n_frames
    k = len(targets)
    base = animation.mesh.vertices
    quats = _quaternions(animation.rotation)
    times = np.arange(n, dtype=np.float32) / np.float32(animation.fps)

    blob = bytearray()
    views, accessors = [], []

    def add(array: np.ndarray, kind: str, component: int, target: int | None = None,
            minmax: bool = False) -> int:
        data = np.ascontiguousarray(array).tobytes()
        while len(blob) % 4:
            blob.append(0)
        view = gl.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(data))
        if target is not None:
            view.target = target
        blob.extend(data)
        views.append(view)
        count = len(array) if array.ndim > 1 or kind == "SCALAR" else 1
        acc = gl.Accessor(bufferView=len(views) - 1, componentType=component, count=count,
                          type=kind)
        if minmax:
            flat = array.reshape(count, -1)
            acc.min = flat.min(axis=0).astype(float).tolist()
            acc.max = flat.max(axis=0).astype(float).tolist()
        accessors.append(acc)
        return len(accessors) - 1

    pos = add((base * mm).astype(np.float32), "VEC3", gl.FLOAT, gl.ARRAY_BUFFER, True)
    idx = add(animation.mesh.faces.astype(np.uint32).ravel(), "SCALAR", gl.UNSIGNED_INT,
              gl.ELEMENT_ARRAY_BUFFER, True)
    target_acc = [add((t * mm).astype(np.float32), "VEC3", gl.FLOAT, gl.ARRAY_BUFFER, True)
                  for t in targets]
    t_in = add(times, "SCALAR", gl.FLOAT, None, True)
    w_out = add(weights.astype(np.float32).ravel(), "SCALAR", gl.FLOAT)
    r_out = add(quats.astype(np.float32), "VEC4", gl.FLOAT)
    tr_out = add((animation.translation * mm).astype(np.float32), "VEC3", gl.FLOAT)

    gltf = gl.GLTF2(
        asset=gl.Asset(generator="animegraph", version="2.0"),
        scene=0, scenes=[gl.Scene(nodes=[0])],
        nodes=[gl.Node(mesh=0, name="face")],
        meshes=[gl.Mesh(name="face", weights=[0.0] * k, extras={"targetNames": names},
                        primitives=[gl.Primitive(
                            attributes=gl.Attributes(POSITION=pos), indices=idx,
                            targets=[{"POSITION": a} for a in target_acc])])],
        animations=[gl.Animation(name="speech", samplers=[
            gl.AnimationSampler(input=t_in, output=w_out, interpolation="LINEAR"),
            gl.AnimationSampler(input=t_in, output=r_out, interpolation="LINEAR"),
            gl.AnimationSampler(input=t_in, output=tr_out, interpolation="LINEAR"),
        ], channels=[
            gl.AnimationChannel(sampler=0, target=gl.AnimationChannelTarget(node=0,
                                                                            path="weights")),
            gl.AnimationChannel(sampler=1, target=gl.AnimationChannelTarget(node=0,
                                                                            path="rotation")),
            gl.AnimationChannel(sampler=2, target=gl.AnimationChannelTarget(
                node=0, path="translation")),
        ])],
        accessors=accessors, bufferViews=views,
        buffers=[gl.Buffer(byteLength=len(blob))],
    )
    gltf.set_binary_blob(bytes(blob))
    data = b"".join(gltf.save_to_bytes())
    with atomic_write(path) as handle:
        handle.write(data)
    return Path(path)


def _quaternions(rotation: np.ndarray) -> np.ndarray:
    """(n, 4) unit quaternions x, y, z, w (glTF order), signs kept continuous."""
    from scipy.spatial.transform import Rotation

    q = Rotation.from_matrix(rotation).as_quat()
    for i in range(1, len(q)):
        if q[i] @ q[i - 1] < 0:
            q[i] = -q[i]
    return q


def read_glb_frames(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read back a .glb written by :func:`write_glb`: times, world vertices (mm), faces.

    The inverse of the writer, through pygltflib, for checking a round trip.

    Returns
    -------
    times : np.ndarray, shape (n_frames,)
    vertices : np.ndarray, shape (n_frames, n_vertices, 3)
    faces : np.ndarray, shape (n_faces, 3)
    """
    import pygltflib as gl
    from scipy.spatial.transform import Rotation

    gltf = gl.GLTF2().load(str(path))
    blob = gltf.binary_blob()
    dtypes = {gl.FLOAT: np.float32, gl.UNSIGNED_INT: np.uint32, gl.UNSIGNED_SHORT: np.uint16}
    widths = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}

    def read(i: int) -> np.ndarray:
        acc = gltf.accessors[i]
        view = gltf.bufferViews[acc.bufferView]
        start = (view.byteOffset or 0) + (acc.byteOffset or 0)
        arr = np.frombuffer(blob, dtype=dtypes[acc.componentType],
                            count=acc.count * widths[acc.type], offset=start)
        return arr.reshape(acc.count, widths[acc.type]).astype(np.float64)

    prim = gltf.meshes[0].primitives[0]
    base = read(prim.attributes.POSITION)
    faces = read(prim.indices).astype(np.int64).reshape(-1, 3)
    targets = np.stack([read(t["POSITION"]) for t in prim.targets])
    anim = gltf.animations[0]
    by_path = {c.target.path: anim.samplers[c.sampler] for c in anim.channels}
    times = read(by_path["weights"].input)[:, 0]
    weights = read(by_path["weights"].output).reshape(len(times), len(targets))
    quat = read(by_path["rotation"].output)
    trans = read(by_path["translation"].output)
    local = base[None] + np.tensordot(weights, targets, axes=1)
    rot = Rotation.from_quat(quat).as_matrix()
    world = np.matmul(local, np.transpose(rot, (0, 2, 1))) + trans[:, None]
    return times, world * 1000.0, faces
