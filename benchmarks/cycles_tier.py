"""Benchmark of the path-traced tier (`render-dataset --engine cycles`, render/cycles.py) next to the fast renderer:
seconds of CPU per 256^2 frame on the same planned frames, and a side-by-side sheet to look at.

Frames: the first FRAMES of the default plan at seed 11 (right hands; its lights and procedural backgrounds), each
rendered as render-dataset renders it (dataset/frames.render_job): by the fast renderer and by Cycles with the
frame's own lights (DEFAULT_CYCLES_SAMPLES samples, OpenImageDenoise), then both again lit by one of the built-in CC0
environment maps instead (ENVIRONMENTS, the frame's camera frame, a rotation per frame) over the environment itself
as the backdrop (the dataset's {'environment': true, 'blur': BLUR}: environment.background_view, the same pixels
in both tiers): how the issue's 86 % frames were made. One thread each.

CPU: the fast renderer's is this process's CPU time over render_job; Cycles' adds the worker process's CPU time of
its render (Blender's own threads included) to the fast frame's (its labels). Wall seconds are reported too. The
first Cycles frame of the run (the worker's start and first scene build) is rendered before timing starts.

Sheet: build/bench/cycles_tier/side_by_side.png (run(out) for another folder), a row per frame: fast | Cycles
under the frame's lights, then fast | Cycles under an environment.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
FRAMES = 4
SIZE = 256
SEED = 11
ENVIRONMENTS = ("studio", "courtyard", "interior", "forest")
BLUR = 2.0                  # degrees: the environment backdrop's blur (the plan draws about 1-3 at this size)
OUT = ROOT / "build" / "bench" / "cycles_tier"
NAMES = ("fast", "cycles", "fast_environment", "cycles_environment")


def _planned_jobs(source, count: int) -> list[dict]:
    from darthand.dataset.plan import Planner, PlanOptions

    spec = {**PlanOptions(seed=SEED).spec(), "sides": ["right"]}
    return list(Planner(spec, {"right": source}).jobs(0, count))


def _render(renderer, job: dict, settings: dict):
    from darthand.dataset.frames import render_job

    t, c = time.perf_counter(), time.process_time()
    frame, _ = render_job(renderer, job, settings)
    cpu = time.process_time() - c + frame.stats.get("cycles_cpu_s", 0.0)
    return frame, cpu, time.perf_counter() - t


def _environment_job(job: dict, k: int) -> dict:
    """The job lit by an environment map instead of its lights, over that environment as its backdrop."""
    environment = {"map": ENVIRONMENTS[k % len(ENVIRONMENTS)], "rotation": 90.0 * k}
    return {**job, "lights": {"environment": environment}, "background": {"environment": True, "blur": BLUR}}


def run(out: Path | None = None) -> dict:
    from darthand.render.api import Renderer, open_source
    from darthand.render.cycles import close_shared_worker
    from darthand.render.engines import DEFAULT_CYCLES_SAMPLES
    from darthand.render.image import write_png

    model = ROOT / "build" / "model" / "right.npz"
    source = open_source(model if model.is_file() else "open")
    jobs = _planned_jobs(source, FRAMES)
    fast = Renderer(source, 1)
    settings = {"size": SIZE, "samples": 4, "aa_shading": "triangle", "shading": None}
    cycles_settings = {**settings, "engine": {"name": "cycles", "samples": DEFAULT_CYCLES_SAMPLES}}
    try:
        _render(fast, jobs[0], cycles_settings)                           # compile, load, start Blender: not timed
        rows, figures = [], {name: [] for name in NAMES}
        for k, job in enumerate(jobs):
            lit = _environment_job(job, k)
            renders = [_render(fast, j, s) for j, s in ((job, settings), (job, cycles_settings), (lit, settings),
                                                        (lit, cycles_settings))]
            for name, (_, cpu, wall) in zip(NAMES, renders):
                figures[name].append((cpu, wall))
            rows.append(np.concatenate([frame.rgba for frame, _, _ in renders], axis=1))
    finally:
        close_shared_worker()
    folder = Path(out) if out is not None else OUT
    folder.mkdir(parents=True, exist_ok=True)
    write_png(folder / "side_by_side.png", np.concatenate(rows, axis=0))
    result: dict = {"frames": len(jobs), "size": SIZE, "cycles_samples": DEFAULT_CYCLES_SAMPLES,
                    "threads": 1, "sheet": str(folder / "side_by_side.png"), "model": str(source.describe())[:80]}
    for name, values in figures.items():
        cpu, wall = np.array(values).T
        result[name] = {"cpu_s_per_frame": round(float(cpu.mean()), 3),
                        "wall_s_per_frame": round(float(wall.mean()), 3)}
    result["cycles_over_fast_cpu"] = round(result["cycles"]["cpu_s_per_frame"] / result["fast"]["cpu_s_per_frame"], 1)
    return result


def summary(result: dict) -> str:
    lines = [f"{result['frames']} planned frames (seed {SEED}) at {result['size']}^2, one thread each; Cycles at "
             f"{result['cycles_samples']} samples with OpenImageDenoise.", "",
             "| engine | CPU s / frame | wall s / frame |", "|---|---|---|"]
    for name in NAMES:
        lines.append(f"| {name} | {result[name]['cpu_s_per_frame']} | {result[name]['wall_s_per_frame']} |")
    lines += ["", f"Cycles costs {result['cycles_over_fast_cpu']}x the fast renderer's CPU. Sheet: "
              f"{result['sheet']} (fast | Cycles under the frame's lights, fast | Cycles under an environment map)."]
    return "\n".join(lines)
