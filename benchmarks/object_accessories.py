"""Worn accessories against the held object (issue 30): over planned object frames of the build's catalogues, every
frame wearing an accessory, how deep each accessory kind passes into the object (the posed accessory's vertices
carried into the object's frame and measured by benchmarks/object_penetration.depth_mm: MeshLab's vertex-to-mesh
distance signed by trimesh's inside test, one mesh per object). The plan leaves the kinds of
dataset/objects.LEFT_OFF off object frames; this measures them worn as planned before that rule (the frames' own
accessory, put back on). DARTHAND_BENCH_OBJECT_FRAMES sets the frames (default 200).

Figures per kind: frames, penetrating (any vertex inside), over_1mm, max_mm, p90_mm, median_mm.
"""

from __future__ import annotations

import os

import numpy as np

from benchmarks.object_dataset import _catalogs
from benchmarks.object_penetration import depth_mm, object_meshes
from benchmarks.render import ROOT


def penetration_mm(mesh, placement, vertices: np.ndarray) -> float:
    """mm the deepest of `vertices` (n, 3, world) lies inside the object's `mesh` (trimesh, object frame) placed at
    `placement` (4, 4): the vertices go into the object's frame, the object mesh stays as built."""
    P = np.asarray(placement, np.float64)
    return depth_mm((np.asarray(vertices, np.float64) - P[:3, 3]) @ P[:3, :3], mesh)[0]


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
    meshes = object_meshes(load_object_catalog(catalog))
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
        depth = penetration_mm(meshes[held["object"]], held["placement"], subject.surfaces[1].vertices)
        depths.setdefault(source.accessory_type(accessory), []).append(depth)
    out: dict = {"frames": frames}
    for kind, values in sorted(depths.items()):
        d = np.asarray(values)
        out[kind] = {"frames": len(d), "penetrating": int((d > 0).sum()), "over_1mm": int((d > 1).sum()),
                     "max_mm": round(float(d.max()), 2), "p90_mm": round(float(np.percentile(d, 90)), 2),
                     "median_mm": round(float(np.median(d)), 2)}
    return out
