"""The grasp catalogue: per object, per grasp type it suits, per approach direction, a grasp fitted to the right
model's mean shape, its mirror image on the left model, dropped fits listed with why.

Approaches: APPROACHES directions around the object's axis (`approach_directions`; the knuckle line laid along
it, so a wrap closes around a bottle, a pinch along a pen, or turned from it by the type's `across_deg`), evenly
spaced, aimed at the object's part named "handle" where it has one (grasps/aims.grip_target). A mug also gets
handle grasps (grasps/aims: aims.HANDLE_TYPES closed round its handle's bar from outside), numbered after its
body's approaches. The left hand's grasp starts from the right one's mirror image: the hand mirrored (x -> -x, the
same anatomical angles) and the object mirrored by the reflection of its own frame that maps it most nearly onto
itself (`object_reflection`). Where the object is mirror-symmetric (to SYMMETRIC) and the left model is the right
one's mirror image, that mirror image is exact and kept (its figures the right one's, marked `mirrored`);
otherwise it is refitted on the left model with the object's field (a few iterations), so an object that is not
mirror-symmetric is still held properly.
"""

from __future__ import annotations

import os
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from darthand.fileio import atomic_path, make_folder, write_json
from darthand.grasps.aims import HANDLE_CONTACTS, HANDLE_TYPES, Aim, grip_target, handle_aim, turned
from darthand.grasps.field import ObjectField
from darthand.grasps.fit import GraspFit, HandRig, fit_grasp, refine
from darthand.grasps.loader import ARRAYS, FORMAT, FORMAT_VERSION
from darthand.grasps.taxonomy import GraspType, load_taxonomy, types_for
from darthand.model.anatomy import angles_to_axis_angle
from darthand.model.forward import forward
from darthand.model.hand_model import HandModel
from darthand.model.mirror import mirror_points
from darthand.model.npz_io import load_npz
from darthand.model.self_crossing import SelfCrossing

APPROACHES = 2
LEFT_ROUNDS, LEFT_NFEV = 2, 6
SYMMETRIC = 1e-5    # m: an object whose reflection maps it onto itself this closely is mirror-symmetric
REFLECTIONS = (np.diag([-1.0, 1, 1]), np.diag([1.0, -1, 1]), np.diag([1.0, 1, -1]))


def approach_directions(size_m, count: int = APPROACHES) -> tuple[np.ndarray, list[np.ndarray]]:
    """(the object's axis (3,), `count` unit approach directions (3,) orthogonal to it), object frame. The axis is
    +z (the catalogue's axis of a bottle, a mug, a pen, a tool) unless z is the object's thinnest extent (a phone,
    a card: z their thin axis), then the longer of x and y."""
    k = 2 if np.argmin(size_m) != 2 else int(np.argmax(np.asarray(size_m)[:2]))
    axis = np.eye(3)[k]
    e1 = np.eye(3)[(k + 1) % 3]
    e2 = np.cross(axis, e1)
    angles = 2 * np.pi * np.arange(count) / count
    return axis, [np.cos(a) * e1 + np.sin(a) * e2 for a in angles]


def object_reflection(field: ObjectField) -> tuple[np.ndarray, float]:
    """((3, 3) the reflection of the object frame (one axis negated) mapping the object most nearly onto itself,
    its error: the largest |distance| (m) of the reflected vertices to the object)."""
    errors = [float(np.abs(field.distance(field.vertices @ S)).max()) for S in REFLECTIONS]
    best = int(np.argmin(errors))
    return REFLECTIONS[best], errors[best]


def mirrored_start(fit: GraspFit, reflection: np.ndarray) -> np.ndarray:
    """(4, 4) the left hand's start, hand model frame -> object frame: the right fit's mirror image."""
    S = np.diag([-1.0, 1, 1, 1])
    R = np.eye(4)
    R[:3, :3] = reflection
    return np.linalg.inv(S @ fit.placement @ R)


class ObjectGrasps:
    """Fits the grasps of one object on both models (rigs built once per process)."""

    def __init__(self, models: dict[str, HandModel], taxonomy: dict[str, GraspType], approaches: int = APPROACHES):
        self.approaches = approaches
        parts = sorted({p for t in taxonomy.values() for p in t.contacts} | set(HANDLE_CONTACTS))
        self.taxonomy = taxonomy
        self.rigs = {side: HandRig.of(m, parts) for side, m in models.items()}
        self.crossing = {side: SelfCrossing(m) for side, m in models.items()}
        self.mirrored_models = "left" in models and mirror_images(models["right"], models["left"])

    def fit_object(self, item) -> tuple[list[dict], list[dict]]:
        """(fitted records, dropped records) of one object; a record holds its GraspFit under 'fit'."""
        field = ObjectField(item.vertices, item.faces, item.id)
        known, unknown = types_for(item, self.taxonomy)
        dropped = [{"object": item.id, "type": n, "side": s, "approach": None, "why": "no such grasp type"}
                   for n in unknown for s in self.rigs]
        fitted: list[dict] = []
        axis, approaches = approach_directions(getattr(item, "size_m", np.ptp(item.vertices, axis=0)),
                                                 self.approaches)
        reflection, error = object_reflection(field)
        symmetric = self.mirrored_models and error < SYMMETRIC
        grip = grip_target(item)
        plans = [(self.taxonomy[n], k, Aim(grip, a, turned(axis, a, self.taxonomy[n].across_deg)))
                 for n in known for k, a in enumerate(approaches)]
        handle = handle_aim(item.vertices, getattr(item, "category", ""))
        if handle is not None:
            plans += [(self.taxonomy[n], len(approaches), handle) for n in HANDLE_TYPES if n in self.taxonomy]
        for g, k, aim in plans:
            contacts = aim.contacts or g.contacts
            right = fit_grasp(self.rigs["right"], field, contacts, g.angles, aim.approach, aim.across, aim.target)
            why = right.dropped or self.digits_crossing("right", right)
            self.record(item.id, g, k, contacts, "right", right, why, fitted, dropped)
            if "left" in self.rigs:
                left = self.left_fit(field, g, contacts, right, reflection, symmetric)
                if not symmetric:            # an exact mirror image is dropped where its original is
                    why = left.dropped or self.digits_crossing("left", left)
                self.record(item.id, g, k, contacts, "left", left, why, fitted, dropped)
        return fitted, dropped

    def left_fit(self, field: ObjectField, g: GraspType, contacts, right: GraspFit, reflection: np.ndarray,
                 symmetric: bool) -> GraspFit:
        """The left hand's grasp: the right one's mirror image, refitted unless the object and the models are
        mirror images of themselves and of each other (then the mirror image is exact: same figures)."""
        if symmetric:
            placement = np.linalg.inv(mirrored_start(right, reflection))
            pose = angles_to_axis_angle(self.rigs["left"].model, right.angles, self.rigs["left"].frames).ravel()
            return GraspFit(right.angles, pose, placement, right.contact_vertices,
                            right.contact_points @ reflection.T, {**right.figures, "mirrored": True}, right.dropped)
        return refine(self.rigs["left"], field, contacts, g.angles, right.angles, mirrored_start(right, reflection),
                      LEFT_ROUNDS, LEFT_NFEV)

    @staticmethod
    def record(object_id: str, g: GraspType, k: int, contacts, side: str, fit: GraspFit, why: str | None,
               fitted: list, dropped: list) -> None:
        """Add the fit (its contact parts `contacts`) to `fitted`, or to `dropped` with why."""
        head = {"object": object_id, "type": g.name, "side": side, "approach": k}
        if why:
            dropped.append({**head, "why": why})
        else:
            fitted.append({**head, "id": f"{object_id}/{g.name}/{k}", "contact_parts": list(contacts),
                           "figures": fit.figures, "fit": fit})

    def digits_crossing(self, side: str, fit: GraspFit) -> str | None:
        v = forward(self.rigs[side].model, fit.pose[None]).vertices[0]
        pair = self.crossing[side].crossing(np.asarray(v, np.float64))
        return f"digits cross ({pair})" if pair else None


def mirror_images(right: HandModel, left: HandModel) -> bool:
    """Whether the left model is the right one's mirror image (model/mirror: x -> -x, every shape the same)."""
    return (right.num_vertices == left.num_vertices and right.num_betas == left.num_betas
            and np.allclose(mirror_points(right.v_template), left.v_template, atol=1e-7)
            and np.allclose(right.shapedirs * np.array([-1.0, 1, 1])[None, :, None], left.shapedirs, atol=1e-7))


_WORKER: dict = {}


def _fit_in_worker(args) -> tuple[list[dict], list[dict]]:
    model_paths, taxonomy_path, approaches, item = args
    key = (tuple(sorted(model_paths.items())), taxonomy_path, approaches)
    if key not in _WORKER:
        _WORKER.clear()
        models = {s: load_npz(p) for s, p in model_paths.items()}
        _WORKER[key] = ObjectGrasps(models, load_taxonomy(taxonomy_path), approaches)
    return _WORKER[key].fit_object(item)


def build_grasps(items, model_paths: dict[str, str], out, taxonomy_path=None, jobs: int = 1,
                 sheet: bool = True, approaches: int = APPROACHES, timing: dict | None = None) -> dict:
    """Fit every object's grasps on the models of `model_paths` ({'right': npz, 'left': npz}) into `out`
    (catalog.json, grasps.npz, contact sheets), `approaches` per object and type; returns the catalogue
    document. The catalogue holds no times (it is the same on every run); `timing`, when given, receives them:
    'fits' [(object, type, side, seconds)] of the kept grasps and 'build_s'."""
    t0 = time.perf_counter()
    out = make_folder(out)
    taxonomy = None if taxonomy_path is None else str(taxonomy_path)
    work = [(dict(model_paths), taxonomy, approaches, item) for item in items]
    if jobs > 1 and len(work) > 1:
        with ProcessPoolExecutor(max_workers=min(jobs, len(work))) as pool:
            results = list(pool.map(_fit_in_worker, work))
    else:
        results = [_fit_in_worker(w) for w in work]
    fitted = [r for f, _ in results for r in f]
    dropped = [r for _, d in results for r in d]
    if timing is not None:
        timing["fits"] = [(r["object"], r["type"], r["side"], r["figures"].pop("seconds")) for r in fitted]
    for r in fitted:
        r["figures"].pop("seconds", None)
    doc = catalog_document(fitted, dropped, model_paths)
    write_arrays(out / ARRAYS, [r["fit"] for r in fitted])
    if sheet and fitted:
        from darthand.grasps.sheet import contact_sheets   # trimesh's ray casting: only when sheets are drawn
        doc["contact_sheets"] = contact_sheets(items, fitted, model_paths, out)
    write_json(out / "catalog.json", doc)
    if timing is not None:
        timing["build_s"] = time.perf_counter() - t0
    return doc


def catalog_document(fitted: list[dict], dropped: list[dict], model_paths: dict) -> dict:
    """The catalogue's JSON document (grasps without their arrays; `row` indexes grasps.npz)."""
    grasps = [{k: v for k, v in r.items() if k != "fit"} | {"row": i} for i, r in enumerate(fitted)]
    pens = [r["figures"]["penetration_max_mm"] for r in fitted]
    gaps = [abs(v) for r in fitted for v in r["figures"]["contact_mm"].values()]
    return {"format": FORMAT, "format_version": FORMAT_VERSION, "arrays": ARRAYS,
            "models": {s: os.path.basename(str(p)) for s, p in model_paths.items()},
            "counts": {"fitted": len(fitted), "dropped": len(dropped),
                       "objects": len({r["object"] for r in fitted + dropped})},
            "figures": {"penetration_max_mm": max(pens, default=0.0),
                        "penetration_p99_mm": float(np.percentile(pens, 99)) if pens else 0.0,
                        "contact_max_mm": max(gaps, default=0.0),
                        "contact_median_mm": float(np.median(gaps)) if gaps else 0.0},
            "grasps": grasps, "dropped": dropped, "contact_sheets": {}}


def write_arrays(path: Path, fits: list[GraspFit]) -> None:
    """grasps.npz: angles (G, 16, 3), pose (G, 48), placement (G, 4, 4), contact_vertices (G, K) int32 (-1
    padded), contact_points (G, K, 3)."""
    K = max((len(f.contact_vertices) for f in fits), default=0)
    cv = np.full((len(fits), K), -1, np.int32)
    cp = np.zeros((len(fits), K, 3))
    for i, f in enumerate(fits):
        cv[i, :len(f.contact_vertices)] = f.contact_vertices
        cp[i, :len(f.contact_points)] = f.contact_points
    arrays: dict = {"angles": np.array([f.angles for f in fits]).reshape(-1, 16, 3),
              "pose": np.array([f.pose for f in fits]).reshape(-1, 48),
              "placement": np.array([f.placement for f in fits]).reshape(-1, 4, 4),
              "contact_vertices": cv, "contact_points": cp}
    with atomic_path(path) as tmp:
        np.savez_compressed(tmp, **arrays)


