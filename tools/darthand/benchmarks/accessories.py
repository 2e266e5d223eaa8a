"""Benchmark of the accessories stage: build time of the 50 and the pose-sweep time.

Runs on the open template (assets_src/template/open_right.npz, wrist added) when present, else on the synthetic
tube hand; `run()` returns JSON-serialisable figures in seconds.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from darthand.accessories.build import generate
from darthand.accessories.sweep import measure, sweep_poses
from darthand.accessories.catalog import entries, load_spec
from darthand.benchmarks._common import bench_model


def run(n_poses: int = 32) -> dict:
    model, name = bench_model()
    spec = load_spec()
    items = entries(spec)
    t0 = time.perf_counter()
    built = [generate(model, e, int(spec["seed"])) for e in items]
    t_generate = time.perf_counter() - t0
    t0 = time.process_time()
    names, poses = sweep_poses(model, int(spec["seed"]), n_poses, gestures=[])
    t_crossing = time.process_time() - t0               # drawing, and the self-crossing test of every draw
    t0 = time.perf_counter()
    c0 = time.process_time()
    measure(model, built, poses)
    t_sweep, c_sweep = time.perf_counter() - t0, time.process_time() - c0
    from darthand.accessories.build import write_accessory

    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        figs = {b.id: {"depth": np.zeros(1), "fit": np.zeros(1), "through": np.zeros(1), "drift": 0.0}
                for b in built}
        for b in built:
            write_accessory(Path(tmp), b, figs[b.id], ["rest"], 1)
    t_write = time.perf_counter() - t0
    return {"model": name, "accessories": len(built), "generate_and_fit_s": round(t_generate, 3),
            "write_files_s": round(t_write, 3), "sweep_poses": len(poses), "sweep_s": round(t_sweep, 3),
            "sweep_s_per_pose_all_50": round(t_sweep / len(poses), 4),
            "sweep_cpu_s_per_pose_all_50": round(c_sweep / len(poses), 4),
            "samples_drawn": n_poses, "samples_left_out_self_crossing": n_poses - (len(poses) - 1),
            "self_crossing_cpu_s_per_sample": round(t_crossing / n_poses, 4),
            "triangles_total": int(sum(len(b.mesh.faces) for b in built))}


if __name__ == "__main__":
    import json

    print(json.dumps(run(), indent=2))
