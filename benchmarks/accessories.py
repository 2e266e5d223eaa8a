"""Benchmark of the accessories stage: build time of the 50, the pose-sweep time, and the CPU a dataset frame pays
to wear a ring in its pose (accessories/wear).

Runs on the open template (assets_src/template/open_right.npz, wrist added) when present, else on the synthetic
tube hand; `run()` returns JSON-serialisable figures in seconds.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from darthand.accessories.build import generate
from darthand.accessories.sweep import PER_POSE, measure, probes, sweep_poses
from darthand.accessories.catalog import entries, load_spec
from benchmarks._common import bench_model


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
        figs = {b.id: {**{key: np.zeros(1) for key in PER_POSE}, "drift": 0.0} for b in built}
        for b in built:
            write_accessory(Path(tmp), b, figs[b.id], ["rest"], 1)
    t_write = time.perf_counter() - t0
    worn = ring_wear_cpu(model, built, poses)
    return {"model": name, "accessories": len(built), "generate_and_fit_s": round(t_generate, 3),
            "write_files_s": round(t_write, 3), "sweep_poses": len(poses), "sweep_s": round(t_sweep, 3),
            "sweep_s_per_pose_all_50": round(t_sweep / len(poses), 4),
            "sweep_cpu_s_per_pose_all_50": round(c_sweep / len(poses), 4),
            "samples_drawn": n_poses, "samples_left_out_self_crossing": n_poses - (len(poses) - 1),
            "self_crossing_cpu_s_per_sample": round(t_crossing / n_poses, 4),
            "triangles_total": int(sum(len(b.mesh.faces) for b in built)), **worn}


def ring_wear_cpu(model, built, poses) -> dict:
    """CPU per pose of wearing each ring (accessories/wear: slide, and room made where needed), as a dataset frame
    with a ring pays it (single-threaded BLAS, as the renderer runs): mean, p90 and largest over the rings and poses
    (ms), and the share of poses that turned digits."""
    from threadpoolctl import threadpool_limits

    from darthand.accessories.wear import RingWear

    times, turned = [], 0
    with threadpool_limits(limits=1, user_api="blas"):
        for item in [i for i in probes(built) if getattr(i, "part", -1) >= 0]:
            wear = RingWear(model, item.joint, item.rest, item.vertices)
            for pose in poses:
                c0 = time.process_time()
                w = wear.worn(pose)
                times.append(time.process_time() - c0)
                turned += bool(w.changed)
    t = np.array(times) * 1000.0
    return {"ring_wear_cpu_ms_per_frame": round(float(t.mean()), 2) if len(t) else None,
            "ring_wear_cpu_ms_max": round(float(t.max()), 2) if len(t) else None,
            "ring_wear_cpu_ms_p90": round(float(np.percentile(t, 90)), 2) if len(t) else None,
            "ring_wear_share_turned": round(turned / max(1, len(t)), 3)}


if __name__ == "__main__":
    import json

    print(json.dumps(run(), indent=2))
