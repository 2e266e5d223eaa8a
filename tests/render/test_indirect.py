"""Indirect light per vertex (render/indirect.py) against closed form: the open fraction of a vertex under an open
sky, at the bottom of a spherical cavity with a round opening (sin^2 of its half-angle), at the bottom of a V-groove
(sin of its half-opening), converging to the many-ray value; one bounce from a lit disk (its view factor); the
integrating sphere; determinism across runs, threads, vertex subsets and mirrored hands."""

from __future__ import annotations

import numpy as np
import pytest
from render_scenes import flat_material, one_light, quad, render, subject, surface, top_camera

from darthand.errors import InputError
from darthand.render import indirect
from darthand.render.lights import Lighting
from darthand.render.scene import Scene
from darthand.render.shade import ShadingOptions


def cavity(theta0: float, radius: float = 1.0, rings: int = 48, segments: int = 256):
    """A floor fan around a centre vertex 0 (normal +z) under a spherical shell of `radius` centred on it, the shell
    covering polar angles theta0..90 degrees (a round opening of half-angle theta0 at the zenith), normals inward.
    (vertices (N, 3), faces (F, 3))."""
    phi = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    floor = np.concatenate([[[0.0, 0.0, 0.0]], np.stack([np.cos(phi), np.sin(phi), 0 * phi], 1) * radius * 1.5])
    faces = [[0, 1 + i, 1 + (i + 1) % segments] for i in range(segments)]
    theta = np.linspace(theta0, np.pi / 2, rings)
    shell = np.concatenate([np.stack([np.sin(t) * np.cos(phi), np.sin(t) * np.sin(phi), np.cos(t) + 0 * phi], 1)
                            for t in theta]) * radius
    base = len(floor)
    for r in range(rings - 1):
        for i in range(segments):
            a, b = base + r * segments + i, base + r * segments + (i + 1) % segments
            c, d = a + segments, b + segments
            faces += [[a, c, b], [b, c, d]]               # wound so that the normals face the centre
    return np.concatenate([floor, shell]), np.array(faces)


def scene_of(vertices, faces, material=None):
    s = surface(vertices, faces, material=material)
    return Scene(subject(s)), s


# ------------------------------------------------------------------------------------------------ sampling


def test_directions_are_cosine_distributed_unit_vectors_about_the_normal():
    """With an analytic occluder that blocks every direction further than theta0 from the normal, the open fraction
    is the cosine-weighted share of the cone, sin^2 theta0; the stratified set gets it closely at K = 256."""
    rng = np.random.default_rng(0)
    normals = rng.normal(size=(50, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    origins, dirs = indirect.vertex_rays(np.zeros((50, 3)), normals, np.arange(50), 256, 0.0)
    assert np.allclose(np.linalg.norm(dirs, axis=1), 1, atol=1e-5)
    cos = np.einsum("ij,ij->i", dirs, np.repeat(normals, 256, axis=0).astype(np.float32))
    assert cos.min() >= -1e-6
    for theta0 in (0.3, 0.7, 1.2):
        blocked = (cos < np.cos(theta0)).reshape(50, 256)
        assert np.allclose(1 - blocked.mean(1), np.sin(theta0) ** 2, atol=0.01)


def test_directions_depend_only_on_the_vertex_not_on_its_company():
    normals = np.tile([[0.0, 0.0, 1.0]], (10, 1))
    _, all_dirs = indirect.vertex_rays(np.zeros((10, 3)), normals, np.arange(10), 8, 0.0)
    _, some = indirect.vertex_rays(np.zeros((3, 3)), normals[:3], np.array([7, 2, 9]), 8, 0.0)
    assert np.array_equal(some.reshape(3, 8, 3), all_dirs.reshape(10, 8, 3)[[7, 2, 9]])


def test_mirrored_rays_are_the_mirror_images():
    rng = np.random.default_rng(1)
    normals = rng.normal(size=(40, 3))
    normals[:5] = [1, 0.1, 0]                              # near the x axis: the other tangent frame
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    F = np.array([-1.0, 1.0, 1.0])
    _, right = indirect.vertex_rays(np.zeros((40, 3)), normals, np.arange(40), 16, 0.0)
    _, left = indirect.vertex_rays(np.zeros((40, 3)), normals * F, np.arange(40), 16, 0.0, mirrored=True)
    assert np.allclose(left, right * F, atol=1e-6)


# ------------------------------------------------------------------------------------------------ open fraction


def test_open_plane_sees_the_whole_sky():
    s = quad(size=2.0)
    scene = Scene(subject(s))
    v = indirect.vertex_occlusion(s.vertices, s.normals, scene.occluded, 64, 1e-4)
    assert np.array_equal(v, np.ones(4, np.float32))


@pytest.mark.parametrize("theta0_deg", [20.0, 45.0, 70.0])
def test_bottom_of_a_spherical_cavity_sees_sin2_of_its_opening(theta0_deg):
    """Cosine-weighted open fraction through a round opening of half-angle theta0 seen from the centre: sin^2."""
    t0 = np.deg2rad(theta0_deg)
    scene, s = scene_of(*cavity(t0))
    v = indirect.vertex_occlusion(s.vertices[:1], s.normals[:1], scene.occluded, 1024, 1e-4)
    assert abs(v[0] - np.sin(t0) ** 2) < 0.01


def test_bottom_of_a_v_groove_sees_sin_of_its_half_opening():
    """An (almost) infinite V-groove of half-opening gamma, seen from its bottom edge: the cosine-weighted open
    fraction is sin(gamma) (the view factor of a 2D wedge)."""
    gamma = np.deg2rad(35.0)
    length, depth = 400.0, 1.0
    x = depth * np.tan(gamma)
    ys = np.linspace(-length / 2, length / 2, 401)
    verts = np.concatenate([np.stack([0 * ys, ys, 0 * ys], 1), np.stack([-x + 0 * ys, ys, depth + 0 * ys], 1),
                            np.stack([x + 0 * ys, ys, depth + 0 * ys], 1)])
    n = len(ys)
    faces = []
    for i in range(n - 1):
        faces += [[i, i + 1, n + i], [n + i, i + 1, n + i + 1]]                  # left wall, facing +x/+z
        faces += [[i, 2 * n + i, i + 1], [2 * n + i, 2 * n + i + 1, i + 1]]      # right wall
    scene, s = scene_of(verts, faces)
    mid = n // 2
    assert np.allclose(s.normals[mid], [0, 0, 1], atol=1e-6)
    v = indirect.vertex_occlusion(s.vertices[[mid]], s.normals[[mid]], scene.occluded, 2048, 1e-4)
    assert abs(v[0] - np.sin(gamma)) < 0.01


def test_open_fraction_converges_to_the_many_ray_value():
    """The error of the K-ray estimate at the cavity's bottom, averaged over the per-vertex rotations (many copies
    of the vertex with other ids), falls as K grows: within 0.02 at K = 16, 0.005 at K = 256."""
    t0 = np.deg2rad(40.0)
    scene, s = scene_of(*cavity(t0))
    copies = 64
    err = {}
    for k in (4, 16, 64, 256):
        origins, dirs = indirect.vertex_rays(np.repeat(s.vertices[:1], copies, 0), np.repeat(s.normals[:1], copies, 0),
                                             np.arange(copies), k, 1e-4)
        v = 1 - scene.occluded(origins, dirs, np.inf).reshape(copies, k).mean(1)
        err[k] = float(np.sqrt(np.mean((v - np.sin(t0) ** 2) ** 2)))
    assert err[4] > err[16] > err[64] > err[256]
    assert err[16] < 0.05 and err[256] < 0.006


# ------------------------------------------------------------------------------------------------ interreflection


def test_one_bounce_from_a_lit_disk_is_its_view_factor():
    """A black floor point under a white disk of radius a at height h whose underside is lit by irradiance I (a
    light from below, without shadows): indirect irradiance = ambient (1 - F) + I F with the disk's view factor
    F = a^2 / (a^2 + h^2)."""
    a, h, intensity, ambient = 1.0, 0.8, 2.0, 0.3
    phi = np.linspace(0, 2 * np.pi, 128, endpoint=False)
    rings = np.linspace(0, a, 33)[1:]
    disk = np.concatenate([[[0, 0, h]]] + [np.stack([r * np.cos(phi), r * np.sin(phi), h + 0 * phi], 1)
                                             for r in rings])
    faces = [[0, 1 + (i + 1) % 128, 1 + i] for i in range(128)]                  # facing -z
    for r in range(len(rings) - 1):
        for i in range(128):
            p, q = 1 + r * 128 + i, 1 + r * 128 + (i + 1) % 128
            faces += [[p, q, q + 128], [p, q + 128, p + 128]]
    ceiling = surface(disk, faces, material=flat_material((1.0, 1.0, 1.0)), name="ceiling", role="accessory")
    assert (ceiling.normals[:, 2] < -0.99).all()
    tiny = 1e-3
    floor = surface([[0, 0, 0], [tiny, 0, 0], [0, tiny, 0], [-tiny, -tiny, 0]], [[0, 1, 2], [0, 2, 3], [0, 3, 1]],
                    material=flat_material((0.0, 0.0, 0.0)))
    scene = Scene(subject(floor, ceiling))
    lights = [{"type": "directional", "direction": np.array([0.0, 0.0, 1.0]), "radiance": np.full(3, intensity,
                                                                                                    np.float32),
               "shadows": False}]
    light = indirect.VertexLight(scene, lights, np.full(3, ambient, np.float32), 4096)
    light.ensure(0, np.array([0]))
    F = a ** 2 / (a ** 2 + h ** 2)
    e, v = light.at(0, np.array([0]), np.zeros(1, np.float32), np.zeros(1, np.float32))
    assert abs(v[0] - (1 - F)) < 0.01
    assert np.allclose(e[:, 0], ambient * (1 - F) + intensity * F, atol=0.02)


def test_integrating_sphere():
    """Inside a sphere with a round opening, every wall point sees the opening with the same view factor f (its
    area share, (1 - cos theta0) / 2), and with interreflection the wall's irradiance is ambient f / (1 - rho (1 -
    f)) (radiometry of the integrating sphere); without, ambient f."""
    import trimesh

    t0 = np.deg2rad(60.0)
    ball = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
    keep = ball.vertices[ball.faces].mean(1)[:, 2] < np.cos(t0)                  # cut the cap of half-angle t0
    faces = ball.faces[keep][:, ::-1]                                            # inward normals
    rho, ambient = 0.6, 0.5
    scene, s = scene_of(ball.vertices, faces, material=flat_material((rho, rho, rho)))
    f = (1 - np.cos(t0)) / 2
    wall = np.flatnonzero(ball.vertices[:, 2] < np.cos(t0) - 0.3)                # away from the rim
    prim = np.array([np.flatnonzero((faces == w).any(1))[0] for w in wall[:40]])
    for inter, want in ((True, ambient * f / (1 - rho * (1 - f))), (False, ambient * f)):
        light = indirect.VertexLight(scene, [], np.full(3, ambient, np.float32), 512, interreflection=inter)
        light.ensure(0, prim)
        done = np.flatnonzero(light.done[0])
        assert abs(light.values[0][3, done].mean() - f) < 0.01
        assert abs(light.values[0][0, done].mean() - want) < 0.01 * want + 0.003


# ------------------------------------------------------------------------------------------------ rendering


def test_ambient_occlusion_darkens_a_cavity_and_leaves_an_open_plane_alone():
    t0 = np.deg2rad(40.0)
    v, f = cavity(t0)
    cav = surface(v, f)
    light = Lighting((1.0, 1.0, 1.0), 0.5, ())
    cam = top_camera(height=3.0, size=48, fov_deg=30)
    plane = render(subject(quad(size=4.0)), top_camera(size=16), light, samples=1)
    assert np.allclose(plane.colour[8, 8], 0.25, atol=1e-6)          # albedo 0.5 x ambient 0.5, nothing blocks it
    off = render(subject(cav), cam, light, samples=1, shading={"ao_rays": 0})
    on = render(subject(cav), cam, light, samples=1, shading={"ao_rays": 64, "interreflection": False})
    c = on.colour[24, 24, 0]
    assert np.isclose(off.colour[24, 24, 0], 0.25, atol=1e-6)
    assert abs(c / 0.25 - np.sin(t0) ** 2) < 0.06                     # the centre pixel sits near the vertex
    assert on.labels["render"]["shading"] == {"ao_rays": 64, "interreflection": False, "skin": "subsurface"}


def test_frames_are_deterministic_across_runs_threads_and_vertex_subsets():
    t0 = np.deg2rad(50.0)
    v, f = cavity(t0, rings=12, segments=48)
    subj = subject(surface(v, f))
    light = one_light((0.3, 0.2, -1.0), 1.0, ambient=0.3)
    cam = top_camera(height=3.0, size=64, fov_deg=40)
    a = render(subj, cam, light, threads=1)
    b = render(subj, cam, light, threads=2)
    c = render(subj, cam, light, threads=1)
    assert np.array_equal(a.rgba, b.rgba) and np.array_equal(a.rgba, c.rgba)
    scene = Scene(subj)
    lights = [{"type": "directional", "direction": np.array([0.3, 0.2, -1.0]) / np.linalg.norm([0.3, 0.2, -1.0]),
               "radiance": np.ones(3, np.float32), "shadows": True}]
    whole = indirect.VertexLight(scene, lights, np.full(3, 0.3, np.float32), 16)
    whole.ensure(0, np.arange(len(f)))
    parts = indirect.VertexLight(scene, lights, np.full(3, 0.3, np.float32), 16)
    for chunk in np.array_split(np.arange(len(f))[::-1], 3):
        parts.ensure(0, chunk)
    assert np.array_equal(whole.values[0], parts.values[0])


def test_bad_shading_options_are_one_line_errors():
    with pytest.raises(InputError, match="ao_rays"):
        ShadingOptions(ao_rays=-1)
    with pytest.raises(InputError, match="skin"):
        ShadingOptions(skin="velvet")
    light = one_light((0, 0, -1))
    with pytest.raises(InputError, match="unknown option 'ao'"):
        render(subject(quad()), top_camera(size=8), light, shading={"ao": 3})
