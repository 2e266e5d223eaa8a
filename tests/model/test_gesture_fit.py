"""Gestures fitted per model: the distance measure in closed form, the fit's Jacobian against finite differences,
the fit on a hand the gestures were not authored on (crossings gone, contacts touching, intent kept, mirror alike),
and the one loader every stage poses gestures through."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import trimesh

from darthand.errors import InputError
from darthand.model.anatomy import angles_to_axis_angle, joint_frames, limits_radians
from darthand.model.forward import forward
from darthand.model.gesture_fit import GestureProblem, fit_gesture
from darthand.model.gestures import GESTURES_FORMAT, angles_to_joints, joints_to_angles, model_gestures
from darthand.model.hand_model import HandModel
from darthand.model.intersections import PARTS, between_digits, face_parts, part_intersections
from darthand.model.layout import FINGER_JOINTS, MANO_PARENTS, NUM_JOINTS, NUM_POSE_FEATURES
from darthand.model.mirror import mirror_model
from darthand.model.npz_io import load_npz, save_npz
from darthand.model.poses import gesture_angles, gesture_contacts
from darthand.model.proximity import PartSurfaces
from darthand.model.regions import ensure_face_labels
from darthand.model.topology import vertex_normals
from darthand.model.wrist import add_wrist
from model.mano_fixture import mano_like_model
from synthetic import tube_hand

R = 0.01  # sphere radius, m


def two_spheres(gap: float) -> HandModel:
    """Two spheres of radius R, the first bound to index1 (part 'index'), the second to middle1 ('middle'),
    their surfaces `gap` apart along X (negative: overlapping by -gap)."""
    s = trimesh.creation.icosphere(subdivisions=4, radius=R)
    v = np.concatenate([s.vertices, s.vertices + [2 * R + gap, 0, 0]])
    f = np.concatenate([s.faces, s.faces + len(s.vertices)])
    w = np.zeros((len(v), NUM_JOINTS))
    w[: len(s.vertices), FINGER_JOINTS["index"][0]] = 1
    w[len(s.vertices):, FINGER_JOINTS["middle"][0]] = 1
    reg = sp.csr_matrix((np.ones(NUM_JOINTS), (np.arange(NUM_JOINTS), np.zeros(NUM_JOINTS, int))),
                        shape=(NUM_JOINTS, len(v)))
    return HandModel.create(v_template=v, faces=f, weights=w, posedirs=np.zeros((len(v), 3, NUM_POSE_FEATURES)),
                            J_regressor=reg, parents=MANO_PARENTS, tip_ids=[0] * 5)


@pytest.mark.parametrize("gap", [2e-3, 0.3e-3, -0.5e-3, -2e-3])
def test_signed_distance_between_spheres_is_the_closed_form(gap):
    """Two spheres whose surfaces are `gap` apart: the smallest signed distance between them is `gap` (negative:
    the depth one sphere reaches into the other), both ways, to the tessellation's sagitta."""
    m = two_spheres(gap)
    surfaces = PartSurfaces(m)
    index, middle = PARTS.index("index"), PARTS.index("middle")
    d = surfaces.distance(m.v_template, vertex_normals(m.v_template, m.faces), index, middle)
    assert d == pytest.approx(gap, abs=0.03e-3)
    assert surfaces.distance(m.v_template, vertex_normals(m.v_template, m.faces), index, PARTS.index("ring")) \
        == np.inf


@pytest.fixture(scope="module")
def thick():
    """The MANO-format fixture 1 mm thicker all round, wrist added and labelled as the model step does: a hand
    on which the authored gestures push digits into each other."""
    return ensure_face_labels(add_wrist(mano_like_model(1.0)))


@pytest.mark.parametrize("correctives, tolerance", [(False, 1e-6), (True, 0.05)])
def test_analytic_jacobian_matches_finite_differences(thick, correctives, tolerance):
    """Exact for linear blend skinning; the correctives' share, which the fit leaves out of its Jacobian, is a few
    per cent in a fist's deep bends."""
    model = thick if correctives else thick.replace(posedirs=np.zeros_like(thick.posedirs))
    frames = joint_frames(model)
    surfaces = PartSurfaces(model)
    for name in ("ok", "fist"):
        contacts = [(PARTS.index(a), PARTS.index(b)) for a, b in gesture_contacts(name)]
        problem = GestureProblem(model, surfaces, frames, gesture_angles(name), contacts, 3e-3, 0.25e-3)
        v, n, _ = problem.pose(problem.authored)
        problem.select(v, n)
        problem.free = problem.involved()
        rng = np.random.default_rng(1)
        x = rng.normal(0, 0.01, len(problem.free))
        columns = rng.choice(len(x), 6, replace=False)
        _, J = problem.evaluate(x)
        h = 1e-6
        numeric = np.stack([(problem.evaluate(x + h * e)[0] - problem.evaluate(x - h * e)[0]) / (2 * h)
                            for e in np.eye(len(x))[columns]], axis=1)
        assert np.linalg.norm(J[:, columns] - numeric) <= tolerance * np.linalg.norm(numeric), name


@pytest.mark.parametrize("name", ["grasp", "ok", "fist", "point"])
def test_fit_separates_the_digits_and_keeps_the_intent(thick, name):
    frames, surfaces, parts = joint_frames(thick), PartSurfaces(thick), face_parts(thick)
    authored = gesture_angles(name)

    def crossing(model, angles):
        v = forward(model, angles_to_axis_angle(model, angles).reshape(1, -1)).vertices[0]
        return part_intersections(v, model.faces, parts)["between"]

    assert crossing(thick, authored), "the authored gesture should cross on this thicker hand"
    fit = fit_gesture(thick, surfaces, frames, name, authored, gesture_contacts(name), parts)
    assert fit.status == "fitted" and fit.crossing == {}
    assert crossing(thick, fit.angles) == {} and crossing(mirror_model(thick), fit.angles) == {}
    delta = np.rad2deg(fit.angles - authored)
    lim = np.rad2deg(limits_radians())
    assert (np.abs(delta) <= 20 + 1e-9).all()
    assert ((np.rad2deg(fit.angles) >= lim[..., 0] - 1e-9) & (np.rad2deg(fit.angles) <= lim[..., 1] + 1e-9)).all()
    hinges = [j for chain in FINGER_JOINTS.values() for j in chain[1:]]
    assert (delta[hinges, :2] == 0).all()                                  # hinges neither twist nor spread
    straight = [f for f, chain in FINGER_JOINTS.items() if f != "thumb" and (authored[list(chain), 2] == 0).all()]
    for finger in straight:                                                # the point's index stays straight
        assert (delta[list(FINGER_JOINTS[finger]), 2] == 0).all(), finger
    v = forward(thick, angles_to_axis_angle(thick, fit.angles).reshape(1, -1)).vertices[0]
    n = vertex_normals(v, thick.faces)
    for a, b in gesture_contacts(name):                                    # contacts touch, not pass through
        assert 0.0 <= surfaces.distance(v, n, PARTS.index(a), PARTS.index(b)) <= 0.6e-3


def record_with(model: HandModel, name: str, angles: np.ndarray) -> HandModel:
    """`model` carrying a fitted-gesture record whose only gesture is `name` at `angles` (16, 3) radians."""
    record = {"format": GESTURES_FORMAT, "version": 1, "gestures": {
        name: {"joints": angles_to_joints(angles), "contacts": [], "status": "fitted", "changed_deg": {},
               "rounds": 1, "clearance_mm": 0.5, "crossing": {}, "at_bound": []}}}
    return model.replace(meta=dict(model.meta, gestures=record))


def test_every_stage_poses_the_models_own_gestures(tmp_path):
    """A model carrying fitted gestures is posed in them -- not in the authored angles -- by export, the
    accessories' sweep, the renderer and the datasets' reference poses; the record survives the npz format."""
    from darthand.accessories.build import sweep_poses
    from darthand.dataset.poses import load_reference
    from darthand.export.gestures import gesture_poses
    from darthand.model.rotations import axis_angle_to_quaternion
    from darthand.render.poses import resolve_pose

    tube = tube_hand(0)
    fitted = gesture_angles("fist")
    fitted[13] += np.deg2rad([7.0, -3.0, 5.0])
    save_npz(record_with(tube, "fist", fitted), tmp_path / "m.npz")
    model = load_npz(tmp_path / "m.npz")
    expected = angles_to_axis_angle(model, fitted).reshape(-1)
    assert not np.allclose(expected, angles_to_axis_angle(model, gesture_angles("fist")).reshape(-1))

    g = model_gestures(model)
    assert g.fitted and g.names == ("fist",)
    np.testing.assert_allclose(g.pose("fist"), expected, atol=1e-12)
    names, poses = gesture_poses(model)
    np.testing.assert_allclose(poses[names.index("fist")], expected, atol=1e-12)
    names, poses = sweep_poses(model, seed=0, n_sampled=0)
    np.testing.assert_allclose(poses[names.index("fist")], expected, atol=1e-12)
    np.testing.assert_allclose(resolve_pose(model, "fist")[0], expected, atol=1e-12)
    reference = load_reference("gestures", model)                        # what datasets draw poses from
    quats = axis_angle_to_quaternion(expected.reshape(16, 3)[1:])
    quats *= np.sign(quats[:, :1]) * np.sign(reference.quats[0, :, :1])  # q and -q are one rotation
    assert reference.names == ("fist",)
    np.testing.assert_allclose(reference.quats[0], quats, atol=1e-6)     # (stored as float32)
    with pytest.raises(InputError, match=r"pose: 'ok' is neither a gesture \(fist\) nor a pose file"):
        resolve_pose(model, "ok")

    plain = model_gestures(tube)                                          # no record: the authored gestures
    assert not plain.fitted and "ok" in plain.names
    np.testing.assert_allclose(plain.angles_of("fist"), gesture_angles("fist"), atol=0)


def test_record_round_trip_and_errors():
    a = np.deg2rad(np.random.default_rng(0).uniform(-20, 20, (NUM_JOINTS, 3)))
    a[3] = 0.0
    np.testing.assert_allclose(joints_to_angles(angles_to_joints(a)), a, rtol=0, atol=1e-15)
    assert "index3" not in angles_to_joints(a)
    tube = tube_hand(0)
    with pytest.raises(InputError, match=r"gesture 'nope': not a gesture of .* \(known: fist\)"):
        model_gestures(record_with(tube, "fist", a), ["nope"])
    with pytest.raises(InputError, match=r"field 'meta.gestures' is not a darthand-fitted-gestures record"):
        model_gestures(tube.replace(meta={"gestures": [1, 2]}))
    bad = record_with(tube, "fist", a)
    bad.meta["gestures"]["gestures"]["fist"]["joints"] = {"index1": {"bend": float("nan")}}
    with pytest.raises(InputError, match=r"index1.bend = nan is not a finite angle"):
        model_gestures(bad)


def test_a_crossing_the_fit_cannot_move_apart_is_unresolved(thick):
    """Digits that cross at rest (the hand pushed 3 mm further out) are beyond what the fit may change: the
    result says so, keeps the least crossing attempt, and names the pairs."""
    fat = ensure_face_labels(add_wrist(mano_like_model(3.0)))
    parts = face_parts(fat)
    fit = fit_gesture(fat, PartSurfaces(fat), joint_frames(fat), "flat", np.zeros((NUM_JOINTS, 3)), [], parts)
    assert fit.status == "unresolved" and between_digits(fit.crossing) > 0
