"""The grasp fit on closed-form cases: a sphere of known radius in a power grasp (contacts at the radius, no vertex
inside by the sphere's own formula), joint limits kept, a grasp that cannot close dropped with why."""

import numpy as np
import pytest

from darthand.grasps.field import ObjectField
from darthand.grasps.fit import MAX_CONTACT, HandRig, fit_grasp
from darthand.grasps.taxonomy import load_taxonomy
from darthand.model.anatomy import within_limits
from darthand.model.forward import forward
from darthand.model.load import open_hand
from grasps.objects_fixture import sphere


@pytest.fixture(scope="module")
def rig():
    taxonomy = load_taxonomy()
    return HandRig.of(open_hand("right"), sorted({p for t in taxonomy.values() for p in t.contacts})), taxonomy


def placed_vertices(model, fit):
    """Hand vertices (V, 3) in the object frame."""
    v = np.asarray(forward(model, fit.pose[None]).vertices[0], np.float64)
    M = np.linalg.inv(fit.placement)
    return v @ M[:3, :3].T + M[:3, 3]


def test_power_grasp_closes_on_a_sphere_at_its_radius(rig):
    rig, taxonomy = rig
    r = 0.035
    ball = sphere(r)
    g = taxonomy["power_sphere"]
    fit = fit_grasp(rig, ObjectField(ball.vertices, ball.faces), g.contacts, g.angles, np.array([1.0, 0, 0]),
                    np.array([0, 0, 1.0]))
    assert fit.dropped is None, fit.dropped
    v = placed_vertices(rig.model, fit)
    inside = r - np.linalg.norm(v, axis=1)            # the sphere's own formula: > 0 inside
    assert inside.max() < 0.5e-3
    gaps = np.linalg.norm(v[fit.contact_vertices], axis=1) - r
    assert np.abs(gaps).max() < 2e-3                  # every contact part at the radius
    assert np.allclose(np.linalg.norm(fit.contact_points, axis=1), r, atol=0.1e-3)
    assert within_limits(fit.angles, tol=1e-6).all()


def test_a_grasp_that_cannot_close_is_dropped_with_why(rig):
    rig, taxonomy = rig
    crumb = sphere(0.002)                             # a 4 mm ball in a whole-hand power grasp
    g = taxonomy["power_sphere"]
    fit = fit_grasp(rig, ObjectField(crumb.vertices, crumb.faces), g.contacts, g.angles, np.array([1.0, 0, 0]),
                    np.array([0, 0, 1.0]))
    assert fit.dropped is not None and "contact" in fit.dropped
    assert max(abs(v) for v in fit.figures["contact_mm"].values()) > MAX_CONTACT * 1e3
