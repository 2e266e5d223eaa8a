"""Per-pixel truth maps (`render-dataset --maps`): what each map adds to a dataset frame, in CPU and disk.

Frames: the first DARTHAND_BENCH_MAPS_FRAMES (default 16) frames of the default plan at 512^2 (both hands, random
views, lights, backgrounds), rendered single-threaded in one process: each without maps, with all three and with
each alone, in an order rotated frame by frame so that machine load falls on all alike. Per map kind: the ms of
computing it from the frame's primary samples (render/truth.truth_maps, the render's timings['maps']: wall time of
one thread), the CPU ms of encoding and writing its PNG, and the file's size; beside them the whole render's CPU
ms (with and without each map) and the image's size.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import numpy as np

KINDS = ("depth", "normals", "parts")


def render_cpu(renderer, job: dict, maps: tuple, size: int):
    """(api.Frame, CPU seconds) of a dataset job rendered with the dataset defaults and `maps`."""
    from darthand.dataset.frames import render_job

    settings = {"size": size, "samples": 4, "aa_shading": "triangle", "maps": maps}
    c = time.process_time()
    frame, _ = render_job(renderer, job, settings)
    return frame, time.process_time() - c


def write_costs(frame, folder: Path) -> dict:
    """{kind: (encode and write CPU ms, file bytes)} of one frame's maps."""
    from darthand.render.truth import write_truth_maps

    out = {}
    for kind in frame.maps:
        path = folder / f"{kind}.png"
        c = time.process_time()
        write_truth_maps({kind: frame.maps[kind]}, {kind: path})
        out[kind] = (1000 * (time.process_time() - c), path.stat().st_size)
    return out


def run(frames: int | None = None) -> dict:
    from benchmarks.render_dataset import dataset_inputs
    from darthand.dataset.plan import Planner, plan_spec
    from darthand.dataset.sources import source_specs
    from darthand.render.api import Renderer
    from darthand.render.image import write_png

    frames = int(os.environ.get("DARTHAND_BENCH_MAPS_FRAMES", frames or 16))
    size = 512
    variants = [(), KINDS] + [(k,) for k in KINDS]
    render_ms: dict = {v: [] for v in variants}
    compute_ms: dict = {v: [] for v in variants[1:]}
    write_ms: dict = {k: [] for k in KINDS}
    file_b: dict = {k: [] for k in KINDS + ("image",)}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        model, textures, accessories, where = dataset_inputs(folder)
        specs = source_specs(str(model), ("right", "left"), textures=str(textures), accessories=str(accessories))
        sources = {side: spec.open() for side, spec in specs.items()}
        planner = Planner({**plan_spec(seed=0), "sides": list(sources)}, sources)
        renderers = {side: Renderer(src, 1) for side, src in sources.items()}
        for k, job in enumerate(planner.jobs(0, frames)):
            renderer = renderers[job["side"]]
            render_cpu(renderer, job, (), size)                           # loads the frame's textures
            for maps in variants[k % len(variants):] + variants[:k % len(variants)]:     # rotated
                frame, seconds = render_cpu(renderer, job, maps, size)
                render_ms[maps].append(1000 * seconds)
                if maps:
                    compute_ms[maps].append(1000 * frame.timings["maps"])
                if maps == KINDS:
                    for kind, (ms, nbytes) in write_costs(frame, folder).items():
                        write_ms[kind].append(ms)
                        file_b[kind].append(nbytes)
                    write_png(folder / "image.png", frame.rgba)
                    file_b["image"].append((folder / "image.png").stat().st_size)
    return {"frames": frames, "size": size, "inputs": where,
            "render_cpu_ms": {"+".join(v) or "none": _mean(t) for v, t in render_ms.items()},
            "compute_ms": {"+".join(v): _mean(t) for v, t in compute_ms.items()},
            "write_cpu_ms": {k: _mean(v) for k, v in write_ms.items()},
            "file_kb": {k: round(float(np.mean(v)) / 1024, 1) for k, v in file_b.items()}}


def summary(res: dict) -> str:
    r, c, w, f = res["render_cpu_ms"], res["compute_ms"], res["write_cpu_ms"], res["file_kb"]
    lines = [f"{res['frames']} frames of the default plan at {res['size']}^2, one thread ({res['inputs']}). "
             f"Render CPU per frame without maps: {r['none']:.1f} ms; with all three: {r['+'.join(KINDS)]:.1f} ms.",
             "", "| map | compute ms | encode + write CPU ms | file kB |", "|---|---|---|---|"]
    lines += [f"| {k} | {c[k]:.2f} | {w[k]:.2f} | {f[k]:.1f} |" for k in KINDS]
    lines.append(f"| all three | {c['+'.join(KINDS)]:.2f} | {sum(w.values()):.2f} | {sum(f[k] for k in KINDS):.1f} |")
    lines.append(f"| (image.png, for scale) | | | {f['image']:.1f} |")
    return "\n".join(lines)


def _mean(values) -> float:
    values = [v for v in values if v == v]
    return round(float(np.mean(values)), 3) if values else float("nan")
