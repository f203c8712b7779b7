"""ARKit blendshape curves on the canonical face mesh: a face to judge a capture or a synthesis by.

An iPhone capture (Live Link Face) or a synthesis from an ARKit database is 52 blendshape
weights plus head and eye rotations, with no geometry. :func:`arkit_shapes` gives each
ARKit shape a displacement field on the canonical face mesh (468 vertices, mediapipe
order, mm; x to the subject's left, y up, z out of the face), built from the smooth
regional weights of the corpus' face rig (:func:`ingest.corpus.face.face_weights`: jaw,
lips, lip corners, cheeks, chin, lids, brows) after the meaning Apple documents for each
``ARFaceAnchor.BlendShapeLocation``. "Left" is the subject's left (+x), as in ARKit.

======================  ==============================================================
ARKit shape             displacement (at weight 1)
======================  ==============================================================
jawOpen                 the lower jaw drops 20 mm at the lower lip and slides back
jawForward/Left/Right   the jaw region moves 5 mm forward / to the side
mouthClose              the lower lip rises back by the jaw's drop (lips shut, jaw open)
mouthFunnel             lips forward 4 mm, narrower, and parted (funnel)
mouthPucker             lips forward 5 mm, 35 % narrower, pressed together
mouthLeft/Right         both lips 6 mm to the side
mouthSmile{L,R}         lip corner up 5, out 4, back 2 mm; cheek and lower lid rise
mouthFrown{L,R}         lip corner down 4 mm, chin boss up
mouthDimple{L,R}        lip corner back 3 and out 2 mm
mouthStretch{L,R}       lip corner out 6 and down 2 mm, lips flattened
mouthRollLower/Upper    that lip rolls in: back 4 mm, towards the other lip 1.5 mm
mouthShrugLower/Upper   lower lip and chin up 3 mm / upper lip up 2.5 mm
mouthPress{L,R}         lips pressed together and back (1.5 mm)
mouthLowerDown{L,R}     lower lip down 5 mm
mouthUpperUp{L,R}       upper lip up 4 mm
browDown{L,R}           brow down 5 mm and inwards
browInnerUp             inner brows up 4.5 mm
browOuterUp{L,R}        outer brow up 5 mm
cheekPuff               cheeks out 5 mm
cheekSquint{L,R}        cheek up 3 mm, lower lid up 1 mm
noseSneer{L,R}          nose wing up 3 mm
eyeBlink{L,R}           upper lid down to the lower lid (6.2 mm)
eyeSquint{L,R}          lower lid up 2 mm, upper lid down 1 mm
eyeWide{L,R}            upper lid up 2.5 mm
eyeLookUp/Down{L,R}     the upper lid follows the gaze 1.5 mm up / down
======================  ==============================================================

Head yaw, pitch and roll (radians) turn the whole mesh about the neck (yaw about y,
pitch about x, positive tipping the face down, roll about z).

What it does not show: the mesh has no eyeballs, teeth or tongue, so gaze (eyeLookIn/Out,
the eye rotations) and ``tongueOut`` are not drawn; the lips do not collide (a strong
mouthClose with little jawOpen pushes the lower lip through the upper); the shapes are a
generic face's, derived, not sculpted or fitted to the capture's actor, and add linearly
(no corrective shapes); the sign convention of the head angles is taken from ARKit's
right-handed face frame and has not been checked against a turning head.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from animegraph.face.animation import FaceAnimation, resample
from animegraph.face.mesh import Mesh, canonical_mesh
from animegraph.motion.files import Motion
from db.errors import DataError
from ingest.corpus.face import action_fields, face_weights
from ingest.formats.livelink import ARKIT_BLENDSHAPES, is_arkit

#: Drop (mm) of the lower lip at jawOpen = 1 (an adult's jaw opens 40-50 mm at the
#: incisors at most; speech rarely passes half of that).
JAW_OPEN_MM = 20.0
#: Pivot of the head's rotations (mm): the top of the neck, behind and below the mouth.
HEAD_PIVOT = np.array([0.0, -80.0, -60.0])
#: Nose wings (mediapipe vertices), right and left: where noseSneer lifts.
NOSE_WINGS = (98, 327)


def _side(x: np.ndarray, which: str) -> np.ndarray:
    """1 on the named half of the face (Left: +x), fading to 0 over 6 mm either side of
    the midline."""
    t = np.clip((x if which == "Left" else -x) / 12.0 + 0.5, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


@lru_cache(maxsize=1)
def arkit_shapes() -> np.ndarray:
    """Displacement of every canonical mesh vertex under each ARKit blendshape at 1.

    Returns
    -------
    np.ndarray, shape (52, 468, 3)
        Millimetres, in :data:`ingest.formats.livelink.ARKIT_BLENDSHAPES` order (read-only).
    """
    rest = canonical_mesh().vertices
    x = rest[:, 0]
    w = face_weights(rest)
    act = action_fields(rest)
    jaw_mm = act["jaw_open"][:, 1].min()  # the rig's drop at the lower lip (negative)
    lips, corners, side = w["lips"], w["corners"], w["side"]
    upper, lower = w["upper_lip"] * lips, w["lower_lip"] * lips
    zero = np.zeros_like(rest)

    def field(dx=0.0, dy=0.0, dz=0.0) -> np.ndarray:
        out = zero.copy()
        out[:, 0], out[:, 1], out[:, 2] = dx, dy, dz
        return out

    nose = np.zeros(len(rest))
    for v in NOSE_WINGS:
        nose += np.exp(-((rest - rest[v]) ** 2).sum(1) / 7.0**2)
    jaw = act["jaw_open"] * (JAW_OPEN_MM / -jaw_mm)
    both: dict[str, np.ndarray] = {
        "jawOpen": jaw,
        "jawForward": field(dz=5.0 * w["jaw"]),
        "jawLeft": field(dx=5.0 * w["jaw"]),
        "jawRight": field(dx=-5.0 * w["jaw"]),
        "mouthClose": -jaw * w["lower_lip"][:, None],
        "mouthFunnel": 0.7 * act["lip_round"] + field(dy=2.0 * upper - 2.5 * lower),
        "mouthPucker": act["lip_round"] + 0.7 * act["lip_press"],
        "mouthLeft": field(dx=6.0 * lips),
        "mouthRight": field(dx=-6.0 * lips),
        "mouthRollLower": field(dy=1.5 * lower, dz=-4.0 * lower),
        "mouthRollUpper": field(dy=-1.5 * upper, dz=-4.0 * upper),
        "mouthShrugLower": field(dy=3.0 * (lower + w["chin"])),
        "mouthShrugUpper": field(dy=2.5 * upper),
        "browInnerUp": act["inner_brow_raise"],
        "cheekPuff": field(dx=5.0 * side * w["cheeks"], dz=2.0 * w["cheeks"]),
    }
    sided: dict[str, np.ndarray] = {
        "mouthSmile": act["smile"],
        "mouthFrown": act["lip_corner_depress"],
        "mouthDimple": field(dx=2.0 * side * corners, dz=-3.0 * corners),
        "mouthStretch": act["lip_spread"] + field(dx=4.0 * side * corners, dy=-3.0 * corners),
        "mouthPress": act["lip_press"],
        "mouthLowerDown": field(dy=-5.0 * lower),
        "mouthUpperUp": field(dy=4.0 * upper),
        "browDown": act["brow_lower"],
        "browOuterUp": act["brow_raise"] * (1.0 - w["inner"])[:, None],
        "cheekSquint": field(dy=3.0 * w["cheeks"] + 1.0 * w["low_lids"]),
        "noseSneer": field(dy=3.0 * nose),
        "eyeBlink": act["blink"],
        "eyeSquint": field(dy=2.0 * w["low_lids"] - 1.0 * w["up_lids"]),
        "eyeWide": field(dy=2.5 * w["up_lids"]),
        "eyeLookUp": field(dy=1.5 * w["up_lids"]),
        "eyeLookDown": field(dy=-1.5 * w["up_lids"]),
    }
    shapes = []
    for name in ARKIT_BLENDSHAPES:
        if name in both:
            shapes.append(both[name])
            continue
        for which in ("Left", "Right"):
            stem = name[: -len(which)] if name.endswith(which) else None
            if stem in sided:
                shapes.append(sided[stem] * _side(x, which)[:, None])
                break
        else:  # eyeLookIn/Out (no eyeballs), tongueOut (no tongue)
            shapes.append(zero.copy())
    out = np.stack(shapes)
    out.setflags(write=False)
    return out


def head_rotations(yaw: np.ndarray, pitch: np.ndarray, roll: np.ndarray) -> np.ndarray:
    """Rotation matrices (n_frames, 3, 3) from head angles in radians (y, x, z axes).

    A positive pitch tips the face down (a nod), a positive yaw turns it towards the
    subject's left, a positive roll tilts the top of the head to the subject's right.
    """
    from scipy.spatial.transform import Rotation

    angles = np.stack([np.asarray(yaw), -np.asarray(pitch), -np.asarray(roll)], axis=1)
    return Rotation.from_euler("YXZ", angles).as_matrix()


def arkit_weights(motion: Motion, fps: float | None = None) -> np.ndarray:
    """The 52 blendshape weights of ARKit motion, clamped to [0, 1], at ``fps``.

    Returns
    -------
    np.ndarray, shape (n_frames, 52)
        In :data:`ingest.formats.livelink.ARKIT_BLENDSHAPES` order (NaN -> 0).
    """
    index = {n.lower(): i for i, n in enumerate(motion.names)}
    values = np.asarray(motion.values, dtype=np.float64)
    weights = np.clip(values[:, [index[n.lower()] for n in ARKIT_BLENDSHAPES]], 0.0, 1.0)
    return resample(np.nan_to_num(weights), motion.fps, motion.fps if fps is None else fps)


def arkit_animation(motion: Motion, *, fps: float | None = None,
                    mesh: Mesh | None = None) -> FaceAnimation:
    """ARKit curves as an animation of the canonical face mesh.

    Parameters
    ----------
    motion : Motion
        Channels holding the 52 ARKit blendshapes (either spelling) and, optionally,
        ``headYaw``/``headPitch``/``headRoll`` (radians); other channels are ignored.
    fps : float, optional
        Frame rate of the animation (default the motion's).
    mesh : Mesh, optional
        The canonical mesh (the shapes are defined on its vertices only).

    Returns
    -------
    FaceAnimation
        ``local = rest + sum_k w_k * shape_k`` with weights clamped to [0, 1];
        ``operator`` is the identity (every vertex its own "marker"), so
        ``displacement`` holds the vertex displacements.

    Raises
    ------
    DataError
        If the motion is not ARKit curves.
    """
    if not is_arkit(motion.names):
        raise DataError("the motion is not ARKit blendshape curves (the 52 ARKit names)")
    mesh = mesh or canonical_mesh()
    index = {n.lower(): i for i, n in enumerate(motion.names)}
    values = np.asarray(motion.values, dtype=np.float64)
    head = np.stack([values[:, index[n.lower()]] if n.lower() in index
                     else np.zeros(len(values)) for n in ("headYaw", "headPitch", "headRoll")],
                    axis=1)
    fps = motion.fps if fps is None else float(fps)
    weights = arkit_weights(motion, fps)
    head = resample(np.nan_to_num(head), motion.fps, fps)
    shapes = arkit_shapes()
    displacement = np.tensordot(weights, shapes, axes=1)  # (n, 468, 3)
    local = mesh.vertices[None] + displacement
    rotation = head_rotations(head[:, 0], head[:, 1], head[:, 2])
    translation = HEAD_PIVOT - np.einsum("nij,j->ni", rotation, HEAD_PIVOT)
    world = np.matmul(local, np.transpose(rotation, (0, 2, 1))) + translation[:, None]
    return FaceAnimation(mesh=mesh, vertices=world, local=local, displacement=displacement,
                         operator=np.eye(mesh.n_vertices), rotation=rotation,
                         translation=translation, fps=fps)
