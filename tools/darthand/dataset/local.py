"""The local runner: chunks of frames rendered by worker processes on this machine (or in this process).

A runner (dataset/runner.Runner) turns chunks (lists of (job, digest)) into results (`render_chunk`'s dicts);
dataset/run.py owns the planning, resume, records and progress. render_chunk is also what a Ray actor renders with
(dataset/ray/node.py).

Workers are started with 'spawn' (a fresh interpreter: nothing inherited from a parent that may hold an Embree
device or thread pools); each opens its sources (dataset/sources.SourceSpec) on first use and renders
single-threaded. They ignore Ctrl-C (the parent stops them after their current frame) and exit by themselves when
their parent dies (darthand.processes.init_worker), so a killed run leaves no orphans.
"""

from __future__ import annotations

import multiprocessing
import os
import resource
import time
from concurrent.futures import Future, ProcessPoolExecutor

from darthand.dataset.frames import frame_error, render_job, write_dataset_frame
from darthand.dataset.jobs import job_objects, job_sides
from darthand.dataset.runner import Runner
from darthand.errors import InputError
from darthand.processes import deaf_to_ctrl_c, init_worker
from darthand.render.api import Renderer
from darthand.render.objects import ObjectLibrary

# The worker's state: set by _init_worker (spawned processes) or LocalRunner (in-process); renderers opened on use.
_STATE: dict = {}


def set_worker_state(specs: dict, settings: dict, threads: int | None, stop=None) -> dict:
    """Make this process a worker that render_chunk renders with: {side: SourceSpec} opened on use, run.py's
    settings, render threads, a stop event (or None); returns the state (a spawned worker, the in-process runner and
    a Ray actor, dataset/ray/node.py, each set it)."""
    _STATE.clear()
    _STATE.update(specs=dict(specs), settings=settings, threads=threads, stop=stop, renderers={}, open_s=0.0)
    return _STATE


def _init_worker(specs: dict, settings: dict, threads: int, stop, parent: int) -> None:
    init_worker(parent)        # the parent handles Ctrl-C and stops the workers; they end when it dies
    set_worker_state(specs, settings, threads, stop)


def worker_renderer(side: str):
    """This worker's renderer of a side, its source opened on first use."""
    renderers = _STATE["renderers"]
    if side not in renderers:
        t = time.monotonic()
        renderers[side] = Renderer(_STATE["specs"][side].open(), _STATE["threads"])
        _STATE["open_s"] += time.monotonic() - t
    return renderers[side]


def job_renderer(job: dict, default_side: str):
    """This worker's renderer of a job: its first hand's side's, given the sources of its other hands' sides."""
    sides = job_sides(job, default_side)
    renderer = worker_renderer(sides[0])
    for side in sides[1:]:
        renderer.sources.setdefault(side, worker_renderer(side).source)
    if renderer.objects is None and job_objects(job):
        if "objects" not in _STATE:
            _STATE["objects"] = ObjectLibrary.load(_STATE["settings"]["objects"])
        renderer.objects = _STATE["objects"]
    return renderer


def render_chunk(items: list) -> dict:
    """Render and write one chunk [(job, digest)] with this process's renderers; per frame its summary, ms, cpu_ms,
    end (monotonic), and the chunk's per-step seconds and peak memory."""
    settings, stop = _STATE["settings"], _STATE.get("stop")
    default_side = next(iter(_STATE["specs"]))
    frames: list = []
    steps: dict = {}
    for job, digest in items:
        if stop is not None and stop.is_set():
            break
        t, c = time.monotonic(), time.process_time()
        try:
            renderer = job_renderer(job, default_side)
            frame, background = render_job(renderer, job, settings)
            t_w = time.perf_counter()
            summary = write_dataset_frame(frame, job, digest, settings["out_dir"], renderer.source, background,
                                          renderer.sources)
            frame.timings["write"] = time.perf_counter() - t_w
        except Exception as e:            # a bug or a broken file: one line naming the frame
            raise frame_error(job["index"], e) from None
        for k, v in frame.timings.items():
            steps[k] = steps.get(k, 0.0) + v
        end = time.monotonic()
        frames.append({**summary, "ms": round(1000 * (end - t), 2),
                       "cpu_ms": round(1000 * (time.process_time() - c), 2), "end": end})
    return {"pid": os.getpid(), "open_s": _STATE["open_s"], "frames": frames, "steps": steps,
            "maxrss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)}


class LocalRunner(Runner):
    """Chunks on `processes` spawned workers (default 1: in this process, in order, with `sources`, the opened
    sources, when given); a runner.Runner. threads: render threads per worker (default 1 in spawned workers, all
    cores in this process)."""

    def __init__(self, specs: dict, settings: dict, sources: dict | None = None, processes: int | None = None,
                 threads: int | None = None):
        self.processes = processes = processes or 1
        self._pool = None
        if processes == 1:
            set_worker_state(specs, settings, threads)
            _STATE["renderers"].update({side: Renderer(src, threads, sources) for side, src in (sources or {}).items()})
            return
        ctx = multiprocessing.get_context("spawn")
        self._stop = ctx.Event()
        self._pool = ProcessPoolExecutor(processes, mp_context=ctx, initializer=_init_worker,
                                         initargs=(specs, settings, 1 if threads is None else threads, self._stop,
                                                   os.getpid()))

    def submit(self, chunk: list) -> Future:
        if self._pool is not None:
            with deaf_to_ctrl_c():          # submit may start a worker: Ctrl-C must not reach it while it imports
                return self._pool.submit(render_chunk, chunk)
        future: Future = Future()
        try:
            future.set_result(render_chunk(chunk))
        except InputError as e:
            future.set_exception(e)
        return future

    def stop(self) -> None:
        """Ask the workers to stop after their current frame (Ctrl-C, a failed frame)."""
        if self._pool is not None:
            self._stop.set()

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
        else:
            _STATE.clear()

    def describe(self) -> dict:
        return {"kind": "local"}
