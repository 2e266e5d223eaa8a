"""USD export: what each export option costs (file size, write / open / UsdSkel compute time) and what it loses
(max vertex error against the full rig).

Options: correctives full | pca:K | pose-pca:K (K = 8, 16, 32, 64) | none, and influences 4 | 8 | all (capped at the
most non-zero weights any vertex has; `influences_written` is the count written). The error of an option is
the max vertex distance (m) between `forward` on the model and `forward` on the rig the asset carries
(`correctives.exported_model`), over the named gestures and random anatomical poses (`anatomy.sample_poses`, seeded).
For every written option the asset is also read back and posed by UsdSkel; `usdskel_vs_rig_m` is UsdSkel's distance
from that option's rig (the export's exactness, ~1e-7 m from float32 storage) and `usdskel_vs_full_m` its distance
from the full rig over the gestures. Texture resolution: size and error (RMS and max, linear RGB, after resampling
back to the source size) of the default skin albedo at 512 / 1024 / 2048 px, when a texture catalogue is built.

The model is `_common.bench_model`: build/model/right.npz if built, else the open template with the wrist.
"""

from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
from pxr import Usd

from benchmarks._common import bench_model
from darthand.export.correctives import export_correctives, exported_model, rig_error
from darthand.export.gestures import gesture_poses
from darthand.export.influences import parse_influences
from darthand.export.usd_asset import ExportOptions, export_usd
from darthand.export.usd_evaluate import skinned_points
from darthand.model.forward import forward

CORRECTIVES = ("full", "pca:8", "pca:16", "pca:32", "pca:64", "pose-pca:8", "pose-pca:16", "pose-pca:32",
               "pose-pca:64", "none")
INFLUENCES = ("4", "8", "all")
RANDOM_POSES = 256
TEXTURE_SIZES = (512, 1024, 2048)


def error_poses(model) -> tuple[list[str], np.ndarray, np.ndarray]:
    """The poses export errors are measured over (both export benchmarks): gesture names, gesture poses (G, 48) and
    seeded random anatomical poses (RANDOM_POSES, 48)."""
    from darthand.model.anatomy import sample_poses

    names, gestures = gesture_poses(model)
    return names, gestures, sample_poses(model, RANDOM_POSES, np.random.default_rng(2022))


def timed(fn, *args, **kw):
    t = time.perf_counter()
    out = fn(*args, **kw)
    return out, time.perf_counter() - t


def option_row(model, folder: Path, correctives: str, influences: str, gestures, poses) -> dict:
    """Write the rig-only asset for one option combination and measure it."""
    k = parse_influences(influences)
    rig = exported_model(model, export_correctives(model, correctives), k)
    out = folder / f"{correctives.replace(':', '')}_{influences}"
    info, write_s = timed(export_usd, model, out, options=ExportOptions(influences=k, correctives=correctives),
                          gestures=gestures)
    stage, open_s = timed(Usd.Stage.Open, str(out / info["interface"]), Usd.Stage.LoadAll)
    points, compute_s = timed(skinned_points, stage)
    usd_pts = points[info["prims"]["hand"]]
    names, g = gestures
    return {
        "correctives": correctives,
        "influences": influences,
        "influences_written": info["rig"]["influences"],
        "max_error_m": rig_error(model, rig, poses),
        "payload_bytes": info["files"]["payload.usdc"],
        "blend_shapes": info["rig"]["blend_shapes"],
        "blend_shape_points": info["rig"]["blend_shape_points"],
        "write_s": round(write_s, 4),
        "open_s": round(open_s, 4),
        "usdskel_compute_s": round(compute_s, 4),
        "usdskel_vs_rig_m": float(np.linalg.norm(usd_pts - forward(rig, g).vertices, axis=-1).max()),
        "usdskel_vs_full_m": float(np.linalg.norm(usd_pts - forward(model, g).vertices, axis=-1).max()),
    }


def texture_rows(folder: Path) -> list[dict] | str:
    """Size and resampling error of the default albedo at each TEXTURE_SIZES, or why it was skipped."""
    import OpenImageIO as oiio

    from darthand.export.texture_files import place_texture
    from darthand.textures.loader import load_texture_catalog

    catalog = Path("build/textures/catalog.json")
    if not catalog.is_file():
        return "skipped: no build/textures/catalog.json"
    src = load_texture_catalog(catalog)[0].albedo
    rows = []
    for size in TEXTURE_SIZES:
        dst = folder / f"albedo_{size}.png"
        _, secs = timed(place_texture, src, dst, size, True)
        _, load_s = timed(lambda dst=dst: oiio.ImageBuf(str(dst)).get_pixels(oiio.UINT8))
        rows.append({"size": size, "bytes": dst.stat().st_size, **resampling_error(src, dst),
                     "resample_s": round(secs, 4), "decode_s": round(load_s, 4)})
    return rows


def resampling_error(src: Path, small: Path) -> dict:
    """RMS and max difference (linear RGB) of the sRGB image `small`, scaled back up to the size of `src`, from
    `src`: what downsizing a texture loses."""
    import OpenImageIO as oiio

    ref = oiio.ImageBufAlgo.colorconvert(oiio.ImageBuf(str(src)), "sRGB", "linear")
    spec = ref.spec()
    back = oiio.ImageBufAlgo.colorconvert(oiio.ImageBuf(str(small)), "sRGB", "linear")
    back = oiio.ImageBufAlgo.resize(back, roi=oiio.ROI(0, spec.width, 0, spec.height, 0, 1, 0, spec.nchannels))
    diff = back.get_pixels(oiio.FLOAT) - ref.get_pixels(oiio.FLOAT)
    return {"rms_error_linear": float(np.sqrt((diff ** 2).mean())), "max_error_linear": float(np.abs(diff).max())}


def package_row(model, folder: Path) -> dict:
    """The whole package with the built catalogues (if any): write time, sizes, open time of one variant."""
    from darthand.accessories.loader import load_accessory_catalog
    from darthand.export.usd_validate import select_variants
    from darthand.textures.loader import load_texture_catalog

    textures = load_texture_catalog("build/textures") if Path("build/textures/catalog.json").is_file() else []
    accessories = load_accessory_catalog("build/accessories", side=model.side) \
        if Path("build/accessories/catalog.json").is_file() else []
    out = folder / "package"
    info, write_s = timed(export_usd, model, out, textures=textures, accessories=accessories)
    sizes = info["files"]
    row = {"textures": len(textures), "accessories": len(accessories), "write_s": round(write_s, 3),
           "files": len(sizes), "total_bytes": sum(sizes.values()),
           "texture_layer_bytes_mean": _mean([v for k, v in sizes.items() if k.startswith("texture/")
                                              and k.endswith(".usda")]),
           "accessory_layer_bytes_mean": _mean([v for k, v in sizes.items() if k.startswith("accessory/")
                                                and k.endswith(".usdc")])}
    stage, row["open_default_s"] = timed(Usd.Stage.Open, str(out / info["interface"]), Usd.Stage.LoadAll)
    if accessories:
        _, secs = timed(select_variants, stage, {"accessory": accessories[-1].id})
        row["switch_accessory_s"] = round(secs, 4)
    row["open_default_s"] = round(row["open_default_s"], 4)
    return row


def _mean(values: list) -> float | None:
    return round(float(np.mean(values)), 1) if values else None


def run() -> dict:
    model, name = bench_model()
    names, gestures, random = error_poses(model)
    poses = np.concatenate([gestures, random])
    folder = Path(tempfile.mkdtemp(prefix="darthand-bench-usd-"))
    try:
        rows = [option_row(model, folder, c, i, (names, gestures), poses)
                for c in CORRECTIVES for i in INFLUENCES]
        textures = texture_rows(folder)
        package = package_row(model, folder)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    return {
        "model": name, "vertices": model.num_vertices, "gestures": len(names), "random_poses": RANDOM_POSES,
        "options": rows, "texture_resolution": textures, "package": package,
        "goal": "full + all: usdskel_vs_full_m <= 1e-5 m",
    }
