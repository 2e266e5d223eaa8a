"""The indirect-light pass's compiled kernels (render/indirect.py) against the numpy they replaced
(indirect_numpy.py), bit for bit: ray making (tangent frames at and near their switch, axis-aligned, zero and
unnormalised normals, mirrored), and whole frames of per-vertex light (E, V, albedo, reflected light, interpolation
at hits) on a posed hand with a rigid ring and the forearm cap, left and right, 1 to 64 rays, with and without
interreflection, directional and point lights with and without shadows; on vertices that see nothing (inside a
closed sphere), everything (an open plane), one triangle, a large sphere, degenerate normals, empty batches. And two
closed forms: a point light at the centre of a closed sphere, an open plane."""

from __future__ import annotations

import dataclasses

import indirect_numpy as reference
import numpy as np
import pytest
import trimesh
from render_scenes import flat_material, quad, subject, surface

from darthand.render import indirect
from darthand.render.scene import Scene


def bits(a: np.ndarray) -> np.ndarray:
    """float32 values as their bit patterns (so -0 differs from 0); NaNs as one pattern (their sign is unspecified)."""
    a = np.asarray(a, np.float32)
    return np.where(np.isnan(a), np.uint32(0x7FC00000), a.view(np.uint32))


def assert_same(new, old, what):
    assert new.shape == old.shape, what
    assert np.array_equal(bits(new), bits(old)), f"{what}: {np.count_nonzero(bits(new) != bits(old))} differ"


# ------------------------------------------------------------------------------------------------ rays


def awkward_normals() -> np.ndarray:
    """Unit normals at random, on the axes (both signs), at the tangent frame's switch |n_x| = 0.9 and a float32 step
    either side, zero, and unnormalised."""
    rng = np.random.default_rng(7)
    n = rng.normal(size=(200, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    axes = np.concatenate([np.eye(3), -np.eye(3)])
    edge = []
    for x in (np.float32(0.9), np.nextafter(np.float32(0.9), np.float32(0)), np.nextafter(np.float32(0.9),
                                                                                            np.float32(1))):
        for sign in (1, -1):
            edge.append([sign * x, np.sqrt(max(0.0, 1 - float(x) ** 2)), 0.0])
    return np.concatenate([n, axes, edge, np.zeros((2, 3)), [[3.0, -4.0, 12.0], [1e-20, 0, 0]]]).astype(np.float32)


@pytest.mark.parametrize("mirrored", [False, True])
@pytest.mark.parametrize("rays", [1, 16])
def test_rays_match_the_numpy(mirrored, rays):
    normals = awkward_normals()
    vertices = np.random.default_rng(8).normal(size=normals.shape).astype(np.float32)
    ids = np.arange(len(normals))
    picked = np.array([5, 203, 0, 207, 210, 211])
    for args in ((vertices, normals, ids, rays, 1e-3, 3, mirrored),
                 (vertices[picked], normals[picked], picked, rays, 2e-4, 5, mirrored, len(normals))):
        new, old = indirect.vertex_rays(*args), reference.vertex_rays(*args)
        assert_same(new[0], old[0], "origins")
        assert_same(new[1], old[1], "directions")
    empty = indirect.vertex_rays(vertices[:0], normals[:0], ids[:0], rays, 1e-3)
    assert empty[0].shape == empty[1].shape == (0, 3)


# ------------------------------------------------------------------------------------------------ VertexLight


def lights(extent: float, centre) -> list[dict]:
    """A shadowed key light, an unshadowed fill, a shadowed point light near the subject."""
    unit = lambda v: np.asarray(v, np.float64) / np.linalg.norm(v)
    return [{"type": "directional", "direction": unit([0.3, -0.8, -0.5]), "radiance": np.float32([2.0, 1.8, 1.5]),
             "shadows": True},
            {"type": "directional", "direction": unit([-0.6, 0.2, 0.7]), "radiance": np.float32([0.3, 0.35, 0.4]),
             "shadows": False},
            {"type": "point", "position": np.asarray(centre, np.float64) + [0.3 * extent, 0.4 * extent, 0.1 * extent],
             "radiance": np.float32([0.02, 0.02, 0.025]), "shadows": True}]


def compare(scene, rays: int, interreflection: bool, batches, hits, light=None):
    """Run the new and the numpy VertexLight through the same ensure batches [(g, prim)] and `at` hits
    [(g, prim, bu, bv)] and compare everything they made."""
    light = lights(scene.extent, scene.lo) if light is None else light
    ambient = np.float32([0.3, 0.25, 0.2])
    new = indirect.VertexLight(scene, light, ambient, rays, interreflection)
    old = reference.VertexLight(scene, light, ambient, rays, interreflection)
    for g, prim in batches:
        new.ensure(g, prim)
        old.ensure(g, prim)
    for g in range(len(scene.surfaces)):
        assert np.array_equal(new.done[g], old.done[g])
        assert_same(new.values[g], old.values[g], f"E, V of surface {g}")
        assert not (new.has_albedo[g] & ~old.lit[g]).any() and not (new.lit[g] & ~old.lit[g]).any()
        assert_same(new.albedo[g][new.has_albedo[g]], old.albedo[g][new.has_albedo[g]], f"albedo of {g}")
        if interreflection:
            assert_same(new.reflected[g][:, new.lit[g]].T, old.reflected[g][new.lit[g]],
                        f"reflected light of {g}")
    for g, prim, bu, bv in hits:
        for a, b in zip(new.at(g, prim, bu, bv), old.at(g, prim, bu, bv)):
            assert_same(a, b, f"interpolated at hits on {g}")
    return new


def every_face_in_batches(scene, seed: int = 0):
    """Each surface's faces in three batches of a random order, a repeated batch and an empty one; and hits on a
    random sample of faces with random barycentrics (some at the corners and edges)."""
    rng = np.random.default_rng(seed)
    batches, hits = [], []
    for g, s in enumerate(scene.surfaces):
        order = rng.permutation(len(s.faces)).astype(np.int32)
        parts = np.array_split(order, 3)
        batches += [(g, parts[0]), (g, np.zeros(0, np.int32)), (g, parts[1]), (g, parts[0]), (g, parts[2])]
        prim = rng.integers(0, len(s.faces), 500).astype(np.int32)
        bu, bv = rng.random(500, dtype=np.float32), rng.random(500, dtype=np.float32)
        flip = bu + bv > 1
        bu[flip], bv[flip] = 1 - bu[flip], 1 - bv[flip]
        bu[:3], bv[:3] = [0, 1, 0], [0, 0, 1]
        hits += [(g, prim, bu, bv), (g, prim[:0], bu[:0], bv[:0])]
    return batches, hits


@pytest.fixture(scope="module")
def hand_scene(hand, texture_files, ring):
    """The fist with the ring on the index finger (a rigid surface) and the forearm cap; textured skin."""
    from darthand.render.assets import HandAssets

    assets = HandAssets(hand, {texture_files.id: texture_files}, texture_files.id, {ring.id: ring}, "open+wrist")
    return Scene(assets.subject("fist", accessory=ring.id))


@pytest.mark.parametrize("rays, interreflection, side", [(16, True, "right"), (16, True, "left"),
                                                          (1, True, "right"), (64, True, "right"),
                                                          (16, False, "right"), (4, False, "left")])
def test_hand_frames_match_the_numpy(hand_scene, rays, interreflection, side):
    scene = hand_scene
    assert [s.role for s in scene.surfaces] == ["hand", "accessory", "cap"] and scene.rigid
    scene.subject = dataclasses.replace(scene.subject, side=side)
    batches, hits = every_face_in_batches(scene)
    new = compare(scene, rays, interreflection, batches, hits)
    v = new.values[0][3, new.done[0]]
    assert v.min() < 0.5 and v.max() == 1                          # inside the fist, and open sky on its back


@pytest.mark.parametrize("interreflection", [True, False])
def test_small_and_large_scenes_match_the_numpy(interreflection):
    closed = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    inside = surface(closed.vertices, closed.faces[:, ::-1], material=flat_material((1.0, 0.6, 0.2)))     # V = 0
    big = trimesh.creation.icosphere(subdivisions=5, radius=3.0)
    white = flat_material((1.0, 1.0, 1.0))                         # clipped to MAX_BOUNCE_ALBEDO in the sphere factor
    outer = surface(big.vertices, big.faces[:, ::-1], material=white, role="accessory", name="big")
    floor = quad(size=0.5, centre=(0, 0, -0.5))                    # inside both spheres, facing the inner one
    one = surface([[0, 0, 5], [0.1, 0, 5], [0, 0.1, 5]], [[0, 1, 2]], role="accessory", name="one")      # V = 1
    for surfaces in ((inside, outer, floor), (one,), (floor,)):
        scene = Scene(subject(*surfaces))
        batches, hits = every_face_in_batches(scene, seed=len(surfaces))
        compare(scene, 16, interreflection, batches, hits)


def test_degenerate_normals_match_the_numpy():
    """Zero, unnormalised and axis-aligned vertex normals (an accessory's mesh may have them)."""
    s = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    ball = surface(s.vertices, s.faces)
    normals = ball.normals.copy()
    normals[:12] = awkward_normals()[[0, 200, 203, 206, 207, 208, 209, 212, 213, 214, 215, 1]]
    scene = Scene(subject(dataclasses.replace(ball, normals=normals), quad(size=4.0, centre=(0, 0, -1.2))))
    batches, hits = every_face_in_batches(scene)
    compare(scene, 16, True, batches, hits)


def test_no_rays_is_not_a_vertex_light():
    with pytest.raises(ValueError, match="at least 1 ray"):
        indirect.VertexLight(Scene(subject(quad())), [], np.zeros(3, np.float32), 0)


# ------------------------------------------------------------------------------------------------ closed forms


def test_point_light_at_the_centre_of_a_closed_sphere():
    """Every wall point of a closed sphere (radius r, albedo rho) sees only wall (V = 0), lit by a point light at
    the centre: direct irradiance I / r^2, one bounce rho I / r^2 from wherever a ray lands, and the sphere series
    1 / (1 - rho): E = rho I / (r^2 (1 - rho))."""
    r, rho, intensity = 0.5, 0.6, 0.2
    ball = trimesh.creation.icosphere(subdivisions=4, radius=r)
    scene = Scene(subject(surface(ball.vertices, ball.faces[:, ::-1], material=flat_material((rho, rho, rho)))))
    light = [{"type": "point", "position": np.zeros(3), "radiance": np.full(3, intensity, np.float32),
              "shadows": True}]
    vl = indirect.VertexLight(scene, light, np.full(3, 0.4, np.float32), 16)
    vl.ensure(0, np.arange(len(ball.faces), dtype=np.int32))
    assert vl.done[0].all() and (vl.values[0][3] == 0).all()
    want = rho * intensity / (r * r * (1 - rho))
    assert np.allclose(vl.values[0][:3], want, rtol=2e-3)


def test_open_plane_reflects_the_ambient_light_only():
    scene = Scene(subject(quad(size=2.0, material=flat_material((0.9, 0.9, 0.9)))))
    ambient = np.float32([0.3, 0.2, 0.1])
    vl = indirect.VertexLight(scene, lights(scene.extent, (0, 0, 1)), ambient, 16)
    vl.ensure(0, np.array([0, 1], np.int32))
    assert (vl.values[0][3] == 1).all() and (vl.values[0][:3] == ambient[:, None]).all()
    assert not vl.lit[0].any()                                    # no ray hit anything: no light made at vertices


def test_direction_tables_are_kept_within_their_budget(monkeypatch):
    """Tables beyond the budget go least recently used first; a kept table is the one made before."""
    monkeypatch.setattr(indirect, "_LOCAL", type(indirect._LOCAL)())
    monkeypatch.setattr(indirect, "LOCAL_BUDGET", 3 * 100 * 4 * 4 * 3)                  # three tables of 100 x 4
    first = indirect.direction_table(100, 4, 1)
    for salt in (2, 3):
        indirect.direction_table(100, 4, salt)
    assert indirect.direction_table(100, 4, 1) is first                                 # used again: now the newest
    indirect.direction_table(100, 4, 4)                                                 # drops salt 2
    assert list(indirect._LOCAL) == [(100, 4, 3), (100, 4, 1), (100, 4, 4)]
    assert np.array_equal(indirect.direction_table(100, 4, 2), indirect.local_directions(np.arange(100), 4, 2))
    assert len(indirect._LOCAL) == 3
