"""The render alone, and its Embree queries: where a default dataset frame's ray tracing goes.

The first frames of the default plan (seed 0) rendered as `render-dataset` renders them (dataset/frames.render_job
with the dataset's defaults: 512^2, 4 edge sub-samples, single-lobe skin, the arm going on), in this
process on one thread, after a warm-up pass over the same frames (kernels, maps and textures loaded). Figures per
frame: CPU ms of the render (time.process_time around render_job), and per Embree query kind (closest hit:
render/scene.Scene.intersect; occlusion: Scene.occluded) the rays, the CPU ms and the ns a ray. The frame's own ray
counts (primary, edge sub-samples, indirect, shadow) come from its stats. DARTHAND_BENCH_RAYS_FRAMES changes the
frame count (default 16).
"""

from __future__ import annotations

import contextlib
import os
import tempfile
import time
from pathlib import Path

FRAMES = 16
QUERIES = ("intersect", "occluded")


@contextlib.contextmanager
def timed_queries(totals: dict):
    """Within the context, Scene.intersect and Scene.occluded add [calls, rays, CPU seconds] into totals[name]."""
    from darthand.render.scene import Scene

    originals = {name: getattr(Scene, name) for name in QUERIES}

    def timed(name, method):
        def call(self, origins, *args, **kwargs):
            c = time.process_time()
            result = method(self, origins, *args, **kwargs)
            entry = totals.setdefault(name, [0, 0, 0.0])
            entry[0] += 1
            entry[1] += len(origins)
            entry[2] += time.process_time() - c
            return result
        return call

    try:
        for name, method in originals.items():
            setattr(Scene, name, timed(name, method))
        yield totals
    finally:
        for name, method in originals.items():
            setattr(Scene, name, method)


@contextlib.contextmanager
def cpu_timed(owner, name: str, totals: dict, key: str):
    """Within the context, owner.name (a module's or class's function) adds its CPU seconds into totals[key]."""
    original = getattr(owner, name)

    def timed(*args, **kwargs):
        c = time.process_time()
        try:
            return original(*args, **kwargs)
        finally:
            totals[key] = totals.get(key, 0.0) + time.process_time() - c

    setattr(owner, name, timed)
    try:
        yield totals
    finally:
        setattr(owner, name, original)


def default_settings() -> dict:
    """render_job's settings of `render-dataset`'s defaults (dataset/options.py)."""
    from darthand.dataset.options import DEFAULT_SAMPLES, DEFAULT_SIZE, PHOTO_GEOMETRY, PHOTO_SHADING

    return {"size": DEFAULT_SIZE, "samples": DEFAULT_SAMPLES, "aa_shading": "triangle",
            "shading": dict(PHOTO_SHADING), "film": None, "geometry": dict(PHOTO_GEOMETRY)}


def run(frames: int | None = None) -> dict:
    from benchmarks.render_dataset import planned_renderers
    from darthand.dataset.frames import render_job

    frames = int(os.environ.get("DARTHAND_BENCH_RAYS_FRAMES", frames or FRAMES))
    settings = default_settings()
    with tempfile.TemporaryDirectory() as tmp:
        planner, _, renderers, where = planned_renderers(Path(tmp))
        jobs = list(planner.jobs(0, frames))
        for job in jobs:                                    # warm-up: kernels, maps, textures
            render_job(renderers[job["side"]], job, settings)
        cpu, counts, totals = [], {}, {}
        with timed_queries(totals):
            for job in jobs:
                c = time.process_time()
                frame, _ = render_job(renderers[job["side"]], job, settings)
                cpu.append(time.process_time() - c)
                for key in ("primary_rays", "aa_rays", "indirect_rays", "shadow_rays"):
                    counts[key] = counts.get(key, 0) + int(frame.stats.get(key, 0))
    queries = {name: {"calls_per_frame": round(calls / frames, 2), "rays_per_frame": round(rays / frames),
                      "cpu_ms_per_frame": round(1e3 * seconds / frames, 2),
                      "ns_per_ray": round(1e9 * seconds / max(rays, 1), 1)}
               for name, (calls, rays, seconds) in totals.items()}
    cpu_sorted = sorted(cpu)
    return {"frames": frames, "inputs": where, "what": "the render alone (render_job), dataset defaults, one thread",
            "cpu_ms_per_frame": round(1e3 * sum(cpu) / frames, 1),
            "cpu_ms_median": round(1e3 * cpu_sorted[len(cpu) // 2], 1),
            "rays_per_frame": {key: round(v / frames) for key, v in counts.items()}, "queries": queries}
