"""Two-hand frames (dataset/interactions.py and the plan's two_hands option): every interaction type's frames are
free of penetration by MeshLab's intersection test and trimesh's inside test (independent of the fit's measure),
the contacts a type asks for touch, frames depend only on (seed, index), and a plan without two hands is as before."""

from __future__ import annotations

import numpy as np
import pymeshlab
import pytest
import trimesh
from scipy.spatial import cKDTree
from trimesh.proximity import closest_point_naive

from darthand.dataset import plan
from darthand.dataset.interaction_shares import TYPES, parse_shares
from darthand.dataset.interactions import InteractionSampler
from darthand.errors import InputError
from darthand.model.forward import forward
from darthand.render.contacts import CONTACT_M
from darthand.model.layout import FINGER_JOINTS
from darthand.model.topology import close_loops, vertex_normals

FRAMES_PER_TYPE = 2


@pytest.fixture(scope="module")
def models(sources):
    opened = sources[0]
    return opened["right"].pose_model(), opened["left"].pose_model()


def posed(model, pose, T=None, betas=None) -> np.ndarray:
    v = np.asarray(forward(model, np.asarray(pose).reshape(1, -1), betas).vertices[0], np.float64)
    return v if T is None else v @ np.asarray(T)[:3, :3].T + np.asarray(T)[:3, 3]


def meshlab_crossing(va, fa, vb, fb) -> int:
    """Faces of the two meshes together that MeshLab flags, less those it flags on each mesh alone."""
    def flagged(v, f):
        ms = pymeshlab.MeshSet()
        ms.add_mesh(pymeshlab.Mesh(vertex_matrix=v, face_matrix=f))
        ms.compute_selection_by_self_intersections_per_face()
        return ms.current_mesh().face_selection_array().astype(bool)
    both = flagged(np.concatenate([va, vb]), np.concatenate([fa, fb + len(va)]))
    return int((both & ~np.concatenate([flagged(va, fa), flagged(vb, fb)])).sum())


def trimesh_inside(va, fa, vb, fb) -> int:
    """Vertices of either hand inside the other (trimesh's ray test on the wrist-capped meshes)."""
    n = 0
    for p, (v, f) in ((va, (vb, fb)), (vb, (va, fa))):
        n += int(trimesh.Trimesh(*close_loops(v, f), process=False).contains(p).sum())
    return n


def surface_gap(va, fa, vb) -> float:
    """Smallest distance (m) from hand b's vertices to hand a's surface (trimesh's exact closest point, over the
    vertices within 1 cm of a's)."""
    near = cKDTree(va).query(vb, distance_upper_bound=0.01)[0] < np.inf
    if not near.any():
        return float(cKDTree(va).query(vb)[0].min())
    return float(closest_point_naive(trimesh.Trimesh(va, fa, process=False), vb[near])[1].min())


@pytest.mark.parametrize("fit_digits", [False, True])
@pytest.mark.parametrize("kind", TYPES)
def test_every_type_is_free_of_penetration_and_touches_where_asked(models, kind, fit_digits):
    right, left = models
    sampler = InteractionSampler(right, left, {kind: 1.0}, fit_digits=fit_digits)
    for i in range(FRAMES_PER_TYPE):
        dart = np.zeros(48)
        out = sampler.sample(5, i, 0.5, dart, None)
        T = np.asarray(out["placement"])
        assert np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-9) and np.linalg.det(T[:3, :3]) > 0
        va, vb = posed(right, out["right_pose"]), posed(left, out["left_pose"], T)
        assert meshlab_crossing(va, right.faces, vb, left.faces) == 0
        assert trimesh_inside(va, right.faces, vb, left.faces) == 0
        record = out["record"]
        assert record["resolved"]["resolved"] and record["type"] in TYPES
        gap = surface_gap(va, right.faces, vb)
        if record["type"] == kind and record["contact_parts"]:
            assert gap < CONTACT_M, (kind, gap)       # touching, by the labels' contact distance
        if record["type"] == "apart":
            assert gap > 0.01
        assert ("digits_max_deg" in record["resolved"]) == (fit_digits and record["resolved"]["rounds"] > 0)


def test_the_digit_fit_is_deterministic_and_bends_the_fingers_a_clasp_closes_on(models):
    """With fit_digits the same (seed, index) gives the same poses and placement, the record reports the digits'
    movement, and the job's poses are the fitted ones (not the drawn pre-shape: some finger angle moved)."""
    right, left = models
    fitted = InteractionSampler(right, left, {"clasped": 1.0}, fit_digits=True)
    drawn = InteractionSampler(right, left, {"clasped": 1.0})
    a, b = fitted.sample(4, 1, 0.5, np.zeros(48), None), fitted.sample(4, 1, 0.5, np.zeros(48), None)
    assert all(np.array_equal(a[k], b[k]) for k in ("right_pose", "left_pose", "placement"))
    assert a["record"] == b["record"]
    plain = drawn.sample(4, 1, 0.5, np.zeros(48), None)
    figures = a["record"]["resolved"]
    assert figures["digits_max_deg"] >= figures["digits_mean_deg"] > 0
    if a["record"]["attempts"] == plain["record"]["attempts"]:       # the same draw, then fitted
        assert not np.allclose(a["right_pose"], plain["right_pose"])


def test_two_hand_jobs_depend_only_on_seed_and_index(sources):
    a = plan.Planner({"seed": 2, "two_hands": 1.0, "interactions": "touching=0.5,mirrored=0.5"}, sources[0])
    b = plan.Planner({"seed": 2, "two_hands": 1.0, "interactions": {"touching": 0.5, "mirrored": 0.5}}, sources[0])
    jobs = [a.job(i) for i in (3, 0)]
    assert jobs == [b.job(i) for i in (3, 0)] == [a.job(i) for i in (3, 0)]
    for job in jobs:
        assert [body["side"] for body in job["bodies"]] == ["right", "left"]
        assert "placement" not in job["bodies"][0] and len(job["bodies"][1]["placement"]) == 4
        assert job["interaction"]["type"] in ("touching", "mirrored", "apart")
        assert not {"side", "pose", "texture", "accessory", "betas"} & set(job)
        assert job["bodies"][0]["betas"] == job["bodies"][1]["betas"]                 # one person's hands
        assert job["bodies"][0]["skin_tone_offset"] == job["bodies"][1]["skin_tone_offset"]


def test_without_two_hands_the_plan_is_as_before(sources):
    base = plan.Planner({"seed": 3}, sources[0])
    off = plan.Planner({"seed": 3, "two_hands": 0.0, "interactions": None}, sources[0])
    assert "two_hands" not in off.spec and "interactions" not in off.spec and off.spec == base.spec
    assert plan.PlanOptions().spec() == plan.DEFAULTS
    some = plan.Planner({"seed": 3, "two_hands": 0.3, "interactions": "apart=1"}, sources[0])
    jobs = [some.job(i) for i in range(12)]
    assert any("bodies" in j for j in jobs) and any("bodies" not in j for j in jobs)
    for i, job in enumerate(jobs):
        if "bodies" not in job:
            assert job == base.job(i)                  # one-hand frames draw as without the option


@pytest.mark.parametrize("spec, message", [
    ({"two_hands": 1.5}, "two hands: 1.5 is not a share"),
    ({"two_hands": 0.5, "interactions": "hugging=1"}, "'hugging' is not an interaction type"),
    ({"two_hands": 0.5, "interactions": "apart=0.5,clasped=0.2"}, "shares sum to 0.7, not 1"),
    ({"two_hands": 0.5, "interactions": "apart=-0.5,clasped=1.5"}, "share -0.5 of 'apart' is outside 0..1"),
    ({"two_hands": 0.5, "interactions": "apart"}, "'apart' is not TYPE=SHARE"),
    ({"two_hands": 0.5, "interaction_fit": "wobbly"}, "interaction fit: 'wobbly' is not one of digits, rigid"),
])
def test_bad_two_hand_options_are_one_line(spec, message):
    with pytest.raises(InputError, match=message) as e:
        plan.plan_spec(**spec)
    assert "\n" not in str(e.value)


def test_the_plan_fits_the_digits_unless_asked_for_a_rigid_fit(sources):
    """The plan's jobs carry the digit fit's figures by default and not with interaction_fit 'rigid'; the option is in
    the plan document only with two hands."""
    spec = {"seed": 4, "two_hands": 1.0, "interactions": "clasped=1"}
    digits, rigid = plan.Planner(spec, sources[0]), plan.Planner({**spec, "interaction_fit": "rigid"}, sources[0])
    assert digits.spec["interaction_fit"] == "digits" and rigid.spec["interaction_fit"] == "rigid"
    fitted, moved = digits.job(0)["interaction"], rigid.job(0)["interaction"]
    assert "digits_max_deg" in fitted["resolved"] and "digits_max_deg" not in moved["resolved"]


def test_two_hands_need_both_sides(sources):
    with pytest.raises(InputError, match="needs both sides"):
        plan.Planner({"two_hands": 0.5}, {"right": sources[0]["right"]})


def test_shares_default_to_equal():
    assert parse_shares(None) == pytest.approx({t: 1 / len(TYPES) for t in TYPES})


def test_a_type_that_never_resolves_falls_back_to_apart(models, monkeypatch):
    right, left = models
    sampler = InteractionSampler(right, left, {"clasped": 1.0})
    original = sampler.draw
    monkeypatch.setattr(sampler, "draw", lambda kind, *a: None if kind == "clasped" else original(kind, *a))
    out = sampler.sample(1, 0, 0.5, np.zeros(48), None)
    assert out["record"]["type"] == "apart" and out["record"]["redrawn_from"] == "clasped"
    assert out["record"]["attempts"] == 4 and out["record"]["resolved"]["resolved"]
    va, vb = posed(right, out["right_pose"]), posed(left, out["left_pose"], out["placement"])
    assert trimesh_inside(va, right.faces, vb, left.faces) == 0


@pytest.mark.parametrize("kind", ["touching", "clasped", "interlaced"])
def test_a_mirrored_preshape_is_the_mirror_image_hand(models, kind):
    """One self-crossing test covers both pre-shaped hands: with the build's left model (the right's mirror image),
    the left hand of a symmetric type is the right hand reflected (x -> -x) vertex for vertex, and MeshLab finds the
    same self-intersecting faces on both."""
    from darthand.model.intersections import self_intersecting

    right, left = models
    sampler = InteractionSampler(right, left, {kind: 1.0})
    assert sampler.mirrored
    r, left_pose, shaped = sampler.poses(kind, np.random.default_rng(5), np.zeros(48))
    assert shaped == (True, False)
    vr, vl = posed(right, r), posed(left, left_pose)
    np.testing.assert_allclose(vl, vr * [-1, 1, 1], atol=1e-9)
    assert (self_intersecting(vr, right.faces) == self_intersecting(vl, left.faces)).all()


@pytest.mark.parametrize("fit_digits", [False, True])
@pytest.mark.parametrize("kind,wearer", [("clasped", "right"), ("holding", "right"), ("clasped", "left")])
def test_a_worn_ring_stays_out_of_the_other_hand(sources, kind, wearer, fit_digits):
    """The ring a hand wears (as its source poses it for the renderer) crosses no face of the other hand (MeshLab)
    and neither has a vertex inside the other (trimesh's ray test; the ring a closed mesh, the hand wrist-capped).
    With the digits fitted, the wearing hand's are held (its ring posed as drawn) and the other's fitted."""
    opened = sources[0]
    right, left = opened["right"].pose_model(), opened["left"].pose_model()
    sampler = InteractionSampler(right, left, {kind: 1.0}, opened, fit_digits=fit_digits)
    for i in range(FRAMES_PER_TYPE):
        d = sampler.sample(2, i, 0.5, np.zeros(48), None, "ring_test", wearer)
        pose = d["right_pose"] if wearer == "right" else d["left_pose"]
        ring = opened[wearer].subject(pose, accessory="ring_test").accessory
        T = np.eye(4) if wearer == "right" else np.asarray(d["placement"])
        vr = np.asarray(ring.vertices, np.float64) @ T[:3, :3].T + T[:3, 3]
        fr = np.asarray(ring.faces, np.int64)
        other = (left, d["left_pose"], d["placement"]) if wearer == "right" else (right, d["right_pose"], None)
        vo, fo = posed(other[0], other[1], other[2]), other[0].faces
        assert meshlab_crossing(vr, fr, vo, fo) == 0, (kind, wearer, i)
        assert int(trimesh.Trimesh(*close_loops(vo, fo), process=False).contains(vr).sum()) == 0
        assert int(trimesh.Trimesh(vr, fr, process=False).contains(vo).sum()) == 0


def flanked_vertices(right_v, right_joints, left_v, left_joints, finger: str, tube=3e-3, reach=25e-3) -> int:
    """Vertices of the left hand's `finger` that have a right-hand finger vertex on either side of them along the
    spread axis (Z: the fingers' row), at the same place along the fingers and the palm normal (within `tube` m in X
    and Y) and within `reach` m: where the finger lies between two of the other hand's fingers."""
    fingers = [j for f in ("index", "middle", "ring", "pinky") for j in FINGER_JOINTS[f]]
    q = right_v[np.isin(right_joints, fingers)]
    p = left_v[np.isin(left_joints, FINGER_JOINTS[finger])]
    beside = ((np.abs(q[None, :, 0] - p[:, None, 0]) < tube) & (np.abs(q[None, :, 1] - p[:, None, 1]) < tube))
    dz = q[None, :, 2] - p[:, None, 2]
    beside &= np.abs(dz) < reach
    return int(((beside & (dz > 0)).any(1) & (beside & (dz < 0)).any(1)).sum())


def test_interlaced_fingers_pass_between_the_other_hands(models):
    """Interlaced: the left hand's index and middle fingers each lie between two right-hand fingers (measured along
    the spread axis, at the same height and place along the fingers) in every frame; touching frames, palms facing
    too, have no such finger."""
    right, left = models
    jr, jl = np.argmax(right.weights, 1), np.argmax(left.weights, 1)
    for kind, expect in (("interlaced", True), ("touching", False)):
        sampler = InteractionSampler(right, left, {kind: 1.0})
        for i in range(3):
            d = sampler.sample(4, i, 0.5, np.zeros(48), None)
            assert d["type"] == kind
            vr, vl = posed(right, d["right_pose"]), posed(left, d["left_pose"], d["placement"])
            counts = [flanked_vertices(vr, jr, vl, jl, f) for f in ("index", "middle")]
            assert all(c >= 5 for c in counts) if expect else sum(counts) < 5, (kind, i, counts)


def test_the_fit_keeps_a_body_off_the_worn_ring(sources):
    """A sphere laid 0.5 mm into the top of a worn ring, clear of the skin: the hand alone is already resolved (the
    sphere stays, through the ring), the hand with its ring (hand_pair.combined_hand, as the sampler measures a
    wearing hand) moves it off: no face of the ring crosses the moved sphere (MeshLab), no vertex of either is inside
    the other (trimesh)."""
    from darthand.model import hand_pair

    opened = sources[0]
    right = opened["right"].pose_model()
    subject = opened["right"].subject(np.zeros(48), accessory="ring_test")
    ring = subject.accessory
    vr, fr = np.asarray(ring.vertices, np.float64), np.asarray(ring.faces, np.int64)
    hand = hand_pair.pose_hand(right, np.zeros(48))
    worn = hand_pair.combined_hand([s for s in subject.surfaces if s.role in ("hand", "accessory")], hand,
                                   subject.info["accessory_parent_joint"])
    top = vr[np.argmax(vr[:, 1])]
    radius = 0.02
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=radius)
    vs = np.asarray(sphere.vertices) + top + [0, radius - 0.5e-3, 0]
    fs = np.asarray(sphere.faces)
    ball = hand_pair.PosedHand(vs, fs, vertex_normals(vs, fs), np.zeros(len(vs), np.int64),
                               np.zeros(len(fs), np.int64))
    assert meshlab_crossing(vr, fr, vs, fs) > 0                        # the ring is in the ball to start with
    bare = hand_pair.resolve(hand, ball)
    assert bare.resolved and np.allclose(bare.T, np.eye(4))             # the skin alone sees nothing to resolve
    fitted = hand_pair.resolve(worn, ball)
    assert fitted.resolved
    moved = vs @ fitted.T[:3, :3].T + fitted.T[:3, 3]
    assert meshlab_crossing(vr, fr, moved, fs) == 0
    assert int(trimesh.Trimesh(moved, fs, process=False).contains(vr).sum()) == 0
    assert int(trimesh.Trimesh(vr, fr, process=False).contains(moved).sum()) == 0


def test_two_hand_jobs_with_a_worn_accessory_depend_only_on_seed_and_index(sources):
    """With an accessory on every frame (the wearing hand measured with it), frame i is the same whatever was
    planned before it, and exactly one hand wears the frame's accessory."""
    spec = {"seed": 4, "two_hands": 1.0, "accessory_share": 1.0, "interactions": "clasped=1"}
    a, b = plan.Planner(spec, sources[0]), plan.Planner(spec, sources[0])
    forward_order = [a.job(i) for i in (0, 1, 2)]
    assert forward_order[::-1] == [b.job(i) for i in (2, 1, 0)]
    for job in forward_order:
        worn = [body["accessory"] for body in job["bodies"] if body["accessory"] != "none"]
        assert worn == ["ring_test"] and job["interaction"]["resolved"]["resolved"]
