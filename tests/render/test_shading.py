"""Shading and image formation against closed form: Lambert and wrap diffuse at known angles with the sRGB
encoding, the GGX lobe at its peak, point-light fall-off, hard shadows of a known occluder, coverage of a known
triangle, compositing over a background without halos, determinism."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from render_scenes import flat_material, one_light, quad, render, subject, surface, top_camera

from darthand.render.camera import look_at
from darthand.textures.color import encode_srgb8
from darthand.render.lights import Light, Lighting
from darthand.render.shade import ambient_specular, ggx_specular, wrap_diffuse
from darthand.render.subject import Material
from darthand.render.texture import constant_texture


def srgb8(x: float) -> int:
    """Independent sRGB encoding (IEC 61966-2-1) to 8 bits."""
    s = 12.92 * x if x <= 0.0031308 else 1.055 * x ** (1 / 2.4) - 0.055
    return int(np.floor(s * 255 + 0.5))


@pytest.mark.parametrize("angle_deg", [0.0, 30.0, 60.0, 80.0])
def test_lambert_plane_at_a_known_angle(angle_deg):
    """Albedo 0.5 lit by a directional light of intensity 1.6 at angle theta renders 0.5 * 1.6 * cos(theta)."""
    t = np.deg2rad(angle_deg)
    light = one_light((np.sin(t), 0.0, -np.cos(t)), intensity=1.6, shadows=True)
    frame = render(subject(quad(size=4.0)), top_camera(size=32), light, samples=1)
    want = 0.5 * 1.6 * np.cos(t)
    assert np.allclose(frame.colour[8:24, 8:24], want, atol=1e-5)
    assert frame.rgba[16, 16, 0] == srgb8(want) and frame.rgba[16, 16, 3] == 255


def test_surface_facing_away_is_black_and_ambient_adds_albedo_times_ambient():
    light = one_light((0, 0, 1), intensity=1.0, ambient=0.25)          # light from below the plane
    frame = render(subject(quad(size=4.0)), top_camera(size=16), light, samples=1)
    # Ambient term of a purely diffuse surface: albedo * ambient.
    assert np.allclose(frame.colour[8, 8], 0.25 * 0.5, atol=1e-6)
    # With its specular lobe, the ambient specular adds Karis' F0 A + B (A, B from the split-sum fit).
    glossy = dataclasses.replace(flat_material(), specular=1.0, f0=0.04)
    frame = render(subject(quad(size=4.0, material=glossy)), top_camera(size=16), light, samples=1)
    # Karis 2014 at roughness 0.5, n.v = 1, by hand: r = 0.5 c0 + c1 = (0.5, 0.02875, 0.754, -0.029);
    # a004 = min(0.25, 2^-9.28) 0.5 + 0.02875; A = -1.04 a004 + 0.754; B = 1.04 a004 - 0.029.
    a004 = min(0.25, 2 ** -9.28) * 0.5 + 0.02875
    env = 0.04 * (-1.04 * a004 + 0.754) + (1.04 * a004 - 0.029)
    assert np.isclose(env, 0.03066, atol=1e-5)
    assert np.isclose(ambient_specular(np.float32(0.04), np.array([0.5], np.float32),
                                       np.array([1.0], np.float32))[0], env, atol=1e-6)
    assert np.allclose(frame.colour[8, 8], 0.25 * (0.5 + env), atol=1e-4)


def test_wrap_diffuse_closed_form():
    ndl = np.array([1.0, 0.5, 0.0, -0.1, -0.5], np.float32)
    w = (0.3, 0.1, 0.0)
    got = wrap_diffuse(ndl, w)
    want = np.array([[max(0.0, (c + wi) / (1 + wi)) for c in ndl] for wi in w])
    assert np.allclose(got, want, atol=1e-6)
    assert np.allclose(wrap_diffuse(ndl, (0, 0, 0))[0], np.maximum(ndl, 0))


def test_ggx_peak_closed_form():
    """At n = h = l = v: D = 1 / (pi a^2), Vis = 1/4, F = f0, so pi D Vis F n.l = f0 / (4 a^2)."""
    for rough in (0.3, 0.5, 0.9):
        one = np.ones(1, np.float32)
        spec = ggx_specular(one, one, one, one, np.array([rough], np.float32), np.float32(0.04))
        assert np.isclose(spec[0], 0.04 / (4 * rough ** 4), rtol=1e-5)
    # Grazing (v.h = 0): Schlick's Fresnel is 1 whatever f0, so f0 no longer matters.
    cosines = [np.array([x], np.float32) for x in (1.0, 1e-4, 0.7, 0.0)]
    g = ggx_specular(*cosines, np.array([0.5], np.float32), np.float32(0.04))
    assert g[0] > 0 and np.isclose(g[0], ggx_specular(*cosines, np.array([0.5], np.float32), np.float32(1.0))[0])


def test_point_light_inverse_square():
    """A point light of intensity I at height h above a Lambert plane: radiance albedo * I cos(theta) / d^2."""
    lighting = Lighting((1, 1, 1), 0.0, (Light("point", (1, 1, 1), 2.0, position=(0.0, 0.0, 0.5)),))
    cam = top_camera(height=3.0, size=33, fov_deg=40)
    frame = render(subject(quad(size=4.0)), cam, lighting, samples=1)
    # Pixel (16, 16)'s centre looks at the origin: d = 0.5, theta = 0.
    assert np.allclose(frame.colour[16, 16], 0.5 * 2.0 / 0.25, rtol=1e-4)
    x = cam.centre + frame.depth[16, 24] * cam.directions(np.array([[24.5, 16.5]]))[0]
    d2 = x @ x - 2 * 0.5 * x[2] + 0.25
    want = 0.5 * 2.0 * (0.5 / np.sqrt(d2)) / d2
    assert np.allclose(frame.colour[16, 24], want, rtol=1e-4)


def test_shadow_of_a_known_occluder():
    """A 0.4 m square 0.5 m above the floor, light from 45 deg: its shadow is the square shifted by 0.5 m along x
    (ambient only there); the floor around it is lit."""
    floor = quad(size=4.0, name="floor")
    block = quad(centre=(0, 0, 0.5), size=0.4, name="block", role="accessory")
    light = one_light((np.sin(np.pi / 4), 0.0, -np.cos(np.pi / 4)), intensity=1.0, ambient=0.0)
    cam = look_at((0.5, 0, 6), (0.5, 0, 0), (0, 1, 0), width=96, height=96, focal_px=96 * 6 / 2.0)  # 2 m wide
    frame = render(subject(floor, block), cam, light, samples=1, labels=False)
    uv, _ = cam.project(np.array([[0.5, 0.0, 0.0], [1.2, 0.0, 0.0]]))
    shadow_px, lit_px = (np.floor(p).astype(int) for p in uv)
    lit_value = 0.5 * np.cos(np.pi / 4)
    assert frame.geom[shadow_px[1], shadow_px[0]] == 0                       # floor, in the shadow
    assert np.allclose(frame.colour[shadow_px[1], shadow_px[0]], 0.0, atol=1e-6)
    assert np.allclose(frame.colour[lit_px[1], lit_px[0]], lit_value, atol=1e-5)
    # The shadow's extent along x: 0.4 m wide -> 0.4 / 2 * 96 = 19.2 pixels, on the floor row through y = 0.
    row = frame.colour[shadow_px[1], :, 0]
    dark = np.flatnonzero((row < 1e-6) & (frame.geom[shadow_px[1]] == 0))
    assert abs(len(dark) - 19.2) <= 2
    centre_x = uv[0, 0]
    assert abs((dark.min() + dark.max() + 1) / 2 - centre_x) <= 1.0
    without = render(subject(floor, block), cam, dataclasses.replace(light, lights=(dataclasses.replace(
        light.lights[0], shadows=False),)), samples=1, labels=False)
    assert np.allclose(without.colour[shadow_px[1], shadow_px[0]], lit_value, atol=1e-5)


def triangle_frame(samples: int, background=None):
    tri = surface([[-0.31, -0.22, 0], [0.37, -0.05, 0], [-0.02, 0.41, 0]], [[0, 1, 2]],
                  material=flat_material((0.8, 0.4, 0.2)))
    cam = top_camera(height=2.0, size=80, fov_deg=30)
    lighting = one_light((0, 0, -1), intensity=1.0, shadows=False)
    return render(subject(tri), cam, lighting, samples=samples, background=background), cam, tri


@pytest.mark.parametrize("samples, tol", [(1, 0.02), (8, 0.004), (16, 0.003)])
def test_mask_coverage_of_a_triangle_matches_its_area(samples, tol):
    frame, cam, tri = triangle_frame(samples)
    uv, _ = cam.project(tri.vertices.astype(np.float64))
    x, y = uv[:, 0], uv[:, 1]
    area = 0.5 * abs((x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0]))
    assert abs(frame.alpha.sum() - area) / area < tol
    assert np.isfinite(frame.colour).all()


def test_compositing_over_a_background_has_no_halo():
    """Every pixel is alpha * fg + (1 - alpha) * bg in linear light, fg the triangle's constant radiance
    (albedo x light: a Lambert surface facing a light of intensity 1)."""
    bg = np.zeros((80, 80, 3), np.float32)
    bg[..., 1] = 0.6
    bg[:, 40:, 2] = 0.3
    frame, _, _ = triangle_frame(8, background=bg)
    fg = np.array([0.8, 0.4, 0.2], np.float32)
    a = frame.alpha[..., None]
    assert ((frame.alpha > 0) & (frame.alpha < 1)).sum() > 50
    assert np.allclose(frame.colour, a * fg + (1 - a) * bg, atol=1e-6)
    assert (frame.rgba[..., 3] == 255).all()
    assert np.array_equal(frame.rgba[..., :3], encode_srgb8(frame.colour))
    # Without a background the PNG holds straight colour: edge pixels have the foreground's colour, alpha < 1.
    plain, _, _ = triangle_frame(8)
    edge = (plain.alpha > 0) & (plain.alpha < 1)
    assert (plain.rgba[edge][:, :3] == encode_srgb8(fg)).all()
    assert np.array_equal(plain.rgba[..., 3], np.rint(plain.alpha * 255).astype(np.uint8))


def test_same_inputs_give_the_same_bytes():
    a, _, _ = triangle_frame(8)
    b, _, _ = triangle_frame(8)
    assert np.array_equal(a.rgba, b.rgba) and np.array_equal(a.alpha, b.alpha)
    assert a.labels == b.labels


def test_metal_reflects_its_albedo_in_ambient_light():
    metal = Material("pbr", constant_texture((1.0, 0.7, 0.3)), None, 0.3, None, 1.0, (0, 0, 0), 0.04, "gold", 1.0)
    frame = render(subject(quad(size=4.0, material=metal)), top_camera(size=16),
                   Lighting((1, 1, 1), 1.0, ()), samples=1)
    c = frame.colour[8, 8]
    # No diffuse for a metal; the ambient specular is F0 A + B with F0 = albedo: ordered like the albedo.
    assert c[0] > c[1] > c[2] > 0


def faceted_frames(samples: int = 8):
    """Two flat-shaded triangles of one surface (no shared vertices: constant normals), tilted differently so a
    directional Lambert light gives each its own constant radiance, the second in front of and overlapping the
    first, plus a third triangle of a second surface (another colour) overlapping both: edge pixels mix background,
    two triangles of one surface and two surfaces. Rendered with 'triangle' and 'sample' anti-aliasing shading,
    without indirect light (interreflection between the triangles would vary across each)."""
    back = [[-0.5, -0.4, 0.0], [0.45, -0.35, 0.1], [-0.1, 0.5, 0.0]]
    front = [[-0.2, -0.5, 0.3], [0.5, 0.1, 0.3], [-0.35, 0.3, 0.5]]
    both = surface(back + front, [[0, 1, 2], [3, 4, 5]], material=flat_material((0.7, 0.5, 0.3)))
    other = surface([[0.0, -0.1, 0.6], [0.4, 0.4, 0.65], [-0.3, 0.2, 0.62]], [[0, 1, 2]],
                    material=flat_material((0.2, 0.6, 0.8)), role="accessory", name="other")
    cam = top_camera(height=2.5, size=72, fov_deg=35)
    lighting = one_light((0.3, -0.2, -1.0), intensity=1.2, shadows=False)
    return [render(subject(both, other), cam, lighting, samples=samples, aa_shading=mode, labels=False,
                   shading={"ao_rays": 0}) for mode in ("triangle", "sample")], (both, other), lighting


@pytest.mark.parametrize("samples", [4, 8, 16])
def test_triangle_shading_equals_per_sample_shading_where_each_triangle_is_constant(samples):
    """When every triangle's radiance is constant, shading once per pixel per triangle must give what shading every
    sub-sample gives: the same coverage, and each edge pixel the coverage-weighted mix of its triangles' closed-form
    Lambert radiances."""
    (tri, per_sample), (both, other), lighting = faceted_frames(samples)
    assert np.array_equal(tri.alpha, per_sample.alpha)
    assert np.allclose(tri.colour, per_sample.colour, atol=1e-6)
    mixed = (tri.alpha > 0) & (tri.alpha < 1)
    assert mixed.sum() > 40
    # Closed form on fully covered pixels: albedo * intensity * max(0, n . -light direction) per triangle.
    l = -np.asarray(lighting.lights[0].direction, float)
    l /= np.linalg.norm(l)
    for s in (both, other):
        for face in s.faces:
            a, b, c = s.vertices[face].astype(float)
            n = np.cross(b - a, c - a)
            n /= np.linalg.norm(n)
            value = np.asarray(s.material.maps.levels[-1]).reshape(-1)[:3] * 1.2 * abs(n @ l)
            assert np.isclose(np.abs(tri.colour.reshape(-1, 3) - value).sum(1), 0, atol=1e-5).any()


def test_default_lights_do_not_overexpose_a_white_surface():
    """The default rig is exposed for albedos up to 1 (the brightest skin textures): a white Lambert sphere, which
    shows every normal facing the camera, stays below radiance 1 everywhere and reaches at least 0.8 where the key
    light meets it head-on (closed form: key + ambient, plus the fill's share at that normal)."""
    import trimesh

    from darthand.render.lights import default_lighting

    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.5)
    ball = surface(sphere.vertices, sphere.faces, material=flat_material((1.0, 1.0, 1.0)))
    lighting = default_lighting()
    frame = render(subject(ball), top_camera(height=3.0, size=96, fov_deg=25), lighting, samples=1, labels=False)
    lit = frame.colour[frame.alpha == 1]
    assert lit.max() < 1.0
    key = lighting.lights[0]
    peak = key.intensity * np.asarray(key.color) + lighting.ambient
    assert lit.max(axis=0)[0] >= 0.8 and lit.max(axis=0)[0] >= 0.95 * peak[0]
