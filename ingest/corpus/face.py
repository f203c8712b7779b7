"""A procedural face rig on the canonical mesh: markers, actions, and posing.

The synthetic corpus needs facial motion with real structure, so the face is driven
by a small set of *controls*, each a physical action with a known meaning:

* speech (articulatory) controls -- ``jaw_open``, ``lip_round``, ``lip_spread``,
  ``lip_close`` (bilabial closure) and ``lip_tuck`` (lower lip to the upper teeth);
* emotion (expressive) controls -- ``smile``, ``lip_corner_depress``, ``brow_raise``,
  ``inner_brow_raise``, ``brow_lower``, ``lip_press``;
* ``blink``, and the rigid head pose (``head_pitch/yaw/roll`` in degrees,
  ``head_tx/ty/tz`` in millimetres).

Each non-rigid action is a displacement field over the rest positions of any set of
points on the mesh (the markers, or every vertex), built from smooth regional weights.
Most actions are linear in their control; ``lip_close`` and ``lip_tuck`` act on the
*current* gap between the lips, so that a bilabial closes the mouth whatever the jaw
is doing. The markers follow the paper's three motion groups (Cao et al. 2005, §3.2):
rigid head motion, upper face (brows, lids, forehead) and lip motion.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ingest import facemesh

#: (label, mesh vertex, motion group) of every marker, after a 70-marker facial set.
MARKERS: tuple[tuple[str, int, str], ...] = (
    # lip motion group: lips, chin and jaw line, cheeks, nose wings
    ("lip_corner_r", 61, "lips"), ("lip_corner_l", 291, "lips"),
    ("ulip_out_r2", 40, "lips"), ("ulip_out_r1", 37, "lips"), ("ulip_out_c", 0, "lips"),
    ("ulip_out_l1", 267, "lips"), ("ulip_out_l2", 270, "lips"),
    ("llip_out_r2", 91, "lips"), ("llip_out_r1", 84, "lips"), ("llip_out_c", 17, "lips"),
    ("llip_out_l1", 314, "lips"), ("llip_out_l2", 321, "lips"),
    ("ulip_in_r", 81, "lips"), ("ulip_in_c", 13, "lips"), ("ulip_in_l", 311, "lips"),
    ("llip_in_r", 178, "lips"), ("llip_in_c", 14, "lips"), ("llip_in_l", 402, "lips"),
    ("chin_top", 18, "lips"), ("chin_mid", 200, "lips"), ("chin_low", 199, "lips"),
    ("chin_tip", 152, "lips"), ("jaw_r1", 176, "lips"), ("jaw_l1", 400, "lips"),
    ("jaw_r2", 150, "lips"), ("jaw_l2", 379, "lips"), ("jaw_r3", 172, "lips"),
    ("jaw_l3", 397, "lips"),
    ("cheek_r1", 50, "lips"), ("cheek_l1", 280, "lips"), ("cheek_r2", 205, "lips"),
    ("cheek_l2", 425, "lips"), ("cheek_r3", 207, "lips"), ("cheek_l3", 427, "lips"),
    ("cheek_r4", 187, "lips"), ("cheek_l4", 411, "lips"),
    ("nose_wing_r", 98, "lips"), ("nose_wing_l", 327, "lips"),
    ("philtrum", 2, "lips"), ("nasolabial_r", 206, "lips"), ("nasolabial_l", 426, "lips"),
    # upper face group: brows, eyelids, forehead
    ("brow_r1", 107, "upper_face"), ("brow_r2", 66, "upper_face"),
    ("brow_r3", 105, "upper_face"), ("brow_r4", 63, "upper_face"),
    ("brow_r5", 70, "upper_face"),
    ("brow_l1", 336, "upper_face"), ("brow_l2", 296, "upper_face"),
    ("brow_l3", 334, "upper_face"), ("brow_l4", 293, "upper_face"),
    ("brow_l5", 300, "upper_face"),
    ("lid_up_r", 159, "upper_face"), ("lid_low_r", 145, "upper_face"),
    ("lid_up_l", 386, "upper_face"), ("lid_low_l", 374, "upper_face"),
    ("eye_out_r", 33, "upper_face"), ("eye_in_r", 133, "upper_face"),
    ("eye_out_l", 263, "upper_face"), ("eye_in_l", 362, "upper_face"),
    ("forehead_c", 151, "upper_face"), ("forehead_r1", 108, "upper_face"),
    ("forehead_l1", 337, "upper_face"), ("forehead_r2", 69, "upper_face"),
    ("forehead_l2", 299, "upper_face"),
    # rigid head group: points the face's muscles do not move
    ("head_top", 10, "head"), ("head_temple_r", 127, "head"), ("head_temple_l", 356, "head"),
    ("head_side_r", 234, "head"), ("head_side_l", 454, "head"), ("nose_bridge", 6, "head"),
    ("nose_tip", 1, "head"), ("nose_ridge", 195, "head"),
)
MOTION_GROUPS = ("head", "upper_face", "lips")

SPEECH_CONTROLS = ("jaw_open", "lip_round", "lip_spread", "lip_close", "lip_tuck")
EMOTION_CONTROLS = (
    "smile", "lip_corner_depress", "brow_raise", "inner_brow_raise", "brow_lower", "lip_press",
)
HEAD_CONTROLS = ("head_pitch", "head_yaw", "head_roll", "head_tx", "head_ty", "head_tz")
CONTROLS = SPEECH_CONTROLS + EMOTION_CONTROLS + ("blink",) + HEAD_CONTROLS

_LINEAR = ("jaw_open", "lip_round", "lip_spread") + EMOTION_CONTROLS + ("blink",)

# Geometry of the canonical face in millimetres (read off the mesh).
_MOUTH_Y = -42.7  # height of the line between the lips (between vertices 13 and 14)
_MOUTH_Z = 52.0
_CORNER_X = 24.6
_JAW_DROP_MM = 14.0  # lower-lip drop at full jaw opening
_HINGE_Z = -25.0  # depth of the jaw hinge: motion fades to nothing there
_HEAD_PIVOT = np.array([0.0, -80.0, -60.0])  # the neck, for rigid head rotation
_LID_GAP_MM = 6.7  # open eye, upper to lower lid (vertices 159 and 145)
# Inner-lip columns, right to left, paired upper/lower; the inner corners close them.
_INNER_UPPER = (78,) + facemesh.UPPER_LIP_INNER + (308,)
_INNER_LOWER = (78,) + facemesh.LOWER_LIP_INNER + (308,)


def _smoothstep(edge0: float, edge1: float, x: np.ndarray) -> np.ndarray:
    """Hermite step from 0 at ``edge0`` to 1 at ``edge1`` (either order)."""
    t = np.clip((x - edge0) / (edge1 - edge0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _gauss(d2: np.ndarray) -> np.ndarray:
    return np.exp(-d2)


def face_weights(rest: np.ndarray) -> dict[str, np.ndarray]:
    """Smooth regional weights of points on the canonical face (each shape (n_points,)).

    ``jaw`` (what the lower jaw carries: below the lips, fading to nothing at the
    hinge; the product of ``jaw_split``, below the lips, and ``jaw_reach``, towards the
    hinge), ``lips`` (a flat-topped blob around the mouth), ``corners`` (the lip
    corners), ``cheeks``, ``chin`` (the chin boss), ``low_lids``/``up_lids`` (lower and
    upper eyelids), ``brows`` (a band over the eyes fading into the forehead), ``inner``
    (1 between the brows, fading outwards), ``upper_lip``/``lower_lip`` (the share of
    each lip's closing motion a point follows) and ``side`` (sign of x: +1 on the
    subject's left). The actions of :func:`action_fields` are built from them.
    """
    x, y, z = rest[:, 0], rest[:, 1], rest[:, 2]
    ax = np.abs(x)
    sharp = _smoothstep(_MOUTH_Y + 2.0, _MOUTH_Y - 2.0, y)
    broad = _smoothstep(_MOUTH_Y + 15.0, _MOUTH_Y - 10.0, y)
    lateral = _smoothstep(22.0, 35.0, ax)
    w_jaw = (1 - lateral) * sharp + lateral * broad
    reach = np.clip((z - _HINGE_Z) / (_MOUTH_Z - _HINGE_Z), 0.0, 1.0)
    brows = _smoothstep(30.0, 40.0, y) * np.exp(-np.maximum(0.0, y - 50.0) / 20.0)
    upper_lip, lower_lip = _lip_weights(rest)
    return {
        "side": np.sign(x),
        "jaw": w_jaw * reach,
        "jaw_split": w_jaw,
        "jaw_reach": reach,
        # The lips as a flat-topped blob around the mouth.
        "lips": _gauss(((x / 28.0) ** 2 + ((y - _MOUTH_Y) / 14.0) ** 2) ** 2) * (z > 25.0),
        "corners": _gauss(((ax - _CORNER_X) ** 2 + (y - (_MOUTH_Y - 0.7)) ** 2
                           + (z - 42.8) ** 2) / 11.0**2),
        "cheeks": _gauss(((ax - 40.0) ** 2 + (y + 20.0) ** 2 + (z - 38.0) ** 2) / 15.0**2),
        "chin": _gauss((x**2 + (y + 62.0) ** 2 + (z - 50.0) ** 2) / 12.0**2),
        "low_lids": _gauss(((ax - 31.8) ** 2 / 9.0**2) + (y - 22.9) ** 2 / 4.0**2),
        "up_lids": _gauss(((ax - 31.8) ** 2 / 9.0**2) + (y - 29.6) ** 2 / 4.0**2),
        "brows": brows * _smoothstep(78.0, 66.0, y) * _smoothstep(68.0, 58.0, ax),
        "inner": np.where(ax < 12.0, 1.0, _gauss(((ax - 12.0) / 14.0) ** 2)),
        "upper_lip": upper_lip,
        "lower_lip": lower_lip,
    }


def action_fields(rest: np.ndarray) -> dict[str, np.ndarray]:
    """Displacement of each point under one unit of each linear action.

    Parameters
    ----------
    rest : np.ndarray, shape (n_points, 3)
        Rest positions on the canonical face, in millimetres.

    Returns
    -------
    dict of str to np.ndarray, each of shape (n_points, 3)
        Millimetres of displacement per unit of control, for every name in the
        linear actions (``jaw_open``, ``lip_round``, ``lip_spread``, the emotion
        controls and ``blink``).
    """
    x, y = rest[:, 0], rest[:, 1]
    w = face_weights(rest)
    side = w["side"]
    zero = np.zeros_like(rest)
    f: dict[str, np.ndarray] = {}

    # Jaw: everything below the lips drops and slides back; a sharp split between the
    # lips inside the mouth's width, a broad one over the cheeks beside it.
    jaw = zero.copy()
    jaw[:, 1] = -_JAW_DROP_MM * w["jaw_split"] * w["jaw_reach"]
    jaw[:, 2] = -0.3 * _JAW_DROP_MM * w["jaw_split"] * w["jaw_reach"]
    f["jaw_open"] = jaw

    lips, corners = w["lips"], w["corners"]
    rnd = zero.copy()
    rnd[:, 0] = -0.35 * x * lips  # narrower
    rnd[:, 2] = 6.0 * lips * np.clip(1 - (x / 30.0) ** 2, 0, 1)  # pushed forward
    f["lip_round"] = rnd

    spr = zero.copy()
    spr[:, 0] = 0.12 * x * lips
    spr[:, 1] = 1.0 * corners
    spr[:, 2] = -2.0 * lips
    f["lip_spread"] = spr

    # Smile (AU6+12): corners up, out and back; cheeks rise; lower lids push up.
    cheeks, low_lids = w["cheeks"], w["low_lids"]
    smile = zero.copy()
    smile[:, 0] = 4.0 * side * corners
    smile[:, 1] = 5.0 * corners + 2.5 * cheeks + 1.0 * low_lids
    smile[:, 2] = -2.0 * corners + 1.5 * cheeks
    f["smile"] = smile

    # Lip-corner depressor (AU15), with the chin boss pushed up (AU17).
    chin = w["chin"]
    dep = zero.copy()
    dep[:, 0] = -1.0 * side * corners
    dep[:, 1] = -4.0 * corners + 1.5 * chin
    f["lip_corner_depress"] = dep

    # Brows: a band over the eyes fading into the forehead, nothing on the skull.
    brows, inner, up_lids = w["brows"], w["inner"], w["up_lids"]
    raise_ = zero.copy()
    raise_[:, 1] = 5.0 * brows + 1.0 * up_lids
    f["brow_raise"] = raise_
    inner_raise = zero.copy()
    inner_raise[:, 1] = 4.5 * brows * inner
    f["inner_brow_raise"] = inner_raise
    lower = zero.copy()
    lower[:, 0] = -2.0 * side * brows * inner
    lower[:, 1] = -5.0 * brows * inner
    lower[:, 2] = 1.0 * brows * inner
    f["brow_lower"] = lower

    # Lip press (AU24): the lips thin and press back.
    upper_half = _smoothstep(_MOUTH_Y - 1.0, _MOUTH_Y + 1.0, y)
    press = zero.copy()
    press[:, 1] = 1.5 * lips * (1 - 2 * upper_half)  # upper lip down, lower up
    press[:, 2] = -1.5 * lips
    f["lip_press"] = press

    # Blink: the upper lid comes down to the lower one.
    blink = zero.copy()
    blink[:, 1] = -0.92 * _LID_GAP_MM * up_lids + 0.5 * low_lids
    f["blink"] = blink
    return f


def _lip_weights(rest: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """How much each point follows the upper and the lower lip when they close."""
    x, y, z = rest[:, 0], rest[:, 1], rest[:, 2]
    lateral = _smoothstep(30.0, 20.0, np.abs(x)) * (z > 25.0)
    above = _smoothstep(_MOUTH_Y - 1.0, _MOUTH_Y + 1.0, y)
    upper = _smoothstep(_MOUTH_Y + 20.0, _MOUTH_Y + 2.7, y) * above * lateral
    lower = _smoothstep(_MOUTH_Y - 25.0, _MOUTH_Y - 2.7, y) * (1 - above) * lateral
    return upper, lower


@dataclass(frozen=True)
class FaceRig:
    """The rig evaluated on a fixed set of points.

    Build one with :meth:`for_points`; :meth:`pose` then turns control curves into
    point trajectories.

    Attributes
    ----------
    rest : np.ndarray, shape (n_points, 3)
        Rest positions (mm).
    fields : np.ndarray, shape (n_linear, n_points, 3)
        Unit displacement of every linear action, in the order of ``linear``.
    linear : tuple of str
        Names of the linear actions.
    upper_w, lower_w : np.ndarray, shape (n_points,)
        Share of the upper and lower lips' closing motion each point follows.
    column, column_frac : np.ndarray, shape (n_points,)
        Which inner-lip column (and where between it and the next) each point's
        lip gap is read from.
    column_fields : np.ndarray, shape (n_linear, n_columns, 2)
        Displacement (y, z) of the upper minus the lower inner lip at each column
        under each linear action.
    column_rest_gap : np.ndarray, shape (n_columns, 2)
        Rest gap (y, z) from the lower to the upper inner lip at each column (mm).
    """

    rest: np.ndarray
    fields: np.ndarray
    linear: tuple[str, ...]
    upper_w: np.ndarray
    lower_w: np.ndarray
    column: np.ndarray
    column_frac: np.ndarray
    column_fields: np.ndarray
    column_rest_gap: np.ndarray

    @classmethod
    def for_points(cls, rest: np.ndarray) -> FaceRig:
        """Evaluate the rig's fields on the points ``rest`` (shape (n_points, 3), mm)."""
        rest = np.asarray(rest, dtype=np.float64)
        fields = action_fields(rest)
        verts = facemesh.load_canonical_face().vertices
        up_pts, low_pts = verts[list(_INNER_UPPER)], verts[list(_INNER_LOWER)]
        up_f, low_f = action_fields(up_pts), action_fields(low_pts)
        col_x = 0.5 * (up_pts[:, 0] + low_pts[:, 0])
        pos = np.interp(rest[:, 0], col_x, np.arange(len(col_x), dtype=np.float64))
        column = np.minimum(np.floor(pos).astype(np.int64), len(col_x) - 2)
        upper_w, lower_w = _lip_weights(rest)
        return cls(
            rest=rest,
            fields=np.stack([fields[name] for name in _LINEAR]),
            linear=_LINEAR,
            upper_w=upper_w,
            lower_w=lower_w,
            column=column,
            column_frac=pos - column,
            column_fields=np.stack([(up_f[n] - low_f[n])[:, 1:] for n in _LINEAR]),
            column_rest_gap=(up_pts - low_pts)[:, 1:],
        )

    def pose(self, controls: np.ndarray, names: tuple[str, ...] = CONTROLS) -> np.ndarray:
        """Point trajectories for control curves.

        Parameters
        ----------
        controls : np.ndarray, shape (n_frames, n_controls)
            Control values, columns named by ``names``.
        names : tuple of str
            Column names; every name in :data:`CONTROLS` must be present.

        Returns
        -------
        np.ndarray, shape (n_frames, n_points, 3)
            Positions in millimetres, rigid head motion included.
        """
        col = {name: controls[:, names.index(name)] for name in CONTROLS}
        act = np.stack([col[name] for name in self.linear], axis=1)  # (n_frames, n_linear)
        out = self.rest[None] + np.einsum("tk,kpc->tpc", act, self.fields)

        # The gap (y, z) between the lips after the linear actions, per inner-lip column;
        # lips already pressed together (negative y) are not pulled apart.
        gap = self.column_rest_gap[None] + np.einsum("tk,kcd->tcd", act, self.column_fields)
        gap[..., 0] = np.maximum(gap[..., 0], 0.0)
        frac = self.column_frac[None, :, None]
        g = gap[:, self.column] * (1 - frac) + gap[:, self.column + 1] * frac  # (t, p, 2)
        close = col["lip_close"][:, None, None]
        # Closed lips cannot also tuck: a bilabial beside an F keeps its closure.
        tuck = (col["lip_tuck"] * (1.0 - np.clip(col["lip_close"], 0.0, 1.0)))[:, None, None]
        up, low = self.upper_w[None, :, None], self.lower_w[None, :, None]
        # Closure brings the lips together, the upper lip covering 40 % of the way and the
        # lower 60 %; a tuck lifts the lower lip most of the way and draws it back under
        # the upper teeth while the upper lip lifts a little.
        out[:, :, 1:] += close * g * (0.6 * low - 0.4 * up)
        out[:, :, 1] += tuck[..., 0] * (0.75 * g[..., 0] * self.lower_w + 1.0 * self.upper_w)
        out[:, :, 2] += -4.0 * tuck[..., 0] * self.lower_w
        return rigid_transform(out, col)


def _rotations(pitch: np.ndarray, yaw: np.ndarray, roll: np.ndarray) -> np.ndarray:
    """Rotation matrices, shape (n_frames, 3, 3), from angles in degrees (x, y, z axes)."""
    p, w, r = (np.deg2rad(a) for a in (pitch, yaw, roll))
    cp, sp, cw, sw, cr, sr = np.cos(p), np.sin(p), np.cos(w), np.sin(w), np.cos(r), np.sin(r)
    one, nil = np.ones_like(p), np.zeros_like(p)
    rx = np.stack([one, nil, nil, nil, cp, -sp, nil, sp, cp], -1).reshape(-1, 3, 3)
    ry = np.stack([cw, nil, sw, nil, one, nil, -sw, nil, cw], -1).reshape(-1, 3, 3)
    rz = np.stack([cr, -sr, nil, sr, cr, nil, nil, nil, one], -1).reshape(-1, 3, 3)
    return ry @ rx @ rz


def rigid_transform(points: np.ndarray, col: dict[str, np.ndarray]) -> np.ndarray:
    """Apply the rigid head pose to points of shape (n_frames, n_points, 3).

    A positive ``head_pitch`` tips the face down (a nod).
    """
    rot = _rotations(col["head_pitch"], col["head_yaw"], col["head_roll"])
    trans = np.stack([col["head_tx"], col["head_ty"], col["head_tz"]], axis=1)
    local = points - _HEAD_PIVOT
    return np.einsum("tij,tpj->tpi", rot, local) + _HEAD_PIVOT + trans[:, None, :]


def marker_rest() -> np.ndarray:
    """Rest positions of the markers, shape (n_markers, 3), in millimetres."""
    verts = facemesh.load_canonical_face().vertices
    return verts[[v for _, v, _ in MARKERS]].copy()


def marker_index(label: str) -> int:
    """Column of the marker ``label`` in :data:`MARKERS` order."""
    for i, (name, _, _) in enumerate(MARKERS):
        if name == label:
            return i
    raise KeyError(label)


def marker_distance(markers: np.ndarray, a: str, b: str) -> np.ndarray:
    """Distance between two markers over time, unaffected by rigid head motion.

    Parameters
    ----------
    markers : np.ndarray, shape (n_frames, n_markers, 3)
        Marker positions in :data:`MARKERS` order.
    a, b : str
        Marker labels.

    Returns
    -------
    np.ndarray, shape (n_frames,)
        Millimetres; NaN where either marker is missing.
    """
    return np.linalg.norm(markers[:, marker_index(a)] - markers[:, marker_index(b)], axis=-1)
