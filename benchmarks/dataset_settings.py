"""Dataset render settings, speed against error: what each lossy setting of `render-dataset` (edge sub-samples,
indirect-light rays per vertex, interreflection) costs in CPU per frame and changes in the images, on the frames a
DART-style dataset renders.

Frames: the first DARTHAND_BENCH_SETTINGS_FRAMES (default 24) frames of the default plan (DART's grid-and-slerp
poses, random views, lights and built-in backgrounds, both hands, the build's textures and accessories), 512^2.
Reference: the same frame with every setting at its most exact (16 sub-samples shaded each, 64 indirect rays).
Errors over the pixels the hand or its accessory covers in either image: mean and 99th percentile of |setting -
reference| per channel in linear light and in 8-bit sRGB codes, and the mean |coverage difference| there.
Speed: single-threaded CPU ms per frame (posing to compositing, textures already loaded), the settings alternated
frame by frame in one process so that machine load falls on all alike.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import numpy as np

REFERENCE = {"samples": 16, "aa_shading": "sample", "shading": {"ao_rays": 64}}
SETTINGS = {
    "8 samples, 16 rays (before)": {"samples": 8, "shading": {"ao_rays": 16}},
    "4 samples, 16 rays": {"samples": 4, "shading": {"ao_rays": 16}},
    "8 samples, 8 rays": {"samples": 8, "shading": {"ao_rays": 8}},
    "4 samples, 8 rays": {"samples": 4, "shading": {"ao_rays": 8}},
    "4 samples, 4 rays": {"samples": 4, "shading": {"ao_rays": 4}},
    "1 sample (no anti-aliasing), 8 rays": {"samples": 1, "shading": {"ao_rays": 8}},
    "4 samples, occlusion only, 8 rays": {"samples": 4, "shading": {"ao_rays": 8, "interreflection": False}},
    "4 samples, ambient unblocked": {"samples": 4, "shading": {"ao_rays": 0}},
}


def render_setting(renderer, job: dict, setting: dict, size: int):
    """(api.Frame, CPU seconds) of a dataset job rendered with a setting."""
    from darthand.dataset.frames import render_job

    settings = {"size": size, "samples": setting["samples"], "aa_shading": setting.get("aa_shading", "triangle"),
                "shading": setting.get("shading")}
    c = time.process_time()
    frame, _ = render_job(renderer, job, settings)
    return frame, time.process_time() - c


def frame_errors(frame, reference) -> dict:
    """Per-channel |difference| over the covered pixels: linear values, sRGB codes (the written image), coverage."""
    covered = (frame.alpha > 0) | (reference.alpha > 0)
    lin = np.abs(frame.colour[covered] - reference.colour[covered]).ravel()
    srgb = np.abs(frame.rgba[..., :3][covered].astype(np.int16) - reference.rgba[..., :3][covered]).ravel()
    return {"linear": lin, "srgb": srgb, "alpha": np.abs(frame.alpha[covered] - reference.alpha[covered])}


def run(frames: int | None = None) -> dict:
    from benchmarks.render_dataset import planned_renderers

    frames = int(os.environ.get("DARTHAND_BENCH_SETTINGS_FRAMES", frames or 24))
    size = 512
    with tempfile.TemporaryDirectory() as tmp:
        planner, sources, renderers, where = planned_renderers(Path(tmp))
        names = list(SETTINGS)
        pooled = {name: {"linear": [], "srgb": [], "alpha": []} for name in names}
        cpu = {name: [] for name in names}
        stats = {name: {} for name in names}
        for k, job in enumerate(planner.jobs(0, frames)):
            renderer = renderers[job["side"]]
            reference, _ = render_setting(renderer, job, REFERENCE, size)       # also loads the frame's textures
            for name in names[k % len(names):] + names[:k % len(names)]:       # rotated: no setting always first
                frame, seconds = render_setting(renderer, job, SETTINGS[name], size)
                cpu[name].append(seconds)
                for key, v in frame_errors(frame, reference).items():
                    pooled[name][key].append(v)
                for key in ("primary_rays", "aa_rays", "indirect_rays", "shadow_rays"):
                    stats[name][key] = stats[name].get(key, 0) + frame.stats.get(key, 0)
    table = []
    for name in names:
        lin, srgb, alpha = (np.concatenate(pooled[name][key]) for key in ("linear", "srgb", "alpha"))
        table.append({"setting": name, **SETTINGS[name], "cpu_ms_per_frame": round(1000 * float(np.mean(cpu[name])), 2),
                      "mean_linear": round(float(lin.mean()), 5), "p99_linear": round(float(np.percentile(lin, 99)), 4),
                      "mean_srgb_codes": round(float(srgb.mean()), 3),
                      "p99_srgb_codes": round(float(np.percentile(srgb, 99)), 1),
                      "mean_coverage": round(float(alpha.mean()), 5),
                      **{f"{key}_per_frame": round(v / frames) for key, v in stats[name].items()}})
    return {"frames": frames, "size": size, "inputs": where, "reference": REFERENCE, "table": table,
            "what": "the default DART-style plan's first frames; errors against the same frames at 16 sub-samples "
                    "shaded each and 64 indirect rays, over the covered pixels; CPU per frame on one thread"}


def summary(res: dict) -> str:
    lines = [f"{res['frames']} frames of {res['size']}² from the default plan ({res['inputs']}); reference: 16 "
             "sub-samples shaded each, 64 indirect rays. Errors over the covered pixels.", "",
             "| setting | CPU ms/frame | mean lin | p99 lin | mean sRGB | p99 sRGB | mean coverage | aa rays | "
             "indirect rays |", "|---|---|---|---|---|---|---|---|---|"]
    for r in res["table"]:
        lines.append(f"| {r['setting']} | {r['cpu_ms_per_frame']:.1f} | {r['mean_linear']:.5f} | {r['p99_linear']:.4f} "
                     f"| {r['mean_srgb_codes']:.3f} | {r['p99_srgb_codes']:.0f} | {r['mean_coverage']:.5f} | "
                     f"{r.get('aa_rays_per_frame', 0)} | {r.get('indirect_rays_per_frame', 0)} |")
    return "\n".join(lines)


if __name__ == "__main__":
    import json

    print(json.dumps(run(), indent=2))
