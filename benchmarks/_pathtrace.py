"""A path-traced reference of a darthand frame, by Mitsuba 3 (`pip install darthand[bench]`, the scalar_rgb variant):
the same posed meshes, camera, textures and lights, with every effect the real-time renderer approximates -- light
blocked and reflected by the hand and accessory (any number of bounces), and, for skin, either an opaque surface or
a scattering volume.

Conventions matched to darthand's (render/lights.py, render/camera.py):
- A directional light of intensity I gives a white Lambert surface facing it radiance I (pi folded in): Mitsuba's
  `directional` emitter takes irradiance, so pi I. The ambient light is a `constant` environment of radiance
  ambient (a Lambert surface seeing all of it reflects albedo x ambient in both).
- The camera is OpenCV's (x right, y down, z forward); Mitsuba's looks along +z with +x to the left and +y up, so its
  to_world has the camera's x and y axes negated. Square pixels, principal point at the image centre (checked).
- Texture v runs up in darthand (v = 0 at the bottom row) and down in Mitsuba's bitmaps: texcoords are (u, 1 - v).
- Meshes get one vertex per (position, uv) corner pair; normals are darthand's vertex normals (smooth shading).

Materials:
- skin 'surface': Lambert diffuse of the texture's albedo plus a GGX lobe with the dielectric Fresnel of skin
  (n = 1.4, F0 = 0.028 = subject.SKIN_F0) and the texture's roughness, summed as darthand sums them (a `blendbsdf`
  of both at weight 1/2, each doubled).
- skin 'volume': the hand is a closed volume (its wrist opening capped) of a homogeneous scattering medium behind an
  index-matched boundary that reflects F0 of the light in a GGX lobe; per channel the medium's mean free path is the
  skin's (render/skin.SKIN_MFP_MM) and its single-scattering albedo is the one whose semi-infinite slab, lit by the
  uniform environment, looks like the skin's albedo seen face-on (`albedo_inversion`: measured by this path tracer).
  The skin's albedo must be a constant colour there (a volume has no uv texture). Nails are an opaque surface.
- accessories: Mitsuba's `principled` BSDF with the material's base colour, roughness and metallic maps.
"""

from __future__ import annotations

import functools
import hashlib
import json
from pathlib import Path

import numpy as np

from darthand.model.layout import FACE_LABEL_IDS
from darthand.model.topology import close_loops
from darthand.render.lights import world_lights
from darthand.render.subject import SKIN_F0

VARIANT = "scalar_rgb"
NAIL = FACE_LABEL_IDS["nail"]
SKIN_IOR = 1.4                  # gives SKIN_F0 at normal incidence: ((1.4 - 1) / 2.4)^2 = 0.0278
# Russian roulette from this depth on only: in a medium of single-scattering albedo near 1, roulette from Mitsuba's
# default depth (5) makes the estimate heavy-tailed -- a face-on slab of albedo 0.9995 measured 0.88 at 4096 spp with
# it and 0.96 without -- so paths are followed until they leave the medium.
VOLUME_RR_DEPTH = 100_000


def mitsuba():
    """The mitsuba module with the scalar_rgb variant set (ImportError with the install hint if it is missing)."""
    try:
        import mitsuba as mi
    except ImportError as e:
        raise ImportError("mitsuba is not installed: pip install -e '.[bench]'") from e
    mi.set_variant(VARIANT)
    return mi


# ------------------------------------------------------------------------------------------------ geometry


def corner_mesh(vertices, normals, faces, uvs=None, faces_uv=None):
    """(positions (K, 3), normals (K, 3), texcoords (K, 2) or None, faces (F, 3) uint32): one vertex per distinct
    (vertex, uv) corner, texcoords in Mitsuba's convention (u, 1 - v)."""
    if uvs is None or faces_uv is None:
        return vertices, normals, None, np.asarray(faces, np.uint32)
    base = len(uvs) + 1
    key = np.asarray(faces, np.int64) * base + np.asarray(faces_uv, np.int64)
    unique, inverse = np.unique(key.ravel(), return_inverse=True)
    vi, ti = unique // base, unique % base
    st = np.asarray(uvs, np.float32)[ti].copy()
    st[:, 1] = 1 - st[:, 1]
    return vertices[vi], normals[vi], st, inverse.reshape(-1, 3).astype(np.uint32)


def mitsuba_mesh(mi, name: str, vertices, normals, faces, uvs=None, faces_uv=None, bsdf=None, interior=None):
    """A mitsuba Mesh of the triangles with smooth normals (and uvs), its BSDF and interior medium."""
    v, n, st, f = corner_mesh(np.asarray(vertices, np.float32), np.asarray(normals, np.float32), faces, uvs,
                              faces_uv)
    props = mi.Properties()
    if bsdf is not None:
        props["bsdf"] = bsdf
    if interior is not None:
        props["interior"] = interior
    mesh = mi.Mesh(name, len(v), len(f), has_vertex_normals=True, has_vertex_texcoords=st is not None, props=props)
    params = mi.traverse(mesh)
    params["vertex_positions"] = np.ascontiguousarray(v, np.float32).ravel()
    params["vertex_normals"] = np.ascontiguousarray(n, np.float32).ravel()
    if st is not None:
        params["vertex_texcoords"] = np.ascontiguousarray(st, np.float32).ravel()
    params["faces"] = np.ascontiguousarray(f, np.uint32).ravel()
    params.update()
    return mesh


def sensor(mi, camera, spp: int):
    """A perspective sensor matching a darthand Camera (square pixels, centred principal point)."""
    K = camera.K
    if abs(K[0, 0] - K[1, 1]) > 1e-9 * K[0, 0] or abs(K[0, 2] - camera.width / 2) > 1e-6 \
            or abs(K[1, 2] - camera.height / 2) > 1e-6 or K[0, 1]:
        raise ValueError("reference: only square pixels with a centred principal point are converted")
    to_world = np.eye(4)
    to_world[:3, 0], to_world[:3, 1], to_world[:3, 2] = -camera.R[0], -camera.R[1], camera.R[2]
    to_world[:3, 3] = camera.centre
    fov = float(np.degrees(2 * np.arctan(camera.width / 2 / K[0, 0])))
    return {"type": "perspective", "fov": fov, "fov_axis": "x", "near_clip": 1e-3, "far_clip": 1e3,
            "to_world": mi.ScalarTransform4f(to_world.tolist()),
            "film": {"type": "hdrfilm", "width": camera.width, "height": camera.height, "pixel_format": "rgba",
                     "rfilter": {"type": "box"}},
            "sampler": {"type": "independent", "sample_count": spp}}


def emitters(mi, lighting, camera) -> dict:
    """Mitsuba emitters of a darthand Lighting seen by a camera (camera-frame lights follow it). Point lights give
    intensity I at 1 m, as darthand's."""
    out = {}
    if lighting.ambient.any():
        out["ambient"] = {"type": "constant", "radiance": {"type": "rgb", "value": lighting.ambient.tolist()}}
    for i, light in enumerate(world_lights(lighting, camera.R, camera.t)):
        if not light["shadows"]:
            raise ValueError("reference: a path tracer cannot render a light without shadows")
        value = {"type": "rgb", "value": (np.pi * light["radiance"]).tolist()} if light["type"] == "directional" \
            else {"type": "rgb", "value": light["radiance"].tolist()}
        if light["type"] == "directional":
            out[f"light{i}"] = {"type": "directional", "direction": light["direction"].tolist(), "irradiance": value}
        else:
            out[f"light{i}"] = {"type": "point", "position": light["position"].tolist(), "intensity": value}
    return out


# ------------------------------------------------------------------------------------------------ materials


def bitmap(mi, image) -> dict:
    """A bilinear, raw (linear) bitmap texture of an (H, W, C) float array."""
    return {"type": "bitmap", "bitmap": mi.Bitmap(np.ascontiguousarray(image, np.float32)), "raw": True,
            "filter_type": "bilinear"}


def _channel(maps, channel, value) -> np.ndarray:
    """(H, W) a data channel of a material's maps, or its constant."""
    return maps[..., channel] if channel is not None else np.full(maps.shape[:2], value, np.float32)


def opaque_skin_bsdf(mi, material) -> dict:
    """Lambert (texture albedo) + GGX with skin's Fresnel and the texture's roughness, summed."""
    maps = material.maps.levels[0]
    rough = np.maximum(_channel(maps, material.roughness_channel, material.roughness_value), 0.045)
    return {"type": "blendbsdf", "weight": 0.5,
            "diffuse": {"type": "diffuse", "reflectance": bitmap(mi, 2 * maps[..., :3])},
            "specular": {"type": "roughconductor", "distribution": "ggx", "alpha": bitmap(mi, (rough ** 2)[..., None]),
                         "eta": {"type": "rgb", "value": [SKIN_IOR] * 3}, "k": {"type": "rgb", "value": [0.0] * 3},
                         "specular_reflectance": bitmap(mi, np.full((1, 1, 3), 2.0 * material.specular))}}


def accessory_bsdf(mi, material) -> dict:
    """Mitsuba's principled BSDF with the metallic-roughness maps (dielectric F0 0.04)."""
    maps = material.maps.levels[0]
    rough = _channel(maps, material.roughness_channel, material.roughness_value)
    metal = _channel(maps, material.metallic_channel, material.metallic_value)
    return {"type": "principled", "base_color": bitmap(mi, maps[..., :3]), "roughness": bitmap(mi, rough[..., None]),
            "metallic": bitmap(mi, metal[..., None]), "specular": 0.5, "spec_tint": 0.0}


def volume_skin(mi, material, inversion):
    """(boundary BSDF, medium) of the scattering skin: index-matched boundary reflecting SKIN_F0 in a GGX lobe of the
    material's roughness, homogeneous medium with the skin's mean free paths and the single-scattering albedo whose
    face-on slab albedo is the material's (constant) albedo."""
    maps = material.maps.levels[0]
    albedo = maps[..., :3].reshape(-1, 3)
    if np.ptp(albedo, axis=0).max() > 1e-4:
        raise ValueError("reference: volume skin needs a constant-colour skin (a medium has no uv texture)")
    rough = float(np.median(_channel(maps, material.roughness_channel, material.roughness_value)))
    boundary = {"type": "mask", "opacity": float(SKIN_F0 * material.specular),
                "nested": {"type": "roughconductor", "distribution": "ggx", "alpha": max(rough, 0.045) ** 2,
                           "material": "none"}}
    sigma_t = 1.0 / (np.asarray(material.mfp_mm, np.float64) * 1e-3)
    medium = {"type": "homogeneous", "albedo": {"type": "rgb", "value": inversion(albedo[0]).tolist()},
              "sigma_t": {"type": "rgb", "value": (sigma_t / sigma_t.max()).tolist()}, "scale": float(sigma_t.max())}
    return mi.load_dict(boundary), mi.load_dict(medium)


# ------------------------------------------------------------------------------------------------ scenes


def frame_scene(subject, camera, lighting, *, skin: str = "surface", spp: int = 256, max_depth: int = 12,
                inversion=None) -> dict:
    """The Mitsuba scene dict of a posed subject seen by a camera under a lighting. skin: 'surface' or 'volume'
    (inversion: albedo (3,) -> single-scattering albedo (3,), see `albedo_inversion`)."""
    mi = mitsuba()
    volume = skin == "volume"
    scene = {"type": "scene",
             "integrator": {"type": "volpath", "max_depth": -1, "rr_depth": VOLUME_RR_DEPTH, "hide_emitters": True}
             if volume else {"type": "path", "max_depth": max_depth, "hide_emitters": True},
             "sensor": sensor(mi, camera, spp), **emitters(mi, lighting, camera)}
    for k, s in enumerate(subject.surfaces):
        name = f"surface{k}"
        if s.material.kind != "skin":
            scene[name] = mitsuba_mesh(mi, name, s.vertices, s.normals, s.faces, s.uvs, s.faces_uv,
                                       mi.load_dict(accessory_bsdf(mi, s.material)))
        elif not volume:
            scene[name] = mitsuba_mesh(mi, name, s.vertices, s.normals, s.faces, s.uvs, s.faces_uv,
                                       mi.load_dict(opaque_skin_bsdf(mi, s.material)))
        else:
            scene.update(_volume_meshes(mi, name, s, inversion))
    return scene


def _volume_meshes(mi, name: str, surface, inversion) -> dict:
    """The skin as a closed volume (wrist opening capped by a fan) and its nails as an opaque surface bounding the
    same medium."""
    boundary, medium = volume_skin(mi, surface.material, inversion)
    vertices, faces = close_loops(np.asarray(surface.vertices, np.float64), surface.faces)
    normals = np.concatenate([surface.normals, np.zeros((len(vertices) - len(surface.vertices), 3), np.float32)])
    caps = np.arange(len(surface.faces), len(faces))
    normals[len(surface.vertices):] = -np.asarray(surface.normals, np.float64)[faces[caps][:, 0]].mean(0)
    labels = surface.face_labels
    nail = np.zeros(len(faces), bool)
    if labels is not None:
        nail[:len(labels)] = labels == NAIL
    out = {name: mitsuba_mesh(mi, name, vertices, normals, faces[~nail], bsdf=boundary, interior=medium)}
    if nail.any():
        out[name + "_nails"] = mitsuba_mesh(mi, name + "_nails", vertices, normals, faces[nail], surface.uvs,
                                            None if surface.faces_uv is None else surface.faces_uv[nail[:len(labels)]],
                                            bsdf=mi.load_dict(opaque_skin_bsdf(mi, surface.material)),
                                            interior=medium)
    return out


def render(scene: dict, spp: int, seed: int) -> np.ndarray:
    """(H, W, 4) float32 RGBA: linear radiance premultiplied by coverage (emitters hidden), and coverage."""
    mi = mitsuba()
    return np.asarray(mi.render(mi.load_dict(scene), spp=spp, seed=seed), np.float32)


# ------------------------------------------------------------------------------------------------ albedo inversion


def slab_albedo(single_scattering, spp: int = 4096, mfp_m: float = 1e-3) -> np.ndarray:
    """(3,) radiance seen face-on from a thick slab of the homogeneous medium (index-matched boundary) lit by a
    uniform environment of radiance 1: the albedo the medium shows."""
    mi = mitsuba()
    medium = {"type": "homogeneous", "albedo": {"type": "rgb", "value": list(map(float, single_scattering))},
              "sigma_t": 1.0, "scale": 1 / mfp_m}
    look = mi.ScalarTransform4f().look_at(origin=[0, 0, 0.5], target=[0, 0, 0], up=[0, 1, 0])
    scene = {"type": "scene",
             "integrator": {"type": "volpath", "max_depth": -1, "rr_depth": VOLUME_RR_DEPTH, "hide_emitters": True},
             "env": {"type": "constant", "radiance": 1.0},
             "slab": {"type": "cube", "to_world": mi.ScalarTransform4f().scale([0.1, 0.1, 0.025]),
                      "bsdf": {"type": "null"}, "interior": medium},
             "sensor": {"type": "orthographic", "to_world": look @ mi.ScalarTransform4f().scale([0.01, 0.01, 1]),
                        "film": {"type": "hdrfilm", "width": 8, "height": 8, "pixel_format": "rgb"},
                        "sampler": {"type": "independent", "sample_count": spp}}}
    return np.asarray(mi.render(mi.load_dict(scene), spp=spp), np.float64).reshape(-1, 3).mean(0)


SINGLE_SCATTERING = (0.3, 0.6, 0.8, 0.9, 0.95, 0.975, 0.99, 0.995, 0.998, 0.9995)


def albedo_inversion(cache: Path | None = None):
    """albedo (3,) -> single-scattering albedo (3,) of the reference's skin medium: `slab_albedo` measured at
    SINGLE_SCATTERING (cached in `cache`, a JSON file) and inverted by monotone interpolation in log(1 - a)."""
    table = None
    if cache is not None and cache.is_file():
        doc = json.loads(cache.read_text())
        if doc.get("single_scattering") == list(SINGLE_SCATTERING):
            table = np.asarray(doc["albedo"])
    if table is None:
        values = np.concatenate([SINGLE_SCATTERING, [SINGLE_SCATTERING[-1]] * (-len(SINGLE_SCATTERING) % 3)])
        table = np.concatenate([slab_albedo(values[i:i + 3]) for i in range(0, len(values), 3)])[
            :len(SINGLE_SCATTERING)]
        if cache is not None:
            cache.parent.mkdir(parents=True, exist_ok=True)
            cache.write_text(json.dumps({"single_scattering": list(SINGLE_SCATTERING), "albedo": table.tolist()}))
    a = np.asarray(SINGLE_SCATTERING)
    order = np.argsort(table)

    def invert(albedo):
        x = np.log(1 - a[order])
        return 1 - np.exp(np.interp(np.asarray(albedo, np.float64), table[order], x))
    invert.table = (a, table)
    return invert


# ------------------------------------------------------------------------------------------------ caching


def scene_digest(subject, camera, lighting, **settings) -> str:
    """sha256 (hex) of what a reference image depends on: posed meshes, materials' texels and constants, camera,
    lights, settings, mitsuba's version."""
    mi = mitsuba()
    h = hashlib.sha256()
    for s in subject.surfaces:
        for a in (s.vertices, s.normals, s.faces, s.uvs, s.faces_uv, s.face_labels, s.material.maps.levels[0]):
            if a is not None:
                h.update(np.ascontiguousarray(a).tobytes())
        m = s.material
        h.update(repr((m.kind, m.roughness_channel, m.roughness_value, m.metallic_channel, m.metallic_value, m.f0,
                       m.specular, tuple(m.mfp_mm))).encode())
    h.update(json.dumps({"camera": camera.to_json(), "lights": lighting.to_json(), "settings": settings,
                         "mitsuba": mi.__version__}, sort_keys=True, default=str).encode())
    return h.hexdigest()


@functools.lru_cache(maxsize=1)
def version() -> str:
    return mitsuba().__version__
