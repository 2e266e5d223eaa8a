"""The environment's specular lookups at vertex rate (render/vertex_specular.py, `--environment-lookups vertex`)
against a lookup per sample ('pixel'): how the images differ and the CPU saved, on default DART-style frames
(render_rays' default_settings: 512^2, 4 edge sub-samples, the dataset's shading and geometry; every frame lit by an
environment map).

Frames: the first DARTHAND_BENCH_LOOKUPS_FRAMES (default 16) frames of the default plan (seed 0). Figures, as
render_shadows measures them: per frame the 8-bit RGBA pixels that differ, their largest difference and the mean
absolute difference over the hand (alpha > 0), the worst frames written as PNGs into the output folder; CPU
(time.process_time, this process, one thread) of the frame and of shade(), in blocks of 16 frames alternating the
modes, 3 rounds, after a warm-up pass in both modes.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

OPTION = "environment_lookups"
FRAMES = 16


def run(out: Path | None = None, frames: int | None = None) -> dict:
    from benchmarks.render_dataset import planned_renderers
    from benchmarks.render_shadows import MODES, compare, cpu_per_frame, mode_settings
    from darthand.dataset.frames import render_job

    frames = int(os.environ.get("DARTHAND_BENCH_LOOKUPS_FRAMES", frames or FRAMES))
    with tempfile.TemporaryDirectory() as tmp:
        planner, _, renderers, where = planned_renderers(Path(tmp))
        jobs = list(planner.jobs(0, frames))
        for job in jobs:                                     # warm-up: kernels, maps, textures
            for mode in MODES:
                render_job(renderers[job["side"]], job, mode_settings(mode, option=OPTION))
        images = compare(jobs, renderers, None if out is None else Path(out), OPTION)
        cpu = cpu_per_frame(jobs, renderers, OPTION)
    keep = ("frames_with_differing_pixels", "differing_pixels_mean", "differing_pixels_max", "largest_difference",
            "mean_difference_over_hand", "worst_frames", "written")
    return {"frames": len(jobs), "inputs": where,
            "what": "render_rays.default_settings, environment_lookups 'pixel' against 'vertex', one thread",
            "images": {k: images[k] for k in keep}, "cpu": {k: cpu[k] for k in ("frame_ms", "shade_ms",
                                                                                 "saved_frame_ms", "saved_shade_ms")}}


def summary(res: dict) -> str:
    i, c = res["images"], res["cpu"]
    return "\n".join([
        f"The first {res['frames']} default frames of the plan ({res['inputs']}); one thread.", "",
        "| figure | pixel | vertex |", "|---|---|---|",
        f"| CPU ms a frame | {c['frame_ms']['pixel']:.1f} | {c['frame_ms']['vertex']:.1f} |",
        f"| CPU ms in shade() | {c['shade_ms']['pixel']:.1f} | {c['shade_ms']['vertex']:.1f} |", "",
        f"8-bit images: {i['frames_with_differing_pixels']} of {res['frames']} frames differ, "
        f"{i['differing_pixels_mean']:.0f} pixels a frame on average (at most {i['differing_pixels_max']}), largest "
        f"channel difference {i['largest_difference']}, mean absolute difference over the hand "
        f"{i['mean_difference_over_hand']:.3f}.", "",
        f"summary: vertex-rate environment lookups save {c['saved_frame_ms']:.1f} ms of CPU a frame "
        f"({c['saved_shade_ms']:.1f} ms in shade()); mean absolute difference over the hand "
        f"{i['mean_difference_over_hand']:.3f} of 255, largest {i['largest_difference']}",
    ])
