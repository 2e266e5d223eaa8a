"""Shadow rays at vertex rate (render/shadows.py, `--shadows vertex`) against a ray per sample ('pixel'): how often
they disagree, how the images differ, and the CPU they save, on default DART-style frames (render_rays'
default_settings: 512^2, 4 edge sub-samples, the dataset's shading and geometry).

Frames: the first half of DARTHAND_BENCH_SHADOWS_FRAMES (default 16) frames of the default plan (seed 0), and the
other half the planned frames with the most shadow rays among the next 4x as many (ranked by a 128^2 'pixel'
render: the frames with a sun-like light, where the rays cost most). Figures:

- agreement: every shadow ray the vertex mode would decide by its corners is also traced per sample
  (shade.vertex_rate_occlusion wrapped), counting the (sample, light) pairs whose visibility differs; shadow rays
  traced per frame in each mode (the frames' stats);
- images: per frame the 8-bit RGBA pixels that differ, their largest difference and the mean absolute difference
  over the hand (alpha > 0); the frames with most differing pixels are written as PNGs (pixel, vertex and 8x the
  difference) into the output folder;
- CPU (time.process_time, this process, one thread): the frame (render_job) and shade() alone, mean per frame, in
  blocks of 16 frames alternating pixel and vertex (the first mode alternating per round), 3 rounds, after a
  warm-up pass that loads kernels and decodes the textures.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
import time
from pathlib import Path

import numpy as np

FRAMES = 16
BLOCK = 16
ROUNDS = 3
RANK_SIZE = 128
MODES = ("pixel", "vertex")
WORST_WRITTEN = 3


def mode_settings(mode: str, size: int | None = None) -> dict:
    """render_rays.default_settings() with ShadingOptions.shadows = mode (and another size)."""
    from benchmarks.render_rays import default_settings

    s = default_settings()
    return {**s, "size": size or s["size"], "shading": {**s["shading"], "shadows": mode}}


def shadow_frames(planner, renderers, frames: int) -> list[dict]:
    """Jobs: the plan's first frames // 2, and the frames - frames // 2 with most shadow rays among the next
    4 x frames (a RANK_SIZE^2 render each)."""
    from darthand.dataset.frames import render_job

    first = frames // 2
    pool = list(planner.jobs(first, first + 4 * frames))
    rays = [int(render_job(renderers[j["side"]], j, mode_settings("pixel", RANK_SIZE))[0].stats.get("shadow_rays", 0))
            for j in pool]
    top = sorted(np.argsort(rays, kind="stable")[::-1][:frames - first])
    return list(planner.jobs(0, first)) + [pool[i] for i in top]


@contextlib.contextmanager
def compared_visibility(totals: dict):
    """Within the context, the vertex mode's occlusion (shade.vertex_rate_occlusion) also traces every sample's own
    ray and adds into totals 'pairs' (sample, light) and 'differ' (visibility not the per-sample ray's)."""
    from darthand.render import shade
    from darthand.render.shadows import sample_rays

    original = shade.vertex_rate_occlusion

    def compared(corners, ray_hit, position, normal, light, lift, occluded):
        blocked, traced = original(corners, ray_hit, position, normal, light, lift, occluded)
        truth = occluded(*sample_rays(position, normal, ray_hit, light, lift))
        totals["pairs"] = totals.get("pairs", 0) + len(truth)
        totals["differ"] = totals.get("differ", 0) + int((truth != blocked).sum())
        return blocked, traced

    shade.vertex_rate_occlusion = compared
    try:
        yield totals
    finally:
        shade.vertex_rate_occlusion = original


def image_difference(a: np.ndarray, b: np.ndarray, alpha: np.ndarray) -> dict:
    """8-bit RGBA images a, b (H, W, 4): pixels that differ, their largest channel difference, and the mean
    absolute channel difference over the hand's pixels (alpha > 0)."""
    d = np.abs(a.astype(np.int16) - b.astype(np.int16))
    hand = alpha > 0
    return {"pixels": int((d.max(axis=-1) > 0).sum()), "max": int(d.max()),
            "mean_over_hand": float(d[hand][:, :3].mean()) if hand.any() else 0.0}


def write_comparison(out: Path, index: int, a: np.ndarray, b: np.ndarray) -> list[str]:
    """shadows-<index>-pixel.png, -vertex.png and -diff.png (8 x |a - b| of RGB, opaque) into out."""
    from darthand.render.image import write_png

    diff = np.clip(8 * np.abs(a[..., :3].astype(np.int16) - b[..., :3].astype(np.int16)), 0, 255).astype(np.uint8)
    names = [f"shadows-{index:06d}-{kind}.png" for kind in ("pixel", "vertex", "diff")]
    for name, img in zip(names, (a, b, diff)):
        write_png(out / name, img)
    return names


def compare(jobs: list[dict], renderers, out: Path | None) -> dict:
    """Agreement, ray counts and image differences of both modes over jobs; the worst frames' PNGs into out."""
    from darthand.dataset.frames import render_job

    totals: dict = {}
    rays: dict[str, list[int]] = {mode: [] for mode in MODES}
    per_frame = []
    images = {}
    for job in jobs:
        renderer = renderers[job["side"]]
        pixel, _ = render_job(renderer, job, mode_settings("pixel"))
        with compared_visibility(totals):
            vertex, _ = render_job(renderer, job, mode_settings("vertex"))
        for mode, frame in zip(MODES, (pixel, vertex)):
            rays[mode].append(int(frame.stats.get("shadow_rays", 0)))
        per_frame.append({"index": job["index"], **image_difference(pixel.rgba, vertex.rgba, pixel.alpha),
                          **{f"rays_{mode}": rays[mode][-1] for mode in MODES}})
        images[job["index"]] = (pixel.rgba, vertex.rgba)
    worst = sorted(per_frame, key=lambda f: -f["pixels"])[:WORST_WRITTEN]
    written = []
    if out is not None:
        for f in worst:
            if f["pixels"]:
                written += write_comparison(out, f["index"], *images[f["index"]])
    differing = [f["pixels"] for f in per_frame]
    return {
        "pairs": totals.get("pairs", 0), "pairs_differing": totals.get("differ", 0),
        "pairs_differing_share": round(totals.get("differ", 0) / max(1, totals.get("pairs", 0)), 7),
        "shadow_rays_per_frame": {mode: round(float(np.mean(rays[mode]))) for mode in MODES},
        "shadow_rays_max": {mode: int(max(rays[mode])) for mode in MODES},
        "frames_with_differing_pixels": int(sum(p > 0 for p in differing)),
        "differing_pixels_mean": round(float(np.mean(differing)), 2), "differing_pixels_max": int(max(differing)),
        "largest_difference": int(max(f["max"] for f in per_frame)),
        "mean_difference_over_hand": round(float(np.mean([f["mean_over_hand"] for f in per_frame])), 5),
        "worst_frames": worst, "written": written, "per_frame": per_frame,
    }


def cpu_per_frame(jobs: list[dict], renderers) -> dict:
    """Mean CPU ms per frame and of shade() per mode: blocks of BLOCK jobs alternating the modes, ROUNDS rounds;
    also the frame's per half of the jobs ('plan': the plan's first frames, 'sunny': the ranked ones)."""
    from benchmarks.render_rays import cpu_timed
    from darthand.dataset.frames import render_job
    from darthand.render import trace

    frame_s = {mode: 0.0 for mode in MODES}
    shade_s = {mode: 0.0 for mode in MODES}
    half_s = {(half, mode): 0.0 for half in ("plan", "sunny") for mode in MODES}
    first = len(jobs) // 2
    blocks = [jobs[a:a + BLOCK] for a in range(0, len(jobs), BLOCK)]
    for r in range(ROUNDS):
        for b, block in enumerate(blocks):
            for mode in (MODES if (r + b) % 2 == 0 else MODES[::-1]):
                settings = mode_settings(mode)
                totals: dict = {}
                with cpu_timed(trace, "shade", totals, "shade"):
                    for j, job in enumerate(block):
                        c = time.process_time()
                        render_job(renderers[job["side"]], job, settings)
                        seconds = time.process_time() - c
                        frame_s[mode] += seconds
                        half_s["plan" if b * BLOCK + j < first else "sunny", mode] += seconds
                shade_s[mode] += totals.get("shade", 0.0)
    n = ROUNDS * len(jobs)
    frame_ms = {mode: round(1e3 * frame_s[mode] / n, 2) for mode in MODES}
    shade_ms = {mode: round(1e3 * shade_s[mode] / n, 2) for mode in MODES}
    count = {"plan": ROUNDS * first, "sunny": ROUNDS * (len(jobs) - first)}
    halves = {half: {mode: round(1e3 * half_s[half, mode] / max(1, count[half]), 2) for mode in MODES}
              for half in count}
    return {"frame_ms": frame_ms, "shade_ms": shade_ms, "frame_ms_by_half": halves,
            "saved_frame_ms": round(frame_ms["pixel"] - frame_ms["vertex"], 2),
            "saved_shade_ms": round(shade_ms["pixel"] - shade_ms["vertex"], 2)}


def run(out: Path | None = None, frames: int | None = None) -> dict:
    from benchmarks.render_dataset import planned_renderers
    from darthand.dataset.frames import render_job

    frames = int(os.environ.get("DARTHAND_BENCH_SHADOWS_FRAMES", frames or FRAMES))
    with tempfile.TemporaryDirectory() as tmp:
        planner, _, renderers, where = planned_renderers(Path(tmp))
        jobs = shadow_frames(planner, renderers, frames)
        for job in jobs:                                     # warm-up: kernels, maps, textures
            for mode in MODES:
                render_job(renderers[job["side"]], job, mode_settings(mode))
        agreement = compare(jobs, renderers, None if out is None else Path(out))
        cpu = cpu_per_frame(jobs, renderers)
    return {"frames": len(jobs), "indices": [j["index"] for j in jobs], "inputs": where,
            "what": "render_rays.default_settings, shadows 'pixel' against 'vertex', one thread",
            "agreement": agreement, "cpu": cpu}


def half_rows(res: dict) -> list[str]:
    """summary's table rows per half of the frames: the plan's first, the sunniest ranked."""
    frames = res["agreement"]["per_frame"]
    first = len(frames) // 2
    rows = []
    for half, part in (("plan", frames[:first]), ("sunny", frames[first:])):
        ms = res["cpu"]["frame_ms_by_half"][half]
        rays = [round(float(np.mean([f[f"rays_{mode}"] for f in part]))) for mode in MODES]
        rows.append(f"| {half} | {len(part)} | {rays[0]:,} | {rays[1]:,} | {ms['pixel']:.1f} | {ms['vertex']:.1f} |")
    return rows


def summary(res: dict) -> str:
    a, c = res["agreement"], res["cpu"]
    rays = a["shadow_rays_per_frame"]
    lines = [
        f"{res['frames']} default frames ({res['inputs']}): the plan's first half, and the planned frames with most "
        "shadow rays; one thread.", "",
        "| figure | pixel | vertex |", "|---|---|---|",
        f"| shadow rays a frame (mean, max) | {rays['pixel']:,} ({a['shadow_rays_max']['pixel']:,}) | "
        f"{rays['vertex']:,} ({a['shadow_rays_max']['vertex']:,}) |",
        f"| CPU ms a frame | {c['frame_ms']['pixel']:.1f} | {c['frame_ms']['vertex']:.1f} |",
        f"| CPU ms in shade() | {c['shade_ms']['pixel']:.1f} | {c['shade_ms']['vertex']:.1f} |", "",
        f"(sample, light) pairs whose visibility differs from a ray per sample: {a['pairs_differing']:,} of "
        f"{a['pairs']:,} ({100 * a['pairs_differing_share']:.4f} %). 8-bit images: {a['frames_with_differing_pixels']} "
        f"of {res['frames']} frames differ, {a['differing_pixels_mean']:.1f} pixels a frame on average (at most "
        f"{a['differing_pixels_max']}), largest channel difference {a['largest_difference']}, mean absolute "
        f"difference over the hand {a['mean_difference_over_hand']:.4f}.",
        "",
        "| half | frames | shadow rays pixel | vertex | CPU ms pixel | vertex |", "|---|---|---|---|---|---|",
        *half_rows(res),
        "",
        f"summary: vertex-rate shadows trace {rays['vertex'] / max(1, rays['pixel']):.1%} of the shadow rays and save "
        f"{c['saved_frame_ms']:.1f} ms of CPU a frame ({c['saved_shade_ms']:.1f} ms in shade()); "
        f"{100 * a['pairs_differing_share']:.4f} % of (sample, light) pairs differ",
    ]
    return "\n".join(lines)
