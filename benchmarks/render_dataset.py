"""DART-style dataset benchmark: `darthand render-dataset` end to end as a researcher runs it. 10,000 frames of
512^2 over every texture of the build's catalogue (325), both hands, an accessory on 25 % of the frames, the
dataset defaults' look (an environment map per frame lighting the hand and seen behind it, the skin's single
lobe, the arm going on), poses from DART's grid-and-slerp sampler over the gesture library, labels with MANO
parameters and meshes; worker processes, one per core. DARTHAND_BENCH_DATASET_FRAMES changes the frame count.

Figures (dataset/run.RunStats.timings): images_per_second is the steady state after every worker has started
(1000 / ms_per_image); overall_images_per_second counts the whole wall time, start-up included; steps_ms says where
a frame's time goes (pose: posing and texture loading; primary, aa: tracing and shading; background: its crop;
labels; write: PNGs, labels, mesh); worker_peak_rss_mb is each worker's peak resident memory.
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

GOAL_IMAGES_PER_SECOND = 25.0


def progress_printer(label: str):
    """A render_dataset progress callback printing `label`, frames done and seconds to stderr every 30 s."""
    last = [-60.0]

    def progress(done: int, total: int, seconds: float) -> None:
        if seconds - last[0] >= 30 or done == total:
            last[0] = seconds
            print(f"[bench] {label} {done}/{total} frames, {seconds:.0f} s", file=sys.stderr, flush=True)
    return progress


def dataset_inputs(tmp: Path) -> tuple:
    """(model, texture catalogue, accessories folder, where from): the build's whole catalogue, else one texture
    and one accessory built in `tmp`."""
    from benchmarks.render import ROOT, _sources

    model = ROOT / "build" / "model" / "right.npz"
    tex = ROOT / "build" / "textures" / "catalog.json"
    if model.is_file() and tex.is_file():
        return model, tex, ROOT / "build" / "accessories", "build/ (the whole catalogue)"
    model, textures, accessories, _, where = _sources(tmp)
    return model, textures, accessories, where + " (one texture: run `make assets` for the DART-style catalogue run)"


def planned_renderers(tmp: Path) -> tuple:
    """(planner, {side: opened source}, {side: one-thread Renderer}, where from) of the default plan (seed 0) over
    `dataset_inputs(tmp)`: what the per-frame benchmarks render."""
    from darthand.dataset.plan import Planner, plan_spec
    from darthand.dataset.sources import source_specs
    from darthand.render.api import Renderer

    model, textures, accessories, where = dataset_inputs(tmp)
    specs = source_specs(str(model), ("right", "left"), textures=str(textures), accessories=str(accessories))
    sources = {side: spec.open() for side, spec in specs.items()}
    planner = Planner({**plan_spec(seed=0), "sides": list(sources)}, sources)
    return planner, sources, {side: Renderer(src, 1) for side, src in sources.items()}, where


def run(frames: int | None = None) -> dict:
    from darthand.dataset.api import render_dataset
    from darthand.dataset.options import DatasetOptions

    frames = int(os.environ.get("DARTHAND_BENCH_DATASET_FRAMES", frames or 10_000))
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        model, textures, accessories, where = dataset_inputs(tmp)

        t0 = time.perf_counter()
        doc = render_dataset(DatasetOptions(str(model), str(tmp / "out"), count=frames, textures=str(textures),
                                            accessories=str(accessories), resume=False,
                                            progress=progress_printer("render_dataset")))
        wall = time.perf_counter() - t0
        disk = sum(p.stat().st_size for p in (tmp / "out").rglob("*") if p.is_file())
    t = doc["timings"]
    counts = doc["summary"]["counts"]
    return {
        "images_per_second": t.get("images_per_second"),
        "goal_images_per_second": GOAL_IMAGES_PER_SECOND,
        "overall_images_per_second": t.get("overall_images_per_second"),
        "frames": frames, "size": doc["size"], "processes": t.get("processes"), "inputs": where,
        "ms_per_image": t.get("ms_per_image"), "cpu_ms_per_image": t.get("cpu_ms_per_image"),
        "startup_s": t.get("startup_s"), "wall_s": round(wall, 1), "tail_idle_s": t.get("tail_idle_s"),
        "steps_ms": t.get("steps_ms"), "worker_peak_rss_mb": t.get("worker_peak_rss_mb"),
        "textures_used": len({k for k in counts.get("category", {})}) and doc["plan"]["textures"],
        "accessory_share": round(1 - counts.get("accessory_type", {}).get("none", 0) / max(1, frames), 4),
        "sides": counts.get("side"), "kb_per_frame_on_disk": round(disk / max(1, frames) / 1024, 1),
        "what": "512x512, DART poses (grid + slerp over the gestures), all catalogue textures, 25 % accessories, "
                "both hands, the dataset defaults (environment light and backdrop, single-lobe skin, arm), "
                "labels with MANO parameters and meshes",
    }


if __name__ == "__main__":
    import json

    print(json.dumps(run(), indent=2))
