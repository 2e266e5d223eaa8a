"""Rigid attachment across poses and the penetration measures against closed-form cases."""

import numpy as np
import pytest
import trimesh

from darthand.accessories.attach import apply, axis_distance, posed_placement, to_local
from darthand.accessories.collide import ClosedHand, Solid, glove_penetration, surface_distance
from darthand.accessories.fit import RING_JOINTS, fit_ring
from darthand.model.forward import forward
from darthand.model.layout import MANO_PARENTS
from darthand.model.wrist import add_wrist
from synthetic import tube_hand


@pytest.mark.parametrize("finger", ["index", "thumb"])
def test_ring_keeps_its_distance_to_the_bone_axis(finger):
    hand = add_wrist(tube_hand(0), rings=4, length=0.05)
    fit = fit_ring(hand, finger, 0.003, 0.0005)
    j = RING_JOINTS[finger]
    child = int(np.where(MANO_PARENTS == j)[0][0])
    posed = forward(hand, 0.5 * np.random.default_rng(3).standard_normal((20, 48)))
    M = posed_placement(posed.transforms, j, fit.rest)
    # Independent truth: the bone axis through the posed joints the forward pass reports.
    d = axis_distance(M[:, :3, 3], posed.joints[:, j], posed.joints[:, child])
    assert np.allclose(d, fit.axis_distance, atol=1e-12)
    # And the placement is rigid: pairwise distances of placed points are those of the rest points.
    pts = np.random.default_rng(0).standard_normal((5, 3)) * 0.01
    placed = apply(M, pts)
    assert np.allclose(np.linalg.norm(placed[:, 0] - placed[:, 1], axis=-1), np.linalg.norm(pts[0] - pts[1]))
    assert np.allclose(to_local(M, placed), pts)


@pytest.mark.parametrize("d", [0.0005, 0.002, 0.004])
def test_sphere_pushed_into_a_box_by_d_has_depth_d(d):
    box = trimesh.creation.box(extents=[0.02, 0.02, 0.02])             # faces at +-10 mm
    r = 0.005
    sphere = trimesh.creation.uv_sphere(radius=r, count=[32, 32])     # poles on the z axis
    sphere.apply_translation([0, 0, 0.01 + r - d])                     # lowest pole at z = 10 mm - d
    solid = Solid(box.vertices, box.faces)
    assert solid.max_depth(sphere.vertices) == pytest.approx(d, abs=1e-12)
    # Pulled out of the box: nothing inside.
    assert solid.max_depth(sphere.vertices + [0, 0, d + 1e-4]) == 0.0


def test_surface_distance_matches_closed_form():
    box = trimesh.creation.box(extents=[2.0, 2.0, 2.0])
    pts = np.array([[0.0, 0.0, 0.0], [0.5, 0.2, -0.1], [3.0, 0.0, 0.0], [2.0, 2.0, 1.0]])
    want = [1.0, 0.5, 2.0, np.sqrt(2.0)]
    assert surface_distance(pts, box.vertices, box.faces) == pytest.approx(want, abs=1e-12)


def test_closed_hand_caps_the_open_end():
    hand = add_wrist(tube_hand(0), rings=4, length=0.05)
    closed = ClosedHand(hand.faces)
    v = closed.vertices(hand.v_template)
    tm = trimesh.Trimesh(v, closed.faces, process=False)
    assert tm.is_watertight and tm.volume > 0
    # The tube's axis just inside the forearm end is inside the capped hand; outside the radius is not.
    end = hand.v_template[:, 0].max()
    solid = closed.solid(hand.v_template)
    assert len(solid.inside(np.array([[end - 0.002, 0, 0], [end - 0.002, 0.05, 0]]))) == 1


def _shell(inner_r, outer_r):
    inner = trimesh.creation.icosphere(subdivisions=3, radius=inner_r)
    outer = trimesh.creation.icosphere(subdivisions=3, radius=outer_r)
    verts = np.concatenate([outer.vertices, inner.vertices])
    faces = np.concatenate([outer.faces, inner.faces[:, ::-1] + len(outer.vertices)])
    inner_mask = np.r_[np.zeros(len(outer.faces), bool), np.ones(len(inner.faces), bool)]
    return verts, faces, inner_mask


def test_glove_measure_inside_into_and_through():
    hand = trimesh.creation.icosphere(subdivisions=2, radius=0.01)
    pts, nrm = hand.vertices, hand.vertex_normals
    verts, faces, inner = _shell(0.0105, 0.0115)                        # hand in the hollow
    assert glove_penetration(verts, faces, inner, pts, nrm) == (0.0, 0.0)
    verts, faces, inner = _shell(0.0095, 0.0105)                       # 0.5 mm into the material
    into, through = glove_penetration(verts, faces, inner, pts, nrm)
    assert into == pytest.approx(0.0005, abs=3e-5) and through == 0.0
    verts, faces, inner = _shell(0.008, 0.009)                          # 1 mm through the outer surface
    into, through = glove_penetration(verts, faces, inner, pts, nrm)
    assert through == pytest.approx(0.001, abs=5e-5) and into == pytest.approx(0.002, abs=5e-5)


def test_inside_matches_closed_form_spheres_and_their_union():
    """The exit test (first face met, both ways) against the closed form on a sphere, and on two overlapping
    spheres (a self-intersecting surface, like a posed hand whose fingers cross): inside either is inside, where
    plain ray parity calls the overlap outside."""
    rng = np.random.default_rng(5)
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.01)
    pts = rng.uniform(-0.012, 0.012, (4000, 3))
    r = np.linalg.norm(pts, axis=1)
    solid = Solid(sphere.vertices, sphere.faces)
    inside = np.zeros(len(pts), bool)
    inside[solid.inside(pts)] = True
    clear = np.abs(r - 0.01) > 1e-4                  # the icosphere's facets sit within 0.1 mm of the sphere
    assert np.array_equal(inside[clear], r[clear] < 0.01)
    both = trimesh.util.concatenate([sphere, sphere.copy().apply_translation([0.006, 0, 0])])
    solid = Solid(both.vertices, both.faces)
    got = np.zeros(len(pts), bool)
    got[solid.inside(pts)] = True
    r2 = np.linalg.norm(pts - [0.006, 0, 0], axis=1)
    clear &= np.abs(r2 - 0.01) > 1e-4
    assert np.array_equal(got[clear], ((r < 0.01) | (r2 < 0.01))[clear])
    overlap = clear & (r < 0.01) & (r2 < 0.01)
    assert overlap.sum() > 100 and not both.ray.contains_points(pts[overlap]).any()


def test_all_hits_meets_every_layer_in_order():
    """Rays along +x through three nested boxes meet six faces at the closed-form distances, nearest first."""
    boxes = trimesh.util.concatenate([trimesh.creation.box(extents=[s] * 3) for s in (0.01, 0.02, 0.03)])
    solid = Solid(boxes.vertices, boxes.faces)
    origins = np.array([[-0.02, 0.001, 0.002], [-0.02, -0.003, 0.001]])
    rid, face, dist = solid.all_hits(origins, np.tile([1.0, 0, 0], (2, 1)), reach=1.0)
    for k in range(2):
        want = np.array([0.005, 0.01, 0.015, 0.025, 0.03, 0.035])
        assert np.allclose(dist[rid == k], want, atol=1e-6)
    rid, _, dist = solid.all_hits(origins, np.tile([1.0, 0, 0], (2, 1)), reach=0.012)
    assert np.allclose(dist, [0.005, 0.01, 0.005, 0.01], atol=1e-6)
