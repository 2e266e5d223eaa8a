"""Benchmark of the renderer's realism against a path tracer (Mitsuba 3, benchmarks/_pathtrace.py), next to its speed:
per-pixel error of darthand's frames against path-traced references of the same scenes -- same posed meshes,
cameras, textures and lights -- for each shading option, and ms per frame.

Frames: gestures x views x skin textures, each without and with an accessory, 256^2, the render benchmark's light
rig (one shadowed directional key light, ambient light; the path tracer cannot render lights without shadows).
Reference: Mitsuba's path tracer, REF_SPP samples per pixel in two halves of different seeds (their difference is
the reference's own noise, reported as `reference_noise`), opaque skin (Lambert + GGX, as darthand's 'lambert'
skin), any number of bounces. Errors are over the pixels either image covers, both composited over mid grey:
mean and 99th percentile of |darthand - reference| per channel, in linear radiance and in 8-bit sRGB codes, and the
mean signed difference (bias).

Subsurface skin is checked separately against a scattering volume (`subsurface` section): a path-traced volume is
about a hundred times noisier per sample than a surface, so it is rendered for fewer, smaller frames of plain-colour
skin (a medium has no uv texture) and compared by the noise-corrected root-mean-square error
sqrt(mean((d - r1) (d - r2))) (r1, r2 the halves), which the reference's noise does not bias.

Speed: ms per 512^2 image with both cores (two worker processes rendering and writing frames, as render-dataset
does; the render benchmark's scene) for today's settings and the new defaults, alternated in the same run; and
single-threaded ms per 512^2 frame (rendering only) for every option, the options alternated frame by frame.

References are cached under build/bench/reference/ by a digest of everything they depend on (a first run renders
them: about 25 s per frame on two quiet cores). Side-by-side images (before | after | reference | 4x |after -
reference|) are written there too.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.render import ACCESSORY, LIGHTS, ROOT, _sources

OUT = ROOT / "build" / "bench" / "reference"
REF_SIZE, REF_SPP = 256, 512
GESTURES = {"fist": ACCESSORY, "grasp": "watch_03_round_metal"}        # gesture -> its accessory
VIEWS = ("three_quarter", "palmar")
TEXTURES = ("light_moles_00", "dark_moles_00")
GREY = np.float32(0.5)
BEFORE = {"ao_rays": 0, "skin": "wrap"}                                 # the renderer before indirect light
AFTER = {}                                                              # the defaults (shade.ShadingOptions)
BEFORE_NAME, AFTER_NAME = "before: wrap skin, ambient unblocked", "after (defaults): subsurface skin, indirect 16"
CONFIGS = {
    BEFORE_NAME: BEFORE,
    "lambert skin, ambient unblocked": {"ao_rays": 0, "skin": "lambert"},
    "wrap skin, indirect 16": {"ao_rays": 16, "skin": "wrap"},
    "lambert skin, occlusion only 16": {"ao_rays": 16, "interreflection": False, "skin": "lambert"},
    "lambert skin, indirect 4": {"ao_rays": 4, "skin": "lambert"},
    "lambert skin, indirect 8": {"ao_rays": 8, "skin": "lambert"},
    "lambert skin, indirect 16": {"ao_rays": 16, "skin": "lambert"},
    "lambert skin, indirect 32": {"ao_rays": 32, "skin": "lambert"},
    "lambert skin, indirect 64": {"ao_rays": 64, "skin": "lambert"},
    "subsurface skin, ambient unblocked": {"ao_rays": 0, "skin": "subsurface"},
    AFTER_NAME: AFTER,
}
CURVE_TRUTH = {"ao_rays": 512, "skin": "lambert"}                        # many-ray ground truth of the estimator
SSS_SIZE, SSS_SPP = 96, 512
SSS_FRAMES = (("relaxed", "three_quarter", 0.10), ("fist", "palmar", -0.35))   # gesture, view, plain skin offset
SSS_CONFIGS = {"wrap": {"skin": "wrap"}, "lambert": {"skin": "lambert"}, "subsurface": {"skin": "subsurface"}}


# ------------------------------------------------------------------------------------------------ errors


def over_grey(colour: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """(H, W, 3) premultiplied colour composited over mid grey."""
    return colour + (1 - alpha[..., None]) * GREY


def errors(images: list[np.ndarray], references: list[np.ndarray], masks: list[np.ndarray]) -> dict:
    """Pooled per-pixel, per-channel error figures of darthand images against references (both (H, W, 3) linear,
    over grey) inside masks: mean and p99 of |difference| in linear and in sRGB codes, signed mean per channel."""
    from darthand.textures.color import encode_srgb8

    d = np.concatenate([(a - r)[m] for a, r, m in zip(images, references, masks)])
    codes = np.concatenate([(encode_srgb8(np.clip(a, 0, 1)).astype(np.int16)
                             - encode_srgb8(np.clip(r, 0, 1)).astype(np.int16))[m]
                            for a, r, m in zip(images, references, masks)])
    lin, srgb = np.abs(d), np.abs(codes)
    return {"mean_linear": round(float(lin.mean()), 5), "p99_linear": round(float(np.percentile(lin, 99)), 4),
            "mean_srgb_codes": round(float(srgb.mean()), 3), "p99_srgb_codes": float(np.percentile(srgb, 99)),
            "bias_linear_rgb": [round(float(x), 5) for x in d.mean(0)], "pixels": int(len(d))}


def noise_corrected_rmse(image: np.ndarray, half1: np.ndarray, half2: np.ndarray, mask: np.ndarray) -> float:
    """sqrt(mean((d - r1)(d - r2))): the RMS error against the noise-free reference, unbiased by the halves'
    independent noise (clipped at 0)."""
    prod = ((image - half1) * (image - half2))[mask]
    return float(np.sqrt(max(prod.mean(), 0.0)))


# ------------------------------------------------------------------------------------------------ references


def reference(subject, camera, lighting, spp: int, skin: str = "surface", inversion=None) -> tuple:
    """(half 1, half 2) (H, W, 4) of the path-traced reference, cached under OUT/cache by the scene's digest."""
    from benchmarks import _pathtrace as pt

    key = pt.scene_digest(subject, camera, lighting, spp=spp, skin=skin,
                          inversion=None if inversion is None else np.round(inversion.table[1], 6).tolist())
    path = OUT / "cache" / f"{key[:32]}.npz"
    if path.is_file():
        with np.load(path) as z:
            return z["a"], z["b"]
    scene = pt.frame_scene(subject, camera, lighting, skin=skin, spp=spp // 2, inversion=inversion)
    a, b = pt.render(scene, spp // 2, seed=1), pt.render(scene, spp // 2, seed=2)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, a=a, b=b)
    return a, b


def side_by_side(path: Path, before: np.ndarray, after: np.ndarray, ref: np.ndarray) -> None:
    """A PNG strip: before | after | reference | 4 x |after - reference| (all over grey, sRGB)."""
    import OpenImageIO as oiio

    from darthand.textures.color import encode_srgb8

    diff = np.clip(4 * np.abs(after - ref), 0, 1)
    strip = np.concatenate([encode_srgb8(np.clip(x, 0, 1)) for x in (before, after, ref)]
                           + [(diff * 255 + 0.5).astype(np.uint8)], axis=1)
    path.parent.mkdir(parents=True, exist_ok=True)
    oiio.ImageBuf(np.ascontiguousarray(strip)).write(str(path))


# ------------------------------------------------------------------------------------------------ speed


def _worker(args) -> float:
    """Render and write `count` frames of the render benchmark's scene with shading options, single-threaded: the
    wall seconds (after a warm-up frame)."""
    model, tex, acc, texture_id, shading, poses, out = args
    from darthand.render.api import Renderer, open_source, write_frame

    renderer = Renderer(open_source(model, textures=tex, accessories=acc), threads=1)
    renderer.render(poses[0], texture=texture_id, accessory=ACCESSORY, lights=LIGHTS, shading=shading)
    t0 = time.perf_counter()
    for i, pose in enumerate(poses):
        frame = renderer.render(pose, texture=texture_id, accessory=ACCESSORY, camera="three_quarter",
                                lights=LIGHTS, shading=shading)
        write_frame(frame, Path(out) / f"{i:03d}")
    return time.perf_counter() - t0


def both_cores_ms(sources, configs: dict, frames: int, rounds: int, tmp: Path) -> dict:
    """ms per 512^2 image with one worker process per core for each config, the configs alternated `rounds` times
    in the same pool (median of rounds): each worker renders and writes `frames` frames; a round's time is the
    slowest worker's (from its first timed frame to its last)."""
    from darthand.model.poses import list_gestures

    model, tex, acc, texture_id = sources
    cores = len(os.sched_getaffinity(0))
    gestures = list_gestures()
    times = {name: [] for name in configs}
    ctx = multiprocessing.get_context("spawn")
    with ctx.Pool(cores) as pool:
        for r in range(rounds):
            for name, shading in (configs.items() if r % 2 == 0 else reversed(configs.items())):
                jobs = [(str(model), str(tex), str(acc), texture_id, shading,
                         [gestures[(w + k * cores) % len(gestures)] for k in range(frames)],
                         str(tmp / f"{name[:8]}{r}{w}")) for w in range(cores)]
                # each worker times its frames after opening the source and a warm-up frame; they run together
                times[name].append(1000 * max(pool.map(_worker, jobs)) / (frames * cores))
    return {name: {"ms_per_image": round(float(np.median(v)), 2), "runs": [round(x, 1) for x in v]}
            for name, v in times.items()}


def frame_ms(renderer, texture_id: str, rounds: int = 2) -> dict:
    """Median single-threaded ms per 512^2 frame (rendering only) of each config on the render benchmark's scene
    (the ring, every gesture), the configs alternated frame by frame; and the median ms of the indirect light's
    steps (vertex lighting, rays) and the rays it cast."""
    from darthand.model.poses import list_gestures

    renderer.threads = 1
    ms = {name: [] for name in CONFIGS}
    indirect = {name: [] for name in CONFIGS}
    rays = {name: [] for name in CONFIGS}
    for r in range(rounds):
        for pose in list_gestures():
            for name, shading in CONFIGS.items():
                t0 = time.perf_counter()
                f = renderer.render(pose, texture=texture_id, accessory=ACCESSORY, camera="three_quarter",
                                    lights=LIGHTS, shading=shading)
                if r or pose != list_gestures()[0]:
                    ms[name].append(1000 * (time.perf_counter() - t0))
                    indirect[name].append(1000 * (f.stats.get("indirect", 0) + f.timings.get("indirect_setup", 0)))
                    rays[name].append(f.stats.get("indirect_rays", 0))
    return {name: {"ms_512_one_thread": round(float(np.median(ms[name])), 1),
                   "indirect_ms": round(float(np.median(indirect[name])), 1),
                   "indirect_rays": int(np.median(rays[name]))} for name in CONFIGS}


# ------------------------------------------------------------------------------------------------ run


def _frames(source, texture_ids):
    """[(name, pose, view, texture, accessory)] of the benchmark's frames."""
    out = []
    for gesture, accessory in GESTURES.items():
        for view in VIEWS:
            for texture in texture_ids:
                for acc in (None, accessory if accessory in source.accessory_ids() else None):
                    name = f"{gesture}_{view}_{texture}_{acc or 'none'}"
                    if name not in [f[0] for f in out]:
                        out.append((name, gesture, view, texture, acc))
    return out


def surface_table(renderer, lighting, frames, tmp: Path) -> dict:
    """Errors of every config (and of the indirect-ray curve against its many-ray truth) over the frames."""
    rows = {name: {"img": []} for name in list(CONFIGS) + ["truth"]}
    refs, masks, noise, ious = [], [], [], []
    for name, pose, view, texture, acc in frames:
        opts = dict(texture=texture, accessory=acc, camera=view, lights=lighting, width=REF_SIZE,
                    height=REF_SIZE)
        base = renderer.render(pose, shading=BEFORE, **opts)
        a, b = reference(base.subject, base.camera, lighting, REF_SPP)
        ref_alpha = (a[..., 3] + b[..., 3]) / 2
        ref = over_grey((a[..., :3] + b[..., :3]) / 2, ref_alpha)
        mask = (base.alpha > 0) | (ref_alpha > 0)
        ious.append(float(((base.alpha > 0.5) & (ref_alpha > 0.5)).sum()
                          / ((base.alpha > 0.5) | (ref_alpha > 0.5)).sum()))
        noise.append(np.abs(over_grey(a[..., :3], a[..., 3]) - over_grey(b[..., :3], b[..., 3]))[mask] / 2)
        refs.append(ref)
        masks.append(mask)
        for config, shading in list(CONFIGS.items()) + [("truth", CURVE_TRUTH)]:
            f = renderer.render(pose, shading=shading, **opts)
            rows[config]["img"].append(over_grey(f.colour, f.alpha))
        if acc is not None or pose == "fist":
            side_by_side(OUT / f"side_by_side_{name}.png", rows[BEFORE_NAME]["img"][-1], rows[AFTER_NAME]["img"][-1],
                         ref)
    if min(ious) < 0.99:
        raise RuntimeError(f"reference: silhouettes disagree with darthand's (mask IoU {min(ious):.4f}): the scene "
                           "conversion is wrong")
    # Lists, not dicts: the JSON writer sorts keys, and the rows read best in this order.
    table = [{"shading": config, "options": CONFIGS[config], **errors(rows[config]["img"], refs, masks)}
             for config in CONFIGS]
    curve = [{"rays": CONFIGS[row["shading"]]["ao_rays"],
              "against_512_rays": errors(rows[row["shading"]]["img"], rows["truth"]["img"], masks),
              "against_path_tracer_mean_linear": row["mean_linear"]}
             for row in table if row["shading"].startswith("lambert skin, indirect")]
    n = np.concatenate(noise)
    return {"table": table, "indirect_rays_curve": curve,
            "reference_noise": {"mean_linear": round(float(n.mean()), 5),
                                "p99_linear": round(float(np.percentile(n, 99)), 4)},
            "mask_iou_min": round(min(ious), 4), "mask_iou_mean": round(float(np.mean(ious)), 4)}


def subsurface_table(renderer, lighting, tmp: Path) -> dict:
    """Skin models against a path-traced scattering volume (plain-colour skin, indirect light on in darthand)."""
    from benchmarks import _pathtrace as pt

    inversion = pt.albedo_inversion(OUT / "albedo_inversion.json")
    rows = {name: {"rmse": [], "img": []} for name in SSS_CONFIGS}
    refs, masks, noise = [], [], []
    for pose, view, offset in SSS_FRAMES:
        opts = dict(texture="plain", skin_tone_offset=offset, camera=view, lights=lighting, width=SSS_SIZE,
                    height=SSS_SIZE)
        base = renderer.render(pose, **opts)
        a, b = reference(base.subject, base.camera, lighting, SSS_SPP, skin="volume", inversion=inversion)
        ha, hb = over_grey(a[..., :3], a[..., 3]), over_grey(b[..., :3], b[..., 3])
        mask = (base.alpha > 0) | (a[..., 3] > 0)
        refs.append((ha + hb) / 2)
        masks.append(mask)
        noise.append(np.abs(ha - hb)[mask] / 2)
        for name, shading in SSS_CONFIGS.items():
            f = renderer.render(pose, shading=shading, **opts)
            img = over_grey(f.colour, f.alpha)
            rows[name]["img"].append(img)
            rows[name]["rmse"].append(noise_corrected_rmse(img, ha, hb, mask))
        side_by_side(OUT / f"subsurface_{pose}_{view}.png", rows["wrap"]["img"][-1], rows["subsurface"]["img"][-1],
                     refs[-1])
    n = np.concatenate(noise)
    out = {"frames": [f"{p} {v} plain skin offset {o:+.2f}" for p, v, o in SSS_FRAMES], "size": SSS_SIZE,
           "spp": SSS_SPP, "reference_noise_mean_linear": round(float(n.mean()), 5),
           "albedo_inversion": {"single_scattering": list(inversion.table[0]),
                                "face_on_albedo": [round(float(x), 4) for x in inversion.table[1]]}}
    for name in SSS_CONFIGS:
        out[name] = {"rmse_noise_corrected_linear": round(float(np.sqrt(np.mean(np.square(rows[name]["rmse"])))), 5),
                     **{k: v for k, v in errors(rows[name]["img"], refs, masks).items()
                        if k in ("mean_linear", "bias_linear_rgb")}}
    return out


def run() -> dict:
    try:
        from benchmarks import _pathtrace as pt

        pt.mitsuba()
    except ImportError as e:
        return {"skipped": str(e)}
    from darthand.render.api import Renderer, open_source
    from darthand.render.lights import load_lighting

    t_start = time.perf_counter()
    lighting = load_lighting(LIGHTS)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        model, tex, acc, texture_id, where = _sources(tmp)
        source = open_source(model, textures=tex, accessories=acc)
        renderer = Renderer(source, threads=1)
        texture_ids = [t for t in TEXTURES if t in source.texture_ids()] or [texture_id]
        frames = _frames(source, texture_ids)
        surface = surface_table(renderer, lighting, frames, tmp)
        subsurface = subsurface_table(renderer, lighting, tmp)
        timing = frame_ms(renderer, texture_id)
        for row in surface["table"]:
            row.update(timing[row["shading"]])
        speed = both_cores_ms((model, tex, acc, texture_id), {"before": BEFORE, "after": AFTER}, frames=24,
                              rounds=6, tmp=tmp)
    table = {row["shading"]: row for row in surface["table"]}
    before, after = table[BEFORE_NAME], table[AFTER_NAME]
    return {
        "headline": {
            "mean_error_linear_before": before["mean_linear"], "mean_error_linear_after": after["mean_linear"],
            "error_ratio": round(after["mean_linear"] / before["mean_linear"], 3),
            "ms_per_image_before": speed["before"]["ms_per_image"],
            "ms_per_image_after": speed["after"]["ms_per_image"],
            "time_ratio": round(speed["after"]["ms_per_image"] / speed["before"]["ms_per_image"], 3),
            "time_ratio_one_thread_alternated": round(after["ms_512_one_thread"] / before["ms_512_one_thread"], 3),
            "goal": "error ratio <= 0.5 at time ratio <= 1.25"},
        "frames": len(frames), "frame_names": [f[0] for f in frames], "size": REF_SIZE, "reference_spp": REF_SPP,
        "inputs": where, "mitsuba": pt.version(), "lights": LIGHTS,
        "surface": surface, "subsurface": subsurface, "both_cores_512": speed,
        "images": str(OUT.relative_to(ROOT)),
        "bench_s": round(time.perf_counter() - t_start, 1),
    }


if __name__ == "__main__":
    print(json.dumps(run(), indent=2))


def summary(res: dict) -> str:
    """The markdown section of `make bench`'s README: the headline, the options' table, the indirect-ray curve, the
    skin models against the scattering volume, the two-core timings."""
    if "skipped" in res:
        return f"Skipped: {res['skipped']}"
    h = res["headline"]
    s = res["surface"]
    lines = [f"**Mean |error| against the path tracer (linear): {h['mean_error_linear_before']:.4f} before, "
             f"{h['mean_error_linear_after']:.4f} after ({h['error_ratio']:.2f}x); ms per 512² image with both cores: "
             f"{h['ms_per_image_before']:.1f} before, {h['ms_per_image_after']:.1f} after ({h['time_ratio']:.2f}x; "
             f"one thread, options alternated frame by frame: {h['time_ratio_one_thread_alternated']:.2f}x).** "
             f"Goal: {h['goal']}.", "",
             f"{res['frames']} frames of {res['size']}² (gestures × views × textures, without and with an "
             f"accessory), Mitsuba {res['mitsuba']} path tracer at {res['reference_spp']} spp, opaque skin; "
             f"reference noise {s['reference_noise']['mean_linear']:.4f} mean, "
             f"{s['reference_noise']['p99_linear']:.3f} p99 (linear); mask IoU ≥ {s['mask_iou_min']:.4f}.", "",
             "| shading | mean lin | p99 lin | mean sRGB | p99 sRGB | bias lin (R, G, B) | ms/frame 512² 1 thread "
             "| of which indirect | indirect rays |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in s["table"]:
        name = r["shading"]
        bias = ", ".join(f"{b:+.4f}" for b in r["bias_linear_rgb"])
        lines.append(f"| {name} | {r['mean_linear']:.4f} | {r['p99_linear']:.3f} | {r['mean_srgb_codes']:.2f} | "
                     f"{r['p99_srgb_codes']:.0f} | {bias} | {r.get('ms_512_one_thread', '')} | "
                     f"{r.get('indirect_ms', '')} | {r.get('indirect_rays', '')} |")
    lines += ["", "Indirect light: rays per hand vertex (accessory vertices a quarter, at least 4) against the same "
              "estimate with 512 rays (the many-ray truth of the estimator) and against the path tracer (lambert "
              "skin):", "",
              "| rays | mean lin vs 512 | p99 lin vs 512 | mean sRGB vs 512 | mean lin vs path tracer |",
              "|---|---|---|---|---|"]
    for r in s["indirect_rays_curve"]:
        a = r["against_512_rays"]
        lines.append(f"| {r['rays']} | {a['mean_linear']:.4f} | {a['p99_linear']:.3f} | "
                     f"{a['mean_srgb_codes']:.2f} | {r['against_path_tracer_mean_linear']:.4f} |")
    sss = res["subsurface"]
    lines += ["", f"Skin models against a path-traced scattering volume ({'; '.join(sss['frames'])}; "
              f"{sss['size']}², {sss['spp']} spp, reference noise {sss['reference_noise_mean_linear']:.4f} mean; "
              "RMSE corrected for that noise), indirect light on:", "",
              "| skin | RMSE lin | mean lin (with noise) | bias lin (R, G, B) |", "|---|---|---|---|"]
    for name in SSS_CONFIGS:
        r = sss[name]
        bias = ", ".join(f"{b:+.4f}" for b in r["bias_linear_rgb"])
        lines.append(f"| {name} | {r['rmse_noise_corrected_linear']:.4f} | {r['mean_linear']:.4f} | {bias} |")
    speed = res["both_cores_512"]
    lines += ["", "Both cores, ms per 512² image (runs alternated): "
              + "; ".join(f"{k} {v['ms_per_image']} ({', '.join(map(str, v['runs']))})" for k, v in speed.items()),
              "", f"Side-by-side images (before | after | reference | 4×|after − reference|): `{res['images']}/`."]
    return "\n".join(lines)
