"""The independent penetration measure of benchmarks/object_penetration.py against closed forms: a sphere's signed
distances, and a cup (a revolved wall closed at the bottom) whose cavity is outside the solid and whose wall and bottom
are inside at their known depths (the catalogue's cup_01 is where MeshLab's own sign, taken from the nearest face's
normal, called a cavity point 37.7 mm deep: the sign here is trimesh's inside test)."""

from __future__ import annotations

import numpy as np
import trimesh

from benchmarks.object_penetration import depth_mm, signed_distances


def test_sphere_distances_are_the_radius_difference():
    sphere = trimesh.creation.icosphere(5, radius=0.05)
    points = np.array([[0, 0, 0.04], [0, 0.06, 0], [0.03, 0.0, 0.0], [0.0, 0.0, -0.2]])
    expected = np.linalg.norm(points, axis=1) - 0.05
    assert np.allclose(signed_distances(points, sphere), expected, atol=1e-4)
    assert abs(depth_mm(points, sphere)[0] - 20.0) < 0.1


def test_a_cups_cavity_is_outside_and_its_wall_inside():
    # wall 4 mm thick from radius 36 to 40 mm, bottom 5 mm thick, 80 mm tall: (r, z) profile revolved about z
    profile = np.array([[0.0, 0.0], [0.040, 0.0], [0.040, 0.080], [0.036, 0.080], [0.036, 0.005], [0.0, 0.005]])
    cup = trimesh.creation.revolve(profile, sections=128)
    assert cup.is_watertight and cup.volume > 0
    points = np.array([[0.0, 0.0, 0.080],        # on the axis at the rim's height: 36 mm from the wall's rim edge
                       [0.030, 0.0, 0.079],      # inside the cavity just below the rim
                       [0.038, 0.0, 0.040],      # in the middle of the wall: 2 mm deep
                       [0.0, 0.0, 0.0025]])      # in the bottom: 2.5 mm deep
    d = signed_distances(points, cup)
    assert (d[:2] > 0).all()
    assert np.allclose(d[2:], [-0.002, -0.0025], atol=2e-4)
