"""Object datasets end to end (issue 30): `render-dataset` with every frame holding an object in one of its grasps
(`--objects 1`: an object of the catalogue, a grasp of it for the frame's side refitted to the frame's shape) next to
the same run with empty hands, as a researcher runs it (the dataset defaults, 512^2, worker processes, the build's
catalogues). Goal: object frames at at least two thirds of the empty-hand rate.

Figures: images_per_second of each run (dataset/run.RunStats: steady state), their ratio, and the plan's share: the
grasp refit runs in the main process while the workers render (dataset/objects.ObjectFrames), timed here alone over
the same frames (ms of CPU per object frame, redraws). DARTHAND_BENCH_OBJECT_FRAMES sets the frames per run (default
200); DARTHAND_BENCH_OBJECTS and DARTHAND_BENCH_GRASPS the catalogues (default build/objects, build/grasps).
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

from benchmarks.render import ROOT
from benchmarks.render_dataset import dataset_inputs, progress_printer

GOAL_RATIO = 2 / 3


def _catalogs() -> tuple[str, str]:
    objects = os.environ.get("DARTHAND_BENCH_OBJECTS", str(ROOT / "build" / "objects" / "catalog.json"))
    grasps = os.environ.get("DARTHAND_BENCH_GRASPS", str(ROOT / "build" / "grasps" / "catalog.json"))
    return objects, grasps


def _run(model, textures, accessories, out: Path, frames: int, objects: float, **plan) -> dict:
    """The timings of a `frames`-frame run with `objects` of them holding an object (plan: more PlanOptions)."""
    from darthand.dataset.api import render_dataset
    from darthand.dataset.options import DatasetOptions
    from darthand.dataset.plan import PlanOptions

    catalog, grasps = _catalogs()
    doc = render_dataset(DatasetOptions(str(model), str(out), count=frames, textures=str(textures),
                                        accessories=str(accessories), objects_catalog=catalog, grasps_catalog=grasps,
                                        resume=False, progress=progress_printer(f"object_dataset ({objects:g})"),
                                        plan=PlanOptions(objects=objects, **plan)))
    t = doc["timings"]
    return {k: t.get(k) for k in ("images_per_second", "overall_images_per_second", "ms_per_image",
                                  "cpu_ms_per_image", "steps_ms")}


def _planning(model, textures, accessories, frames: int) -> dict:
    """CPU ms per frame of planning `frames` object frames (the main process's share), redraws, categories."""
    from darthand.dataset.plan import Planner, PlanOptions
    from darthand.dataset.sources import source_specs

    catalog, grasps = _catalogs()
    specs = source_specs(str(model), ("right", "left"), textures=str(textures), accessories=str(accessories))
    sources = {side: spec.open() for side, spec in specs.items()}
    planner = Planner({**PlanOptions(objects=1.0).spec(), "sides": list(sources)}, sources,
                      {"objects": catalog, "grasps": grasps})
    planner.job(0)                                                        # load and compile before timing
    t = time.process_time()
    jobs = list(planner.jobs(1, frames + 1))
    cpu = time.process_time() - t
    categories: dict = {}
    for job in jobs:
        kind = (job["sample"].get("object") or {}).get("category", "none")
        categories[kind] = categories.get(kind, 0) + 1
    return {"cpu_ms_per_frame": round(1000 * cpu / max(1, len(jobs)), 1), "redraws": planner.object_redraws,
            "categories": categories}


def run() -> dict:
    frames = int(os.environ.get("DARTHAND_BENCH_OBJECT_FRAMES", 200))
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        model, textures, accessories, where = dataset_inputs(tmp)
        plan = _planning(model, textures, accessories, min(frames, 100))
        empty = _run(model, textures, accessories, tmp / "empty", frames, 0.0)
        held = _run(model, textures, accessories, tmp / "objects", frames, 1.0)
    ratio = (held["images_per_second"] or 0) / max(1e-9, empty["images_per_second"] or 0)
    return {"object_vs_empty_hand_rate": round(ratio, 3), "goal_ratio": round(GOAL_RATIO, 3), "frames": frames,
            "inputs": where, "catalogs": list(_catalogs()), "empty_hand": empty, "objects": held, "planning": plan}


def summary(result: dict) -> str:
    empty, held, plan = result["empty_hand"], result["objects"], result["planning"]
    return "\n".join([
        f"**Object frames at {result['object_vs_empty_hand_rate']:.2f} of the empty-hand rate** (goal "
        f"{result['goal_ratio']}): {held['images_per_second']} against {empty['images_per_second']} images/s, "
        f"{result['frames']} frames each, 512^2, the dataset defaults, {result['inputs']}.", "",
        f"CPU per image: {held['cpu_ms_per_image']} ms with objects, {empty['cpu_ms_per_image']} ms empty-handed "
        f"(workers). Planning (the grasp refit, in the main process): {plan['cpu_ms_per_frame']} ms CPU an object "
        f"frame, {plan['redraws']} redraws; categories {plan['categories']}."])
