"""The dataset stage's entry: `render_dataset(options)` renders a dataset (`darthand render-dataset` is this call
with options from its arguments), `write_plan(options, path)` writes the planned jobs instead (`--plan`).

From options (dataset/options.DatasetOptions) to frames: open each side's source (dataset/sources.py), plan the
frames (dataset/plan.py) or read the jobs, check the layouts asked for, render (dataset/run.py through a runner),
then write the layouts (dataset/writers.py). Worker processes are spawned: a script calling render_dataset needs the
usual `if __name__ == "__main__":` guard.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from darthand.dataset import writers
from darthand.dataset.freihand import check_mano
from darthand.dataset.jobs import job_sides, load_jobs, write_jobs
from darthand.dataset.options import DatasetOptions, bounded_int
from darthand.dataset.object_catalogs import grasps_catalog, objects_catalog
from darthand.dataset.plan import Planner
from darthand.dataset.run import render_frames
from darthand.dataset.sources import SourceSpec, parse_sides, source_specs
from darthand.errors import InputError
from darthand.render import truth


def render_dataset(options: DatasetOptions) -> dict:
    """Render the dataset `options` describe into options.out; returns its dataset.json document."""
    truth.check_kinds(options.maps)                       # an unknown map kind: refused before anything opens
    run = _open(options)
    _check_formats(options, run.sources)
    doc = render_frames(options, run.sources, run.specs, run.planner, run.jobs, run.origin)
    for fmt in options.formats:
        export_format(options.out, fmt, None, left=options.left, allow_non_mano=options.allow_non_mano)
    return doc


def write_plan(options: DatasetOptions, path) -> int:
    """Write the jobs of frames options.start .. start + count - 1 of the plan to `path` (a jobs file, one job per
    line, schemas/dataset_jobs.schema.json); returns how many. Nothing is rendered."""
    if options.jobs is not None:
        raise InputError("--plan: writes planned jobs, so it cannot be given with --jobs")
    run = _open(options)
    assert run.planner is not None                        # no jobs given: the frames are planned
    count = bounded_int(options.count, "count", 0, options.max_frames, "frames", "(--max-frames raises it)")
    return write_jobs(path, run.planner.jobs(options.start, options.start + count),
                      {"package": str(options.package), **run.origin})


def export_format(dataset, fmt: str, out, **options) -> Path:
    """Write a rendered dataset in another layout (dataset/writers.FORMATS; options: the writer's, e.g. the
    FreiHAND writer's left=, allow_non_mano=); returns where."""
    if fmt not in writers.FORMATS:
        raise InputError(f"--format: {fmt!r} is not one of {', '.join(writers.FORMATS)}")
    where = writers.FORMATS[fmt](dataset, out, **options)
    print(f"[dataset] {fmt}: {where}")
    return where


@dataclass(frozen=True)
class _Run:
    """A run's opened inputs: sources {side: opened source}, specs {side: SourceSpec} (what workers open), the
    planner or the jobs (a list of job dicts), and `origin`, what dataset.json records the frames came from."""

    sources: dict
    specs: dict
    planner: Planner | None
    jobs: list | None
    origin: dict


def _open(options: DatasetOptions) -> _Run:
    """Open PACKAGE and its other side's twin for the sides the plan or the jobs ask, and the plan."""
    package = str(options.package)
    first = SourceSpec(package, options.textures, options.accessories, options.model).open()
    jobs = options.jobs
    if jobs is not None:
        if isinstance(jobs, (str, Path)):
            origin = {"file": str(jobs)}
            jobs = load_jobs(jobs)
        else:
            origin = {"given": "list"}
        sides = tuple(dict.fromkeys([first.side] + [side for j in jobs for side in job_sides(j, first.side)]))
    else:
        sides = parse_sides(options.plan.sides)
    specs = source_specs(package, sides, textures=options.textures, accessories=options.accessories,
                         model=options.model, opened=first)
    sources = {side: (first if spec.package == package and not spec.mirror else spec.open())
               for side, spec in specs.items()}
    if jobs is not None:
        return _Run(sources, specs, None, list(jobs), origin)
    planner = Planner({**options.plan.spec(), "sides": list(sides)}, sources,
                      {"objects": objects_catalog(options), "grasps": grasps_catalog(options)})
    return _Run(sources, specs, planner, None, {"plan": planner.spec, "start": options.start, "count": options.count})


def _check_formats(options: DatasetOptions, sources: dict) -> None:
    """The layouts asked for, checked before anything renders: a FreiHAND layout of a hand that is not MANO is
    refused (unless allow_non_mano) now, not after a long run."""
    for fmt in options.formats:
        if fmt not in writers.FORMATS:
            raise InputError(f"--formats: {fmt!r} is not one of {', '.join(writers.FORMATS)}")
    if "freihand" in options.formats:
        check_mano({side: s.describe() for side, s in sources.items()}, "--formats freihand",
                   options.allow_non_mano)
