"""Benchmark of image-based lighting (render/environment.py): per-frame CPU of the default light rig against each
built-in environment map, and the error of the renderer's approximation of an environment's light (a few shadowed
directional lights for the bright part, the remainder looked up by the per-vertex indirect rays or its SH irradiance)
against a brute-force reference that integrates the whole map with many rays per pixel.

Speed: 512^2 frames of the render benchmark's scene (textured hand wearing a ring, three-quarter view), one thread,
CPU seconds per frame (median over the gestures), the default rig (render/lights.default_lighting) and each map with
its directional lights, with and without the environment as the background; the lights taken from each map (K) and
the rays a frame casts.

Error: one frame per map in REF_MAPS (a gesture, 160^2), Lambert skin without specular and without interreflection
(what the reference computes: the map's light reflected once, with the hand's and ring's shadows), against
REF_RAYS rays per pixel drawn half from the cosine lobe and half from the map's texels in proportion to their power,
combined by the balance heuristic, every ray shadow-tested, the map at the resolution the renderer's lights are taken
from (LIGHT_WIDTH). Figures over the pixels the subject covers: mean |error| and the 99th percentile of |error|
relative to the reference's mean, the signed bias, and the reference's own noise (half its two halves' mean
difference). Side-by-side images (approximation | reference | 4 x |difference|) go to a temporary folder named in
the results.

Lights per map: the studio map (six soft boxes) with at most 1, 2, 4, 6, 8 lights (environment.MAX_LIGHTS, set here
for the measurement), CPU per frame and error as above (ao_rays 16).
"""

from __future__ import annotations

import dataclasses
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.render import ACCESSORY, _sources

SIZE, FRAMES_PER_CONFIG = 512, 4
REF_SIZE, REF_RAYS, REF_MAPS, REF_GESTURE = 160, 1024, ("studio", "sunrise", "forest", "interior"), "grasp"
AO_RAYS = (0, 4, 16, 64)
LIGHT_COUNTS, SWEEP_MAP = (1, 2, 4, 6, 8), "studio"     # the most lights a map gives (environment.MAX_LIGHTS)
BATCH = 128                          # reference pixels per batch of occlusion queries (BATCH x REF_RAYS rays)


# ------------------------------------------------------------------------------------------------ speed


def _speed(renderer, texture_id: str, gestures: list[str]) -> dict:
    """CPU ms per 512^2 frame, one thread, per lighting: the default rig, each map, each map as the background."""
    from darthand.render.environment import list_builtin

    configs: dict = {"default rig": (None, None)}
    for name in list_builtin():
        configs[f"environment {name}"] = ({"environment": {"map": name}}, None)
    configs["environment studio, background environment"] = ({"environment": {"map": "studio"}}, "environment")
    renderer.threads = 1
    out = {}
    for label, (lights, background) in configs.items():
        renderer.render(gestures[0], texture=texture_id, accessory=ACCESSORY, lights=lights, background=background,
                        width=SIZE, height=SIZE)                 # warm: the map's lights and levels, the kernels
        cpu, stats = [], []
        for pose in gestures[:FRAMES_PER_CONFIG]:
            t = time.process_time()
            frame = renderer.render(pose, texture=texture_id, accessory=ACCESSORY, lights=lights,
                                    background=background, width=SIZE, height=SIZE)
            cpu.append(time.process_time() - t)
            stats.append(frame.stats)
        env = frame.labels["render"]["lights"].get("environment")
        out[label] = {"cpu_ms_median": round(1000 * float(np.median(cpu)), 1),
                      "shadow_rays": round(float(np.mean([s.get("shadow_rays", 0) for s in stats]))),
                      "indirect_rays": round(float(np.mean([s.get("indirect_rays", 0) for s in stats]))),
                      "lights": _light_count(env["map"]) if env else 2}
    return out


def _with_max_lights(count: int):
    """A context in which maps give at most `count` lights (environment.MAX_LIGHTS; the prepared maps are
    forgotten on entry and exit)."""
    import contextlib

    from darthand.render import environment

    @contextlib.contextmanager
    def scope():
        saved = environment.MAX_LIGHTS
        environment.MAX_LIGHTS = count
        environment._map_lighting.cache_clear()
        try:
            yield
        finally:
            environment.MAX_LIGHTS = saved
            environment._map_lighting.cache_clear()

    return scope()


def _sweep_speed(renderer, texture_id: str, gestures: list[str]) -> dict:
    """CPU ms per 512^2 frame, one thread, under SWEEP_MAP with at most k lights, per k in LIGHT_COUNTS."""
    lights = {"environment": {"map": SWEEP_MAP}}
    out = {}
    for count in LIGHT_COUNTS:
        with _with_max_lights(count):
            renderer.render(gestures[0], texture=texture_id, accessory=ACCESSORY, lights=lights, width=SIZE,
                            height=SIZE)
            cpu = []
            for pose in gestures[:FRAMES_PER_CONFIG]:
                t = time.process_time()
                frame = renderer.render(pose, texture=texture_id, accessory=ACCESSORY, lights=lights, width=SIZE,
                                        height=SIZE)
                cpu.append(time.process_time() - t)
            out[count] = {"cpu_ms_median": round(1000 * float(np.median(cpu)), 1),
                          "lights": _light_count(SWEEP_MAP), "shadow_rays": int(frame.stats.get("shadow_rays", 0))}
    return out


def _light_count(name: str) -> int:
    from darthand.render.environment import map_lighting

    return len(map_lighting(name).light_dirs)


# ------------------------------------------------------------------------------------------------ reference


def _lambert_subject(subject):
    """The subject with every material's specular lobe off (the reference reflects diffusely only)."""
    surfaces = tuple(dataclasses.replace(s, material=dataclasses.replace(s.material, specular=0.0))
                     for s in subject.surfaces)
    return dataclasses.replace(subject, surfaces=surfaces)


def _reference(scene, cam, name: str, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(radiance (H, W, 3), geom (H, W)) of the map `name` (frame 'camera', rotation 0) reflected once by Lambert
    surfaces with shadows, REF_RAYS rays per pixel in two halves of different seeds: (radiance of each half stacked
    (2, H, W, 3), geom)."""
    from darthand.render.environment import (LIGHT_WIDTH, frame_matrix, level_of_width, map_lighting,
                                             texel_solid_angles)
    from darthand.render.shade import SHADOW_LIFT, material_params, surface_hits
    from darthand.render.trace import Context, intersect_samples, pixel_centres

    level = level_of_width(map_lighting(name).full, LIGHT_WIDTH).astype(np.float64)
    h, w = level.shape[:2]
    omega = np.broadcast_to(texel_solid_angles(h), (h, w)).ravel()
    texels = level.reshape(-1, 3)
    power = texels @ np.array([0.2126, 0.7152, 0.0722]) * omega
    cdf = np.cumsum(power) / power.sum()
    density = power / power.sum() / omega                     # per steradian, constant over a texel
    to_map = frame_matrix("camera", cam.R)
    ctx = Context(scene, cam, [], np.zeros(3, np.float32))
    hits = intersect_samples(ctx, pixel_centres(0, cam.height, 0, cam.width))
    pixel_angle = 1.0 / float(np.sqrt(abs(np.linalg.det(cam.K[:2, :2]))))
    out = np.zeros((2, cam.height * cam.width, 3))
    lift = SHADOW_LIFT * max(scene.extent, 1e-3)
    for g, surface in enumerate(scene.surfaces):
        idx = np.flatnonzero(hits.geom == g)
        if not len(idx):
            continue
        on = hits.take(idx)
        at = surface_hits(scene.faces[g], on.prim, on.u, on.v, on.directions, on.depth, pixel_angle)
        albedo = material_params(surface.material, at).albedo.T.astype(np.float64)
        for half in range(2):
            rng = np.random.default_rng([seed, g, half])
            for a in range(0, len(idx), BATCH):
                b = min(a + BATCH, len(idx))
                n = at.normal[:, a:b].T.astype(np.float64)
                p = at.position[:, a:b].T.astype(np.float64)
                d = _mixture_directions(rng, n, cdf, h, w, to_map)
                tex = _texel_of(d @ to_map.T, h, w)
                cos = np.maximum((d * n[:, None, :]).sum(-1), 0)
                pdf = 0.5 * cos / np.pi + 0.5 * density[tex]
                origins = np.repeat(p + lift * n, d.shape[1], axis=0).astype(np.float32)
                blocked = scene.occluded(origins, d.reshape(-1, 3).astype(np.float32),
                                         np.full(origins.shape[0], np.inf, np.float32)).reshape(cos.shape)
                weight = np.where(blocked | (pdf <= 0), 0.0, cos / np.maximum(pdf, 1e-30)) / np.pi
                irradiance = (texels[tex] * weight[..., None]).mean(axis=1)
                out[half, idx[a:b]] = albedo[a:b] * irradiance
    return out.reshape(2, cam.height, cam.width, 3), hits.geom.reshape(cam.height, cam.width)


def _mixture_directions(rng, normals: np.ndarray, cdf: np.ndarray, h: int, w: int, to_map: np.ndarray) -> np.ndarray:
    """(P, R, 3) world directions, R = REF_RAYS / 2 per pixel, for P pixels with unit normals (P, 3): each drawn from
    the cosine lobe or from the map's texels by power (uniform in solid angle inside the texel), with equal
    probability."""
    count = len(normals)
    half = REF_RAYS // 2
    # cosine lobe (Malley): a uniform disk point lifted to the hemisphere, in a frame about the normal
    r, phi = np.sqrt(rng.random((count, half))), 2 * np.pi * rng.random((count, half))
    local = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1 - r * r)], -1)
    helper = np.where(np.abs(normals[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    t = np.cross(helper, normals)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    s = np.cross(normals, t)
    cosine = local[..., :1] * t[:, None] + local[..., 1:2] * s[:, None] + local[..., 2:] * normals[:, None]
    # the map by power: a texel, then a uniform point of its solid angle (sin(elevation) uniform between its rows)
    tex = np.minimum(np.searchsorted(cdf, rng.random((count, half))), len(cdf) - 1)
    row, col = np.divmod(tex, w)
    top, bottom = np.pi * (0.5 - row / h), np.pi * (0.5 - (row + 1) / h)
    z = np.sin(bottom) + rng.random((count, half)) * (np.sin(top) - np.sin(bottom))
    az = 2 * np.pi * ((col + rng.random((count, half))) / w - 0.5)
    c = np.sqrt(1 - z * z)
    d_map = np.stack([-c * np.cos(az), c * np.sin(az), z], -1)
    mapped = d_map @ to_map                                    # back to the world (to_map is a rotation)
    pick = rng.random((count, half, 1)) < 0.5
    return np.concatenate([np.where(pick, cosine, mapped), np.where(pick, mapped, cosine)], axis=1)


def _texel_of(d: np.ndarray, h: int, w: int) -> np.ndarray:
    """Flat texel index (P, R) of lookup directions d (P, R, 3) (environment.direction_uv's formula)."""
    u = np.arctan2(d[..., 1], -d[..., 0]) / (2 * np.pi) + 0.5
    v = np.arctan2(d[..., 2], np.hypot(d[..., 0], d[..., 1])) / np.pi + 0.5
    col = np.clip((u * w).astype(np.int64), 0, w - 1)
    row = np.clip(((1 - v) * h).astype(np.int64), 0, h - 1)
    return row * w + col


def _error(renderer, texture_id: str, name: str, images: Path) -> dict:
    """The approximation's error against the reference on one frame under map `name`, per ao_rays."""
    from darthand.render.api import render_subject
    from darthand.render.camera import load_camera
    from darthand.render.image import write_png
    from darthand.render.lights import load_lighting
    from darthand.render.scene import Scene
    from darthand.textures.color import encode_srgb8

    source = renderer.source
    subject = _lambert_subject(source.subject(REF_GESTURE, texture=texture_id, accessory=ACCESSORY))
    scene = Scene(subject)
    cam = load_camera("three_quarter", subject.all_vertices(), width=REF_SIZE, height=REF_SIZE, side=subject.side)
    lighting = load_lighting({"environment": {"map": name}})
    t = time.process_time()
    halves, geom = _reference(scene, cam, name, seed=7)
    ref_s = time.process_time() - t
    reference = halves.mean(axis=0)
    covered = geom >= 0
    scale = float(reference[covered].mean())
    out = {"reference_cpu_s": round(ref_s, 1), "reference_mean": round(scale, 4),
           "reference_noise_rel": round(float(np.abs(halves[0] - halves[1])[covered].mean() / 2 / scale), 4)}
    tiles = []
    for rays in AO_RAYS:
        frame = render_subject(subject, scene, cam, lighting, samples=1, labels=False,
                               shading={"ao_rays": rays, "interreflection": False, "skin": "lambert"})
        diff = (frame.colour - reference)[covered]
        out[f"ao_rays {rays}"] = {"mean_abs_rel": round(float(np.abs(diff).mean() / scale), 4),
                                  "p99_abs_rel": round(float(np.percentile(np.abs(diff), 99) / scale), 4),
                                  "bias_rel": round(float(diff.mean() / scale), 4)}
        if rays == 16:
            exposure = 0.5 / float(np.percentile(reference[covered], 90))
            tiles = [frame.colour * exposure, reference * exposure, 4 * np.abs(frame.colour - reference) * exposure]
    write_png(images / f"{name}.png", np.concatenate([encode_srgb8(t) for t in tiles], axis=1))
    if name == SWEEP_MAP:
        out["max_lights"] = {}
        for count in LIGHT_COUNTS:
            with _with_max_lights(count):
                frame = render_subject(subject, scene, cam, lighting, samples=1, labels=False,
                                       shading={"ao_rays": 16, "interreflection": False, "skin": "lambert"})
            diff = (frame.colour - reference)[covered]
            out["max_lights"][count] = {"mean_abs_rel": round(float(np.abs(diff).mean() / scale), 4),
                                        "p99_abs_rel": round(float(np.percentile(np.abs(diff), 99) / scale), 4)}
    return out


# ------------------------------------------------------------------------------------------------ entry


def run() -> dict:
    from darthand.model.poses import list_gestures
    from darthand.render.api import Renderer, open_source
    from darthand.render.environment import MAX_LIGHTS

    images = Path(tempfile.mkdtemp(prefix="darthand-environment-bench-"))
    with tempfile.TemporaryDirectory() as tmp:
        model, tex, acc, texture_id, where = _sources(Path(tmp))
        renderer = Renderer(open_source(model, textures=tex, accessories=acc), threads=1)
        gestures = list_gestures()
        speed = _speed(renderer, texture_id, gestures)
        sweep = _sweep_speed(renderer, texture_id, gestures)
        error = {name: _error(renderer, texture_id, name, images) for name in REF_MAPS}
    for count, row in sweep.items():
        row.update(error[SWEEP_MAP]["max_lights"][count])
    return {"inputs": where, "texture": texture_id, "accessory": ACCESSORY, "max_lights": MAX_LIGHTS,
            "speed": {"how": f"{SIZE}^2 frames, one thread, CPU ms per frame (median of {FRAMES_PER_CONFIG} "
                             "gestures), default shading", **speed},
            "error": {"how": f"{REF_SIZE}^2, gesture {REF_GESTURE} with {ACCESSORY}, Lambert, no specular, no "
                             f"interreflection, against {REF_RAYS} rays per pixel (cosine + map power, balance "
                             "heuristic); relative to the reference's mean over covered pixels", **error},
            "max_lights_sweep": {"map": SWEEP_MAP, "how": "speed as above, error as above at ao_rays 16",
                                 **{str(k): v for k, v in sweep.items()}},
            "images": str(images)}


def summary(result: dict) -> str:
    speed = {k: v for k, v in result["speed"].items() if k != "how"}
    lines = [f"Speed ({result['speed']['how']}):", "", "| lighting | CPU ms | lights | shadow rays | indirect rays |",
             "|---|---|---|---|---|"]
    lines += [f"| {k} | {v['cpu_ms_median']} | {v['lights']} | {v['shadow_rays']} | {v['indirect_rays']} |"
              for k, v in speed.items()]
    lines += ["", f"Error ({result['error']['how']}):", "",
              "| map | ao_rays | mean abs | p99 abs | bias | reference noise |", "|---|---|---|---|---|---|"]
    for name, res in result["error"].items():
        if name == "how":
            continue
        for rays in AO_RAYS:
            e = res[f"ao_rays {rays}"]
            lines.append(f"| {name} | {rays} | {e['mean_abs_rel']:.1%} | {e['p99_abs_rel']:.1%} | "
                         f"{e['bias_rel']:+.1%} | {res['reference_noise_rel']:.1%} |")
    sweep = result["max_lights_sweep"]
    lines += ["", f"At most K lights from the {sweep['map']} map ({sweep['how']}):", "",
              "| K | lights | CPU ms | shadow rays | mean abs | p99 abs |", "|---|---|---|---|---|---|"]
    lines += [f"| {k} | {v['lights']} | {v['cpu_ms_median']} | {v['shadow_rays']} | {v['mean_abs_rel']:.1%} | "
              f"{v['p99_abs_rel']:.1%} |" for k, v in sweep.items() if k not in ("map", "how")]
    return "\n".join(lines)


if __name__ == "__main__":
    import json

    print(json.dumps(run(), indent=2))
