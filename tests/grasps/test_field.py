"""The object's distance field against independent truth: trimesh's exact point-triangle distances over every
face, signed by the generalised winding number (tests/grasps/truth.py), and a sphere's own formula."""

import numpy as np
import pytest
import trimesh

from darthand.errors import InputError
from darthand.grasps.field import EXACT_REACH, SPACING, ObjectField
from grasps.truth import signed_distances

MESHES = {
    "sphere": lambda: trimesh.creation.icosphere(3, 0.03),
    "box": lambda: trimesh.creation.box((0.06, 0.03, 0.12)),
    "cylinder": lambda: trimesh.creation.cylinder(0.02, 0.15, sections=48),   # long thin cap triangles
    "card": lambda: trimesh.creation.box((0.085, 0.054, 0.0008)),            # thinner than a sample spacing
    "annulus": lambda: trimesh.creation.annulus(0.03, 0.04, 0.1),              # concave: a mug without a bottom
    "slivers": lambda: trimesh.creation.annulus(0.035, 0.038, 0.1, sections=64),   # 100 x 3.4 mm side faces
}


@pytest.mark.parametrize("name", sorted(MESHES))
def test_field_matches_exact_signed_distance_near_the_surface(name):
    mesh = MESHES[name]()
    field = ObjectField(mesh.vertices, mesh.faces, name)
    rng = np.random.default_rng(3)
    points = rng.uniform(-1, 1, (400, 3)) * (mesh.extents / 2 + 0.008)
    truth = signed_distances(np.asarray(mesh.vertices), np.asarray(mesh.faces), points)
    near = np.abs(truth) < EXACT_REACH - SPACING     # where a hand touches: within a few mm of the surface
    d = field.distance(points)
    assert near.sum() > 30
    assert np.abs(d - truth)[near].max() < 1e-6
    assert (np.sign(d) == np.sign(truth)).all()


def test_sphere_field_is_radius_less_distance_with_radial_gradient():
    r = 0.04
    mesh = trimesh.creation.icosphere(5, r)      # chords within 0.01 mm of the true sphere
    field = ObjectField(mesh.vertices, mesh.faces)
    rng = np.random.default_rng(0)
    dirs = rng.normal(size=(200, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    radii = rng.uniform(r - 0.01, r + 0.02, 200)
    d, grad, _ = field.query(dirs * radii[:, None])
    assert np.abs(d - (radii - r)).max() < 2e-5
    assert (np.einsum("ij,ij->i", grad, dirs) > 0.99).all()


def test_field_refuses_a_broken_mesh_in_one_line():
    with pytest.raises(InputError, match="non-finite"):
        ObjectField(np.array([[0, 0, 0], [1, 0, 0], [0, np.nan, 0]]), np.array([[0, 1, 2]]), "bad")
