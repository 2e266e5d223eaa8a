"""Worn accessories against the held object (issue 30): over planned object frames of the build's catalogues, every
frame wearing an accessory, how deep each accessory kind passes into the object (MeshLab's signed distance,
pymeshlab, of the posed accessory's vertices to the object's mesh in its frame). The plan leaves the kinds of
dataset/objects.LEFT_OFF off object frames; this measures them worn as planned before that rule (the frames' own
accessory, put back on). DARTHAND_BENCH_OBJECT_FRAMES sets the frames (default 200).

Figures per kind: frames, penetrating (any vertex inside), over_1mm, max_mm, p90_mm, median_mm.
"""

from __future__ import annotations

import os

import numpy as np

from benchmarks.object_dataset import _catalogs
from benchmarks.render import ROOT


def penetration_mm(item, placement, vertices: np.ndarray) -> float:
    """mm the deepest of `vertices` (n, 3, world) lies inside the object `item` placed at `placement` (4, 4)."""
    import pymeshlab       # MeshLab: the independent distance (the grasp fit uses darthand's own field)

    P = np.asarray(placement, np.float64)
    local = (np.asarray(vertices, np.float64) - P[:3, 3]) @ P[:3, :3]
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(local), "accessory")
    ms.add_mesh(pymeshlab.Mesh(np.asarray(item.vertices, np.float64), np.asarray(item.faces, np.int32)), "object")
    ms.compute_scalar_by_distance_from_another_mesh_per_vertex(measuremesh=0, refmesh=1, signeddist=True,
                                                               maxdist=pymeshlab.PureValue(1.0))
    return 1000 * max(0.0, float(-ms.mesh(0).vertex_scalar_array().min()))      # negative inside


def run() -> dict:
    from darthand.dataset.plan import Planner, PlanOptions
    from darthand.dataset.sources import source_specs
    from darthand.objects.loader import load_object_catalog

    frames = int(os.environ.get("DARTHAND_BENCH_OBJECT_FRAMES", 200))
    build = ROOT / "build"
    catalog, grasps = _catalogs()
    specs = source_specs(str(build / "model" / "right.npz"), ("right", "left"),
                         textures=str(build / "textures" / "catalog.json"), accessories=str(build / "accessories"))
    sources = {side: spec.open() for side, spec in specs.items()}
    planner = Planner({**PlanOptions(objects=1.0, accessory_share=1.0).spec(), "sides": list(sources)}, sources,
                      {"objects": catalog, "grasps": grasps})
    plain = Planner({**PlanOptions(accessory_share=1.0).spec(), "sides": list(sources)}, sources)
    items = {i.id: i for i in load_object_catalog(catalog)}
    depths: dict = {}
    for i in range(frames):
        job = planner.job(i)
        if "bodies" not in job:
            continue
        hand, held = job["bodies"]
        accessory = plain.job(i)["accessory"]           # the frame's own draw (object frames leave some off)
        if accessory == "none":
            continue
        source = sources[hand["side"]]
        subject = source.subject(np.asarray(hand["pose"]), accessory=accessory, betas=hand.get("betas"))
        depth = penetration_mm(items[held["object"]], held["placement"], subject.surfaces[1].vertices)
        depths.setdefault(source.accessory_type(accessory), []).append(depth)
    out: dict = {"frames": frames}
    for kind, values in sorted(depths.items()):
        d = np.asarray(values)
        out[kind] = {"frames": len(d), "penetrating": int((d > 0).sum()), "over_1mm": int((d > 1).sum()),
                     "max_mm": round(float(d.max()), 2), "p90_mm": round(float(np.percentile(d, 90)), 2),
                     "median_mm": round(float(np.median(d)), 2)}
    return out
