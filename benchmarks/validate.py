"""`darthand validate` speed: seconds per package without --render (the target is <= 1 s per package).

Packages, written into a temporary folder by the exporters' public APIs, on build/model/right.npz if built, else the
open template with the wrist:
    small        2 skin textures (256 px), one rigid ring and one glove: as .usda package, .glb and .gltf folder
    catalogue    the full variant count of the pipeline's package: 325 skin textures (links to one 2048 px PNG; the
                 default check reads each texture's header and end, so its size hardly matters) and 50 accessories
                 (the catalogue's ids: 40 rigid patches on joint 5 and 10 gloves), USD only
    deep         --deep (every PNG chunk's CRC and a full decode) on a USD package of DEEP_TEXTURES such variants,
                 run once: its cost grows with texture count and size, so it is reported per texture variant
    pipeline     the packages `make assets` built (build/usd/<side>, build/gltf/<side>.glb and the .gltf package
                 build/gltf/<side>/), when they exist
Figures are the median of REPEATS warm runs in this process (imports and the validator registry loaded once;
`first_call_s` is the first run, with those imports), the Khronos glTF-Validator's share (a node process per file),
and a cold command-line run (a new Python process: imports + one small USD package).
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks._common import bench_model

REPEATS = 3
TEXTURES = 325
DEEP_TEXTURES = 16
RIGID, GLOVES = 40, 10


def _png(path: Path, size: int, seed: int) -> Path:
    import OpenImageIO as oiio

    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size] / size
    rgb = np.stack([0.6 + 0.1 * np.sin(20 * x), 0.4 + 0.1 * np.cos(17 * y), 0.3 + 0.05 * rng.random((size, size))],
                   -1).astype(np.float32)
    buf = oiio.ImageBuf(oiio.ImageSpec(size, size, 3, oiio.UINT8))
    buf.set_pixels(oiio.ROI(), rgb)
    path.parent.mkdir(parents=True, exist_ok=True)
    buf.write(str(path))
    return path


def _link(src: Path, dst: Path) -> Path:
    dst.parent.mkdir(parents=True, exist_ok=True)
    os.link(src, dst)
    return dst


def _accessories(model, ids_rigid, ids_glove):
    from darthand.accessories.loader import Accessory
    from darthand.model.topology import vertex_normals

    joint = np.asarray(model.J_regressor @ model.v_template)[5]
    near = model.v_template[np.linalg.norm(model.v_template - joint, axis=1) < 0.012]
    out = []
    if len(near) >= 3:   # a small rigid patch lifted 1 mm off the skin around joint 5 (geometry is not the point)
        n = vertex_normals(model.v_template, model.faces)
        patch = near + 0.001 * n[np.linalg.norm(model.v_template - joint, axis=1) < 0.012]
        faces = np.array([[0, 1, 2]] + [[0, k, k + 1] for k in range(2, len(patch) - 1)])
        out += [Accessory(i, patch, faces, parent_joint=5, kind="ring") for i in ids_rigid]
    glove_v = model.v_template + 0.001 * vertex_normals(model.v_template, model.faces)
    out += [Accessory(i, glove_v, model.faces, uvs=model.uvs, faces_uv=model.faces_uv, weights=model.weights,
                      posedirs=model.posedirs, kind="glove") for i in ids_glove]
    return out


def _timed(paths, repeats: int = REPEATS, **kwargs) -> tuple[float, float, object]:
    """(first call s, median warm s, last report) of validate_paths(paths)."""
    from darthand.validate.run import validate_paths

    times, report = [], None
    for _ in range(repeats + 1):
        t0 = time.perf_counter()
        report = validate_paths(paths, **kwargs)
        times.append(time.perf_counter() - t0)
    return times[0], statistics.median(times[1:]), report


def run() -> dict:
    from darthand.accessories.catalog import load_spec as accessory_spec
    from darthand.textures.loader import TextureSet
    from darthand.export.gltf_export import export_gltf
    from darthand.export.usd_asset import export_usd
    from darthand.textures.catalog import expand_catalog, load_spec as texture_spec
    from darthand.validate.rules_gltf import khronos_findings

    model, source = bench_model()
    if not model.has_uvs:
        from darthand.model.atlas import ensure_uvs
        model = ensure_uvs(model, 1024)
    texture_ids = [e.id for e in expand_catalog(texture_spec())][:TEXTURES]
    items = accessory_spec()["items"]
    rigid_ids = [i["id"] for i in items if i["type"] != "glove"][:RIGID]
    glove_ids = [i["id"] for i in items if i["type"] == "glove"][:GLOVES]
    gestures = (["flat", "bent"], np.stack([np.zeros(48), np.r_[np.zeros(3), np.tile([0.0, 0.0, 0.5], 15)]]))
    out: dict = {"model": source, "vertices": model.num_vertices, "faces": model.num_faces, "repeats": REPEATS}
    with tempfile.TemporaryDirectory(prefix="darthand-bench-validate-") as tmp:
        tmp = Path(tmp)
        small_tex = [TextureSet(texture_ids[0], _png(tmp / "src/a0.png", 256, 0), _png(tmp / "src/r0.png", 256, 1)),
                     TextureSet(texture_ids[1], _png(tmp / "src/a1.png", 256, 2))]
        small_acc = _accessories(model, rigid_ids[:1], glove_ids[:1])
        usd = tmp / "small" / "usd" / "right"
        export_usd(model, usd, textures=small_tex, accessories=small_acc, gestures=gestures)
        glb = tmp / "small" / "right.glb"
        export_gltf(model, glb, textures=small_tex, accessories=small_acc, gestures=gestures)
        gltf = tmp / "small" / "gltf" / "right.gltf"
        gltf.parent.mkdir(parents=True)
        export_gltf(model, gltf, textures=small_tex, accessories=small_acc, gestures=gestures)
        small = {}
        for name, path in (("usd", usd), ("glb", glb), ("gltf", gltf)):
            first, warm, report = _timed([path])
            small[name] = {"seconds": round(warm, 4), "first_call_s": round(first, 4),
                           "errors": sum(f.severity == "error" for f in report.findings)}
        t0 = time.perf_counter()
        khronos_findings(glb)
        small["glb"]["khronos_validator_s"] = round(time.perf_counter() - t0, 4)
        out["small"] = small

        big_src = _png(tmp / "src" / "big.png", 2048, 3)
        big_tex = [TextureSet(tid, _link(big_src, tmp / "src" / tid / "albedo.png"),
                              _link(big_src, tmp / "src" / tid / "roughness.png")) for tid in texture_ids]
        t0 = time.perf_counter()
        big = tmp / "catalogue" / "usd" / "right"
        export_usd(model, big, textures=big_tex, accessories=_accessories(model, rigid_ids, glove_ids),
                   gestures=gestures)
        export_s = time.perf_counter() - t0
        first, warm, report = _timed([big])
        out["catalogue_usd"] = {"texture_variants": len(big_tex), "accessory_variants": len(rigid_ids) + len(glove_ids),
                                "export_s": round(export_s, 2), "seconds": round(warm, 4),
                                "first_call_s": round(first, 4),
                                "errors": sum(f.severity == "error" for f in report.findings)}
        deep_pkg = tmp / "deep" / "usd" / "right"
        export_usd(model, deep_pkg, textures=big_tex[:DEEP_TEXTURES], gestures=gestures)
        _, plain, _ = _timed([deep_pkg], repeats=1)
        _, deep, _ = _timed([deep_pkg], repeats=1, deep=True)
        out["deep_usd"] = {"texture_variants": DEEP_TEXTURES, "texture_px": 2048, "seconds": round(plain, 4),
                           "deep_seconds": round(deep, 4),
                           "deep_s_per_texture_variant": round((deep - plain) / DEEP_TEXTURES, 4)}

        pipeline = {}
        for side in ("right", "left"):
            for name, path in ((f"usd_{side}", Path("build/usd") / side),
                               (f"glb_{side}", Path("build/gltf") / f"{side}.glb"),
                               (f"gltf_{side}", Path("build/gltf") / side)):
                if path.exists():
                    first, warm, report = _timed([path])
                    pipeline[name] = {"seconds": round(warm, 4), "first_call_s": round(first, 4),
                                      "errors": sum(f.severity == "error" for f in report.findings)}
        for name, path in (("glb_right", Path("build/gltf/right.glb")),
                           ("gltf_right", Path("build/gltf/right/right.gltf"))):
            if path.is_file():
                t0 = time.perf_counter()
                khronos_findings(path.absolute())
                pipeline[name]["khronos_validator_s"] = round(time.perf_counter() - t0, 4)
        out["pipeline"] = pipeline or "not built (make assets)"

        script = ("import argparse, sys; from darthand.validate import commands; p = argparse.ArgumentParser(); "
                  "commands.add_arguments(p); sys.exit(commands.validate(p.parse_args(sys.argv[1:])))")
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", script, str(usd)], capture_output=True, timeout=600)
        out["cli_cold_small_usd_s"] = round(time.perf_counter() - t0, 3)
    return out


if __name__ == "__main__":
    import json
    print(json.dumps(run(), indent=2))
