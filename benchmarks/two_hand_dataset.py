"""Two-hand datasets end to end (issue 29): `render-dataset` with every frame holding two interacting hands
(`--two-hands 1`, the seven interaction types in equal shares) next to the same run with one hand, as a researcher
runs it (the dataset defaults, 512^2, worker processes, one per core, the build's catalogues). Goal: two-hand frames
at at least half the one-hand rate.

Figures: images_per_second of each run (dataset/run.RunStats: steady state), their ratio, and the plan's share: the
interaction sampler and penetration fit run in the main process while the workers render (dataset/plan.Planner),
timed here alone over the same frames (ms of CPU per two-hand frame, and as a share of the two-hand run's CPU per
image). DARTHAND_BENCH_TWO_HAND_FRAMES sets the frames per run (default 300).
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

from benchmarks.render_dataset import dataset_inputs, progress_printer

GOAL_RATIO = 0.5


def _run(model, textures, accessories, out: Path, frames: int, two_hands: float) -> dict:
    from darthand.dataset.api import render_dataset
    from darthand.dataset.options import DatasetOptions
    from darthand.dataset.plan import PlanOptions

    doc = render_dataset(DatasetOptions(str(model), str(out), count=frames, textures=str(textures),
                                        accessories=str(accessories), resume=False,
                                        progress=progress_printer(f"two_hand_dataset ({two_hands:g})"),
                                        plan=PlanOptions(two_hands=two_hands)))
    t = doc["timings"]
    return {k: t.get(k) for k in ("images_per_second", "overall_images_per_second", "ms_per_image",
                                  "cpu_ms_per_image", "steps_ms")}


def _planning(model, textures, accessories, frames: int) -> dict:
    """CPU ms per frame of planning `frames` two-hand frames (the main process's share), and the interaction types."""
    from darthand.dataset.plan import Planner, PlanOptions
    from darthand.dataset.sources import source_specs

    specs = source_specs(str(model), ("right", "left"), textures=str(textures), accessories=str(accessories))
    sources = {side: spec.open() for side, spec in specs.items()}
    planner = Planner({**PlanOptions(two_hands=1.0).spec(), "sides": list(sources)}, sources)
    planner.job(0)                                                        # load and compile before timing
    t = time.process_time()
    jobs = list(planner.jobs(1, frames + 1))
    cpu = time.process_time() - t
    types: dict = {}
    for job in jobs:
        kind = (job.get("interaction") or {}).get("type", "none")
        types[kind] = types.get(kind, 0) + 1
    return {"cpu_ms_per_frame": round(1000 * cpu / max(1, len(jobs)), 1), "interaction_types": types}


def run() -> dict:
    frames = int(os.environ.get("DARTHAND_BENCH_TWO_HAND_FRAMES", 300))
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        model, textures, accessories, where = dataset_inputs(tmp)
        plan = _planning(model, textures, accessories, min(frames, 100))
        one = _run(model, textures, accessories, tmp / "one", frames, 0.0)
        two = _run(model, textures, accessories, tmp / "two", frames, 1.0)
    ratio = (two["images_per_second"] or 0) / max(1e-9, one["images_per_second"] or 0)
    cpu_two = two.get("cpu_ms_per_image") or 0
    return {"two_hand_vs_one_hand_rate": round(ratio, 3), "goal_ratio": GOAL_RATIO, "frames": frames,
            "inputs": where, "one_hand": one, "two_hands": two, "planning": {
                **plan, "share_of_two_hand_cpu": round(plan["cpu_ms_per_frame"] / (cpu_two + plan["cpu_ms_per_frame"]),
                                                       3) if cpu_two else None}}


def summary(result: dict) -> str:
    one, two, plan = result["one_hand"], result["two_hands"], result["planning"]
    return "\n".join([
        f"**Two-hand frames at {result['two_hand_vs_one_hand_rate']:.2f} of the one-hand rate** (goal "
        f"{result['goal_ratio']}): {two['images_per_second']} against {one['images_per_second']} images/s, "
        f"{result['frames']} frames each, 512^2, the dataset defaults, {result['inputs']}.", "",
        f"CPU per image: {two['cpu_ms_per_image']} ms with two hands, {one['cpu_ms_per_image']} ms with one "
        f"(workers). Planning (interaction sampling and the penetration fit, in the main process): "
        f"{plan['cpu_ms_per_frame']} ms CPU a two-hand frame, {plan['share_of_two_hand_cpu']} of its CPU; "
        f"types {plan['interaction_types']}."])
