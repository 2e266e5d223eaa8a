"""Benchmark of the path-traced tier (`render-dataset --engine cycles`, render/cycles.py) next to the fast renderer:
seconds of CPU per 256^2 frame on the same planned frames, and a side-by-side sheet to look at.

Frames: the first FRAMES of the default plan at seed 11 (right hands; its lights and procedural backgrounds), each
rendered as render-dataset renders it (dataset/frames.render_job): by the fast renderer, by Cycles with the frame's
own lights (DEFAULT_CYCLES_SAMPLES samples, OpenImageDenoise), and by Cycles lit by one of Blender's CC0 environment
maps instead (ENVIRONMENTS, the frame's camera frame, a rotation per frame), composited over the environment itself
as Cycles sees it (its Environment pass): how the issue's 86 % frames were made. One thread each.

CPU: the fast renderer's is this process's CPU time over render_job; Cycles' adds the worker process's CPU time of
its render (Blender's own threads included) to the fast frame's (its labels). Wall seconds are reported too. The
first Cycles frame of the run (the worker's start and first scene build) is rendered before timing starts.

Sheet: build/bench/cycles_tier/side_by_side.png (run(out) for another folder), a row per frame: fast | Cycles,
the frame's lights | Cycles, an environment.
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
OUT = ROOT / "build" / "bench" / "cycles_tier"


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


def _environment_frame(cycles, job: dict, settings: dict, k: int):
    """The frame lit by an environment map and composited over that environment (Cycles' own view of it)."""
    from darthand.render.image import compose
    from darthand.render.scenes import Scene

    environment = {"map": ENVIRONMENTS[k % len(ENVIRONMENTS)], "rotation": 90.0 * k}
    scene = Scene.from_job({**job, "lights": {"environment": environment}})
    t, c = time.perf_counter(), time.process_time()
    frame, image = cycles.render_scene_image(scene, width=SIZE, height=SIZE, samples=settings["samples"])
    _, rgba = compose(np.moveaxis(image.premult, -1, 0), image.alpha, (0, 0), image.environment, (SIZE, SIZE))
    cpu = time.process_time() - c + image.cpu_seconds
    return rgba, cpu, time.perf_counter() - t


def run(out: Path | None = None) -> dict:
    from darthand.render.api import Renderer, open_source
    from darthand.render.cycles import CyclesRenderer, close_shared_worker
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
        cycles = CyclesRenderer(fast, DEFAULT_CYCLES_SAMPLES)
        rows, figures = [], {"fast": [], "cycles": [], "cycles_environment": []}
        for k, job in enumerate(jobs):
            a, cpu_a, wall_a = _render(fast, job, settings)
            b, cpu_b, wall_b = _render(fast, job, cycles_settings)
            env_rgba, cpu_c, wall_c = _environment_frame(cycles, job, settings, k)
            figures["fast"].append((cpu_a, wall_a))
            figures["cycles"].append((cpu_b, wall_b))
            figures["cycles_environment"].append((cpu_c, wall_c))
            rows.append(np.concatenate([a.rgba, b.rgba, env_rgba], axis=1))
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
    for name in ("fast", "cycles", "cycles_environment"):
        lines.append(f"| {name} | {result[name]['cpu_s_per_frame']} | {result[name]['wall_s_per_frame']} |")
    lines += ["", f"Cycles costs {result['cycles_over_fast_cpu']}x the fast renderer's CPU. Sheet: "
              f"{result['sheet']} (fast | Cycles, the frame's lights | Cycles, an environment map)."]
    return "\n".join(lines)
