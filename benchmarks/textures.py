"""Benchmark of the textures stage: bake time and seconds per variant at 1024, 2048 and 4096, and the whole
325-variant catalogue at 2048 on 2 worker processes (optional: `run(catalogue=False)` skips it).

Runs on the open template with the DART wrist when present, else on the synthetic tube hand with an xatlas
atlas. Per-variant figures are in one process: render (pure compute) and write (PNG + roughness + .tx).
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks._common import bench_model

# A spread of categories (cheap and expensive overlays) for the per-variant figures.
SAMPLE_IDS = ("dark_bandage_00", "brown_palm_prints_01", "light_scars_02", "dark_tattoos_03", "brown_moles_04",
              "light_nail_colors_05", "base_freckles_00", "base_veins_01")


def per_variant(model, res: int, ids=SAMPLE_IDS) -> dict:
    """Bake seconds, and mean seconds per variant to render and to write its files, at `res`."""
    import OpenImageIO as oiio

    from darthand.textures import build as build_mod
    from darthand.textures.bake import bake
    from darthand.textures.catalog import expand_catalog, load_spec

    oiio.attribute("threads", 1)  # as in the build's worker processes
    entries = {e.id: e for e in expand_catalog(load_spec())}
    t0 = time.perf_counter()
    b = bake(model, res)
    t_bake = time.perf_counter() - t0
    build_mod._WORKER_BAKE = b
    from darthand.textures.variant import render_variant

    from darthand.textures.imageio import write_png, write_tx

    render_variant(b, entries[ids[0]])  # warm-up: first-touch allocations, k-d tree
    t_render, t_total, t_png, t_tx = [], [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for i in ids:
            t0 = time.perf_counter()
            v = render_variant(b, entries[i])
            t_render.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            write_png(Path(tmp) / "a.png", v.albedo)
            t_png.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            write_tx(Path(tmp) / "a.tx", v.albedo)
            t_tx.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            build_mod._render_one((entries[i].to_json(), tmp, res, b.key, True, True))
            t_total.append(time.perf_counter() - t0)
    render = float(np.mean(t_render))
    total = float(np.mean(t_total))
    return {"bake_s": round(t_bake, 2), "texels": b.num_texels, "render_s": round(render, 3),
            "png_s": round(float(np.mean(t_png)), 3), "tx_s": round(float(np.mean(t_tx)), 3),
            "write_s": round(total - render, 3), "per_variant_s": round(total, 3)}


def whole_catalogue(model, res: int = 2048, workers: int = 2) -> dict:
    """Wall time of building all 325 variants (bake included, then without the bake)."""
    from darthand.textures.bake import cached_bake
    from darthand.textures.build import build_textures
    from darthand.textures.catalog import load_spec

    spec = load_spec()
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        cached_bake(model, res, tmp)
        t_bake = time.perf_counter() - t0
        t0 = time.perf_counter()
        catalog = build_textures(model, spec, tmp, res=res, workers=workers, progress=False)
        t_build = time.perf_counter() - t0
        sizes = [os.path.getsize(Path(tmp) / f) for e in catalog["entries"] for f in e["files"].values() if f]
    n = len(catalog["entries"])
    return {"variants": n, "resolution": res, "workers": workers, "bake_s": round(t_bake, 1),
            "build_s": round(t_build, 1), "total_s": round(t_bake + t_build, 1),
            "wall_s_per_variant": round(t_build / n, 3), "output_mb": round(sum(sizes) / 1e6, 1)}


def run(catalogue: bool = True, resolutions=(1024, 2048, 4096)) -> dict:
    model, name = bench_model()
    out = {"model": name, "cores": os.cpu_count(),
           "per_variant": {str(r): per_variant(model, r) for r in resolutions}}
    if catalogue:
        out["catalogue_2048"] = whole_catalogue(model, 2048, workers=2)
    return out


if __name__ == "__main__":
    import json
    import sys

    print(json.dumps(run(catalogue="--no-catalogue" not in sys.argv), indent=2))
