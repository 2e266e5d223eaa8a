"""Frames with an object held: where a run's object catalogue is, and the catalogue of a run's jobs.

The catalogue is read only when a frame holds an object (render/objects.ObjectLibrary), so runs without objects
neither need it built nor change.
"""

from __future__ import annotations

from pathlib import Path

from darthand.dataset.jobs import job_objects
from darthand.render.objects import ObjectLibrary

DEFAULT_CATALOG = Path("build") / "objects" / "catalog.json"


def objects_catalog(options) -> str:
    """The object catalogue of a run (dataset/options.DatasetOptions): its objects_catalog, else
    build/objects/catalog.json beside the model's build (a model .npz in build/model/), else in the working folder."""
    if options.objects_catalog:
        return str(options.objects_catalog)
    package = Path(str(options.package))
    if package.suffix == ".npz" and package.parent.name == "model":
        return str(package.resolve().parent.parent / "objects" / "catalog.json")
    return str(DEFAULT_CATALOG)


def jobs_objects(jobs: list[dict], catalog) -> ObjectLibrary | None:
    """The object catalogue `catalog` loaded when any of `jobs` holds an object, else None."""
    return ObjectLibrary.load(catalog) if any(job_objects(job) for job in jobs) else None
