"""WebDataset tar shards for streaming training: OUT/{split}-000000.tar, ... with up to SAMPLES_PER_SHARD samples
each, in frame order. A sample's key is its zero-padded frame index (no dots: WebDataset splits a member name at the
first dot into key and extension); its members:

    <key>.png        the image (RGBA; opaque over a background)
    <key>.mask.png   the 8-bit coverage mask
    <key>.json       the labels (schemas/labels.schema.json)
    <key>.verts.npy  (V, 3) float32 posed vertices, camera frame, metres; (B, V, 3) for a two-hand frame (hands in
                     the labels' `hands` order)
    <key>.instances.png  a two-hand or object frame's 8-bit instance mask (0 background, 1 + 2b hand b, 2 + 2b its
                     accessory; 3 the object held beside one hand)
    <key>.object.npy an object frame's (N, 3) float32 object mesh, camera frame, metres (its labels' objects say
                     which catalogue object: its faces are the catalogue's)
    <key>.depth.png, <key>.normals.png, <key>.parts.png   the per-pixel truth maps, when the dataset has them
                     (dataset.json 'maps'; encodings in render/truth.py and each sample's labels 'maps')

Tar headers carry no time, owner or host (mtime 0, uid/gid 0, empty names, mode 0644), so the same dataset gives
the same bytes.
"""

from __future__ import annotations

import io
import tarfile
from pathlib import Path

from darthand.dataset.frames import frame_names
from darthand.dataset.run import rendered_dataset
from darthand.fileio import atomic_path

SAMPLES_PER_SHARD = 1000
SPLITS = ("train", "val", "test")


def write_webdataset(dataset, out=None, samples_per_shard: int = SAMPLES_PER_SHARD) -> Path:
    """Write the shards of a rendered dataset folder into `out` (default DATASET/webdataset)."""
    root = Path(dataset)
    doc, frames = rendered_dataset(root)
    maps = tuple(doc.get("maps") or ())                              # the truth maps' kinds
    out = Path(out) if out is not None else root / "webdataset"
    out.mkdir(parents=True, exist_ok=True)
    for split in SPLITS:
        indices = [f["index"] for f in frames if f["split"] == split]
        for shard, k in enumerate(range(0, len(indices), samples_per_shard)):
            with atomic_path(out / f"{split}-{shard:06d}.tar") as tmp, tarfile.open(tmp, "w",
                                                                                 format=tarfile.USTAR_FORMAT) as tar:
                for index in indices[k:k + samples_per_shard]:
                    names = frame_names(index, maps)
                    key = Path(names["labels"]).stem
                    for member, kind in ((f"{key}.png", "image"), (f"{key}.mask.png", "mask"),
                                         (f"{key}.json", "labels"), (f"{key}.verts.npy", "vertices"),
                                         *((f"{key}.{kind}.png", kind) for kind in maps)):
                        add_member(tar, member, (root / names[kind]).read_bytes())
                    instances = instances_path(root, names)
                    if instances.is_file():
                        add_member(tar, f"{key}.instances.png", instances.read_bytes())
                    held = root / "object_meshes" / f"{key}.npy"
                    if held.is_file():
                        add_member(tar, f"{key}.object.npy", held.read_bytes())
    return out


def instances_path(root: Path, names: dict) -> Path:
    """Where a frame's instance mask is (instances/<n>.png: only two-hand frames write one)."""
    return root / "instances" / Path(names["image"]).name


def add_member(tar: tarfile.TarFile, name: str, data: bytes) -> None:
    """A tar member without time, owner or host (the same dataset gives the same bytes)."""
    info = tarfile.TarInfo(name)
    info.size, info.mtime, info.mode = len(data), 0, 0o644
    info.uid = info.gid = 0
    info.uname = info.gname = ""
    tar.addfile(info, io.BytesIO(data))
