"""HaMeR layout writer: milliseconds per frame of `darthand dataset export --format hamer` (dataset/hamer.py) over a
rendered dataset of 512^2 frames (both hands, backgrounds, labels and meshes), and the parts of a frame's time: its
JPEG (decode the PNG, composite, encode) and the rest (labels, keypoints, box, pickle, tar, files). CPU time of this
process (a shared machine's wall time is noise at this scale), the least of REPEATS exports;
DARTHAND_BENCH_WRITER_FRAMES changes the frame count (default 48).
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

REPEATS = 5


def run(frames: int | None = None) -> dict:
    from benchmarks.render_dataset import dataset_inputs
    from darthand.dataset.api import render_dataset
    from darthand.dataset.hamer import jpeg_bytes, write_hamer
    from darthand.dataset.options import DatasetOptions
    from darthand.render.image import over_black, read_straight_png

    frames = int(os.environ.get("DARTHAND_BENCH_WRITER_FRAMES", frames or 48))
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        model, textures, accessories, where = dataset_inputs(tmp)
        data = tmp / "data"
        render_dataset(DatasetOptions(str(model), str(data), count=frames, textures=str(textures),
                                      accessories=str(accessories), resume=False, progress=False, processes=1))
        images = sorted((data / "images").glob("*.png"))
        export = min(_seconds(lambda: write_hamer(data, tmp / "hamer")) for _ in range(REPEATS))
        jpeg = min(_seconds(lambda: [jpeg_bytes(over_black(read_straight_png(p)), tmp) for p in images])
                   for _ in range(REPEATS))
        disk = sum(p.stat().st_size for p in (tmp / "hamer").rglob("*") if p.is_file())
    ms = 1000 / frames
    return {"frames": frames, "inputs": where, "cpu_ms_per_frame": round(export * ms, 2),
            "jpeg_cpu_ms_per_frame": round(jpeg * ms, 2), "rest_cpu_ms_per_frame": round((export - jpeg) * ms, 2),
            "kb_per_frame_on_disk": round(disk / frames / 1024, 1),
            "what": "write_hamer over a rendered dataset: tars (jpg + data.pyd), val/test .npz and images, README"}


def _seconds(work) -> float:
    t0 = time.process_time()
    work()
    return time.process_time() - t0


if __name__ == "__main__":
    import json

    print(json.dumps(run(), indent=2))
