"""Benchmark of `darthand render-dataset` on planned datasets: 512^2 labelled images, views and poses planned at
random (gestures perturbed, random views), rendered frame-parallel over worker processes (one per core) and written
(PNG + mask + labels). 'one_texture': the scene of benchmarks/render.py (the textured hand wearing the ring, one
shadowed directional light and ambient light); benchmarks/render.py compares processes, threads and one thread.

Figures per configuration (render/dataset.timings): ms_per_image is the steady-state wall time per image once every
worker has started (1000 / images per second); startup_s the time until then (spawning, imports, opening the
source); cpu_ms_per_image the CPU time of the rendering processes per image; tail_idle_s the sharding's imbalance.

'catalogue' renders frames whose textures, skin tones and accessories are drawn from the whole catalogue, as a real
dataset does, but few: nearly every frame loads a new texture (0.1-0.2 s per 2048^2 texture), the worst case; a
large dataset's frames share each texture (render-dataset hands a texture's frames to one worker together).
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

from darthand.benchmarks.render import ACCESSORY, LIGHTS, _sources

KEYS = ("ms_per_image", "images_per_second", "cpu_ms_per_image", "frame_ms_median", "startup_s", "open_s",
        "tail_idle_s", "wall_s", "frames")


def _measure(model, tex, acc, jobs, out: Path, processes: int) -> dict:
    from darthand.render.dataset import render_dataset

    doc = render_dataset(model, out, jobs, processes=processes, textures=tex, accessories=acc, resume=False,
                         progress=False)
    return {k: doc["timings"][k] for k in KEYS if k in doc["timings"]}


def run(frames: int = 64, catalogue_frames: int = 24) -> dict:
    from darthand.render.api import open_source
    from darthand.render.dataset import plan_frames

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        model, tex, acc, texture_id, where = _sources(tmp)
        source = open_source(model, textures=tex, accessories=acc)
        jobs = plan_frames(source, frames, seed=0, textures=[texture_id], accessories=[ACCESSORY],
                           no_accessory_share=0.0, skin_tone_range=(0.0, 0.0), skin_tone_steps=1, lights=LIGHTS)
        t0 = time.perf_counter()
        processes = len(os.sched_getaffinity(0))
        result = {
            "image": "512x512 RGBA + mask + labels.json, textured hand with a ring, 1 shadowed light + ambient, "
                     "8 sub-samples on edge pixels; random views, gestures perturbed by 5 deg per joint axis",
            "inputs": where, "texture": texture_id, "accessory": ACCESSORY, "frames": frames,
            "cores": len(os.sched_getaffinity(0)),
            "processes": processes,
            "one_texture": _measure(model, tex, acc, jobs, tmp / "one", processes),
        }
        if len(source.texture_ids()) > 3:
            cat = plan_frames(source, catalogue_frames, seed=0, lights=LIGHTS)
            result["catalogue"] = {
                **_measure(model, tex, acc, cat, tmp / "cat", processes),
                "textures": len({j["texture"] for j in cat}), "frames": catalogue_frames}
        result["bench_s"] = round(time.perf_counter() - t0, 1)
    return result


if __name__ == "__main__":
    import json

    print(json.dumps(run(), indent=2))
