"""The face rig and the coarticulation model, on known answers."""

from __future__ import annotations

import numpy as np
import pytest

from db.errors import ParameterError
from ingest import facemesh
from ingest.corpus import articulation, face
from ingest.speech.phones import PHONES


def _controls(n=1, **values):
    c = np.zeros((n, len(face.CONTROLS)))
    for name, v in values.items():
        c[:, face.CONTROLS.index(name)] = v
    return c


@pytest.fixture(scope="module")
def rig():
    return face.FaceRig.for_points(face.marker_rest())


def test_markers_sit_on_mesh_vertices_in_three_groups():
    verts = facemesh.load_canonical_face().vertices
    assert verts.shape == (468, 3)
    labels = [m[0] for m in face.MARKERS]
    assert len(set(labels)) == len(labels) >= 60
    assert len({m[1] for m in face.MARKERS}) == len(labels)
    assert {m[2] for m in face.MARKERS} == set(face.MOTION_GROUPS)
    np.testing.assert_array_equal(face.marker_rest(), verts[[m[1] for m in face.MARKERS]])


def test_zero_controls_give_the_rest_pose(rig):
    np.testing.assert_allclose(rig.pose(_controls(3))[1], face.marker_rest(), atol=1e-12)


@pytest.mark.parametrize("jaw", [0.0, 0.3, 0.7, 1.0])
def test_full_closure_closes_the_lips_at_any_jaw_opening(rig, jaw):
    pose = rig.pose(_controls(jaw_open=jaw, lip_close=1.0))
    gap = face.marker_distance(pose, "ulip_in_c", "llip_in_c")[0]
    assert gap < 0.05
    open_ = face.marker_distance(rig.pose(_controls(jaw_open=jaw)), "ulip_in_c", "llip_in_c")[0]
    assert open_ > 5.0 + 10.0 * jaw  # rest gap is 5.5 mm; the jaw drops 14 mm at 1.0


def test_actions_move_what_they_name(rig):
    def y(pose, label):
        return pose[0, face.marker_index(label), 1]

    rest = rig.pose(_controls())
    assert y(rig.pose(_controls(smile=1)), "lip_corner_l") > y(rest, "lip_corner_l") + 4
    depressed = rig.pose(_controls(lip_corner_depress=1))
    assert y(depressed, "lip_corner_l") < y(rest, "lip_corner_l") - 3
    assert y(rig.pose(_controls(brow_raise=1)), "brow_l3") > y(rest, "brow_l3") + 4
    assert y(rig.pose(_controls(brow_lower=1)), "brow_l1") < y(rest, "brow_l1") - 4
    blink = face.marker_distance(rig.pose(_controls(blink=1)), "lid_up_r", "lid_low_r")[0]
    assert blink < 1.5  # mm; the lids also differ by 1 mm in depth
    width = face.marker_distance(rig.pose(_controls(lip_round=1)), "lip_corner_r", "lip_corner_l")
    assert width[0] < 0.85 * face.marker_distance(rest, "lip_corner_r", "lip_corner_l")[0]


def test_expressions_leave_the_rigid_group_alone(rig):
    head = [i for i, m in enumerate(face.MARKERS) if m[2] == "head"]
    every = _controls(**{name: 1.0 for name in face.SPEECH_CONTROLS + face.EMOTION_CONTROLS},
                      blink=1.0)
    np.testing.assert_allclose(rig.pose(every)[0, head], face.marker_rest()[head], atol=1e-4)


def test_a_nod_rotates_the_face_down(rig):
    pose = rig.pose(_controls(head_pitch=5.0))
    chin = face.marker_index("chin_tip")
    assert pose[0, chin, 1] < face.marker_rest()[chin, 1] - 1.0


def test_rig_evaluates_on_every_mesh_vertex():
    verts = facemesh.load_canonical_face().vertices
    pose = face.FaceRig.for_points(verts).pose(_controls(jaw_open=0.5, smile=0.5))
    assert pose.shape == (1, 468, 3) and np.isfinite(pose).all()


# --- coarticulation ----------------------------------------------------------------


def test_every_phone_has_articulatory_targets():
    assert set(articulation.PHONE_TARGETS) == set(PHONES)


def test_bilabial_closes_between_open_vowels_and_releases_for_them():
    phones = [("SIL", 0.0, 0.2), ("AA", 0.2, 0.35), ("B", 0.35, 0.42), ("AA", 0.42, 0.57),
              ("SIL", 0.57, 0.8)]
    times = np.array([0.275, 0.385, 0.495])  # centres of AA, B, AA
    c = articulation.speech_controls(phones, times)
    close = c[:, face.SPEECH_CONTROLS.index("lip_close")]
    jaw = c[:, face.SPEECH_CONTROLS.index("jaw_open")]
    assert close[1] > 0.9
    assert close[0] < 0.2 and close[2] < 0.2
    assert jaw[0] > 1.5 * jaw[1]


def test_coarticulation_colours_a_vowel_by_its_neighbours():
    t = np.array([0.3])
    rounded = articulation.speech_controls(
        [("W", 0.2, 0.26), ("AH", 0.26, 0.34), ("W", 0.34, 0.40)], t)
    plain = articulation.speech_controls(
        [("T", 0.2, 0.26), ("AH", 0.26, 0.34), ("T", 0.34, 0.40)], t)
    r = face.SPEECH_CONTROLS.index("lip_round")
    assert rounded[0, r] > plain[0, r] + 0.3  # schwa between W's is rounded


def test_unknown_phone_is_refused():
    with pytest.raises(ParameterError, match="ARPAbet"):
        articulation.speech_controls([("XX", 0.0, 0.1)], np.array([0.05]))
