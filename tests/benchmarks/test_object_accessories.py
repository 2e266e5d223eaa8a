"""benchmarks/object_accessories.penetration_mm against closed forms: world points carried into a placed object's
frame (a sphere moved and turned by its placement), and a point in a cup's cavity (outside the solid: MeshLab's own
sign called such points deep inside) measured as not inside."""

from __future__ import annotations

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from benchmarks.object_accessories import penetration_mm


def test_a_placed_spheres_depth_is_its_radius_less_the_distance_to_its_centre():
    sphere = trimesh.creation.icosphere(5, radius=0.05)
    P = np.eye(4)
    P[:3, :3] = Rotation.from_euler("xyz", [0.4, -1.1, 2.0]).as_matrix()
    P[:3, 3] = [0.3, -0.2, 0.5]
    local = np.array([[0.0, 0.0, 0.035], [0.0, 0.08, 0.0]])          # 15 mm inside, 30 mm outside
    world = local @ P[:3, :3].T + P[:3, 3]
    assert abs(penetration_mm(sphere, P, world) - 15.0) < 0.1
    assert penetration_mm(sphere, P, world[1:]) == 0.0


def test_a_point_in_a_cups_cavity_is_not_inside():
    profile = np.array([[0.0, 0.0], [0.040, 0.0], [0.040, 0.080], [0.036, 0.080], [0.036, 0.005], [0.0, 0.005]])
    cup = trimesh.creation.revolve(profile, sections=128)
    P = np.eye(4)
    P[:3, 3] = [0.1, 0.0, 0.0]
    assert penetration_mm(cup, P, np.array([[0.1, 0.0, 0.080], [0.130, 0.0, 0.079]])) == 0.0
    assert abs(penetration_mm(cup, P, np.array([[0.138, 0.0, 0.040]])) - 2.0) < 0.2
