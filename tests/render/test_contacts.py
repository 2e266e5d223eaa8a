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
