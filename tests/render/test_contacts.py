"""render/contacts.py against closed forms: points near and inside a sphere's mesh (distance |r - R| to a sphere of
radius R, fine enough that the mesh is within 0.1 mm of it)."""

from __future__ import annotations

import numpy as np
import trimesh

from darthand.render.contacts import CONTACT_M, contact_vertices, surface_distance, winding_number

R = 0.03            # every point inside within INSIDE_REACH_M of the surface, as in a hand


def test_contacts_are_the_points_near_or_inside_a_sphere():
    sphere = trimesh.creation.icosphere(5, R)
    assert np.abs(np.linalg.norm(sphere.triangles_center, axis=1) - R).max() < 1e-4
    rng = np.random.default_rng(0)
    directions = rng.normal(size=(600, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    radii = rng.uniform(0.0, 2 * R, 600)
    radii = radii[np.abs(np.abs(radii - R) - CONTACT_M) > 2e-4]          # clear of the threshold by the mesh error
    points = directions[:len(radii)] * radii[:, None]
    expected = np.flatnonzero((radii <= R) | (np.abs(radii - R) <= CONTACT_M))
    assert contact_vertices(points, sphere.vertices, sphere.faces).tolist() == expected.tolist()
    assert np.abs(surface_distance(points, sphere.triangles) - np.abs(radii - R)).max() < 1e-4
    assert ((winding_number(points, sphere.triangles) > 0.5) == (radii < R)).all()


def test_nothing_touches_a_mesh_far_away():
    sphere = trimesh.creation.icosphere(2, R)
    assert contact_vertices(sphere.vertices + [1.0, 0, 0], sphere.vertices, sphere.faces).size == 0


def _exact_winding(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """The winding number summed over every triangle (Van Oosterom-Strackee), in numpy: the far field's reference."""
    a, b, c = (triangles[None, :, k] - points[:, None] for k in range(3))
    la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
    num = np.einsum("pfi,pfi->pf", a, np.cross(b, c))
    den = (la * lb * lc + np.einsum("pfi,pfi->pf", a, b) * lc + np.einsum("pfi,pfi->pf", b, c) * la
           + np.einsum("pfi,pfi->pf", c, a) * lb)
    return 2 * np.arctan2(num, den).sum(1) / (4 * np.pi)


def test_the_far_field_winding_number_of_a_hand_is_the_exact_sums():
    """Around a posed hand (open at its wrist cut): within 0.03 of the triangle-by-triangle sum everywhere, and the
    same inside/outside verdict for every point farther than CONTACT_M from the surface (nearer ones are contacts
    whatever the verdict)."""
    from darthand.model.forward import forward
    from darthand.model.load import load_model
    from darthand.model.wrist import add_wrist

    hand = add_wrist(load_model("open"))
    pose = np.zeros(48)
    pose[3:] = np.random.default_rng(1).normal(scale=0.3, size=45)
    vertices = np.asarray(forward(hand, pose[None]).vertices[0], np.float64)
    triangles = np.ascontiguousarray(vertices[np.asarray(hand.faces)])
    rng = np.random.default_rng(2)
    points = vertices[rng.integers(0, len(vertices), 1500)] + rng.normal(scale=0.01, size=(1500, 3))
    exact = np.concatenate([_exact_winding(points[k:k + 250], triangles) for k in range(0, 1500, 250)])
    fast = winding_number(points, triangles)
    apart = surface_distance(points, triangles) > CONTACT_M
    assert np.abs(fast - exact).max() < 0.03
    assert ((fast > 0.5) == (exact > 0.5))[apart].all() and 100 < (exact > 0.5).sum() < 1400
