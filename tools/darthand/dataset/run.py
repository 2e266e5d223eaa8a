"""Rendering a dataset: shards of frames planned on demand, resumed, grouped into chunks for a runner
(dataset/runner.py), recorded, summarised in dataset.json.

    OUT/images/, masks/, labels/, meshes/   the frames (dataset/frames.py)
    OUT/maps/<kind>/                        per-pixel truth maps, when asked (options.maps: depth, normals, parts)
    OUT/shards/<first>-<last>.json          one record per finished shard: its digest and its frames' summaries
    OUT/dataset.json                        the run: sources, plan, settings, counts, visibility rates, timings

Shards: consecutive runs of `shard_size` frames, planned when their turn comes (a plan of any length costs no
memory beyond a shard or two in flight). A shard is the unit of resume bookkeeping: a rerun skips a shard whose
record carries the same digest (of its jobs and settings) and whose files exist, without opening its labels;
inside an unfinished shard a frame is skipped when its files exist and its labels carry its job's digest. Frames are
written atomically, so an interrupted run leaves whole frames (and at most temporary files, removed by the next run),
and a resumed run writes the same bytes as an uninterrupted one. A shard is also what a cluster runner hands to a
node (issue 14).

Chunks: a shard's frames to render are grouped by (side, texture), so that a worker decodes a texture once for many
frames (a 2048^2 texture costs 0.1-0.2 s, three to five frames' rendering), split into chunks of at most
`chunk_size` frames sorted by accessory (a change costs 5-17 ms), largest first. At most a few chunks per worker are
in flight; the next shard is planned while the workers finish the last one's chunks.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import time
from pathlib import Path

import numpy as np

from darthand.dataset.frames import existing_frame, frame_names, job_digest
from darthand.dataset.jobs import check_jobs, load_jobs, validate_jobs
from darthand.dataset.object_catalogs import jobs_objects, objects_catalog
from darthand.dataset.options import MAX_SIZE, DatasetOptions, bounded_int
from darthand.dataset.runner import Runner, make_runner
from darthand.errors import InputError
from darthand.fileio import read_json, write_json
from darthand.render import aa, truth
from darthand.dataset.film import film_setting
from darthand.render.api import shading_options
from darthand.render.cycles import check_available, check_samples
from darthand.render.engines import ENGINES
from darthand.render.environment import MAPS_KEPT
from darthand.render.dress import geometry_options

DATASET_FORMAT = "darthand-dataset"
DATASET_VERSION = 2
MAX_CHUNK = 64                    # frames per task: ~3-6 s of work (progress stays live; a stop is seen per frame),
                                  # and a texture's frames in a 16,384-frame shard (~50) fit one task
FOLDERS = ("images", "masks", "labels", "meshes", "shards")


def render_frames(options: DatasetOptions, sources: dict, specs: dict, planner=None, jobs=None,
                  jobs_source: dict | None = None) -> dict:
    """Render a run's frames into options.out (module docstring); returns the dataset.json document.

    The frames: `jobs` (a list of job dicts or a jobs file; default options.jobs) when `planner` is None, else frames
        options.start .. start + count - 1 of `planner` (dataset/plan.Planner). sources: {side: opened source}
        (used to check jobs, and for processes=1); specs: {side: SourceSpec} the workers open. jobs_source: what
        dataset.json records the frames came from (default: the jobs file, or the plan).
    A frame that fails stops the run with an InputError 'frame N: cause'. `dataset.api.render_dataset` opens the
    sources and plans; this is the part below it.
    """
    o = options
    samples, aa_shading, processes, threads = o.samples, o.aa_shading, o.processes, o.threads
    jobs = o.jobs if jobs is None else jobs
    max_frames, cluster = o.max_frames, None if o.cluster is None else o.cluster.runner_options()
    t_start = time.monotonic()
    aa.check_options(samples, aa_shading)
    shading = shading_options(o.shading).to_json()
    geometry = geometry_options(o.geometry).to_json()
    if geometry.get("arm") and any(source.kind != "model" for source in sources.values()):
        del geometry["arm"]          # a USD package's forearm has no rig to extend: its frames keep their cap
    size = bounded_int(o.size, "size", 8, MAX_SIZE, "pixels")
    if cluster is None:
        processes = bounded_int(len(os.sched_getaffinity(0)) if processes is None else processes, "processes", 1,
                                 256)
    workers = None if processes is None else bounded_int(processes, "processes", 1, 100_000)
    threads = None if threads is None else bounded_int(threads, "threads", 1, 256)
    shard_size = bounded_int(o.shard_size, "shard size", 1, 10_000_000)
    if planner is None:
        if isinstance(jobs, (str, Path)):
            jobs_source = jobs_source or {"file": str(jobs)}
            jobs = load_jobs(jobs)
        else:
            jobs = check_jobs(list(jobs or []))
        validate_jobs(sources, jobs, objects=jobs_objects(jobs, objects_catalog(o)))
        total = len(jobs)
        shards = [jobs[k:k + shard_size] for k in range(0, total, shard_size)]
    else:
        count = bounded_int(o.count, "count", 0, max_frames, "frames",
                             "(the frame budget; --max-frames raises it, a frame takes ~80 kB of disk)")
        start = bounded_int(o.start, "start", 0, 10**12 - count)
        total = count
        shards = (planner.jobs(a, min(a + shard_size, start + count)) for a in range(start, start + count, shard_size))
    if total > max_frames:
        raise InputError(f"jobs: {total} frames are over the frame budget of {max_frames} (--max-frames raises it)")
    maps = truth.check_kinds(o.maps)
    engine = engine_settings(o.engine, o.cycles_samples)
    out = Path(o.out)
    _prepare_folders(out, maps)
    settings = {"out_dir": str(out), "size": size, "samples": int(samples), "aa_shading": aa_shading,
                "shading": shading, "maps": maps, "film": film_setting(o.film),
                **({"engine": engine} if engine else {}), **({"geometry": geometry} if geometry else {}),
                "objects": objects_catalog(o)}
    stats = RunStats(t_start)
    report = _progress_printer(stats) if o.progress is True else (o.progress or None)
    runner = make_runner(cluster, specs, settings, sources, workers, threads, total)
    processes = runner.processes
    try:
        _render_shards(shards, runner, settings, o.resume, processes, o.chunk_size, stats, total, report)
    finally:
        runner.close()
    models = {side: src.describe() for side, src in (sources or {}).items()}
    doc = _write_dataset(out, o.package, jobs_source, planner, total, settings, stats, processes, models,
                         runner.describe())
    return doc


def engine_settings(engine: str, cycles_samples) -> dict | None:
    """The run's engine as its settings carry it: None for the fast renderer, {'name': 'cycles', 'samples': N}
    after checking that Blender's Python imports bpy (one line, before anything renders)."""
    if engine not in ENGINES:
        raise InputError(f"--engine: {engine!r} is not one of {', '.join(ENGINES)}")
    if engine == "darthand":
        return None
    samples = check_samples(cycles_samples)
    check_available()
    return {"name": engine, "samples": samples}


def _render_shards(shards, runner: Runner, settings, resume, processes, chunk_size, stats, total, report) -> None:
    """Feed the shards' chunks to the runner, at most 2 per worker in flight; write each shard's record when its
    last chunk is in."""
    from concurrent.futures import FIRST_COMPLETED, wait

    out = Path(settings["out_dir"])
    inflight: dict = {}                      # future -> shard state
    limit = 2 * processes + 1
    pending_shards: list = []

    def collect(block: bool) -> None:
        finished = wait(list(inflight), timeout=None if block else 0, return_when=FIRST_COMPLETED)[0] \
            if inflight else ()
        for f in finished:
            state = inflight.pop(f)
            result = f.result()
            stats.add_result(result)
            state["summaries"] += [{k: v for k, v in fr.items() if k not in ("ms", "cpu_ms", "end")}
                                   for fr in result["frames"]]
            state["left"] -= 1
        while pending_shards and pending_shards[0]["left"] == 0 and not pending_shards[0]["submitting"]:
            state = pending_shards.pop(0)
            _write_shard_record(out, state)
            stats.add_shard(state)
        if report:
            report(stats.done, total, time.monotonic() - stats.t_start)

    try:
        for shard_jobs in shards:
            state = _open_shard(out, list(shard_jobs), settings, resume)
            stats.skipped += len(state["summaries"])
            stats.done += len(state["summaries"])
            pending_shards.append(state)
            state["submitting"] = True
            for chunk in make_chunks(state["todo"], processes, chunk_size):
                while len(inflight) >= limit:
                    collect(block=True)
                state["left"] += 1
                inflight[runner.submit(chunk)] = state
            state["submitting"] = False
            collect(block=False)
        while inflight or pending_shards:
            collect(block=True)
    except BaseException:
        runner.stop()
        raise


# ------------------------------------------------------------------------------------------------ shards, resume


def shard_digest(digests: list[str]) -> str:
    return hashlib.sha256(" ".join(digests).encode()).hexdigest()[:16]


def shard_record_path(out: Path, jobs: list[dict]) -> Path:
    return out / "shards" / f"{frame_names(jobs[0]['index'])['labels'][7:-5]}-{jobs[-1]['index']}.json"


def _open_shard(out: Path, jobs: list[dict], settings: dict, resume: bool) -> dict:
    """A shard's state: the frames to render (with their digests), the summaries of those already there."""
    digests = [job_digest(j, settings) for j in jobs]
    state: dict
    state = {"jobs": len(jobs), "first": jobs[0]["index"] if jobs else 0, "last": jobs[-1]["index"] if jobs else 0,
             "digest": shard_digest(digests), "summaries": [], "todo": [], "left": 0, "path": None}
    if not jobs:
        return state
    state["path"] = shard_record_path(out, jobs)
    if resume and _shard_done(state, jobs, settings["maps"]):
        state["summaries"] = read_json(state["path"], "shard record")["frames"]
        return state
    for job, digest in zip(jobs, digests):
        summary = existing_frame(out, job, digest, settings["maps"]) if resume else None
        if summary is None:
            state["todo"].append((job, digest))
        else:
            state["summaries"].append(summary)
    return state


def _shard_done(state: dict, jobs: list[dict], maps: tuple = ()) -> bool:
    try:
        record = json.loads(state["path"].read_text())
    except (OSError, ValueError):
        return False
    if record.get("digest") != state["digest"] or len(record.get("frames", [])) != len(jobs):
        return False
    out = state["path"].parent.parent
    return all((out / name).is_file() for job in jobs for name in frame_names(job["index"], maps).values())


def _write_shard_record(out: Path, state: dict) -> None:
    if state["path"] is None:
        return
    frames = sorted(state["summaries"], key=lambda s: s["index"])
    write_json(state["path"], {"first": state["first"], "last": state["last"], "digest": state["digest"],
                               "frames": frames}, indent=None)


def read_shard_records(out) -> list[dict]:
    """Every frame summary of a dataset's shard records, in index order (shards sorted by first index)."""
    records = sorted(Path(out, "shards").glob("*.json"), key=lambda p: int(p.name.split("-")[0]))
    frames = []
    for path in records:
        frames += read_json(path, "shard record")["frames"]
    return frames


def rendered_dataset(folder, splits: tuple | None = None) -> tuple[dict, list[dict]]:
    """(dataset.json, its frame summaries in index order, only those of `splits` when given) of a rendered dataset
    folder; InputError naming the folder when it holds no such frame."""
    root = Path(folder)
    doc = read_json(root / "dataset.json", "dataset.json")
    frames = [f for f in read_shard_records(root) if splits is None or f["split"] in splits]
    if not frames:
        within = "" if splits is None else f" in {', '.join(splits)}"
        raise InputError(f"{root}: no rendered frames{within} (shards/*.json)")
    return doc, frames


def _prepare_folders(out: Path, maps: tuple = ()) -> None:
    """Make the output folders (maps/<kind> of the truth maps asked for too); remove temporary files an interrupted
    run left (fileio.atomic_path's '.name.*')."""
    try:
        for name in FOLDERS + tuple(f"maps/{kind}" for kind in maps):
            folder = out / name
            folder.mkdir(parents=True, exist_ok=True)
            for entry in os.scandir(folder):
                if entry.name.startswith(".") and entry.name.count(".") >= 2 and entry.is_file():
                    os.unlink(entry.path)
    except OSError as e:
        raise InputError(f"{out}: cannot write the dataset there ({e.strerror})") from None


def make_chunks(items: list, processes: int, chunk_size: int | None = None) -> list[list]:
    """Items [(job, digest)] in tasks for the workers: grouped by what a worker loads before it can render a frame
    (`load_key`: its texture, or its environment map when the items draw from more maps than a worker keeps), each
    group split into chunks of at most `chunk_size` frames (default: a quarter of an even share per process, at most
    MAX_CHUNK), sorted by texture, side and accessory inside; largest chunks first."""
    if not items:
        return []
    size = chunk_size or min(MAX_CHUNK, max(1, math.ceil(len(items) / (4 * processes))))
    by_map = len({job_map(job) for job, _ in items}) > MAPS_KEPT
    groups: dict = {}
    for item in items:
        groups.setdefault(load_key(item[0], by_map), []).append(item)
    chunks = []
    for key in sorted(groups):
        group = sorted(groups[key], key=lambda it: (job_texture(it[0]), str(it[0].get("side")),
                                                    str(it[0].get("accessory")), it[0]["index"]))
        chunks += [group[k:k + size] for k in range(0, len(group), size)]
    return sorted(chunks, key=len, reverse=True)


def load_key(job: dict, by_map: bool) -> str:
    """What a worker loads once for a run of frames: the job's texture (a model's left and right hands read the same
    files; a decode costs about a frame's render), or with `by_map` its environment map (preparing a 2K map costs
    about two frames, and a worker keeps MAPS_KEPT of them: a run over a large folder of maps grouped by texture
    would prepare a map for nearly every frame)."""
    return job_map(job) if by_map else job_texture(job)


def job_texture(job: dict) -> str:
    """The texture of a job's hand (of its first hand for a scene of several)."""
    bodies = job.get("bodies")
    return str(bodies[0].get("texture") if bodies else job.get("texture"))


def job_map(job: dict) -> str:
    """The environment map of a job's lights ('' for a light rig or the default lights)."""
    lights = job.get("lights")
    environment = lights.get("environment") if isinstance(lights, dict) else None
    return str(environment.get("map", "")) if isinstance(environment, dict) else ""


# ------------------------------------------------------------------------------------------------ statistics


class RunStats:
    """Streaming statistics of a run: throughput (monotonic clock times, which the processes share), per-step
    times, worker memory, and the dataset's counts (per shard as shards complete)."""

    def __init__(self, t_start: float):
        self.t_start, self.done, self.skipped, self.rendered = t_start, 0, 0, 0
        self.first_end: dict = {}
        self.last_end: dict = {}
        self.open_s: dict = {}
        self.rss: dict = {}
        self.frame_ms: list = []
        self.cpu_ms: list = []
        self.ends: list = []
        self.steps: dict = {}
        self.counts: dict = {}
        self.visible = np.zeros(21)
        self.frames_counted = 0
        self.coverage = 0.0
        self.skipped_backgrounds: dict = {}
        self.nodes: dict = {}

    def add_result(self, result: dict) -> None:
        """A chunk's result (local.render_chunk's); frames without 'end' were rendered before a worker was lost
        (dataset/ray) and count without timings; 'node' (dataset/ray) keys the per-node figures."""
        pid = result["pid"]
        if pid is not None:
            self.open_s[pid] = result["open_s"]
            self.rss[pid] = max(self.rss.get(pid, 0), result["maxrss_mb"])
        for k, v in result["steps"].items():
            self.steps[k] = self.steps.get(k, 0.0) + v
        node = self.nodes.setdefault(result["node"], {"ip": result.get("ip"), "frames": 0, "first_end": math.inf,
                                                      "last_end": -math.inf}) if result.get("node") else None
        for f in result["frames"]:
            if "end" not in f:
                continue
            if node is not None:
                node["frames"] += 1
                node["first_end"], node["last_end"] = min(node["first_end"], f["end"]), max(node["last_end"], f["end"])
            self.first_end[pid] = min(self.first_end.get(pid, math.inf), f["end"])
            self.last_end[pid] = max(self.last_end.get(pid, -math.inf), f["end"])
            self.ends.append(f["end"])
            if len(self.frame_ms) < 100_000:                  # enough for medians; bounded memory
                self.frame_ms.append(f["ms"])
                self.cpu_ms.append((f["end"], f["cpu_ms"]))
        self.rendered += len(result["frames"])
        self.done += len(result["frames"])
        if len(self.ends) > 200_000:
            self.ends = sorted(self.ends)[-100_000:]

    def add_shard(self, state: dict) -> None:
        for s in state["summaries"]:
            for key in ("side", "split", "tone", "category", "accessory_type"):
                table = self.counts.setdefault(key, {})
                table[str(s.get(key))] = table.get(str(s.get(key)), 0) + 1
            self.visible += np.asarray(s["visible"], float)
            self.coverage += s["coverage"]
            self.frames_counted += 1
            for name in s.get("skipped_backgrounds") or ():
                self.skipped_backgrounds[name] = self.skipped_backgrounds.get(name, 0) + 1

    def timings(self, processes: int) -> dict:
        """startup_s: from the call until every worker had finished its first frame (spawning, imports, opening
        the sources, first texture); ms_per_image: steady-state wall time per frame finished after that
        (1000 / images_per_second); overall_images_per_second: all frames over the whole wall time; cpu_ms_per_image:
        CPU time of the rendering processes per frame after start-up; frame_ms_median: one frame's render + write
        in its worker; steps_ms: mean per frame of each step (pose includes texture loading); tail_idle_s: how long
        the first worker to finish waited for the last; worker_peak_rss_mb: each worker's peak resident memory."""
        t_end = time.monotonic()
        n = self.rendered
        out: dict = {"processes": processes, "wall_s": round(t_end - self.t_start, 3), "frames": n}
        if not n or not self.first_end:
            return out
        warm = max(self.first_end.values())
        after = sum(1 for e in self.ends if e > warm)
        last = max(self.last_end.values())
        steady = 1000 * (last - warm) / after if after else 1000 * (t_end - self.t_start) / n
        steady_cpu = [c for e, c in self.cpu_ms if e > warm] or [c for _, c in self.cpu_ms]
        out.update({
            "startup_s": round(warm - self.t_start, 3),
            "open_s": round(max(self.open_s.values()), 3),
            "ms_per_image": round(steady, 2),
            "images_per_second": round(1000 / steady, 2),
            "overall_images_per_second": round(n / (t_end - self.t_start), 2),
            "cpu_ms_per_image": round(float(np.mean(steady_cpu)), 2),
            "frame_ms_median": round(float(np.median(self.frame_ms)), 2),
            "steps_ms": {k: round(1000 * v / n, 2) for k, v in sorted(self.steps.items())},
            "tail_idle_s": round(last - min(self.last_end.values()), 3),
            "worker_peak_rss_mb": sorted(self.rss.values()),
        })
        if self.nodes:
            out["nodes"] = self.node_rates()
        return out

    def node_rates(self) -> dict:
        """{node: {ip, frames, images_per_second}}: each node's frames over the time between its first and last
        (so start-up is left out, as in images_per_second)."""
        rates = {}
        for key, n in sorted(self.nodes.items()):
            span = n["last_end"] - n["first_end"]
            rates[key] = {"ip": n["ip"], "frames": n["frames"],
                          "images_per_second": round((n["frames"] - 1) / span, 2) if span > 0 else None}
        return rates

    def summary(self) -> dict:
        n = max(1, self.frames_counted)
        return {"frames": self.frames_counted, "counts": {k: dict(sorted(v.items())) for k, v in self.counts.items()},
                "visibility_rate": [round(float(x) / n, 4) for x in self.visible],
                "mean_coverage": round(self.coverage / n, 5),
                "skipped_backgrounds": {"count": sum(self.skipped_backgrounds.values()),
                                        "files": sorted(self.skipped_backgrounds)[:100]}}


def _progress_printer(stats: RunStats | None = None, every_s: float = 5.0):
    """A progress callback: frames done, images/s, ETA, at most every `every_s` seconds and at the end; with
    several nodes (dataset/ray), each node's frames and images/s."""
    last = [-math.inf]

    def report(done: int, total: int, seconds: float) -> None:
        if done == total or seconds - last[0] >= every_s:
            last[0] = seconds
            rate = done / seconds if seconds > 0 else 0.0
            eta = f", ETA {(total - done) / rate:.0f} s" if rate and done < total else ""
            nodes = ""
            if stats is not None and stats.nodes:
                nodes = "; " + ", ".join(f"node {key}@{n['ip']} {n['frames']}"
                                         + (f" ({n['images_per_second']:.1f}/s)" if n["images_per_second"] else "")
                                         for key, n in stats.node_rates().items())
            print(f"[render-dataset] {done}/{total} frames, {seconds:.1f} s, {rate:.1f} images/s{eta}{nodes}",
                  flush=True)
    return report


def _write_dataset(out: Path, package, jobs_source, planner, total, settings, stats: RunStats, processes,
                   models, runner: dict) -> dict:
    """dataset.json: the run's inputs, counts and timings (no per-frame list: those are in the shard records)."""
    doc = {"format": DATASET_FORMAT, "version": DATASET_VERSION, "package": str(package),
           "jobs": jobs_source or ({"plan": planner.spec} if planner is not None else {"given": "list"}),
           "plan": planner.describe() if planner is not None else None,
           "count": total, "size": settings["size"], "samples": settings["samples"],
           "aa_shading": settings["aa_shading"], "shading": settings["shading"],
           "files": {kind: name.replace("000000", "<index>")
                     for kind, name in frame_names(0, settings["maps"]).items()},
           "models": models, "rendered": stats.rendered, "skipped": stats.skipped,
           "summary": stats.summary(), "timings": stats.timings(processes), "runner": runner}
    if settings.get("engine"):             # likewise: the fast renderer's dataset.json is unchanged
        doc["engine"] = settings["engine"]
    if settings.get("film") is not None:   # only when asked, as the maps
        doc["film"] = settings["film"]
    if settings.get("geometry"):           # likewise: a run with the geometry options off keeps its dataset.json
        doc["geometry"] = settings["geometry"]
    if settings["maps"]:                   # only when asked: a dataset without maps keeps its dataset.json
        doc["maps"] = truth.describe(settings["maps"], {kind: doc["files"][kind] for kind in settings["maps"]})
    write_json(out / "dataset.json", doc)
    return doc
