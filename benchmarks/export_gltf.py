"""glTF export options, speed against error: influences 4 / 8 / all, correctives full / pca:K / pose-pca:K / none
(the USD benchmark's list), texture size.

For each option the asset is written as .glb and measured: file size, write time, load time (pygltflib, trimesh)
and the error it costs, a max vertex distance in metres over the gesture set plus random anatomical poses (the USD
benchmark's `error_poses`, `correctives.option_errors`):
    influences k   forward pass with weights pruned to k (renormalised) against the full weights;
    correctives    forward pass with the exported correctives (rank-K reconstruction, or none) against the model's;
    texture size   RMS and max difference (linear RGB) of the downsized albedo, scaled back up, against the source
                   (`export_usd.resampling_error`).
The default asset (4 influences, full correctives) is also run through the Khronos validator.

Model: `_common.bench_model` (build/model/right.npz when built, else the open template with the DART wrist).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks._common import bench_model
from benchmarks.export_usd import CORRECTIVES, RANDOM_POSES, error_poses, resampling_error
from darthand.export.correctives import export_correctives, option_errors
from darthand.textures.loader import TextureSet
from darthand.export.gltf_export import GltfOptions, export_gltf
from darthand.model.forward import forward

TEXTURE_SIZES = (256, 512, 1024, 2048)
TEXTURE_CATALOG = Path("build/textures/catalog.json")


def measure_file(model, path: Path, repeats: int = 3, **kwargs) -> dict:
    """Write `path` with export_gltf(**kwargs); its size, the write time and the best-of-`repeats` load times."""
    import pygltflib
    import trimesh

    t = time.perf_counter()
    export_gltf(model, path, **kwargs)
    write_s = time.perf_counter() - t
    return {"size_kb": round(path.stat().st_size / 1024, 1), "write_s": round(write_s, 3),
            "load_pygltflib_s": _best(lambda: pygltflib.GLTF2.load(str(path)), repeats),
            "load_trimesh_s": _best(lambda: trimesh.load(path, process=False), repeats)}


def _best(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return round(min(times), 4)


def albedo_source(tmp: Path) -> tuple[Path, str]:
    """The default catalogue albedo, or a generated 2048 px noise PNG when the textures stage has not run."""
    from darthand.textures.loader import load_texture_catalog

    if TEXTURE_CATALOG.is_file():
        default = load_texture_catalog(TEXTURE_CATALOG)[0]
        return default.albedo, f"catalogue default ({default.id})"
    import OpenImageIO as oiio

    # Octaves of value noise (16 .. 2048 px cells), so downsizing loses detail gradually as on a real albedo.
    rng = np.random.default_rng(0)
    size, img = 2048, None
    for cells, amplitude in ((16, 0.5), (64, 0.25), (256, 0.15), (2048, 0.1)):
        small = oiio.ImageBuf(oiio.ImageSpec(cells, cells, 3, oiio.FLOAT))
        small.set_pixels(oiio.ROI(0, cells, 0, cells, 0, 1, 0, 3), rng.random((cells, cells, 3)).astype(np.float32))
        big = oiio.ImageBufAlgo.resize(small, roi=oiio.ROI(0, size, 0, size, 0, 1, 0, 3))
        layer = amplitude * np.asarray(big.get_pixels(oiio.FLOAT))
        img = layer if img is None else img + layer
    path = tmp / "noise.png"
    buf = oiio.ImageBuf(oiio.ImageSpec(size, size, 3, oiio.UINT8))
    buf.set_pixels(oiio.ROI(0, size, 0, size, 0, 1, 0, 3), (np.clip(img, 0, 1) * 255).astype(np.uint8))
    buf.write(str(path))
    return path, "generated 2048 px value noise, 4 octaves (no texture catalogue)"


def texture_error(src: Path, size: int) -> dict:
    """What embedding the albedo downsized to `size` loses (`export_usd.resampling_error`)."""
    from darthand.export.texture_files import texture_bytes

    with tempfile.TemporaryDirectory() as tmp:
        small = Path(tmp) / "small.png"
        small.write_bytes(texture_bytes(src, size))
        return resampling_error(src, small)


def run() -> dict:
    model, source = bench_model()
    names, gestures, random = error_poses(model)
    poses, n_gestures = np.concatenate([gestures, random]), len(names)
    truth = forward(model, poses).vertices
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for k in (4, 8, None):
            name = f"influences={k or 'all'}"
            errors = option_errors(model, export_correctives(model, "full"), k, poses, truth)
            rows.append({"option": name, "max_error_m": errors["influence_error_m"],
                         **measure_file(model, tmp / "a.glb", options=GltfOptions(influences=k))})
        for mode in CORRECTIVES:
            errors = option_errors(model, export_correctives(model, mode), None, poses, truth)
            rows.append({"option": f"correctives={mode}", "max_error_m": errors["corrective_error_m"],
                         **measure_file(model, tmp / "a.glb", options=GltfOptions(influences=None,
                                                                                  correctives=mode))})
        albedo, texture_source = albedo_source(tmp)
        for size in TEXTURE_SIZES:
            rows.append({"option": f"texture={size}px", **texture_error(albedo, size),
                         **measure_file(model, tmp / "a.glb", textures=[TextureSet("default", albedo)],
                                        options=GltfOptions(texture_size=size))})
        validation = _validate_default(model, tmp / "default.glb")
    return {"model": source, "vertices": model.num_vertices, "poses": {"gestures": n_gestures,
                                                                       "random_anatomical": RANDOM_POSES},
            "texture_source": texture_source, "options": rows, "validator_default_asset": validation}


def _validate_default(model, path: Path) -> dict:
    from darthand.errors import DarthandError
    from darthand.export.gltf_validator import validate

    export_gltf(model, path)
    try:
        return validate(path).counts
    except DarthandError as e:
        return {"unavailable": str(e)}


if __name__ == "__main__":
    import json

    print(json.dumps(run(), indent=2))
