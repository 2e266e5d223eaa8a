"""model/hand_pair.py: penetration between two posed surfaces against closed forms (two spheres overlapping by a
known depth, apart by a known gap) and trimesh's inside test; the rigid resolution on spheres and on two hands."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from darthand.model import hand_pair as hp
from darthand.model.load import load_model
from darthand.model.topology import close_loops, vertex_normals
from darthand.render.contacts import CONTACT_M, contact_vertices

R = 0.02                       # m: sphere radius
TESSELLATION = 0.2e-3          # m: an icosphere of 4 subdivisions of radius R lies within this of the true sphere


def sphere(centre) -> hp.PosedHand:
    m = trimesh.creation.icosphere(subdivisions=4, radius=R)
    v = np.asarray(m.vertices) + centre
    f = np.asarray(m.faces)
    return hp.PosedHand(v, f, vertex_normals(v, f), np.zeros(len(v), np.int64), np.zeros(len(f), np.int64))


def inside_trimesh(a: hp.PosedHand, b: hp.PosedHand) -> int:
    """Vertices of a inside b and of b inside a, by trimesh's ray test on the closed meshes (independent)."""
    n = 0
    for p, q in ((a, b), (b, a)):
        mesh = trimesh.Trimesh(*close_loops(q.vertices, q.faces), process=False)   # the wrist capped
        assert mesh.is_watertight
        n += int(mesh.contains(p.vertices).sum())
    return n


@pytest.mark.parametrize("depth", [1e-3, 4e-3, 8e-3])
def test_spheres_overlapping_by_a_known_depth(depth):
    a, b = sphere([0, 0, 0]), sphere([2 * R - depth, 0, 0])
    pen = hp.penetration(a, b)
    assert pen.max_m == pytest.approx(depth, abs=TESSELLATION)
    assert pen.inside > 0 and pen.crossing_faces > 0


@pytest.mark.parametrize("gap", [0.5e-3, 5e-3, 50e-3])
def test_spheres_apart_by_a_known_gap(gap):
    a, b = sphere([0, 0, 0]), sphere([2 * R + gap, 0, 0])
    pen = hp.penetration(a, b)
    assert pen.clear and pen.max_m == 0
    assert inside_trimesh(a, b) == 0
    assert hp.first_contact_shift(a, b, np.array([-1.0, 0, 0])) == pytest.approx(gap, abs=2 * TESSELLATION)
    assert (len(contact_vertices(a.vertices, b.vertices, b.faces)) > 0) == (gap < CONTACT_M)


def test_resolving_two_overlapping_spheres_moves_one_off_by_the_depth():
    depth = 5e-3
    a, b = sphere([0, 0, 0]), sphere([2 * R - depth, 0, 0])
    res = hp.resolve(a, b)
    moved = b.moved(res.T)
    assert res.resolved and res.after.clear and inside_trimesh(a, moved) == 0
    gap = np.linalg.norm(moved.vertices.mean(0)) - 2 * R
    assert hp.CLEARANCE - TESSELLATION <= gap <= hp.CLEARANCE + 2 * hp.STEP + TESSELLATION


def test_a_contact_asked_for_ends_touching():
    a, b = sphere([0, 0, 0]), sphere([2 * R + 0.01, 0.003, 0])
    res = hp.resolve(a, b, touch=[(None, None)])
    moved = b.moved(res.T)
    assert res.resolved and inside_trimesh(a, moved) == 0
    assert res.contacts[0] == pytest.approx(hp.CONTACT_GAP, abs=0.3e-3)
    assert len(contact_vertices(moved.vertices, a.vertices, a.faces)) > 0


@pytest.fixture(scope="module")
def hands():
    return load_model("open"), load_model("open-left")


def test_a_hand_pushed_into_another_is_found_and_resolved(hands):
    right, left = hands
    a = hp.pose_hand(right, np.zeros(48))
    T = np.diag([-1.0, -1.0, 1.0, 1.0])                      # palms facing
    b = hp.pose_hand(left, np.zeros(48), T=T)
    shift = hp.first_contact_shift(a, b, np.array([0.0, 1.0, 0.0]))
    T[1, 3] = shift + 3e-3                                    # 3 mm past first contact: into the other palm
    b = hp.pose_hand(left, np.zeros(48), T=T)
    pen = hp.penetration(a, b)
    assert pen.crossing_faces > 0 and inside_trimesh(a, b) > 0
    assert 1e-3 < pen.max_m < 4e-3
    res = hp.resolve(a, b, touch=[((0,), (0,))])
    moved = b.moved(res.T)
    assert res.resolved and hp.penetration(a, moved).clear and inside_trimesh(a, moved) == 0
    assert res.contacts[0] == pytest.approx(hp.CONTACT_GAP, abs=0.5e-3)


def test_nearest_point_kernel_matches_trimesh():
    """pair_kernels.nearest_on_candidates (the compiled inner step of Surface) against trimesh's exact closest point,
    every triangle a candidate, on points near, on and far from a random soup (vertex, edge and face regions)."""
    from trimesh.proximity import closest_point_naive

    from darthand.model.pair_kernels import nearest_on_candidates

    rng = np.random.default_rng(3)
    tris = rng.normal(size=(40, 3, 3)) * 0.01
    points = rng.normal(size=(300, 3)) * 0.02
    cand = np.tile(np.arange(len(tris)), (len(points), 1))
    best, bary, dist = nearest_on_candidates(tris, cand, points)
    mesh = trimesh.Trimesh(tris.reshape(-1, 3), np.arange(len(tris) * 3).reshape(-1, 3), process=False)
    closest, exact, _ = closest_point_naive(mesh, points)
    np.testing.assert_allclose(dist, exact, atol=1e-12)
    on = np.einsum("pk,pkd->pd", bary, tris[cand[np.arange(len(points)), best]])
    np.testing.assert_allclose(on, closest, atol=1e-9)
    assert (bary >= -1e-12).all() and np.allclose(bary.sum(1), 1)
