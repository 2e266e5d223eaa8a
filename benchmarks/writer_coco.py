"""The COCO-style layout's writer (dataset/coco.py) per frame: `darthand dataset export DIR --format coco` over a
rendered dataset of DARTHAND_BENCH_COCO_FRAMES (64) frames of 512^2, both hands, once over built-in backgrounds
(images hard-linked) and once without (each image composited over black and encoded again). The rendering is not
timed; the export is, best of REPEATS.

Figures: ms_per_frame (wall time of one export / frames) per case, and bytes_per_frame of the annotation files.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

REPEATS = 3


def _render(model, textures, accessories, out: Path, frames: int, backgrounds: str) -> None:
    from darthand.dataset.api import render_dataset
    from darthand.dataset.options import DatasetOptions
    from darthand.dataset.plan import PlanOptions

    render_dataset(DatasetOptions(str(model), str(out), count=frames, textures=str(textures),
                                  accessories=str(accessories), resume=False, progress=False,
                                  plan=PlanOptions(seed=1, backgrounds=backgrounds)))


def best_seconds(write, repeats: int = REPEATS) -> tuple:
    """(the shortest wall time of `repeats` calls of write(), what the last call returned)."""
    best, out = float("inf"), None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = write()
        best = min(best, time.perf_counter() - t0)
    return best, out


def _time_export(dataset: Path, frames: int) -> dict:
    """{ms_per_frame, bytes_per_frame}: the best of REPEATS exports of `dataset`."""
    from darthand.dataset.coco import write_coco

    best, out = best_seconds(lambda: write_coco(dataset, dataset / "coco"))
    size = sum(p.stat().st_size for p in (out / "annotations").iterdir())
    return {"ms_per_frame": round(1000 * best / frames, 3), "bytes_per_frame": round(size / frames)}


def run(frames: int | None = None) -> dict:
    from benchmarks.render_dataset import dataset_inputs

    frames = int(os.environ.get("DARTHAND_BENCH_COCO_FRAMES", frames or 64))
    result: dict = {"frames": frames, "repeats": REPEATS}
    with tempfile.TemporaryDirectory() as tmp:
        model, textures, accessories, where = dataset_inputs(Path(tmp))
        result["inputs"] = where
        for case, backgrounds in (("backgrounds", "builtin"), ("no_background", "none")):
            dataset = Path(tmp) / case
            _render(model, textures, accessories, dataset, frames, backgrounds)
            result[case] = _time_export(dataset, frames)
    return result


def summary(result: dict) -> str:
    rows = [f"| {case.replace('_', ' ')} | {result[case]['ms_per_frame']:.2f} | {result[case]['bytes_per_frame']} |"
            for case in ("backgrounds", "no_background")]
    return "\n".join([f"`dataset export --format coco` over {result['frames']} frames of 512^2 "
                      f"(best of {result['repeats']}; {result['inputs']}).", "",
                      "| frames | ms per frame | annotation bytes per frame |", "|---|---|---|", *rows])
