"""Runners: what renders a run's chunks of frames. run.py owns the planning, resume, shard records and progress and
hands chunks to a runner through the Runner interface below, so frame i is the same job, the same digest and the
same bytes whatever renders it.

    local   LocalRunner (dataset/local.py): worker processes on this machine, or this process
    ray     RayRunner (dataset/ray/runner.py): actors over the nodes of a Ray cluster (`--ray`)

A runner is made by make_runner, from the table RUNNERS: a new cluster engine is one module with a Runner class
constructed as Class(specs, settings, sources, processes, threads, **options) plus its line in RUNNERS.
"""

from __future__ import annotations

import importlib
from concurrent.futures import Future
from typing import Protocol, runtime_checkable

from darthand.errors import InputError

# kind -> "module:class", imported when used (Ray's is optional and slow to import)
RUNNERS = {"local": "darthand.dataset.local:LocalRunner", "ray": "darthand.dataset.ray.runner:RayRunner"}


@runtime_checkable
class Runner(Protocol):
    """Renders chunks of frames and writes their files into settings['out_dir'] (dataset/frames.py's layout).

    Constructed as Class(specs, settings, sources=None, processes=None, threads=None, **options): specs {side:
    SourceSpec} the workers open; settings run.py's {out_dir, size, samples, aa_shading, shading}; sources {side:
    opened source} of this process (or None); processes: workers wanted (None: the runner's default); threads: render
    threads per worker (None: the runner's default); options: the engine's own (make_runner's `cluster`)."""

    processes: int
    """Workers rendering at once (processes or actors): run.py keeps about 2 chunks per worker in flight and sizes
    chunks by it."""

    def submit(self, chunk: list) -> Future:
        """Queue a chunk [(job dict, digest str)] (frames in any order, each rendered and written once); the future
        resolves to local.render_chunk's result: {'pid': int or None, 'open_s': s spent opening sources, 'frames':
        [frame summary + 'ms', 'cpu_ms' (ms) and 'end' (s, time.monotonic on this process's clock)], 'steps':
        {step: s}, 'maxrss_mb': MB}, plus 'node' and 'ip' from a cluster (frames finished before a worker was lost
        come without 'end'); or to an InputError 'frame N: cause'."""
        ...

    def stop(self) -> None:
        """Ask every worker to stop after its current frame (Ctrl-C, a failed frame); queued chunks may be dropped."""
        ...

    def close(self) -> None:
        """Let running chunks end, release the workers; the runner is not used after."""
        ...

    def describe(self) -> dict:
        """What dataset.json records of the runner: {'kind': 'local'}, or a cluster's kind, address, nodes..."""
        ...


def make_runner(cluster: dict | None, specs: dict, settings: dict, sources: dict | None, processes: int | None,
                threads: int | None, frames: int) -> Runner:
    """The runner of a run of `frames` frames (the other arguments: Runner's constructor): LocalRunner when cluster
    is None (processes: at most one per frame), else the engine cluster['engine'] (default 'ray') of RUNNERS with the
    rest of `cluster` as its options."""
    options = dict(cluster or {})
    kind = "local" if cluster is None else options.pop("engine", "ray")
    if kind not in RUNNERS:
        raise InputError(f"cluster: {kind!r} is not one of {', '.join(k for k in RUNNERS if k != 'local')}")
    if cluster is None:
        processes = max(1, min(processes or 1, frames))
    module, _, name = RUNNERS[kind].partition(":")
    runner_class = getattr(importlib.import_module(module), name)
    return runner_class(specs, settings, sources, processes, threads, **options)
