"""The environment's map lookups with fast_atan2 (render/environment.py, since branch i40-atan) against the same
lookups with libm's np.arctan2 and np.hypot (the kernels of REFERENCE, loaded from git), on default DART-style
frames (render_rays' default_settings: 512^2, 4 edge sub-samples, the dataset's shading and geometry).

Figures:

- the arctangent: largest |fast_atan2 - np.arctan2| (radians) over a dense grid of directions around the circle
  (every float32 angle step of 2 pi / GRID, at radii from 1e-3 to 1e3), the axes, the diagonals, signed zeros;
- images: DARTHAND_BENCH_ATAN_FRAMES (default 16) frames of the default plan (seed 0) rendered with both
  kernels: 8-bit RGBA pixels that differ, their largest and mean difference, labels compared as JSON;
- CPU (time.process_time, this process, one thread): the frame (render_job) and the two lookup kernels alone,
  mean per frame, in blocks of BLOCK frames alternating old and new (the first alternating per round), ROUNDS
  rounds, after a warm-up pass (both kernels over every frame: kernels compiled, maps and textures decoded).
"""

from __future__ import annotations

import contextlib
import importlib.util
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

FRAMES = 16
BLOCK = 16
ROUNDS = 3
GRID = 1 << 20
REFERENCE = "0d5744e"       # main before fast_atan2: its kernels call np.arctan2
MODES = ("old", "new")
KERNELS = ("_lookup_kernel", "_blurred_kernel")
REPO = Path(__file__).resolve().parents[1]


def reference_environment(tmp: Path):
    """render/environment.py of REFERENCE, imported as its own module (its kernels compiled from that file)."""
    source = subprocess.run(["git", "-C", str(REPO), "show", f"{REFERENCE}:tools/darthand/render/environment.py"],
                            check=True, capture_output=True, text=True).stdout
    path = tmp / "environment_reference.py"
    path.write_text(source)
    spec = importlib.util.spec_from_file_location("environment_reference", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules["environment_reference"] = module
    spec.loader.exec_module(module)
    return module


@contextlib.contextmanager
def kernels(mode: str, reference, totals: dict):
    """Within the context, render/environment.py's lookup kernels are `mode`'s ('old': REFERENCE's), each adding
    its CPU seconds into totals[kernel name]."""
    from darthand.render import environment

    originals = {name: getattr(environment, name) for name in KERNELS}

    def timed(name, func):
        def call(*args):
            c = time.process_time()
            try:
                return func(*args)
            finally:
                totals[name] = totals.get(name, 0.0) + time.process_time() - c
        return call

    for name in KERNELS:
        setattr(environment, name, timed(name, getattr(reference, name) if mode == "old" else originals[name]))
    try:
        yield totals
    finally:
        for name, func in originals.items():
            setattr(environment, name, func)


def atan_error() -> dict:
    """Largest |fast_atan2 - np.arctan2| (rad) over the grid, and whether the special cases match exactly where
    np.arctan2 is exact (signed zeros, the seam, the poles)."""
    from darthand.render.environment import atan2_many

    angle = np.linspace(-np.pi, np.pi, GRID + 1)
    radius = np.geomspace(1e-3, 1e3, 7)[:, None]
    y, x = (radius * np.sin(angle)).ravel(), (radius * np.cos(angle)).ravel()
    axes = np.array([0.0, -0.0, 1.0, -1.0, 1e-300, -1e-300, 5e-324, 1e300, -1e300])
    ay, ax = (a.ravel() for a in np.meshgrid(axes, axes))
    grid = np.abs(atan2_many(y, x) - np.arctan2(y, x)).max()
    special = atan2_many(ay, ax)
    truth = np.arctan2(ay, ax)
    exact = (ay == 0) | (ax == 0)            # on an axis or at a signed zero: np.arctan2 gives 0, +-pi/2, +-pi
    return {"grid_points": int(len(y)), "max_error_rad": float(grid),
            "special_max_error_rad": float(np.abs(special - truth).max()),
            "special_exact": bool(np.array_equal(special[exact], truth[exact])
                                  and np.array_equal(np.signbit(special), np.signbit(truth)))}


def image_difference(a: np.ndarray, b: np.ndarray) -> dict:
    """8-bit RGBA images a, b (H, W, 4): pixels that differ, their largest and mean channel difference."""
    d = np.abs(a.astype(np.int16) - b.astype(np.int16))
    differ = d.max(axis=-1) > 0
    return {"pixels": int(differ.sum()), "max": int(d.max()),
            "mean_over_differing": float(d[differ].max(axis=-1).mean()) if differ.any() else 0.0}


def compare(jobs: list[dict], renderers, reference) -> dict:
    """Both kernels' images and labels over jobs (this pass is also the warm-up)."""
    from benchmarks.render_rays import default_settings
    from darthand.dataset.frames import render_job

    settings = default_settings()
    per_frame = []
    for job in jobs:
        frames = {}
        for mode in MODES:
            with kernels(mode, reference, {}):
                frames[mode], _ = render_job(renderers[job["side"]], job, settings)
        labels = [json.dumps(frames[m].labels, sort_keys=True, default=str) for m in MODES]
        per_frame.append({"index": job["index"], **image_difference(frames["old"].rgba, frames["new"].rgba),
                          "labels_equal": labels[0] == labels[1]})
    differing = [f["pixels"] for f in per_frame]
    return {"frames_with_differing_pixels": int(sum(p > 0 for p in differing)),
            "differing_pixels_total": int(sum(differing)), "differing_pixels_max": int(max(differing)),
            "largest_difference": int(max(f["max"] for f in per_frame)),
            "labels_identical": all(f["labels_equal"] for f in per_frame), "per_frame": per_frame}


def cpu_per_frame(jobs: list[dict], renderers, reference) -> dict:
    """Mean CPU ms a frame and in each kernel per mode: blocks of BLOCK jobs alternating the modes, ROUNDS rounds."""
    from benchmarks.render_rays import default_settings
    from darthand.dataset.frames import render_job

    settings = default_settings()
    frame_s = {mode: 0.0 for mode in MODES}
    kernel_s = {(mode, name): 0.0 for mode in MODES for name in KERNELS}
    blocks = [jobs[a:a + BLOCK] for a in range(0, len(jobs), BLOCK)]
    for r in range(ROUNDS):
        for b, block in enumerate(blocks):
            for mode in (MODES if (r + b) % 2 == 0 else MODES[::-1]):
                totals: dict = {}
                with kernels(mode, reference, totals):
                    for job in block:
                        c = time.process_time()
                        render_job(renderers[job["side"]], job, settings)
                        frame_s[mode] += time.process_time() - c
                for name in KERNELS:
                    kernel_s[mode, name] += totals.get(name, 0.0)
    n = ROUNDS * len(jobs)
    frame_ms = {mode: round(1e3 * frame_s[mode] / n, 2) for mode in MODES}
    kernel_ms = {name: {mode: round(1e3 * kernel_s[mode, name] / n, 2) for mode in MODES} for name in KERNELS}
    return {"frame_ms": frame_ms, "kernel_ms": kernel_ms,
            "saved_frame_ms": round(frame_ms["old"] - frame_ms["new"], 2),
            "saved_kernel_ms": round(sum(kernel_ms[k]["old"] - kernel_ms[k]["new"] for k in KERNELS), 2)}


def run(frames: int | None = None) -> dict:
    from benchmarks.render_dataset import planned_renderers

    frames = int(os.environ.get("DARTHAND_BENCH_ATAN_FRAMES", frames or FRAMES))
    with tempfile.TemporaryDirectory() as tmp:
        reference = reference_environment(Path(tmp))
        planner, _, renderers, where = planned_renderers(Path(tmp))
        jobs = list(planner.jobs(0, frames))
        agreement = compare(jobs, renderers, reference)
        cpu = cpu_per_frame(jobs, renderers, reference)
    return {"frames": len(jobs), "inputs": where, "reference": REFERENCE,
            "what": "render_rays.default_settings, np.arctan2 lookups (old) against fast_atan2 (new), one thread",
            "atan": atan_error(), "agreement": agreement, "cpu": cpu}


def summary(res: dict) -> str:
    a, c, t = res["agreement"], res["cpu"], res["atan"]
    k = c["kernel_ms"]
    return "\n".join([
        f"{res['frames']} default frames ({res['inputs']}); one thread.", "",
        "| CPU ms a frame | np.arctan2 (old) | fast_atan2 (new) |", "|---|---|---|",
        f"| frame | {c['frame_ms']['old']:.2f} | {c['frame_ms']['new']:.2f} |",
        *(f"| {name} | {k[name]['old']:.2f} | {k[name]['new']:.2f} |" for name in KERNELS), "",
        f"fast_atan2 against np.arctan2: at most {t['max_error_rad']:.2e} rad over {t['grid_points']:,} directions; "
        f"special cases exact: {t['special_exact']}. 8-bit images: {a['frames_with_differing_pixels']} of "
        f"{res['frames']} frames differ, {a['differing_pixels_total']} pixels in all (at most "
        f"{a['differing_pixels_max']} a frame), largest channel difference {a['largest_difference']}; labels "
        f"identical: {a['labels_identical']}.", "",
        f"summary: {c['saved_frame_ms']:.2f} ms of CPU a frame saved ({c['saved_kernel_ms']:.2f} ms in the kernels)",
    ])
