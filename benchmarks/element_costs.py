"""What each appearance element of a dataset frame costs: the render alone per setting, in one process.

The first frames of the default plan (seed 0), rendered as `render-dataset` renders them (dataset/frames.render_job,
the dataset's defaults: benchmarks/render_rays.default_settings) with one element changed at a time, in this process
on one thread after a warm-up pass. The settings are rendered in turn, frame block by frame block, ROUNDS times over
(so a change in the machine's load falls on every setting alike); the figure is CPU ms a frame (time.process_time
around render_job), the median over the rounds, and its difference from the default's. Elements chosen at planning
(the light rig, the backdrop) are not here: their CPU is the realism benchmark's per-row figure (realism.py, the
whole command). benchmarks/results/realism.md puts the two next to what each element adds to the detection rate.

DARTHAND_BENCH_ELEMENT_FRAMES changes the frame count (default 16), DARTHAND_BENCH_ELEMENT_ROUNDS the rounds (3).
"""

from __future__ import annotations

import copy
import os
import statistics
import tempfile
import time
from pathlib import Path

FRAMES = 16
ROUNDS = 3
# name -> (what, changes to render_job's settings: {section: {key: value}} or {key: value} for a top-level key)
VARIANTS: dict[str, tuple[str, dict]] = {
    "default": ("the dataset's defaults", {}),
    "dual-skin": ("two specular lobes and a sheen (--skin-specular dual)", {"shading": {"skin_specular": "dual"}}),
    "skin-relief": ("the skin's relief (--skin-detail 1)", {"shading": {"skin_detail": 1.0}}),
    "dual-skin+relief": ("both (the dataset default before issue 28's measurement)",
                         {"shading": {"skin_specular": "dual", "skin_detail": 1.0}}),
    "subdivision": ("Loop subdivision, one level (--subdivision 1)", {"geometry": {"subdivision": 1}}),
    "no-arm": ("the forearm's cap instead of the arm (--arm off)", {"geometry": {"arm": 0.0}}),
    "random-film": ("a random camera per frame (--film random)", {"film": {"random": True}}),
    "no-indirect": ("no ambient occlusion or interreflection (--ao-rays 0)", {"shading": {"ao_rays": 0}}),
}


def variant_settings(base: dict, changes: dict) -> dict:
    """A copy of render_job's settings `base` with `changes` applied (a dict value updates that section)."""
    out = copy.deepcopy(base)
    for key, value in changes.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key].update(value)
        else:
            out[key] = value
    return out


def run(frames: int | None = None, rounds: int | None = None) -> dict:
    from benchmarks.render_dataset import planned_renderers
    from benchmarks.render_rays import default_settings
    from darthand.dataset.frames import render_job

    frames = int(os.environ.get("DARTHAND_BENCH_ELEMENT_FRAMES", frames or FRAMES))
    rounds = int(os.environ.get("DARTHAND_BENCH_ELEMENT_ROUNDS", rounds or ROUNDS))
    base = default_settings()
    settings = {name: variant_settings(base, changes) for name, (_, changes) in VARIANTS.items()}
    with tempfile.TemporaryDirectory() as tmp:
        planner, _, renderers, _ = planned_renderers(Path(tmp))
        jobs = list(planner.jobs(0, frames))
        for job in jobs:                                        # warm-up: maps and textures of every frame
            render_job(renderers[job["side"]], job, settings["default"])
        for name in settings:                                   # then each setting's kernels and relief
            for job in jobs[:2]:
                render_job(renderers[job["side"]], job, settings[name])
        per_round: dict = {name: [] for name in settings}
        for _ in range(rounds):
            for name, s in settings.items():
                c = time.process_time()
                for job in jobs:
                    render_job(renderers[job["side"]], job, s)
                per_round[name].append(1e3 * (time.process_time() - c) / len(jobs))
    ms = {name: round(statistics.median(v), 1) for name, v in per_round.items()}
    return {"frames": frames, "rounds": rounds, "headline": {"default_cpu_ms": ms["default"]},
            "cpu_ms_per_frame": ms, "rounds_ms": {n: [round(x, 1) for x in v] for n, v in per_round.items()},
            "added_ms": {n: round(ms[n] - ms["default"], 1) for n in ms},
            "what": {n: w for n, (w, _) in VARIANTS.items()},
            "settings": "benchmarks/render_rays.default_settings, one element changed; 512^2, one process, one thread"}


def summary(res: dict) -> str:
    lines = [f"element costs: default frame {res['cpu_ms_per_frame']['default']} ms CPU (render alone, "
             f"{res['frames']} frames x {res['rounds']} rounds)"]
    for name, added in res["added_ms"].items():
        if name != "default":
            lines.append(f"  {name:18s} {added:+7.1f} ms  ({res['what'][name]})")
    return "\n".join(lines)
