"""Sections and fitting against closed forms: a cylinder of known radius, an elliptic cylinder, the tube hand."""

import numpy as np
import pytest
import trimesh

from darthand.accessories.fit import fit_wrist, wrist_axis
from darthand.accessories.measure import enclosing_circle, enclosing_ellipse, section_points
from darthand.accessories.mesh import frame_matrix
from darthand.errors import InputError
from darthand.model.wrist import add_wrist
from synthetic import tube_hand

AXIS_FRAME = frame_matrix([0.0, 0.0, 0.0], [1, 0, 0], [0, 1, 0])


def x_cylinder(radius, sections=64, length=0.05, scale_z=1.0):
    """A closed cylinder along X (trimesh builds it along Z; rotate Z -> X), optionally squashed in z."""
    c = trimesh.creation.cylinder(radius=radius, height=length, sections=sections)
    c.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))
    c.vertices[:, 2] *= scale_z
    return c


def test_cylinder_section_has_the_cylinders_radius():
    c = x_cylinder(0.009)
    pts = section_points(c.vertices, c.faces, AXIS_FRAME, offsets=(-0.01, 0.0, 0.01))
    centre, r = enclosing_circle(pts)
    assert r == pytest.approx(0.009, abs=1e-9)             # polygon vertices lie on the circle
    assert np.linalg.norm(centre) < 1e-9


def test_ellipse_fit_of_an_elliptic_cylinder():
    c = x_cylinder(0.03, sections=128, scale_z=0.7)          # half-axes 30 mm along y, 21 mm along z
    pts = section_points(c.vertices, c.faces, AXIS_FRAME)
    centre, a, b = enclosing_ellipse(pts)
    assert a == pytest.approx(0.03, rel=2e-3) and b == pytest.approx(0.021, rel=2e-3)
    assert (np.sqrt((pts[:, 0] / a) ** 2 + (pts[:, 1] / b) ** 2) <= 1 + 1e-9).all()


def test_section_keeps_the_loop_around_the_axis():
    """Two parallel cylinders: the section of the one the axis runs through, not the other."""
    a, b = x_cylinder(0.008), x_cylinder(0.008)
    b.vertices[:, 1] += 0.03
    both = trimesh.util.concatenate([a, b])
    pts = section_points(both.vertices, both.faces, AXIS_FRAME)
    assert np.abs(pts).max() == pytest.approx(0.008, abs=1e-9)


def test_plane_missing_the_mesh_is_an_input_error():
    c = x_cylinder(0.009, length=0.01)
    with pytest.raises(InputError, match="no closed section"):
        section_points(c.vertices, c.faces, AXIS_FRAME, offsets=(0.02,), what="ring_x")


@pytest.mark.parametrize("clearance", [0.0, 0.0015, 0.004])
def test_wrist_fit_on_a_round_forearm_is_radius_plus_clearance(clearance):
    hand = add_wrist(tube_hand(0), rings=4, length=0.05)     # the tube's forearm: radius 30 mm about the X axis
    fit = fit_wrist(hand, 0.03, 0.01, clearance)
    assert fit.bore["inner_a"] == pytest.approx(0.03 + clearance, abs=2e-4)
    assert fit.bore["inner_b"] == pytest.approx(0.03 + clearance, abs=2e-4)
    j0, axis = wrist_axis(hand)
    assert np.allclose(axis, [1, 0, 0], atol=1e-9)
    # Centred on the forearm (the tube's axis y = z = 0), 30 mm past the wrist joint; the bone axis runs through
    # the regressed wrist joint, which sits off the tube's axis by |j0_yz|.
    assert fit.rest[:3, 3] == pytest.approx([j0[0] + 0.03, 0.0, 0.0], abs=1e-6)
    assert fit.axis_distance == pytest.approx(np.linalg.norm(j0[1:]), abs=1e-6)
