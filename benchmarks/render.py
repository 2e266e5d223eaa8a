"""Benchmark of the reference renderer: 512^2 labelled images of the textured hand wearing a ring, lit by one
shadowed directional light and ambient light, the pose changing every frame (so the scene is rebuilt each time), PNGs
and labels written. Reports ms per image and rays per second with both cores busy (frames rendered in parallel by
`render-dataset`'s worker processes), the same in one process (threads) and on one thread, where a frame's time
goes, and the anti-aliasing's speed against its error.

Uses the pipeline's build/ outputs when present (build/model/right.npz, build/textures, build/accessories); otherwise
builds the open hand, one texture variant (1024^2) and the ring into a temporary folder first (not timed).
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
TEXTURE = "light_moles_00"
ACCESSORY = "ring_01_court_gold"
LIGHTS = {"ambient": {"color": [0.85, 0.9, 1.0], "intensity": 0.2},
          "lights": [{"type": "directional", "direction": [0.5, 0.6, 0.62], "color": [1.0, 0.96, 0.9],
                      "intensity": 0.8, "shadows": True, "frame": "camera"}]}


def _sources(tmp: Path):
    """(model path, textures catalogue, accessories folder, texture id, note)."""
    build = ROOT / "build"
    model = build / "model" / "right.npz"
    tex, acc = build / "textures" / "catalog.json", build / "accessories" / "catalog.json"
    if model.is_file() and tex.is_file() and acc.is_file():
        import json

        ids = [e["id"] for e in json.loads(tex.read_text())["entries"]]
        accs = [a["id"] for a in json.loads(acc.read_text())["accessories"]]
        if ids and ACCESSORY in accs:
            return model, tex, acc.parent, (TEXTURE if TEXTURE in ids else ids[0]), "build/"
    from darthand.accessories.build import build_accessories
    from darthand.accessories.catalog import load_spec as accessory_spec
    from darthand.model.load import load_model
    from darthand.model.npz_io import save_npz
    from darthand.model.wrist import add_wrist
    from darthand.textures.build import build_textures
    from darthand.textures.catalog import load_spec as texture_spec

    m = add_wrist(load_model("open"))
    save_npz(m, tmp / "model" / "right.npz")
    build_textures(m, texture_spec(), tmp / "textures", res=1024, ids=[TEXTURE], workers=1, progress=False,
                   tx=False, sheet=False)
    build_accessories(m, accessory_spec(), tmp / "accessories", ids=[ACCESSORY], n_sampled=0, sheet=False)
    return tmp / "model" / "right.npz", tmp / "textures", tmp / "accessories", TEXTURE, "built in a temporary folder"


def _frames(renderer, gestures, out: Path, count: int, threads: int) -> dict:
    """Render and write `count` frames as a dataset loop does (Renderer.render_many: the next frame is posed and
    its scene built while this one traces; the PNGs are written on a background thread while the next frame
    renders): ms per image is the loop's wall time per frame, all files written; the breakdown is per step
    (median), with 'pose', 'setup', 'scene' on the helper thread and 'write' on the writer thread."""
    from darthand.render.api import FrameWriter

    renderer.threads = threads
    steps, rays = {}, 0
    frames = []
    c0, t0 = time.process_time(), time.perf_counter()
    poses = [gestures[i % len(gestures)] for i in range(count)]
    with FrameWriter() as writer:
        for i, frame in enumerate(renderer.render_many(poses, texture=renderer.texture_id, accessory=ACCESSORY,
                                                       camera="three_quarter", lights=LIGHTS, width=512,
                                                       height=512)):
            writer.submit(frame, out / f"{i:03d}")
            frames.append(frame)
            rays += frame.stats["total_rays"]
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    for frame in frames:
        for k, v in frame.timings.items():
            steps.setdefault(k, []).append(v)
        for k in ("trace", "shade"):
            steps.setdefault(f"threads_{k}", []).append(frame.stats.get(k, 0.0))
    render_ms = [1000 * sum(v for k, v in f.timings.items() if k != "write") for f in frames]
    return {"ms_per_image": round(1000 * wall / count, 2),
            "render_ms_per_image_median": round(float(np.median(render_ms)), 2),
            "cpu_ms_per_image": round(1000 * cpu / count, 2),
            "rays_per_second": round(rays / wall),
            "rays_per_image": round(rays / count),
            "breakdown_ms": {k: round(1000 * float(np.median(v)), 2) for k, v in steps.items()}}


AA_CONFIGS = (("4_triangle", 4, "triangle"), ("8_triangle", 8, "triangle"), ("8_sample", 8, "sample"),
              ("16_triangle", 16, "triangle"))
AA_REFERENCE = ("16_sample", 16, "sample")


def _antialiasing_error(renderer, gestures, texture_id: str) -> dict:
    """Speed against error of the edge anti-aliasing: sub-samples per edge pixel (4, 8, 16) and their shading
    ('triangle': once per pixel per triangle, the default; 'sample': every sub-sample), each against 16 sub-samples
    shaded every one. Differences in 8-bit sRGB codes of the images composited over mid grey, over the pixels the
    hand covers in either; the anti-aliasing step's ms single-threaded (median over the gestures; the rest of a
    frame is the same for all) and the sub-samples it shaded."""
    from darthand.textures.color import encode_srgb8

    def over_grey(frame):
        return encode_srgb8(frame.colour + (1 - frame.alpha[..., None]) * np.float32(0.5)).astype(np.int16)

    renderer.threads = 1
    rows = {name: {"aa_ms": [], "shaded": [], "diff": []} for name, _, _ in AA_CONFIGS + (AA_REFERENCE,)}
    for pose in gestures:
        frames = {}
        for name, samples, mode in (AA_REFERENCE,) + AA_CONFIGS:
            frames[name] = f = renderer.render(pose, texture=texture_id, accessory=ACCESSORY, camera="three_quarter",
                                               lights=LIGHTS, samples=samples, aa_shading=mode)
            rows[name]["aa_ms"].append(1000 * f.timings["aa"])
            rows[name]["shaded"].append(f.stats["aa_shaded"])
        ref = frames[AA_REFERENCE[0]]
        for name, _, _ in AA_CONFIGS:
            covered = (ref.alpha > 0) | (frames[name].alpha > 0)
            rows[name]["diff"].append(np.abs(over_grey(frames[name]) - over_grey(ref)).max(-1)[covered])
    out = {"reference": "16 sub-samples per edge pixel, each shaded"}
    for name, row in rows.items():
        out[name] = {"aa_ms_median": round(float(np.median(row["aa_ms"])), 2),
                     "shaded_sub_samples": round(float(np.mean(row["shaded"])))}
        if row["diff"]:
            d = np.concatenate(row["diff"])
            out[name].update({"mean_codes": round(float(d.mean()), 3), "p99_9_codes": float(np.percentile(d, 99.9)),
                              "max_codes": int(d.max()),
                              "pixels_over_8_codes_per_image": round(float((d > 8).sum()) / len(gestures), 1)})
    return out


def _processes(model, tex, acc, texture_id: str, gestures, out: Path, count: int, processes: int) -> dict:
    """The same frames rendered by `darthand render-dataset` over `processes` worker processes (each frame
    single-threaded, written by its worker): steady-state throughput after start-up (dataset/run.RunStats)."""
    from darthand.dataset.api import render_dataset
    from darthand.dataset.options import DatasetOptions

    jobs = [{"index": i, "pose": gestures[i % len(gestures)], "texture": texture_id, "accessory": ACCESSORY,
             "camera": "three_quarter", "lights": LIGHTS} for i in range(count)]
    doc = render_dataset(DatasetOptions(str(model), str(out), jobs=jobs, processes=processes, textures=tex,
                                        accessories=acc, resume=False, progress=False))
    t = doc["timings"]
    return {k: t[k] for k in ("ms_per_image", "cpu_ms_per_image", "frame_ms_median", "startup_s", "frames")}


def run(frames: int = 48) -> dict:
    from darthand.model.poses import list_gestures
    from darthand.render.api import Renderer, open_source
    from darthand.render.trace import default_threads

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        model, tex, acc, texture_id, where = _sources(tmp)
        renderer = Renderer(open_source(model, textures=tex, accessories=acc))
        renderer.texture_id = texture_id
        gestures = list_gestures()
        t0 = time.perf_counter()
        first = renderer.render(gestures[0], texture=texture_id, accessory=ACCESSORY, camera="three_quarter",
                                lights=LIGHTS)
        first_s = time.perf_counter() - t0
        cores = len(os.sched_getaffinity(0))
        workers = _processes(model, tex, acc, texture_id, gestures, tmp / "workers", frames, cores)
        threads = default_threads()
        parallel = _frames(renderer, gestures, tmp / "out", frames // 2, threads)
        single = _frames(renderer, gestures, tmp / "out1", max(4, frames // 4), 1)
        stats = first.stats
        aa_error = _antialiasing_error(renderer, gestures[:8], texture_id)
    rays = single["rays_per_image"]
    return {
        "image": "512x512 RGBA + mask + labels.json, textured hand with a ring, 1 shadowed light + ambient, "
                 "8 sub-samples on edge pixels (shaded once per pixel per triangle), pose changing every frame",
        "inputs": where, "texture": texture_id, "accessory": ACCESSORY, "cores": cores,
        "ms_per_image": workers["ms_per_image"],
        "rays_per_image": rays,
        "rays_per_second": round(rays / workers["ms_per_image"] * 1000),
        "how": f"render-dataset over {cores} worker processes, each rendering whole frames single-threaded and "
               "writing them (steady state after start-up)",
        "processes": {**workers, "processes": cores},
        "one_process_threads": {"threads": threads, **{k: v for k, v in parallel.items() if k != "breakdown_ms"}},
        "one_process_threads_breakdown_ms": parallel["breakdown_ms"],
        "one_thread": {k: v for k, v in single.items() if k != "breakdown_ms"},
        "one_thread_breakdown_ms": single["breakdown_ms"],
        "first_image_s": round(first_s, 3),
        "per_image_counts": {k: int(stats[k]) for k in ("primary_rays", "edge_pixels", "aa_rays", "aa_shaded",
                                                          "shadow_rays")},
        "antialiasing": aa_error,
        "goal_ms": 50,
    }


if __name__ == "__main__":
    import json

    print(json.dumps(run(), indent=2))
