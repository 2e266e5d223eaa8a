"""The InterHand2.6M layout's writer (dataset/interhand.py) per frame: `darthand dataset export DIR --format
interhand` over a rendered dataset of DARTHAND_BENCH_INTERHAND_FRAMES (64) frames of 512^2, both hands, over
built-in backgrounds. The rendering is not timed; the export is (images re-encoded as JPEG, four annotation files
per split), best of REPEATS. One-hand frames: a two-hand frame writes the same image and annotation per frame, with
a second hand's joints and MANO parameters in place of zeros and None.

Figures: ms_per_frame (wall time of one export / frames), annotation_bytes_per_frame, image_bytes_per_frame.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

REPEATS = 3


def _time_export(dataset: Path, frames: int) -> dict:
    """{ms_per_frame, annotation_bytes_per_frame, image_bytes_per_frame}: the best of REPEATS exports."""
    from benchmarks.writer_coco import best_seconds
    from darthand.dataset.interhand import write_interhand

    best, out = best_seconds(lambda: write_interhand(dataset, dataset / "interhand"), REPEATS)
    notes = sum(p.stat().st_size for p in (out / "annotations").rglob("*.json"))
    images = sum(p.stat().st_size for p in (out / "images").rglob("*.jpg"))
    return {"ms_per_frame": round(1000 * best / frames, 3), "annotation_bytes_per_frame": round(notes / frames),
            "image_bytes_per_frame": round(images / frames)}


def run(frames: int | None = None) -> dict:
    from benchmarks.render_dataset import dataset_inputs
    from benchmarks.writer_coco import _render

    frames = int(os.environ.get("DARTHAND_BENCH_INTERHAND_FRAMES", frames or 64))
    result: dict = {"frames": frames, "repeats": REPEATS}
    with tempfile.TemporaryDirectory() as tmp:
        model, textures, accessories, where = dataset_inputs(Path(tmp))
        result["inputs"] = where
        dataset = Path(tmp) / "dataset"
        _render(model, textures, accessories, dataset, frames, "builtin")
        result["export"] = _time_export(dataset, frames)
    return result


def summary(result: dict) -> str:
    e = result["export"]
    return "\n".join([f"`dataset export --format interhand` over {result['frames']} frames of 512^2 (best of "
                      f"{result['repeats']}; {result['inputs']}).", "",
                      "| ms per frame | annotation bytes per frame | image bytes per frame |", "|---|---|---|",
                      f"| {e['ms_per_frame']:.2f} | {e['annotation_bytes_per_frame']} | "
                      f"{e['image_bytes_per_frame']} |"])
