"""Every generator output is a closed, consistently wound, outward solid with UVs in [0, 1] and the dimensions it
was asked for (closed-form checks against the parameters)."""

import numpy as np
import pymeshlab
import pytest
from scipy.special import ellipe
import trimesh

from darthand.accessories.generators.bracelet import STYLES as BRACELETS, bracelet
from darthand.accessories.generators.ring import STYLES as RINGS, ring
from darthand.accessories.generators.watch import watch
from darthand.accessories.mesh import ellipse_perimeter


def self_intersecting_faces(v, f) -> int:
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(v, f))
    ms.compute_selection_by_self_intersections_per_face()
    return ms.current_mesh().selected_face_number()


def assert_solid(mesh):
    tm = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    assert tm.is_watertight
    assert tm.is_winding_consistent
    assert tm.volume > 0                                 # outward
    assert np.isfinite(mesh.uvs).all() and mesh.uvs.min() >= 0 and mesh.uvs.max() <= 1
    assert mesh.faces_uv.shape == mesh.faces.shape and mesh.faces_uv.max() < len(mesh.uvs)
    # Separate parts must not overlap, or inside tests and volumes would be wrong.
    assert self_intersecting_faces(mesh.vertices, mesh.faces) == 0
    for key in ("base_color", "metallic_roughness"):
        img = mesh.textures[key]
        assert img.ndim == 3 and img.shape[2] == 3 and np.isfinite(img).all() and 0 <= img.min() <= img.max() <= 1
    assert 0 <= mesh.material["metallic"] <= 1 and 0 <= mesh.material["roughness"] <= 1


RING = dict(inner_radius=0.0091, width=0.003, thickness=0.0018, metal="gold", stone="ruby")


@pytest.mark.parametrize("style", RINGS)
def test_ring_is_a_solid_with_the_requested_bore(style):
    m = ring(dict(RING, style=style), np.random.default_rng(1))
    assert_solid(m)
    # Closed form: the bore of radius r is the innermost surface -- min distance to the axis is r.
    radial = np.linalg.norm(m.vertices[:, 1:], axis=1)
    assert radial.min() == pytest.approx(0.0091, abs=2e-6)
    assert m.dims["inner_radius"] == 0.0091
    # Centred on the origin along the axis.
    assert abs(m.vertices[:, 0].max() + m.vertices[:, 0].min()) < 1e-3


def test_flat_band_has_the_requested_width_and_thickness():
    m = ring(dict(RING, style="flat"), np.random.default_rng(0))
    assert np.ptp(m.vertices[:, 0]) == pytest.approx(0.003, rel=1e-6)
    radial = np.linalg.norm(m.vertices[:, 1:], axis=1)
    assert radial.max() == pytest.approx(0.0091 + 0.0018, rel=1e-6)


def test_stone_sits_on_top():
    m = ring(dict(RING, style="solitaire"), np.random.default_rng(0))
    top = m.vertices[np.argmax(m.vertices[:, 1])]
    assert top[1] > 0.0091 + 0.0018 and abs(top[2]) < 0.004      # above the band, on the +Y (dorsal) side


BORE = dict(inner_a=0.022, inner_b=0.029)


def _bore_ratio(v):
    return np.sqrt((v[:, 1] / BORE["inner_a"]) ** 2 + (v[:, 2] / BORE["inner_b"]) ** 2)


@pytest.mark.parametrize("strap", ["leather", "fabric", "metal"])
@pytest.mark.parametrize("case", ["round", "square"])
def test_watch_is_a_solid_on_its_bore(strap, case):
    m = watch(dict(BORE, strap=strap, case=case, case_size=0.038, case_height=0.011, strap_width=0.019,
                   strap_thickness=0.0025, metal="steel"), np.random.default_rng(2))
    assert_solid(m)
    assert _bore_ratio(m.vertices).min() == pytest.approx(1.0, abs=1e-6)   # nothing inside the bore
    assert m.vertices[:, 1].max() > BORE["inner_a"] + 0.0025 + 0.011 * 0.99   # case on the dorsal side
    # The exact perimeter of the bore's ellipse (semi-axes 29 and 22 mm): 4 a E(1 - b^2 / a^2).
    exact = 4 * 0.029 * ellipe(1 - (0.022 / 0.029) ** 2)
    assert m.dims["inner_circumference"] == pytest.approx(exact, rel=1e-9)


BRACELET = dict(BORE, metal="silver", width=0.008, thickness=0.003, wire=0.0006, bead_diameter=0.008,
                bead_colors=["onyx", [0.8, 0.8, 0.8]], opening=1.2)


@pytest.mark.parametrize("style", BRACELETS)
def test_bracelet_is_a_solid_on_its_bore(style):
    m = bracelet(dict(BRACELET, style=style), np.random.default_rng(3))
    assert_solid(m)
    assert _bore_ratio(m.vertices).min() == pytest.approx(1.0, abs=2e-3)


def test_ellipse_perimeter_closed_forms():
    assert ellipse_perimeter(1.0, 1.0) == pytest.approx(2 * np.pi)
    # Degenerate ellipse: a segment of length 2a traversed twice -> 4a.
    assert ellipse_perimeter(1.0, 1e-12) == pytest.approx(4.0, rel=1e-3)


def test_generators_are_deterministic_per_rng():
    a = watch(dict(BORE, strap="leather", case="round", case_size=0.038, case_height=0.011, strap_width=0.019,
                   strap_thickness=0.0025, metal="steel"), np.random.default_rng(7))
    b = watch(dict(BORE, strap="leather", case="round", case_size=0.038, case_height=0.011, strap_width=0.019,
                   strap_thickness=0.0025, metal="steel"), np.random.default_rng(7))
    assert np.array_equal(a.vertices, b.vertices)
    assert np.array_equal(a.textures["base_color"], b.textures["base_color"])
