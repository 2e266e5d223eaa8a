"""Where a run's object and grasp catalogues are, and the object catalogue a run's jobs need (read only when a job
holds an object: runs without objects neither need the catalogues built nor change)."""

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


def grasps_catalog(options) -> str:
    """The grasp catalogue of a run: its grasps_catalog, else build/grasps/catalog.json beside the object
    catalogue's build folder."""
    if options.grasps_catalog:
        return str(options.grasps_catalog)
    return str(Path(objects_catalog(options)).parent.parent / "grasps" / "catalog.json")
