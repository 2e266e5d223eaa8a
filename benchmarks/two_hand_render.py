"""Rendering two-hand frames (issue 29, render/bodies.py): ms per labelled frame of two hands next to one hand,
the same size, settings and poses, on one thread in one process (a dataset worker's setting), and where the extra
time goes (posing both hands, the labels with their contacts).

Uses build/model/{right,left}.npz and build/textures when present; otherwise the open hand and its mirror image
(no texture catalogue).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SIZE, SAMPLES, FRAMES = 256, 4, 8
GESTURES = ("flat", "fist")
TURN = np.diag([-1.0, -1.0, 1.0])
PLACEMENTS = {"facing": (0.0, -0.07, -0.06), "apart": (0.0, -0.25, 0.0), "in_front": (0.0, 0.08, 0.0)}


def _sources():
    """({side: source}, note)."""
    from darthand.render.api import open_source

    if (ROOT / "build" / "model" / "left.npz").is_file():
        return {side: open_source(ROOT / "build" / "model" / f"{side}.npz") for side in ("right", "left")}, "build/"
    from darthand.model.load import load_model
    from darthand.model.mirror import mirror_model
    from darthand.model.wrist import add_wrist
    from darthand.render.assets import HandAssets

    hand = add_wrist(load_model("open"))
    return ({"right": HandAssets(hand, {}, None, {}, "open"), "left": HandAssets(mirror_model(hand), {}, None, {},
                                                                                  "open (mirrored)")},
            "the open hand, untextured")


def _jobs(two: bool) -> list[dict]:
    jobs = []
    for i in range(FRAMES):
        right = {"kind": "hand", "side": "right", "pose": GESTURES[i % 2]}
        if not two:
            jobs.append({"index": i, "side": "right", "pose": GESTURES[i % 2], "camera": "three_quarter"})
            continue
        P = np.eye(4)
        P[:3, :3], P[:3, 3] = TURN, list(PLACEMENTS.values())[i % len(PLACEMENTS)]
        left = {"kind": "hand", "side": "left", "pose": GESTURES[(i + 1) % 2], "placement": P.tolist()}
        jobs.append({"index": i, "bodies": [right, left], "camera": "three_quarter"})
    return jobs


def _time(renderer, jobs) -> dict:
    """ms per frame (median over the frames after the first, which compiles and caches) and its steps' medians."""
    from darthand.render.scenes import Scene

    total, steps = [], {}
    for job in jobs:
        t = time.perf_counter()
        frame = renderer.render_scene(Scene.from_job(job), width=SIZE, height=SIZE, samples=SAMPLES)
        total.append(1000 * (time.perf_counter() - t))
        for k, v in frame.timings.items():
            steps.setdefault(k, []).append(1000 * v)
    return {"ms_per_frame": round(float(np.median(total[1:])), 1),
            "steps_ms": {k: round(float(np.median(v[1:])), 2) for k, v in steps.items()}}


def run() -> dict:
    from darthand.render.api import Renderer

    sources, note = _sources()
    renderer = Renderer(sources["right"], 1, sources={"left": sources["left"]})
    _time(renderer, _jobs(True)[:2])                                    # compile the kernels before timing
    one, two = _time(renderer, _jobs(False)), _time(renderer, _jobs(True))
    return {"inputs": note, "size": SIZE, "samples": SAMPLES, "frames": FRAMES, "threads": 1,
            "one_hand": one, "two_hands": two,
            "two_hand_rate_vs_one_hand": round(one["ms_per_frame"] / two["ms_per_frame"], 3)}
