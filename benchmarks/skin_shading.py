"""Skin shading options (issue 28: render/skin_specular.py, render/skin_detail.py): what each adds to a frame's CPU.

Frames: the first DARTHAND_BENCH_SKIN_FRAMES (default 12) frames of the default plan (both hands, random views,
lights, textures, backgrounds), at 256^2 and 512^2, rendered single-threaded in one process with the dataset's
render settings: today's shading, skin_specular 'dual', skin_detail 1, and both, in an order rotated frame by frame
so that machine load falls on all alike. Per variant and size: mean CPU ms per frame and its difference to today's.
The relief is built once per model before timing (its build, a one-off per process and side, is reported apart).
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import numpy as np

VARIANTS = {"today": {}, "dual": {"skin_specular": "dual"}, "detail": {"skin_detail": 1.0},
            "dual+detail": {"skin_specular": "dual", "skin_detail": 1.0}}
SIZES = (256, 512)


def render_cpu(renderer, job: dict, shading: dict, size: int) -> float:
    """CPU seconds of one dataset job rendered with the dataset's settings and `shading`."""
    from darthand.dataset.frames import render_job

    settings = {"size": size, "samples": 4, "aa_shading": "triangle", "shading": shading}
    c = time.process_time()
    render_job(renderer, job, settings)
    return time.process_time() - c


def run(frames: int | None = None) -> dict:
    from benchmarks.render_dataset import planned_renderers

    frames = int(os.environ.get("DARTHAND_BENCH_SKIN_FRAMES", frames or 12))
    names = list(VARIANTS)
    cpu: dict = {(v, s): [] for v in names for s in SIZES}
    build_s = {}
    with tempfile.TemporaryDirectory() as tmp:
        planner, sources, renderers, where = planned_renderers(Path(tmp))
        for side, src in sources.items():
            c = time.process_time()
            src.detail_map().texture()
            build_s[side] = round(time.process_time() - c, 2)
        for k, job in enumerate(planner.jobs(0, frames)):
            renderer = renderers[job["side"]]
            for shading in VARIANTS.values() if k < 2 else ({},):   # loads textures (and first-call tables)
                render_cpu(renderer, job, shading, SIZES[0])
            for size in SIZES:
                for name in names[k % len(names):] + names[:k % len(names)]:     # rotated
                    cpu[name, size].append(1000 * render_cpu(renderer, job, VARIANTS[name], size))
    ms = {f"{s}": {v: round(float(np.mean(cpu[v, s])), 2) for v in names} for s in SIZES}
    return {"frames": frames, "inputs": where, "cpu_ms": ms,
            "added_ms": {f"{s}": {v: round(ms[f"{s}"][v] - ms[f"{s}"]["today"], 2) for v in names[1:]}
                         for s in SIZES},
            "relief_build_cpu_s": build_s}


def summary(res: dict) -> str:
    ms, added = res["cpu_ms"], res["added_ms"]
    lines = [f"{res['frames']} frames of the default plan, one thread ({res['inputs']}); CPU ms per frame "
             "(added to today's in brackets).", "",
             "| size | " + " | ".join(VARIANTS) + " |", "|---" * (len(VARIANTS) + 1) + "|"]
    for s in SIZES:
        row = [f"{ms[str(s)]['today']:.1f}"] + [f"{ms[str(s)][v]:.1f} (+{added[str(s)][v]:.1f})"
                                               for v in list(VARIANTS)[1:]]
        lines.append(f"| {s}^2 | " + " | ".join(row) + " |")
    build = ", ".join(f"{side} {sec:.1f} s" for side, sec in res["relief_build_cpu_s"].items())
    lines += ["", f"Relief build (once per process and model): {build} of CPU."]
    return "\n".join(lines)
