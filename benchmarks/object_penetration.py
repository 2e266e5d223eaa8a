"""Hand into object, measured by independent mesh tools (MeshLab's vertex-to-mesh distance through pymeshlab, signed by
trimesh's inside test; not darthand's distance field): over EVERY grasp of the built grasp catalogue, and over the
object frames of a sampled dataset as written (meshes/<n>.npy against object_meshes/<n>.npy).

Per grasp: the hand posed by its side's model (build/model/<side>.npz, darthand's forward pass) at the grasp's pose,
the object's closed mesh carried into the hand's model frame by the grasp's placement; the depth of the deepest hand
vertex inside the object (mm, 0 when none is inside) and the distance of each contact vertex to the object's surface.
Per dataset frame: the same depth for every hand of the frame. Figures: max, p99 and counts over the catalogue's drop
rule (2 mm) and the jobs check (1 mm). DARTHAND_BENCH_GRASPS / DARTHAND_BENCH_OBJECTS name other catalogues;
DARTHAND_BENCH_PENETRATION_FRAMES the dataset's size (default 100, 0 skips it).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
import pymeshlab
import trimesh

GRASPS = Path("build/grasps/catalog.json")
OBJECTS = Path("build/objects/catalog.json")
MODELS = Path("build/model")
FRAMES = 100
DROP_MM = 2.0            # the grasp catalogue's drop rule (grasps/fit.MAX_PENETRATION)
JOBS_MM = 1.0            # a jobs file's limit (dataset/jobs.PASS_THROUGH_M)
CONTACT_MM = 5.0         # the catalogue's contact bound (grasps/fit.MAX_CONTACT)


def signed_distances(points: np.ndarray, mesh: trimesh.Trimesh) -> np.ndarray:
    """(P,) signed distance (m, negative inside) of points (P, 3) to the closed `mesh`: MeshLab's vertex-to-mesh
    distance for the magnitude, trimesh's ray-parity `contains` for the sign (MeshLab's own sign, from the nearest
    face's normal, flips for points in a cup's cavity whose nearest point is on the rim's edge)."""
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=np.asarray(points, np.float64), face_matrix=np.zeros((0, 3), np.int32)))
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=np.asarray(mesh.vertices, np.float64),
                               face_matrix=np.asarray(mesh.faces, np.int32)))
    ms.compute_scalar_by_distance_from_another_mesh_per_vertex(measuremesh=0, refmesh=1, signeddist=False,
                                                               maxdist=pymeshlab.PureValue(10.0))
    distance = np.abs(ms.mesh(0).vertex_scalar_array())
    return np.where(mesh.contains(points), -distance, distance)


def depth_mm(points: np.ndarray, mesh: trimesh.Trimesh) -> tuple[float, np.ndarray]:
    """(deepest inside depth in mm, 0 if none; the signed distances in m)."""
    d = signed_distances(points, mesh)
    return max(0.0, -1e3 * float(d.min())), d


def object_meshes(items) -> dict:
    """{id: trimesh.Trimesh} of catalogue items (object frame), built once: its inside test's structures too."""
    return {it.id: trimesh.Trimesh(it.vertices, it.faces, process=False) for it in items}


def catalogue_figures(grasps_path: Path, objects_path: Path, models: Path) -> dict:
    """Every grasp of the catalogue measured by MeshLab: depth and contact distances."""
    from darthand.grasps.loader import load_grasp_catalog
    from darthand.model.forward import forward
    from darthand.model.npz_io import load_npz
    from darthand.objects.loader import load_object_catalog

    meshes = object_meshes(load_object_catalog(objects_path))
    grasps = load_grasp_catalog(grasps_path)
    hands = {side: load_npz(models / f"{side}.npz") for side in sorted({g.side for g in grasps})}
    depths, contacts, worst = [], [], []
    for g in grasps:
        hand = forward(hands[g.side], np.asarray(g.pose, np.float64)[None]).vertices[0]
        P = g.placement                                    # object frame -> the hand's: the hand into the object's
        deepest, d = depth_mm((hand - P[:3, 3]) @ P[:3, :3], meshes[g.object_id])
        depths.append(deepest)
        contacts.extend(np.abs(1e3 * d[g.contact_vertices]).tolist())
        worst.append((deepest, g.id))
    depths_a, contacts_a = np.array(depths), np.array(contacts)
    return {"grasps": len(grasps), "objects": len({g.object_id for g in grasps}),
            "penetration_max_mm": round(float(depths_a.max(initial=0.0)), 3),
            "penetration_p99_mm": round(float(np.percentile(depths_a, 99)), 3) if len(depths_a) else 0.0,
            "penetration_median_mm": round(float(np.median(depths_a)), 3) if len(depths_a) else 0.0,
            f"over_{DROP_MM:g}_mm": int((depths_a > DROP_MM).sum()),
            f"over_{JOBS_MM:g}_mm": int((depths_a > JOBS_MM).sum()),
            "contact_median_mm": round(float(np.median(contacts_a)), 3) if len(contacts_a) else 0.0,
            "contact_p99_mm": round(float(np.percentile(contacts_a, 99)), 3) if len(contacts_a) else 0.0,
            f"contacts_over_{CONTACT_MM:g}_mm": int((contacts_a > CONTACT_MM).sum()),
            "contacts": len(contacts_a),
            "deepest": [gid for _, gid in sorted(worst, reverse=True)[:5]]}


def dataset_figures(frames: int, objects_path: Path, grasps_path: Path, models: Path) -> dict:
    """A planned dataset whose every frame is asked to hold an object, rendered small (64^2); its written hand meshes
    (meshes/<n>.npy, camera frame) carried into the object's frame by the labels' object pose (object frame ->
    camera: R, t), against the object's catalogue mesh (one per object, as for the grasps); a frame is an object
    frame when it wrote its object mesh (object_meshes/<n>.npy)."""
    from darthand.dataset.api import render_dataset
    from darthand.dataset.options import DatasetOptions
    from darthand.dataset.plan import PlanOptions
    from darthand.fileio import read_json
    from darthand.objects.loader import load_object_catalog

    meshes = object_meshes(load_object_catalog(objects_path))
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "ds"
        render_dataset(DatasetOptions(str(models / "right.npz"), str(out), count=frames, size=64, resume=False,
                                      objects_catalog=str(objects_path), grasps_catalog=str(grasps_path),
                                      progress=False, plan=PlanOptions(seed=5, objects=1.0)))
        depths = []
        mesh_files = sorted((out / "object_meshes").glob("*.npy"))
        for mesh_file in mesh_files:
            held = read_json(out / "labels" / f"{mesh_file.stem}.json", "labels")["objects"][0]
            R, t = np.asarray(held["pose"]["R"], np.float64), np.asarray(held["pose"]["t"], np.float64)
            hands = np.load(out / "meshes" / mesh_file.name).astype(np.float64)
            hands = hands[None] if hands.ndim == 2 else hands
            depths += [depth_mm((h - t) @ R, meshes[held["id"]])[0] for h in hands]
    depths_a = np.array(depths)
    return {"frames": frames, "object_frames": len(mesh_files), "hands": len(depths_a),
            "penetration_max_mm": round(float(depths_a.max(initial=0.0)), 3),
            "penetration_p99_mm": round(float(np.percentile(depths_a, 99)), 3) if len(depths_a) else 0.0,
            f"over_{JOBS_MM:g}_mm": int((depths_a > JOBS_MM).sum())}


def run() -> dict:
    grasps = Path(os.environ.get("DARTHAND_BENCH_GRASPS") or GRASPS)
    objects = Path(os.environ.get("DARTHAND_BENCH_OBJECTS") or OBJECTS)
    frames = int(os.environ.get("DARTHAND_BENCH_PENETRATION_FRAMES", FRAMES))
    if not grasps.is_file() or not objects.is_file():
        return {"skipped": f"no catalogues at {grasps} and {objects} (make assets builds them)"}
    out = {"tool": "MeshLab's vertex-to-mesh distance (pymeshlab), signed by trimesh's contains",
           "catalogue": catalogue_figures(grasps, objects, MODELS)}
    if frames:
        out["dataset"] = dataset_figures(frames, objects, grasps, MODELS)
    return out
