"""Everything a dataset run takes, with its defaults: what `darthand render-dataset` fills from its arguments and a
Python user builds directly, both then calling `dataset.api.render_dataset(options)`.

    from darthand.dataset.api import render_dataset
    from darthand.dataset.options import DatasetOptions
    from darthand.dataset.plan import PlanOptions
from darthand.errors import InputError

    if __name__ == "__main__":                # worker processes are spawned
        render_dataset(DatasetOptions("build/model/right.npz", "out", count=1000, plan=PlanOptions(seed=1)))

The plan's options and defaults are the plan's (plan.PlanOptions); the render and run defaults are defined here.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from darthand.dataset.plan import PlanOptions
from darthand.errors import InputError
from darthand.render.engines import DEFAULT_CYCLES_SAMPLES, DEFAULT_ENGINE

# 16,384 frames: a shard's chunks load each catalogue texture about once (325 textures of 2048^2, ~0.1 s of CPU
# each), so the larger the shard the fewer loads per frame. Simulated over the benchmark's plan (32,768 frames, two
# workers, the 512 MB texture cache): 8,192-frame shards and 32-frame tasks load 1,405 textures (4.7 ms of CPU a
# frame), 16,384 and 64 load 661 (2.2 ms). A shard's plan in memory is ~6 kB a job (~100 MB at 16,384); frames
# inside an unfinished shard still resume one by one.
DEFAULT_SHARD_SIZE = 16384
# Dataset render settings, chosen from benchmarks/dataset_settings.py (CPU per 512^2 frame against error, 24 frames
# of the default plan, against 16 sub-samples shaded each and 64 indirect rays; quiet machine): 4 edge sub-samples
# instead of the renderer's 8 save 7.2 of 56.6 ms a frame for +0.05 sRGB codes of mean error (0.62 -> 0.67); 8
# indirect rays instead of 16 would save 1.6 ms more for +0.18 codes (0.67 -> 0.85), so the shading defaults stay.
DEFAULT_SAMPLES = 4
# What a dataset draws beyond the renderer's defaults, for frames that look like photographs (issue 28; measured in
# benchmarks/realism.py and render_dataset.py): the forearm going on out of the frame (a model source; 0.3 m,
# render/arm.ARM_ON_M). The lights and backgrounds are the plan's (an environment map per frame, seen behind the
# hand). The skin keeps the renderer's single lobe without relief: on the 124 frames MediaPipe compares with
# Cycles on (realism benchmark), the two lobes, sheen and relief took its detection rate from 79 to 72 % (relief
# alone 79 -> 76 %) for 16 ms more CPU a frame, so they stay options (--skin-specular dual, --skin-detail X). A
# random camera per frame (film 'random') stays an option too: 79 -> 59 %, 48 ms a frame. The lights' shadow rays
# are traced from the vertices of the faces seen, per sample only where a face's corners disagree (shade.py's
# 'vertex' shadows): 20 ms a frame less, 0.07 % of (sample, light) pairs differ (benchmarks/render_shadows.py).
PHOTO_SHADING: dict = {"shadows": "vertex"}
PHOTO_GEOMETRY = {"subdivision": 0, "arm": 0.3}
DEFAULT_SIZE = 512
DEFAULT_COUNT = 100
DEFAULT_MAX_FRAMES = 1_000_000    # a budget: more needs max_frames= (--max-frames)
MAX_SIZE = 4096


@dataclass
class ClusterOptions:
    """Rendering on a cluster (dataset/runner.py): engine 'ray'; address: the head's HOST:PORT, 'auto' or None
    (RAY_ADDRESS, else a cluster on this machine, else a new local one); files: how inputs and frames move ('auto',
    'shared', 'ship', dataset/ray/shipping.py)."""

    address: str | None = None
    files: str = "auto"
    engine: str = "ray"

    def runner_options(self) -> dict:
        """What runner.make_runner takes as `cluster` (the engine's options; 'ray' is its default engine)."""
        return {"address": self.address, "files": self.files, **({} if self.engine == "ray" else
                                                                  {"engine": self.engine})}


@dataclass
class DatasetOptions:
    """One dataset run.

    package: a USD package folder or .usda, a model (.npz, .pkl, 'open', 'right'/'left': build/model/<side>.npz);
        textures, accessories: catalogue files or folders (default: the build's beside the model); model: a USD
        package's model, for its fingertip ids. objects_catalog: the object catalogue held objects come from
        (catalog.json or its folder; None: build/objects/catalog.json beside the model's build), read only when a
        frame holds an object; grasps_catalog: the grasp catalogue a plan's object frames draw from (None:
        build/grasps/catalog.json beside the object catalogue's build).
    out: the output folder (dataset/run.py's layout).
    The frames: `jobs` (a jobs file or a list of job dicts, schemas/dataset_jobs.schema.json), else frames
        start .. start + count - 1 of `plan`.
    size: square image size (pixels); samples, aa_shading: edge anti-aliasing (render/aa.py); shading: the
        renderer's shading options (render/shade.ShadingOptions' fields; None: its defaults); film: a camera's
        image per frame (dataset/film.py: 'none', 'random', a FILM.json path or a dict of render/film.Film's
        fields); part of a frame's job digest only when not 'none'; geometry: the drawn surfaces' options
        (render/dress.GeometryOptions' fields: subdivision, arm; None: off), part of a frame's job digest only when
        not the defaults.
    processes: worker processes (None: the cores available; 1 renders in this process), or a cluster's workers;
        threads: render threads per process; cluster: render on a cluster instead (None: this machine).
    resume: skip frames already rendered from the same jobs; shard_size: frames per shard (the unit of planning and
        resume records); chunk_size: frames per task (None: chosen per shard); max_frames: the run's frame budget.
    engine: where the images come from (render/engines.ENGINES: 'darthand' the fast renderer, 'cycles' Blender's
        Cycles through .venv-blender, labels still the fast renderer's); cycles_samples: Cycles' samples per pixel.
        Not ClusterOptions.engine, which picks the runner. Part of a frame's job digest only when not 'darthand'.
    maps: per-pixel truth maps written beside the images (render/truth.KINDS: 'depth', 'normals', 'parts'; maps/
        <kind>/<n>.png); part of a frame's job digest only when not empty.
    formats: layouts also written after rendering (dataset/writers.py); left, allow_non_mano: their options.
    progress: False, True (a line at most every 5 s) or a callable(done, total, seconds).
    """

    package: str
    out: str
    count: int = DEFAULT_COUNT
    start: int = 0
    jobs: str | list | None = None
    plan: PlanOptions = field(default_factory=PlanOptions)
    textures: str | None = None
    accessories: str | None = None
    model: str | None = None
    objects_catalog: str | None = None
    grasps_catalog: str | None = None
    size: int = DEFAULT_SIZE
    samples: int = DEFAULT_SAMPLES
    aa_shading: str = "triangle"
    shading: dict | None = field(default_factory=lambda: dict(PHOTO_SHADING))
    film: str | dict = "none"
    geometry: dict | None = field(default_factory=lambda: dict(PHOTO_GEOMETRY))
    processes: int | None = None
    threads: int | None = None
    cluster: ClusterOptions | None = None
    resume: bool = True
    shard_size: int = DEFAULT_SHARD_SIZE
    chunk_size: int | None = None
    max_frames: int = DEFAULT_MAX_FRAMES
    engine: str = DEFAULT_ENGINE
    cycles_samples: int = DEFAULT_CYCLES_SAMPLES
    maps: tuple = ()
    formats: tuple = ()
    left: str = "mirror"
    allow_non_mano: bool = False
    progress: bool | Callable = True


def bounded_int(value, what: str, lo: int, hi: int, unit: str = "", hint: str = "") -> int:
    """`value` as an int within lo..hi (an integral float or numeric string is taken); InputError naming `what`."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        try:
            ok = float(value).is_integer()
        except (TypeError, ValueError, OverflowError):
            ok = False
        if not ok:
            raise InputError(f"{what}: {value!r} is not an integer")
        value = int(float(value))
    if not lo <= value <= hi:
        raise InputError(f"{what}: {value} {unit + ' ' if unit else ''}is outside {lo}..{hi}"
                         + (f" {hint}" if hint else ""))
    return int(value)
