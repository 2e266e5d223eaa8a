"""Smooth skin at the outline and an arm that goes on (render/subdivision.py, render/arm.py): what they cost and what
they change.

- CPU per frame (one thread, `time.process_time`) at 256^2 and 512^2 for subdivision 0, 1, 2 with the arm off, and
  subdivision 0, 1 with the arm on, over the first DARTHAND_BENCH_SMOOTH_FRAMES (default 8) frames of the default
  plan (both hands, seed 11), each variant in an order rotated frame by frame so machine load falls on all alike.
- The limit surface's distance to the control mesh (the built model's rest hand; mm, max and mean over the
  subdivided vertices; testkit.mesh_distance, closed-form point-triangle distances).
- The outline's corners: for each frame's camera, the turning angle (degrees) at every vertex where two of the
  posed hand's silhouette edges meet (an edge between a face turned to the camera and one turned away), projected
  to the image (cusps of the contour, turns over 90 degrees, left out): median and 90th percentile, control mesh
  against subdivided. A round outline turns a little at
  many corners; a faceted one a lot at few.
- The cap: the share of DARTHAND_BENCH_SMOOTH_CAP_FRAMES (default 200) frames of that plan at 256^2 in which the
  camera's primary rays hit a cap surface (the forearm's cut, or the arm's far end), arm off and on, and the share
  in which the arm was cut back because the camera looked along it (render/arm.shorten_before); over the same
  frames, the share whose visibility labels or mask bbox change with one level of subdivision or with the arm
  (keypoints, camera, pose and mesh never do: tests/render/test_subdivision.py, test_arm.py).
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import numpy as np

SEED = 11
ARM_M = 0.3
FOLD_DEG = 90.0
VARIANTS = ({}, {"subdivision": 1}, {"subdivision": 2}, {"arm": ARM_M}, {"subdivision": 1, "arm": ARM_M})


def variant_name(geometry: dict) -> str:
    return f"sub{geometry.get('subdivision', 0)}" + ("+arm" if geometry.get("arm") else "")


def render_cpu(renderer, job: dict, geometry: dict, size: int):
    """(api.Frame, CPU seconds) of a dataset job with the dataset's render defaults and `geometry`."""
    from darthand.dataset.frames import render_job

    settings = {"size": size, "samples": 4, "aa_shading": "triangle", "geometry": geometry}
    c = time.process_time()
    frame, _ = render_job(renderer, job, settings)
    return frame, time.process_time() - c


def silhouette_turns(vertices: np.ndarray, faces: np.ndarray, camera) -> np.ndarray:
    """(K,) degrees: the image-plane turning angle at each vertex joining exactly two silhouette edges of the mesh
    seen from `camera` (api.Frame.camera), below FOLD_DEG (a larger turn is a cusp where the contour folds behind
    the surface, not a corner of the outline)."""
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64)
    normal = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    front = np.einsum("ij,ij->i", normal, camera.centre - v[f[:, 0]]) > 0
    pairs = np.sort(np.stack([f, np.roll(f, -1, axis=1)], -1).reshape(-1, 2), axis=1)
    edges, inverse = np.unique(pairs, axis=0, return_inverse=True)
    facing = np.zeros((len(edges), 2), np.int64)
    np.add.at(facing[:, 0], inverse.reshape(-1), np.repeat(front, 3))
    np.add.at(facing[:, 1], inverse.reshape(-1), 1)
    silhouette = edges[(facing[:, 1] == 2) & (facing[:, 0] == 1)]
    uv, _ = camera.project(v)
    ends: dict = {}
    for a, b in silhouette.tolist():
        ends.setdefault(a, []).append(b)
        ends.setdefault(b, []).append(a)
    turns = []
    for vertex, others in ends.items():
        if len(others) != 2:
            continue
        d1, d2 = uv[vertex] - uv[others[0]], uv[others[1]] - uv[vertex]
        n1, n2 = np.linalg.norm(d1), np.linalg.norm(d2)
        if n1 > 1e-9 and n2 > 1e-9:
            turns.append(np.degrees(np.arccos(np.clip(d1 @ d2 / (n1 * n2), -1, 1))))
    turns = np.array(turns)
    return turns[turns < FOLD_DEG]


def limit_distances(model) -> dict:
    from darthand.render.subdivision import SubdivisionPlan
    from testkit.mesh_distance import distance_to_mesh

    out = {}
    for level in (1, 2):
        plan = SubdivisionPlan.build(model.faces, model.num_vertices, level)
        d = distance_to_mesh(plan.positions(model.v_template), model.v_template, model.faces)
        out[f"level{level}"] = {"max_mm": round(1000 * float(d.max()), 3), "mean_mm": round(1000 * float(d.mean()), 3)}
    return out


def cap_shares(renderers: dict, jobs: list) -> dict:
    """Over `jobs` at 256^2, plain, subdivided once and with the arm: the share of frames with cap pixels (plain,
    arm), of frames whose arm was cut back, and of frames whose visibility labels or mask bbox differ from the
    plain frame's (subdivision, arm)."""
    cap = {"off": 0, "on": 0}
    changed = {"subdivision1": {"visibility": 0, "bbox": 0}, "arm": {"visibility": 0, "bbox": 0}}
    cut_back = 0
    for job in jobs:
        frames = {key: render_cpu(renderers[job["side"]], job, geometry, 256)[0]
                  for key, geometry in (("off", {}), ("subdivision1", {"subdivision": 1}), ("on", {"arm": ARM_M}))}
        for key in ("off", "on"):
            caps = [i for i, s in enumerate(frames[key].subject.surfaces) if s.role == "cap"]
            cap[key] += bool(np.isin(frames[key].geom, caps).any())
        tube = next(s for s in frames["on"].subject.surfaces if s.role == "arm")
        cut_back += float(np.ptp(tube.vertices, axis=0).max()) < ARM_M / 2
        plain = frames["off"].labels
        for key, frame in (("subdivision1", frames["subdivision1"]), ("arm", frames["on"])):
            for field in ("visibility", "bbox"):
                changed[key][field] += frame.labels[field] != plain[field]
    n = max(len(jobs), 1)
    return {"frames": len(jobs), "cap_visible_share": {k: round(v / n, 4) for k, v in cap.items()},
            "arm_cut_back_share": round(cut_back / n, 4),
            "labels_changed_share": {k: {f: round(v / n, 4) for f, v in c.items()} for k, c in changed.items()}}


def run(frames: int | None = None) -> dict:
    from benchmarks._common import bench_model
    from benchmarks.render_dataset import dataset_inputs
    from darthand.dataset.plan import Planner, plan_spec
    from darthand.dataset.sources import source_specs
    from darthand.render.api import Renderer

    frames = int(os.environ.get("DARTHAND_BENCH_SMOOTH_FRAMES", frames or 8))
    cap_frames = int(os.environ.get("DARTHAND_BENCH_SMOOTH_CAP_FRAMES", 200))
    cpu_ms: dict = {size: {variant_name(g): [] for g in VARIANTS} for size in (256, 512)}
    turns: dict = {variant_name(g): [] for g in VARIANTS[:3]}
    with tempfile.TemporaryDirectory() as tmp:
        model, textures, accessories, where = dataset_inputs(Path(tmp))
        specs = source_specs(str(model), ("right", "left"), textures=str(textures), accessories=str(accessories))
        sources = {side: spec.open() for side, spec in specs.items()}
        planner = Planner({**plan_spec(seed=SEED), "sides": list(sources)}, sources)
        renderers = {side: Renderer(src, 1) for side, src in sources.items()}
        first = {}
        for job in planner.jobs(0, 32):
            first.setdefault(job["side"], job)
        for job in first.values():                 # each side's renderer builds its subdivision plans, untimed
            for geometry in VARIANTS:
                render_cpu(renderers[job["side"]], job, geometry, 64)
        for k, job in enumerate(planner.jobs(0, frames)):
            renderer = renderers[job["side"]]
            render_cpu(renderer, job, {}, 256)                         # loads the frame's textures
            for size in (256, 512):
                for geometry in VARIANTS[k % len(VARIANTS):] + VARIANTS[:k % len(VARIANTS)]:     # rotated
                    frame, seconds = render_cpu(renderer, job, geometry, size)
                    cpu_ms[size][variant_name(geometry)].append(1000 * seconds)
                    if size == 512 and variant_name(geometry) in turns:
                        hand = frame.subject.hand
                        turns[variant_name(geometry)].append(silhouette_turns(hand.vertices, hand.faces,
                                                                              frame.camera))
        caps = cap_shares(renderers, list(planner.jobs(0, cap_frames)))
    rest, name = bench_model()
    return {"frames": frames, "inputs": where, "seed": SEED, "arm_m": ARM_M,
            "cpu_ms": {str(size): {k: _mean(v) for k, v in t.items()} for size, t in cpu_ms.items()},
            "limit_distance": {"model": name, **limit_distances(rest)},
            "silhouette_turn_deg": {k: {"median": round(float(np.median(np.concatenate(v))), 2),
                                        "p90": round(float(np.percentile(np.concatenate(v), 90)), 2),
                                        "corners_per_frame": round(sum(map(len, v)) / len(v), 1)}
                                    for k, v in turns.items()},
            "cap": caps}


def summary(res: dict) -> str:
    cpu, turn, cap = res["cpu_ms"], res["silhouette_turn_deg"], res["cap"]
    lines = [f"{res['frames']} frames of the default plan (seed {res['seed']}), one thread ({res['inputs']}).", "",
             "| variant | CPU ms 256^2 | CPU ms 512^2 | outline turn median / p90 (deg) |", "|---|---|---|---|"]
    for k in cpu["256"]:
        t = turn.get(k)
        lines.append(f"| {k} | {cpu['256'][k]:.1f} | {cpu['512'][k]:.1f} | "
                     + (f"{t['median']:.1f} / {t['p90']:.1f} |" if t else "|"))
    lim, one, two = res["limit_distance"], res["limit_distance"]["level1"], res["limit_distance"]["level2"]
    lines += ["", f"Limit surface to control mesh ({lim['model']}): level 1 max {one['max_mm']} mm (mean "
              f"{one['mean_mm']}), level 2 max {two['max_mm']} mm (mean {two['mean_mm']}).",
              f"Cap seen in {100 * cap['cap_visible_share']['off']:.1f} % of {cap['frames']} frames without the arm, "
              f"{100 * cap['cap_visible_share']['on']:.1f} % with a {res['arm_m']} m arm (cut back in "
              f"{100 * cap['arm_cut_back_share']:.1f} %: the camera looked along it).",
              "Frames whose labels differ from the plain frame's (keypoints, camera, pose and mesh never do; "
              "coverage follows the mask): " + "; ".join(f"{k}: visibility {100 * v['visibility']:.1f} %, mask bbox "
                                            f"{100 * v['bbox']:.1f} %" for k, v in cap["labels_changed_share"].items())
              + "."]
    return "\n".join(lines)


def _mean(values) -> float:
    return round(float(np.mean(values)), 2) if values else float("nan")
