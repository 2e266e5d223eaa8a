"""Benchmark of the renderer's skin textures: 8-bit (SRGB8-style) pyramids shared across skin-tone offsets against
float32 pyramids decoded per (texture, offset) -- the earlier storage.

Figures: load time of the skin texture + roughness map (cold: nothing cached, wall and CPU time; then a second offset of
the same files; and the CPU of a cold load with the files read through OpenImageIO rather than render/png.py's decoder),
memory per loaded texture, ms per 512^2 frame single-threaded (the scene of benchmarks/render.py) with the time spent in
texture lookups, and the image difference between the two storages at skin-tone offsets 0 and -0.1 over the pixels the
hand covers, in 8-bit sRGB codes (the re-quantised mips and the offset applied after filtering at levels >= 1 are the
lossy part).

The reference ('before') is texture.load_maps(..., codes=False), the float32 storage of linear values with the
offset applied at load; or, with `before` (the path of an earlier render/texture.py, e.g. a copy of it), that
module's load_maps, so that its own load and lookup times are measured. Timings are repeated `repeats` times; each
repeat is reported (the machine may be shared).
"""

from __future__ import annotations

import importlib.util
import os
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path
from unittest import mock

import numpy as np

from benchmarks.render import ACCESSORY, LIGHTS, _sources

OFFSETS = (0.0, -0.1)


def _module(path):
    spec = importlib.util.spec_from_file_location("darthand_texture_before", str(path))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class _Loader:
    """A load_maps to render with, its cache to clear, and the time its textures spend in `sample` (seconds,
    accumulated until `take_sample_time`)."""

    def __init__(self, load_maps, clear):
        self._load, self.clear, self._sample_s = load_maps, clear, 0.0

    def __call__(self, *args, **kwargs):
        tex = self._load(*args, **kwargs)
        if not getattr(tex, "_bench_timed", False):
            inner = tex.sample

            def sample(*a, **k):
                t0 = time.perf_counter()
                out = inner(*a, **k)
                self._sample_s += time.perf_counter() - t0
                return out

            tex.sample, tex._bench_timed = sample, True
        return tex

    def take_sample_time(self) -> float:
        s, self._sample_s = self._sample_s, 0.0
        return s


def _loaders(before) -> dict:
    from darthand.render import texture

    after = _Loader(texture.load_maps, texture.clear_cache)
    if before is None:
        ref = _Loader(lambda *a, **k: texture.load_maps(*a, **k, codes=False), texture._float_maps.cache_clear)
    else:
        old = _module(before)
        ref = _Loader(old.load_maps, getattr(old, "clear_cache", None) or old._load_maps.cache_clear)
    return {"after": after, "before": ref}


@contextmanager
def _rendering_with(loader):
    from darthand.render import assets

    with mock.patch.object(assets, "load_maps", loader):
        yield


def _memory(tex) -> int:
    """Bytes held by a texture: its flat storage, plus separate level arrays (the earlier MipTexture kept both)."""
    if hasattr(tex, "nbytes"):
        return tex.nbytes
    return int(tex.flat.nbytes + sum(np.asarray(lv).nbytes for lv in tex.levels))


def _load_times(loader, albedo, rough, repeats: int) -> dict:
    cold, cold_cpu, second = [], [], []
    for _ in range(repeats):
        loader.clear()
        t0, c0 = time.perf_counter(), time.process_time()
        tex = loader(albedo, offset=OFFSETS[0], data=rough, channels=(0,))
        t1, c1 = time.perf_counter(), time.process_time()
        loader(albedo, offset=OFFSETS[1], data=rough, channels=(0,))
        t2 = time.perf_counter()
        cold.append(round(1000 * (t1 - t0), 1))
        cold_cpu.append(round(1000 * (c1 - c0), 1))
        second.append(round(1000 * (t2 - t1), 2))
    return {"cold_ms": cold, "cold_cpu_ms": cold_cpu, "second_offset_ms": second,
            "memory_mb": round(_memory(tex) / 1e6, 1),
            "memory_mb_two_offsets": round(_memory(tex) * (1 if hasattr(tex, "decode") and
                                                          tex.decode is not None else 2) / 1e6, 1)}


def _openimageio_decode_times(albedo, rough, repeats: int) -> list[float]:
    """CPU ms of cold load_maps with every file read through OpenImageIO (render/png.py's fast path off)."""
    from darthand.render import texture

    cpu = []
    with mock.patch.object(texture, "open_png8", lambda path: None):
        for _ in range(repeats):
            texture.clear_cache()
            c0 = time.process_time()
            texture.load_maps(albedo, offset=OFFSETS[0], data=rough, channels=(0,))
            cpu.append(round(1000 * (time.process_time() - c0), 1))
    texture.clear_cache()
    return cpu


def _render_times(renderers, loaders, gestures, texture_id, frames: int, repeats: int) -> dict:
    """Median ms per frame and ms in texture lookups per frame, each repeat; the storages alternate frame by frame
    (each with its own Renderer and source, so that neither reuses the other's posing) so that both see the same
    load on the machine."""
    out = {name: {"render_ms_median": [], "sample_ms_median": []} for name in loaders}
    for _ in range(repeats):
        ms = {name: [] for name in loaders}
        sample = {name: [] for name in loaders}
        for i in range(frames):
            for name, loader in loaders.items():
                with _rendering_with(loader):
                    loader.take_sample_time()
                    t0 = time.perf_counter()
                    renderers[name].render(gestures[i % len(gestures)], texture=texture_id, accessory=ACCESSORY,
                                    camera="three_quarter", lights=LIGHTS, labels=False)
                    ms[name].append(1000 * (time.perf_counter() - t0))
                    sample[name].append(1000 * loader.take_sample_time())
        for name in loaders:
            out[name]["render_ms_median"].append(round(float(np.median(ms[name])), 2))
            out[name]["sample_ms_median"].append(round(float(np.median(sample[name])), 3))
    return out


def _image_difference(renderers, loaders, gestures, texture_id) -> dict:
    """Per offset: differences in 8-bit sRGB codes (max over channels) between the storages' images, composited
    over mid grey, over the pixels whose centre ray hits the hand."""
    from darthand.textures.color import encode_srgb8

    def codes(frame):
        return encode_srgb8(frame.colour + (1 - frame.alpha[..., None]) * np.float32(0.5)).astype(np.int16)

    out = {}
    for offset in OFFSETS:
        diffs = []
        for pose in gestures:
            frames = {}
            for name, loader in loaders.items():
                with _rendering_with(loader):
                    frames[name] = renderers[name].render(pose, texture=texture_id, skin_tone_offset=offset,
                                                   accessory=ACCESSORY, camera="three_quarter", lights=LIGHTS,
                                                   labels=False)
            hand = frames["after"].geom == 0
            diffs.append(np.abs(codes(frames["after"]) - codes(frames["before"])).max(-1)[hand])
        d = np.concatenate(diffs)
        out[f"offset_{offset:g}"] = {"mean_codes": round(float(d.mean()), 4),
                                     "p99_9_codes": float(np.percentile(d, 99.9)), "max_codes": int(d.max()),
                                     "pixels_differing_share": round(float((d > 0).mean()), 4),
                                     "hand_pixels": int(len(d))}
    return out


def run(frames: int = 20, repeats: int = 3, before: str | os.PathLike | None = None, diff_poses: int = 8) -> dict:
    """Figures as the module docstring says; `before`: path of an earlier render/texture.py (else the float32
    storage of the current module is the reference)."""
    from darthand.model.poses import list_gestures
    from darthand.render.api import Renderer, open_source

    loaders = _loaders(before)
    with tempfile.TemporaryDirectory() as tmp:
        model, tex, acc, texture_id, where = _sources(Path(tmp))
        source = open_source(model, textures=tex, accessories=acc)
        files = source.textures[texture_id]
        loads = {}
        for name, loader in loaders.items():
            loader.clear()
            t0 = time.perf_counter()
            loader(files.albedo, offset=0.0, data=files.roughness, channels=(0,))
            first = round(1000 * (time.perf_counter() - t0), 1)
            loads[name] = {"first_in_process_ms": first,
                           **_load_times(loader, files.albedo, files.roughness, repeats)}
        loads["after"]["cold_cpu_ms_openimageio_decode"] = _openimageio_decode_times(files.albedo, files.roughness,
                                                                                     repeats)
        import OpenImageIO as oiio

        spec = oiio.ImageInput.open(str(files.albedo)).spec()
        renderers = {name: Renderer(open_source(model, textures=tex, accessories=acc), threads=1)
                     for name in loaders}
        gestures = list_gestures()
        for name, loader in loaders.items():            # warm: caches filled, first-frame work done
            with _rendering_with(loader):
                renderers[name].render(gestures[0], texture=texture_id, accessory=ACCESSORY, lights=LIGHTS)
        renders = _render_times(renderers, loaders, gestures, texture_id, frames, repeats)
        diff = _image_difference(renderers, loaders, gestures[:diff_poses], texture_id)
    return {
        "texture": texture_id, "inputs": where, "resolution": [spec.width, spec.height],
        "roughness_map": files.roughness is not None,
        "reference": "float32 storage, offset at load (texture.load_maps codes=False)" if before is None
                     else f"{before}",
        "load": loads,
        "render_512_single_thread": {**renders, "frames": frames, "accessory": ACCESSORY},
        "image_difference_codes": diff,
        "cores": len(os.sched_getaffinity(0)),
        "load_average_1min": round(os.getloadavg()[0], 2),
    }


if __name__ == "__main__":
    import json
    import sys

    print(json.dumps(run(before=sys.argv[1] if len(sys.argv) > 1 else None), indent=2))
