"""shade()'s compiled passes (shade._lights_kernel, shade._radiance_kernel) against the numpy formulas they replace:
`reference_shade` below is the per-light numpy loop shade() was before it was compiled, built from the module's
numpy definitions (material_params, ambient_light, wrap_diffuse, skin.subsurface_diffuse, ggx_specular). Both must
give the same float32 bits and cast the same shadow rays, on random hits with the hard cases placed on purpose:
grazing views, n.l at and around 0 and just past the terminator, roughness at its floor, metals, zero specular,
point lights nearly touching the surface and very far, nails among the skin, every skin model, empty batches."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from darthand.render import shade as sh
from darthand.render.skin import skin_width, subsurface_diffuse
from darthand.render.subject import Material, skin_material
from darthand.render.texture import MipTexture


def dot(a, b):
    """(M,) dot products of (3, M) vectors, summed x, y, z."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def normalize(v):
    return v / np.maximum(np.sqrt(dot(v, v)), np.float32(1e-30))


def reference_diffuse(material, hits, skin_model):
    """(response(ndl) -> (3, M) or (M,), reach): the numpy diffuse models (shade.diffuse_model's meaning)."""
    if material.kind != "skin" or skin_model == "lambert" or (skin_model == "subsurface" and hits.radius is None):
        return (lambda ndl: np.maximum(ndl, 0)), 0.0
    if skin_model == "subsurface":
        width = skin_width(material)
        nails = None if hits.skin is None or hits.skin.all() else np.flatnonzero(~hits.skin)

        def subsurface(ndl):
            out = subsurface_diffuse(ndl, hits.radius, width)
            if nails is not None:
                out[:, nails] = np.maximum(ndl[nails], 0)
            return out
        return subsurface, -1.0
    wrap = np.asarray(material.wrap, np.float32)
    if not wrap.any():
        return (lambda ndl: np.maximum(ndl, 0)), 0.0
    return (lambda ndl: sh.wrap_diffuse(ndl, wrap)), -float(wrap.max())


def reference_shade(material, hits, lights, ambient, occluded, extent, counters, skin_model):
    """shade() as numpy passes, light after light."""
    p = sh.material_params(material, hits)
    n, v = hits.normal, hits.view
    nv = np.clip(dot(n, v), 1e-4, 1)
    spec = np.float32(material.specular)
    out = sh.ambient_light(p, ambient, spec, nv, hits)
    response, reach = reference_diffuse(material, hits, skin_model)
    lift = np.float32(sh.SHADOW_LIFT * max(extent, 1e-3))
    for light in lights:
        if light["type"] == "directional":
            l = (-light["direction"]).astype(np.float32)[:, None]
            dist = None
            scale = light["radiance"][:, None]
        else:
            l = light["position"].astype(np.float32)[:, None] - hits.position
            dist = np.sqrt(dot(l, l))
            l = l / np.maximum(dist, 1e-9)
            scale = light["radiance"][:, None] / np.maximum(dist * dist, 1e-12)
        ndl = dot(n, l)
        diffuse = response(ndl)
        reached = ndl > 0 if reach >= 0 else (diffuse.max(axis=0) if diffuse.ndim == 2 else diffuse) > 1e-4
        if light["shadows"]:
            idx = np.flatnonzero(reached)
            if len(idx):
                origin = (hits.position[:, idx] + lift * n[:, idx]).T
                dirs = np.broadcast_to(l.T, (len(idx), 3)) if dist is None else l[:, idx].T
                tfar = np.inf if dist is None else np.maximum(dist[idx] - lift, 0)
                reached[idx[occluded(np.ascontiguousarray(origin), np.ascontiguousarray(dirs), tfar)]] = False
                counters["shadow_rays"] = counters.get("shadow_rays", 0) + len(idx)
        colour = p.albedo * diffuse
        if spec:
            h = normalize(v + l)
            colour += spec * sh.ggx_specular(np.clip(ndl, 0, 1), nv, np.clip(dot(n, h), 0, 1),
                                             np.clip(dot(v, h), 0, 1), p.roughness, p.f0)
        colour *= reached
        colour *= scale
        out += colour
    return out.astype(np.float32, copy=False)


class Occluder:
    """A stand-in for the scene's occlusion query: blocks a fixed pseudo-random half of the rays (a function of the
    ray's bits, so both paths see the same answers) and records every ray it was asked about."""

    def __init__(self):
        self.rays = []

    def __call__(self, origins, directions, tfar):
        tfar = np.broadcast_to(np.asarray(tfar, np.float32), (len(origins),))
        self.rays.append((origins.copy(), directions.copy(), tfar.copy()))
        key = origins.view(np.uint32).sum(1, dtype=np.uint64) + directions.view(np.uint32).sum(1, dtype=np.uint64)
        return (key % np.uint64(7) < 3) | (tfar < 0.05)


def unit(a):
    return a / np.linalg.norm(a, axis=0, keepdims=True)


def random_hits(rng, m, light_dir, nails=True, indirect=True):
    """m hits near the origin, a third with a grazing view, a third with n.l at or near 0 for light_dir (travel)."""
    normal = unit(rng.normal(size=(3, m)))
    view = unit(rng.normal(size=(3, m)))
    view *= np.where((normal * view).sum(0) < 0, -1, 1)
    k = m // 3
    tangent = unit(np.cross(normal[:, :k].T, rng.normal(size=(k, 3))).T)
    c = rng.choice([0.0, 1e-6, 1e-5, 1e-4, 2e-4, 1e-3, 0.02], size=k)
    view[:, :k] = c * normal[:, :k] + np.sqrt(1 - c * c) * tangent          # grazing views
    to_light = -np.asarray(light_dir, float) / np.linalg.norm(light_dir)
    side = unit(np.cross(to_light, rng.normal(size=(k, 3))).T)
    c = rng.choice([-0.3, -0.05, -1e-3, -1e-6, 0.0, 1e-7, 1e-4, 1e-3, 0.05], size=k) + rng.normal(0, 1e-3, k) * (
        rng.random(k) < 0.5)
    normal[:, k:2 * k] = c * to_light[:, None] + np.sqrt(1 - c * c) * side      # at, before and past the terminator
    view[:, k:2 * k] = unit(normal[:, k:2 * k] + rng.normal(0, 0.5, (3, k)))
    view[:, k:2 * k] *= np.where((normal[:, k:2 * k] * view[:, k:2 * k]).sum(0) < 1e-3, -1, 1)
    position = rng.normal(0, 0.05, (3, m))
    f32 = lambda a: np.ascontiguousarray(a, np.float32)
    hits = sh.Hits(f32(position), f32(normal), f32(view), f32(rng.random((2, m))), f32(10 ** rng.uniform(-5, 0, m)))
    if indirect:
        hits.indirect = f32(rng.random((3, m)) * 0.3)
        hits.visible = f32(rng.random(m))
    hits.radius = f32(10 ** rng.uniform(-3, 0, m))                                # 1 mm .. flat
    hits.skin = rng.random(m) > 0.2 if nails else None
    return hits


def lights_for(rng, direction, position):
    """A directional light with shadows, one without, a point light at `position` with shadows."""
    return [
        {"type": "directional", "radiance": np.float32([2.1, 1.9, 1.6]), "shadows": True,
         "direction": np.asarray(direction, float) / np.linalg.norm(direction)},
        {"type": "directional", "radiance": np.float32([0.3, 0.35, 0.5]), "shadows": False,
         "direction": unit(rng.normal(size=(3, 1)))[:, 0]},
        {"type": "point", "radiance": np.float32([0.9, 0.8, 0.7]), "shadows": True,
         "position": np.asarray(position, float)},
    ]


def texture(rng, channels, rough_floor=True):
    img = rng.random((32, 32, channels)).astype(np.float32)
    if rough_floor and channels > 3:
        img[::2, :, 3] = 0                     # roughness 0: clamped to MIN_ROUGHNESS
    if channels > 4:
        img[:, ::3, 4] = 1                     # fully metallic texels
    return MipTexture([img])


def materials(rng):
    skin = skin_material(texture(rng, 4), roughness_channel=3)
    return {
        "skin": skin,
        "skin_dull": dataclasses.replace(skin, specular=0.0),
        "skin_nowrap": dataclasses.replace(skin, wrap=(0.0, 0.0, 0.0)),
        "metal_map": Material("pbr", texture(rng, 5), 3, 0.5, 4, 0.0),
        "metal_const": Material("pbr", texture(rng, 3), None, 0.0, None, 1.0, f0=0.04),
        "plastic": Material("pbr", texture(rng, 3), None, 0.3, None, 0.0),
        "flat": Material("pbr", texture(rng, 3), None, 0.5, None, 0.0, specular=0.0),
    }


AMBIENT = np.float32([0.1, 0.12, 0.15])


def compare(material, hits, lights, skin_model, ambient=AMBIENT, extent=0.3):
    want_occ, got_occ = Occluder(), Occluder()
    want_counters, got_counters = {}, {}
    want = reference_shade(material, hits, lights, ambient, want_occ, extent, want_counters, skin_model)
    got = sh.shade(material, hits, lights, ambient, got_occ, extent, got_counters, skin_model)
    assert got.dtype == np.float32 and got.shape == want.shape
    assert np.array_equal(got, want), (f"{np.sum(got != want)} of {got.size} differ, largest by "
                                       f"{np.abs(got.astype(float) - want).max():.3g}")
    assert got_counters == want_counters
    assert len(got_occ.rays) == len(want_occ.rays)
    for g, w in zip(got_occ.rays, want_occ.rays):
        for a, b in zip(g, w):
            assert np.array_equal(a, b)
    return got


@pytest.mark.parametrize("skin_model", sh.SKIN_MODELS)
def test_the_compiled_shading_is_the_numpy_shading_to_the_bit(skin_model):
    rng = np.random.default_rng(13)
    direction = (0.3, -0.8, 0.5)
    for material in materials(rng).values():
        for near in (False, True):
            hits = random_hits(rng, 3000, direction, indirect=not near)
            # point light: 10 um off one hit's surface, or a kilometre away
            point = hits.position[:, 5] + 1e-5 * hits.normal[:, 5] if near else np.array([300.0, -900.0, 400.0])
            compare(material, hits, lights_for(rng, direction, point), skin_model)


def test_the_subsurface_table_is_looked_up_as_numpy_does_at_its_edges():
    """Cosines at the table's ends and every column boundary, radii from below its first row to past its last."""
    rng = np.random.default_rng(5)
    cos = np.concatenate([np.linspace(-1, 1, 2 * 129 - 1), [-1.5, 1.5, -1e-8, 1e-8]]).astype(np.float32)
    m = len(cos)
    to_light = np.array([0.0, 0.0, 1.0])
    side = unit(np.cross(to_light, rng.normal(size=(m, 3))).T)
    normal = cos.clip(-1, 1) * to_light[:, None] + np.sqrt(1 - cos.clip(-1, 1) ** 2) * side
    f32 = lambda a: np.ascontiguousarray(a, np.float32)
    hits = sh.Hits(f32(rng.normal(0, 0.01, (3, m))), f32(normal), f32(normal), None, None)
    material = skin_material()
    lights = [{"type": "directional", "radiance": np.float32([1, 1, 1]), "shadows": False,
               "direction": -to_light}]
    for radius in (1e-5, 1e-3, 4e-3, 0.016, 0.3, 1.0, 50.0):
        hits.radius = np.full(m, radius, np.float32)
        hits.skin = None
        compare(material, hits, lights, "subsurface")
    hits.radius = f32(np.geomspace(1e-4, 10, m))
    compare(material, hits, lights, "subsurface")


def test_empty_batches_and_no_lights():
    rng = np.random.default_rng(1)
    mats = materials(rng)
    lights = lights_for(rng, (0, 0, -1), (0, 0, 1))
    for m in (0, 1):
        hits = random_hits(rng, m, (0, 0, -1))
        for model in sh.SKIN_MODELS:
            assert compare(mats["skin"], hits, lights, model).shape == (3, m)
    hits = random_hits(rng, 50, (0, 0, -1), nails=False, indirect=False)
    hits.radius = None
    for name in ("skin", "metal_map"):
        compare(mats[name], hits, [], "subsurface")
        compare(mats[name], hits, lights, "subsurface")           # subsurface without radii: Lambert
    hits.uv = hits.footprint = None                               # no UVs: the texture's mean
    compare(mats["metal_map"], hits, lights, "wrap")


def random_environment(rng):
    """A FrameEnvironment of a random positive map (no lights), turned and coloured."""
    from darthand.render import environment as env
    levels = env.pyramid(rng.uniform(0.0, 4.0, (32, 64, 3)).astype(np.float32))
    lighting = env.MapLighting(np.zeros((0, 3)), np.zeros((0, 3)), levels, np.zeros((9, 3)), [])
    return env.FrameEnvironment([], lighting, env.frame_matrix("camera", np.eye(3), 30.0), np.array([1.0, 0.9, 0.8]))


def test_the_environment_specular_is_its_numpy_definition_to_the_bit():
    # the term: spec x the prefiltered lookup along 2 (n.v) n - v x Karis' F0 A + B (numpy's ambient_specular at
    # the clipped n.v) x the open fraction, added to the rest of the shading
    rng = np.random.default_rng(17)
    environment = random_environment(rng)
    for name, material in materials(rng).items():
        for indirect in (False, True):
            hits = random_hits(rng, 2000, (0.3, -0.8, 0.5), indirect=indirect)
            lights = lights_for(rng, (0.3, -0.8, 0.5), np.array([300.0, -900.0, 400.0]))
            want = reference_shade(material, hits, lights, AMBIENT, Occluder(), 0.3, {}, "wrap")
            spec = np.float32(material.specular)
            if spec:
                p = sh.material_params(material, hits)
                n, v = hits.normal, hits.view
                nv = np.clip(dot(n, v), 1e-4, 1)
                reflect = 2 * dot(n, v) * n - v
                term = environment.specular(reflect, p.roughness) * sh.ambient_specular(p.f0, p.roughness, nv)
                visible = np.ones(n.shape[1], np.float32) if hits.visible is None else hits.visible
                want += spec * term * visible
            got = sh.shade(material, hits, lights, AMBIENT, Occluder(), 0.3, {}, "wrap", environment)
            assert np.array_equal(got, want), (name, indirect, int(np.sum(got != want)))
