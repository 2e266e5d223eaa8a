"""Ray runner benchmark: one plan rendered by local worker processes (one per core) and through Ray on a two-node
cluster on this machine (a head and a worker node as separate `ray start` processes, one CPU each: the same two
cores), in one run. Headline: images/s of each and their ratio (goal >= 0.9: the engine costs almost nothing).

The runs alternate local, Ray, Ray, local (ABBA, so a load that drifts during the benchmark weighs on both alike),
each rendering the plan from scratch into a fresh folder; images_per_second is each run's steady state after its
workers started (dataset/run.RunStats), overall_images_per_second includes start-up (for Ray: connecting,
starting the actors, opening the package on each). One more Ray run with files='ship' measures the no-shared-
filesystem path: inputs through the object store, every frame returned to the driver and written there.
On a loaded machine images/s measure the share of the CPU each run got as much as the engine; ratio_cpu (local over
Ray, of cpu_ms_per_image_all: the CPU time of every process of a run per frame, driver, workers, raylets, GCS) is
what the engine costs in CPU, which the load does not change.

Also measured, for the README's scaling note: per frame (ms of one core, kB on disk), per texture (decoding one of
the catalogue's textures, the first time a worker meets it), per shard (planning and digesting its 8,192 jobs on
the driver, which bounds how many frames/s one driver can feed), per shipped MB.

DARTHAND_BENCH_RAY_FRAMES (default 1000) and DARTHAND_BENCH_RAY_ROUNDS (default 2: ABBA) change the size.
"""

from __future__ import annotations

import os
import tempfile
import threading
import time
from pathlib import Path

GOAL_RATIO = 0.9
SIZE = 512


def run(frames: int | None = None) -> dict:
    import importlib.util

    from benchmarks.render_dataset import dataset_inputs
    from testkit.ray_cluster import LocalRayCluster

    if importlib.util.find_spec("ray") is None:
        return {"skipped": "Ray is not installed (pip install '.[cluster]'; make installs it)"}

    frames = int(os.environ.get("DARTHAND_BENCH_RAY_FRAMES", frames or 1000))
    rounds = int(os.environ.get("DARTHAND_BENCH_RAY_ROUNDS", 2))
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        model, textures, accessories, where = dataset_inputs(tmp)
        plan = {"seed": 0}
        t0 = time.perf_counter()
        with LocalRayCluster(nodes=2, cpus=1) as cluster, cluster.driver():
            cluster_start = time.perf_counter() - t0
            order = ["local", "ray", "ray", "local"] * (rounds // 2) + (["local", "ray"] if rounds % 2 else [])
            runs: dict = {"local": [], "ray": []}
            for k, kind in enumerate(order):
                runs[kind].append(_render(model, textures, accessories, plan, frames, tmp / f"{kind}{k}",
                                          None if kind == "local" else {"address": cluster.address}, cluster))
            ship = _render(model, textures, accessories, plan, frames, tmp / "ship",
                           {"address": cluster.address, "files": "ship"}, cluster)
        costs = _unit_costs(model, textures, accessories, plan, tmp)
    local, ray = _mean(runs["local"]), _mean(runs["ray"])
    return {
        "ratio_ray_to_local": round(ray["images_per_second"] / local["images_per_second"], 3),
        "goal_ratio": GOAL_RATIO,
        "local_images_per_second": local["images_per_second"], "ray_images_per_second": ray["images_per_second"],
        "ratio_overall": round(ray["overall_images_per_second"] / local["overall_images_per_second"], 3),
        "ratio_cpu": round(local["cpu_ms_per_image_all"] / ray["cpu_ms_per_image_all"], 3),
        "local": local, "ray": ray, "ray_ship": ship,
        "runs": {kind: [r["images_per_second"] for r in rs] for kind, rs in runs.items()},
        "cluster_start_s": round(cluster_start, 1), "frames": frames, "size": SIZE, "inputs": where,
        "unit_costs": costs,
        "what": "the same plan (DART poses, all catalogue textures, 25 % accessories, both hands, random lights, "
                "built-in backgrounds, 512^2, labels and meshes): local worker processes, one per core, against "
                "Ray on a local two-node cluster (head + worker node, 1 CPU each, separate processes); ABBA order",
        "machine_load_1min": round(os.getloadavg()[0], 1),
    }


def summary(res: dict) -> str:
    """The markdown section of `make bench`'s README: the headline (images/s of each and their ratio, the CPU
    ratio), then each run's figures and the unit costs."""
    if "skipped" in res:
        return f"Skipped: {res['skipped']}"
    local, ray, ship, u = res["local"], res["ray"], res["ray_ship"], res["unit_costs"]
    lines = [f"**Ray / local images/s: {res['ratio_ray_to_local']:.2f} ({res['ray_images_per_second']:.2f} against "
             f"{res['local_images_per_second']:.2f}; goal >= {res['goal_ratio']}); CPU of every process per frame, "
             f"local / Ray: {res['ratio_cpu']:.2f} ({local['cpu_ms_per_image_all']:.0f} against "
             f"{ray['cpu_ms_per_image_all']:.0f} ms).** {res['frames']} frames of {res['size']}², machine load "
             f"{res['machine_load_1min']} at the end (images/s on a loaded machine measure the CPU share each run "
             "got).",
             "", "| run | images/s | with start-up | start-up s | CPU ms/frame (workers) | CPU ms/frame (all) |",
             "|---|---|---|---|---|---|"]
    for name, r in (("local processes", local), ("Ray, files auto", ray), ("Ray, files ship", ship)):
        lines.append(f"| {name} | {r['images_per_second']} | {r['overall_images_per_second']} | {r['startup_s']} | "
                     f"{r['cpu_ms_per_image']} | {r['cpu_ms_per_image_all']} |")
    lines += ["", f"Runs (ABBA): local {res['runs']['local']}, Ray {res['runs']['ray']} images/s; "
              f"{ship['shipped_mb']} MB shipped with files=ship; {local['kb_per_frame']} kB per frame on disk; "
              f"a shard of {u['shard_frames']} jobs planned and digested in {u['shard_plan_ms'] / 1000:.1f} s "
              f"({u['driver_plan_frames_per_second']} frames/s per driver); a {u['texture_resolution']}² texture "
              f"decoded in {u['texture_decode_ms']} ms."]
    return "\n".join(lines)


def _render(model, textures, accessories, plan, frames, out, cluster, nodes) -> dict:
    """One run; its timings, and cpu_ms_per_image_all: the CPU time of every process of the run (this driver, and
    the local workers or the Ray nodes' processes: raylets, GCS, actors) per frame, which a shared machine's load
    does not change."""
    from darthand.dataset.api import render_dataset
    from darthand.dataset.options import ClusterOptions, DatasetOptions
    from darthand.dataset.plan import PlanOptions

    from benchmarks.render_dataset import progress_printer

    label = "local" if cluster is None else f"ray ({cluster.get('files', 'auto')})"
    progress = progress_printer(f"render_dataset_ray {label}:")

    with CpuMeter(nodes if cluster is not None else None) as cpu:
        doc = render_dataset(DatasetOptions(
            str(model), str(out), count=frames, plan=PlanOptions(**plan), textures=str(textures),
            accessories=str(accessories), resume=False, progress=progress, size=SIZE,
            cluster=None if cluster is None else ClusterOptions(**cluster)))
    t = doc["timings"]
    disk = sum(p.stat().st_size for p in out.rglob("*") if p.is_file())
    result = {k: t.get(k) for k in ("images_per_second", "overall_images_per_second", "startup_s", "wall_s",
                                    "cpu_ms_per_image", "processes")}
    result["kb_per_frame"] = round(disk / max(1, frames) / 1024, 1)
    result["cpu_ms_per_image_all"] = round(1000 * cpu.seconds / max(1, frames), 1)
    if cluster is not None:
        result["nodes"] = t.get("nodes")
        result["shipped_mb"] = doc["runner"]["shipped"]["mb"]
    return result


def _mean(runs: list[dict]) -> dict:
    keys = ("images_per_second", "overall_images_per_second", "startup_s", "wall_s", "cpu_ms_per_image",
            "cpu_ms_per_image_all", "kb_per_frame")
    return {k: round(sum(r[k] for r in runs) / len(runs), 2) for k in keys} | {"processes": runs[0]["processes"]}


class CpuMeter:
    """CPU seconds of a run's processes: this one and its reaped children (the local workers: os.times), and with a
    cluster every process of its nodes' trees (raylets, GCS, agents, actors), sampled from /proc every SAMPLE_S
    while the run lasts, since the actors are gone (killed, their time not added to a parent) when it ends."""

    SAMPLE_S = 0.2

    def __init__(self, cluster):
        self.cluster, self.seconds, self._seen = cluster, 0.0, {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._sample_loop, daemon=True)

    def __enter__(self) -> "CpuMeter":
        self._start = self._own()
        if self.cluster is not None:
            self._sample()
            self._before = dict(self._seen)
            self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.seconds = self._own() - self._start
        if self.cluster is not None:
            self._stop.set()
            self._thread.join()
            self.seconds += sum(v - self._before.get(pid, 0.0) for pid, v in self._seen.items())

    @staticmethod
    def _own() -> float:
        t = os.times()
        return t.user + t.system + t.children_user + t.children_system

    def _sample_loop(self) -> None:
        while not self._stop.wait(self.SAMPLE_S):
            self._sample()

    def _sample(self) -> None:
        from testkit.ray_cluster import process_tree

        tick = os.sysconf("SC_CLK_TCK")
        for proc in self.cluster.procs:
            for pid in process_tree(proc.pid) if proc is not None else ():
                try:
                    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
                except OSError:
                    continue
                # utime + stime only: a reaped child's time also lands in its parent's cutime (an actor killed
                # and reaped by its raylet), and every process of the trees is sampled on its own
                cpu = sum(int(f) for f in fields[11:13]) / tick
                self._seen[pid] = max(self._seen.get(pid, 0.0), cpu)


def _unit_costs(model, textures, accessories, plan, tmp: Path) -> dict:
    """ms to plan and digest a shard (DEFAULT_SHARD_SIZE jobs) on the driver; ms to decode a catalogue texture the
    first time (the albedo and roughness of three textures, no cache); MB of a texture's files."""
    from darthand.dataset.frames import job_digest
    from darthand.dataset.plan import Planner, plan_spec
    from darthand.dataset.options import DEFAULT_SAMPLES, DEFAULT_SHARD_SIZE
    from darthand.render.api import open_source
    from darthand.render.texture import load_maps

    source = open_source(str(model), textures=str(textures), accessories=str(accessories))
    planner = Planner({**plan_spec(**plan), "sides": ["right"]}, {"right": source})
    settings = {"size": SIZE, "samples": DEFAULT_SAMPLES, "aa_shading": "triangle"}
    t = time.perf_counter()
    digests = [job_digest(job, settings) for job in planner.jobs(10_000, 10_000 + DEFAULT_SHARD_SIZE)]
    shard_ms = 1000 * (time.perf_counter() - t)
    sets = list(source.textures.values())[-3:]
    copies = [(_copy(s.albedo, tmp), s.roughness and _copy(s.roughness, tmp)) for s in sets]
    t = time.perf_counter()
    for albedo, rough in copies:                   # fresh paths: the texture cache (by path and time) misses
        load_maps(albedo, data=rough, channels=(0,))
    texture_ms = 1000 * (time.perf_counter() - t) / max(1, len(sets))
    texture_mb = sum(p.stat().st_size for s in sets for p in (s.albedo, s.roughness) if p) / max(1, len(sets)) / 2**20
    return {"shard_plan_ms": round(shard_ms, 1), "shard_frames": len(digests),
            "driver_plan_frames_per_second": round(len(digests) / (shard_ms / 1000)),
            "texture_decode_ms": round(texture_ms, 1), "texture_files_mb": round(texture_mb, 2),
            "texture_resolution": _resolution(sets[0].albedo) if sets else None}


def _copy(path: Path, tmp: Path) -> str:
    """A copy of a file under a new name."""
    import shutil

    dst = tmp / "cold" / f"{time.perf_counter_ns()}{Path(path).suffix}"
    dst.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(path, dst)
    return str(dst)


def _resolution(path: Path) -> int | None:
    import OpenImageIO as oiio

    spec = oiio.ImageInput.open(str(path))
    if spec is None:
        return None
    try:
        return int(spec.spec().width)
    finally:
        spec.close()


if __name__ == "__main__":
    import json

    print(json.dumps(run(), indent=2))
