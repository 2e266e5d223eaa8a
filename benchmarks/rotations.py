"""Benchmark of the rig's hot rotation kernel: axis_angle_to_matrix throughput and float32 accuracy.

`run()` times axis_angle_to_matrix on 65,536 axis-angle vectors (B = 4096 poses x 16 joints) with angles
uniform in [0, pi] about uniform random axes, in float32 and float64, and reports vectors per second of the best
of several repeats (plus the median, which includes allocator and page-fault noise from the 65,536 x 3 x 3
output; the minor page faults per call are reported to show it), scipy's Rotation.from_rotvec for scale, and the
largest entry-wise error of the float32 matrices against float64 ones.
"""

from __future__ import annotations

import resource
import time

import numpy as np
from scipy.spatial.transform import Rotation

from darthand.model.rotations import axis_angle_to_matrix

NUM_VECTORS = 65_536
REPEATS = 7
CALLS_PER_REPEAT = 10


def _vectors(n: int, seed: int = 0) -> np.ndarray:
    """n axis-angle vectors (n, 3) float64: uniform random axes, angles uniform in [0, pi]."""
    rng = np.random.default_rng(seed)
    axes = rng.normal(size=(n, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    return axes * rng.uniform(0, np.pi, size=(n, 1))


def _seconds_per_call(func, arg) -> tuple[float, float, float]:
    """(best, median) wall-clock seconds per call over REPEATS repeats of CALLS_PER_REPEAT calls, and the minor
    page faults per call."""
    func(arg)  # warm-up
    times = []
    faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(REPEATS):
        start = time.perf_counter()
        for _ in range(CALLS_PER_REPEAT):
            func(arg)
        times.append((time.perf_counter() - start) / CALLS_PER_REPEAT)
    faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt - faults
    return min(times), float(np.median(times)), faults / (REPEATS * CALLS_PER_REPEAT)


def run() -> dict:
    v64 = _vectors(NUM_VECTORS)
    v32 = v64.astype(np.float32)
    result: dict = {"num_vectors": NUM_VECTORS, "repeats": REPEATS, "calls_per_repeat": CALLS_PER_REPEAT}
    for name, v in (("float32", v32), ("float64", v64)):
        best, median, faults = _seconds_per_call(axis_angle_to_matrix, v)
        result[f"{name}_vectors_per_s"] = NUM_VECTORS / best
        result[f"{name}_ms_per_call_best"] = best * 1e3
        result[f"{name}_ms_per_call_median"] = median * 1e3
        result[f"{name}_page_faults_per_call"] = faults

    best, _, _ = _seconds_per_call(lambda x: Rotation.from_rotvec(x).as_matrix(), v64)
    result["scipy_from_rotvec_float64_vectors_per_s"] = NUM_VECTORS / best

    r32 = axis_angle_to_matrix(v32).astype(np.float64)
    # same input values: the error of the float32 arithmetic alone
    result["float32_max_abs_err_same_input"] = float(np.abs(r32 - axis_angle_to_matrix(v32.astype(np.float64))).max())
    # against the float64 vectors they were rounded from: what a float32 caller actually gets
    result["float32_max_abs_err_vs_float64_input"] = float(np.abs(r32 - axis_angle_to_matrix(v64)).max())
    return result


if __name__ == "__main__":
    import json

    print(json.dumps(run(), indent=2))
