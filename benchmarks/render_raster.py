"""Rasterised camera visibility (render/raster.py) against Embree's camera rays, on DART-style frames.

The first frames of the default plan (seed 0, both sides, the dataset defaults: benchmarks.render_rays
.default_settings), rendered as `render-dataset` renders them (dataset/frames.render_job) in this process on one
thread. Figures:

- agreement: every camera sample of each frame (the primary samples at pixel centres, the edge pixels'
  sub-samples) traced by Embree and rasterised: the share whose surface or face differ, and where they agree the
  largest and mean |du|, |dv| and relative depth difference; then each frame rendered both ways: pixels of the
  8-bit image and mask that differ and the largest difference, frames whose labels differ (they come from the
  model and the labels' own rays; only `coverage`, the mask's sum, may follow the mask) and in which fields, and
  frames whose camera rays went to Embree after all (raster.camera_hits' fallback: a vertex not finite).
- cpu: CPU ms a frame (time.process_time) of the render and of its camera visibility alone (trace
  .intersect_samples: the camera rays and their closest hits), after a warm-up pass over the same frames (kernels,
  maps, textures), in alternating blocks (Embree, raster) of the same frames, ROUNDS rounds.

DARTHAND_BENCH_RASTER_FRAMES changes the agreement's frame count (default 16), DARTHAND_BENCH_RASTER_BLOCK the
timing block's (default 16).
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np

FRAMES = 16
BLOCK = 16
ROUNDS = 3


@contextlib.contextmanager
def rasterising(on: bool):
    """Within the context, raster.ENABLED is `on`."""
    from darthand.render import raster

    before = raster.ENABLED
    raster.ENABLED = on
    try:
        yield
    finally:
        raster.ENABLED = before


@contextlib.contextmanager
def compared_samples(totals: dict):
    """Within the context, trace.intersect_samples answers with Embree and also rasterises the same samples,
    adding into totals['primary'] or totals['aa'] (pixel centres or not) the sample count, those whose surface or
    face differ, and the |du|, |dv|, relative depth arrays where they agree."""
    from darthand.render import trace

    original = trace.intersect_samples

    def both(ctx, uv, stats=None):
        with rasterising(False):
            embree = original(ctx, uv, stats)
        with rasterising(True):
            ours = original(ctx, uv, None)
        kind = "primary" if np.all(np.mod(uv, 1.0) == 0.5) else "aa"
        entry = totals.setdefault(kind, {"samples": 0, "differ": 0, "du": [], "dv": [], "depth": []})
        agree = (embree.geom == ours.geom) & ((embree.prim == ours.prim) | (embree.geom < 0))
        on = agree & (embree.geom >= 0)
        entry["samples"] += len(uv)
        entry["differ"] += int((~agree).sum())
        entry["du"].append(np.abs(embree.u[on] - ours.u[on]))
        entry["dv"].append(np.abs(embree.v[on] - ours.v[on]))
        entry["depth"].append(np.abs(embree.depth[on] - ours.depth[on]) / embree.depth[on])
        return embree

    trace.intersect_samples = both
    try:
        yield totals
    finally:
        trace.intersect_samples = original


def sample_figures(entry: dict) -> dict:
    """A compared_samples entry as figures: share differing, max and mean |du|, |dv|, relative depth."""
    out = {"samples": entry["samples"], "differ": entry["differ"],
           "differ_share": round(entry["differ"] / max(entry["samples"], 1), 7)}
    for key in ("du", "dv", "depth"):
        values = np.concatenate(entry[key]) if entry[key] else np.zeros(1)
        out[f"{key}_max"] = float(values.max())
        out[f"{key}_mean"] = float(values.mean())
        out[f"{key}_over_1e-4"] = int((values > 1e-4).sum())
    return out


def image_figures(pairs: list) -> dict:
    """Pixels (of all frames) of the 8-bit images and masks that differ between Embree and raster frames, their
    largest difference, the frames whose labels differ and in which top-level fields ('coverage' is the mask's
    sum, so it follows the mask)."""
    from darthand.render.image import encode_mask8

    out: dict = {"frames": len(pairs), "pixels": 0, "image_pixels_differ": 0, "image_max_diff": 0,
                 "mask_pixels_differ": 0, "mask_max_diff": 0, "labels_differ": 0, "labels_fields_differ": []}
    for embree, ours in pairs:
        out["pixels"] += embree.rgba.shape[0] * embree.rgba.shape[1]
        diff = np.abs(embree.rgba.astype(np.int16) - ours.rgba.astype(np.int16)).max(axis=2)
        out["image_pixels_differ"] += int((diff > 0).sum())
        out["image_max_diff"] = max(out["image_max_diff"], int(diff.max()))
        mask = np.abs(encode_mask8(embree.alpha).astype(np.int16) - encode_mask8(ours.alpha).astype(np.int16))
        out["mask_pixels_differ"] += int((mask > 0).sum())
        out["mask_max_diff"] = max(out["mask_max_diff"], int(mask.max()))
        fields = {k for k in set(embree.labels) | set(ours.labels) if json.dumps(embree.labels.get(k), sort_keys=True)
                  != json.dumps(ours.labels.get(k), sort_keys=True)}
        out["labels_differ"] += int(bool(fields))
        out["labels_fields_differ"] = sorted(set(out.get("labels_fields_differ", [])) | fields)
    return out


def agreement(renderers, jobs, settings) -> dict:
    """Sample and image agreement of the jobs rendered with Embree's and with rasterised camera visibility."""
    from darthand.dataset.frames import render_job

    totals: dict = {}
    pairs = []
    for job in jobs:
        renderer = renderers[job["side"]]
        with compared_samples(totals):
            embree, _ = render_job(renderer, job, settings)
        with rasterising(True):
            ours, _ = render_job(renderer, job, settings)
        pairs.append((embree, ours))
    fell_back = sum(ours.stats.get("rasterised", 0) != ours.stats.get("rays", 0) for _, ours in pairs)
    return {"samples": {kind: sample_figures(entry) for kind, entry in sorted(totals.items())},
            "images": image_figures(pairs), "frames_given_to_embree": int(fell_back)}


def cpu_per_frame(renderers, jobs, settings, rounds: int = ROUNDS) -> dict:
    """CPU ms a frame of the render and of its camera visibility, Embree and raster, in alternating blocks."""
    from benchmarks.render_rays import cpu_timed
    from darthand.dataset.frames import render_job
    from darthand.render import trace

    blocks: dict = {"embree": [], "raster": []}                    # per block: (frame ms, visibility ms)
    for _ in range(rounds):
        for mode in ("embree", "raster"):
            visibility: dict = {}
            with rasterising(mode == "raster"), cpu_timed(trace, "intersect_samples", visibility, "s"):
                c = time.process_time()
                for job in jobs:
                    render_job(renderers[job["side"]], job, settings)
                frame = time.process_time() - c
            blocks[mode].append((1e3 * frame / len(jobs), 1e3 * visibility.get("s", 0.0) / len(jobs)))
    out: dict = {mode: {"frame_ms": round(float(np.mean([b[0] for b in runs])), 2),
                        "visibility_ms": round(float(np.mean([b[1] for b in runs])), 2),
                        "blocks_frame_ms": [round(b[0], 2) for b in runs],
                        "blocks_visibility_ms": [round(b[1], 2) for b in runs]}
                 for mode, runs in blocks.items()}
    out["saved_ms"] = round(out["embree"]["frame_ms"] - out["raster"]["frame_ms"], 2)
    out["visibility_saved_ms"] = round(out["embree"]["visibility_ms"] - out["raster"]["visibility_ms"], 2)
    out["frames_per_block"], out["rounds"] = len(jobs), rounds
    return out


def run(frames: int | None = None) -> dict:
    from benchmarks.render_dataset import planned_renderers
    from benchmarks.render_rays import default_settings
    from darthand.dataset.frames import render_job

    frames = int(os.environ.get("DARTHAND_BENCH_RASTER_FRAMES", frames or FRAMES))
    block = int(os.environ.get("DARTHAND_BENCH_RASTER_BLOCK", BLOCK))
    settings = default_settings()
    with tempfile.TemporaryDirectory() as tmp:
        planner, _, renderers, where = planned_renderers(Path(tmp))
        jobs = list(planner.jobs(0, max(frames, block)))
        for job in jobs[:block]:                                  # warm-up: kernels, maps, textures
            for on in (False, True):
                with rasterising(on):
                    render_job(renderers[job["side"]], job, settings)
        agree = agreement(renderers, jobs[:frames], settings)
        for job in jobs[:block]:          # their textures again: the agreement's frames pushed them out of the cache
            render_job(renderers[job["side"]], job, settings)
        cpu = cpu_per_frame(renderers, jobs[:block], settings)
    return {"frames": frames, "inputs": where, "what": "render_job of the default plan's first frames, dataset "
            "defaults, one thread: camera visibility by Embree and rasterised (render/raster.py)",
            "agreement": agree, "cpu": cpu}


def summary(result: dict) -> str:
    a, cpu = result["agreement"], result["cpu"]
    p, s = a["samples"].get("primary", {}), a["samples"].get("aa", {})
    img = a["images"]
    fields = ", ".join(img.get("labels_fields_differ", [])) or "no field"
    return (f"raster: of {result['frames']} frames, {100 * p.get('differ_share', 0):.4f} % of primary samples and "
            f"{100 * s.get('differ_share', 0):.4f} % of edge sub-samples hit another face than Embree's (max |du| "
            f"{max(p.get('du_max', 0), s.get('du_max', 0)):.1e}); images: {img['image_pixels_differ']} of "
            f"{img['pixels']} pixels differ (max {img['image_max_diff']}), masks {img['mask_pixels_differ']}, labels "
            f"differ in {img['labels_differ']} frames ({fields}). CPU a frame {cpu['embree']['frame_ms']} -> "
            f"{cpu['raster']['frame_ms']} ms (camera visibility {cpu['embree']['visibility_ms']} -> "
            f"{cpu['raster']['visibility_ms']} ms).")


if __name__ == "__main__":
    print(json.dumps(run(), indent=2))
