"""Frames with an object held, planned (`ObjectFrames`: which object, which grasp, refitted to the frame's hand; the
catalogues' paths are dataset/object_catalogs.py's).

An object frame is drawn on its own stream: frame i's OBJECT_STREAM uniforms (seed, OBJECT_STREAM, i) decide whether
it holds an object (uniform 0 under the plan's `objects` share), which object (uniform 1, uniform over the
catalogue's objects of the categories asked that have a grasp for the frame's side) and which of its grasps
(uniform 2). A refit that fails the grasp catalogue's bounds (grasps/refit: contacts <= 5 mm) or passes into the object
deeper than a hand-written job may (dataset/jobs.PASS_THROUGH_M, 1 mm: a planned jobs file renders again as jobs)
draws object and grasp again from (seed, RETRY_STREAM, i, attempt); the redraws are counted in the sampling record.
The catalogues are read only when a plan or a job holds an object, so runs without objects neither need them built
nor change.

The hand of an object frame wears its frame's accessory unless that is of a kind in LEFT_OFF (then none; the sampling
record says which kind was left off): a grasp is fitted to the bare hand, and measured over 200 planned object frames
of the default build (every frame an accessory; benchmarks/object_accessories: MeshLab's distance of the accessory's
vertices to the object, signed by trimesh's inside test), rings passed into the object in 6 of 44 frames (5 deeper
than 1 mm, up to 4.9 mm) and gloves in 54 of 56 (median 0.9 mm, their thickness, up to 2.0 mm), while bracelets (65)
and watches (35) never touched it.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np

from darthand.dataset.jobs import PASS_THROUGH_M
from darthand.errors import InputError
from darthand.grasps.loader import Grasp, load_grasp_catalog
from darthand.grasps.refit import object_field, refit_grasp
from darthand.render.objects import ObjectLibrary

OBJECT_STREAM = 10
RETRY_STREAM = 11
OBJECT_UNIFORMS = 3            # object frame or not, the object, the grasp
MAX_REDRAWS = 8
LEFT_OFF = ("ring", "glove")     # accessory kinds an object frame's hand does not wear (they pass into the object)


class ObjectDraw(NamedTuple):
    """An object frame's draw: the hand's pose (48,) on its side's shaped model, the object's id and placement
    (4, 4) object frame -> the hand's model frame, the grasp, the refit's figures and how many draws failed first."""

    pose: np.ndarray
    object_id: str
    category: str
    placement: np.ndarray
    grasp: Grasp
    figures: dict
    redraws: int


class ObjectFrames:
    """The object frames of a plan: which object, which of its grasps for the frame's side, refitted to the frame's
    hand shape (grasps/refit.refit_grasp). objects, grasps: the catalogues' paths; models: {side: HandModel} of
    the plan's sources; categories: the object categories to draw from (None: all)."""

    def __init__(self, objects, grasps, models: dict, categories=None):
        library = ObjectLibrary.load(objects)
        known = sorted({item.category for item in library.items.values()})
        for category in categories or ():
            if category not in known:
                raise InputError(f"object categories: {category!r} is not a category of the catalogue "
                                 f"({', '.join(known)})")
        self.items = {k: v for k, v in library.items.items() if not categories or v.category in categories}
        grasp_file = Path(grasps)
        if not (grasp_file / "catalog.json" if grasp_file.is_dir() else grasp_file).is_file():
            raise InputError(f"{grasp_file}: no grasp catalogue there (build it: `make build/grasps/catalog.json`)")
        self.grasps: dict = {side: {} for side in models}
        for grasp in load_grasp_catalog(grasps, objects=list(self.items)):
            if grasp.side in self.grasps:
                self.grasps[grasp.side].setdefault(grasp.object_id, []).append(grasp)
        for side, by_object in self.grasps.items():
            if not by_object:
                raise InputError(f"objects: the grasp catalogue has no {side} grasp of the objects asked")
        self.models = models
        self._fields: dict = {}

    def holds(self, seed: int, index: int, share: float) -> bool:
        """Whether frame `index` holds an object (object_frame)."""
        return object_frame(seed, index, share)

    def job(self, job: dict, draw: ObjectDraw) -> dict:
        """The frame's object job (object_job)."""
        return object_job(job, draw)

    def describe(self) -> dict:
        return {"objects": len(self.items), "grasps": {side: sum(map(len, g.values())) for side, g in
                                                         self.grasps.items()}}

    def draw(self, seed: int, index: int, side: str, betas) -> ObjectDraw | None:
        """Frame `index`'s object and grasp on `side` refitted to the hand of `betas` (None: the model's shape):
        uniforms 1, 2 of its OBJECT_STREAM draw pick the object and the grasp; a refit out of bounds (module
        docstring) is drawn again from RETRY_STREAM, at most MAX_REDRAWS times (None when all fail)."""
        model = self.models[side] if betas is None else self.models[side].shaped(np.asarray(betas, np.float64))
        by_object = self.grasps[side]
        ids = sorted(by_object)
        for attempt in range(MAX_REDRAWS + 1):
            stream = [seed, OBJECT_STREAM, index] if attempt == 0 else [seed, RETRY_STREAM, index, attempt]
            u = np.random.default_rng(stream).random(OBJECT_UNIFORMS)
            object_id = ids[_choose(u[1], len(ids))]
            grasp = by_object[object_id][_choose(u[2], len(by_object[object_id]))]
            item = self.items[object_id]
            fitted = refit_grasp(model, item, grasp, self.field(item))
            if fitted.ok and fitted.penetration_max_m <= PASS_THROUGH_M:
                return ObjectDraw(np.asarray(fitted.pose, np.float64), object_id, item.category,
                                  np.asarray(fitted.placement, np.float64), grasp,
                                  {"penetration_max_mm": round(1000 * fitted.penetration_max_m, 3),
                                   "penetration_p99_mm": round(1000 * fitted.penetration_p99_m, 3)}, attempt)
        return None

    def field(self, item):
        """The item's distance field (grasps/refit.object_field), built once."""
        if item.id not in self._fields:
            self._fields[item.id] = object_field(item)
        return self._fields[item.id]


def object_frame(seed: int, index: int, share: float) -> bool:
    """Whether frame `index` holds an object: uniform 0 of its OBJECT_STREAM draw under `share`."""
    return bool(share) and np.random.default_rng([seed, OBJECT_STREAM, index]).random(OBJECT_UNIFORMS)[0] < share


def object_job(job: dict, draw: ObjectDraw) -> dict:
    """A one-hand job made the frame's object job: the `bodies` form (the hand at the identity with the grasp's pose,
    the object at its placement) with the grasp record; the sampling record says which object and grasp, and that
    the hand's pose is the grasp's ('pose': {'mode': 'grasp', 'grasp': id}, in place of the pose sampler's draw);
    an accessory of a kind in LEFT_OFF is left off (module docstring)."""
    worn, left_off = worn_accessory(job)
    hand = {"kind": "hand", "side": job["side"], "pose": np.round(draw.pose, 9).tolist(), "texture": job["texture"],
            "skin_tone_offset": job["skin_tone_offset"], "accessory": worn}
    if "betas" in job:
        hand["betas"] = job["betas"]
    held = {"kind": "object", "object": draw.object_id, "placement": np.round(draw.placement, 9).tolist()}
    out = {k: v for k, v in job.items() if k not in ("side", "pose", "texture", "skin_tone_offset", "accessory",
                                                      "betas")}
    out["gesture"] = None
    # The hand's pose is the grasp's: the sampling record says so instead of carrying the pose sampler's unused draw.
    record = {"id": draw.object_id, "category": draw.category, "grasp": draw.grasp.type, "redraws": draw.redraws}
    if left_off:
        record["accessory_left_off"] = left_off
    out["sample"] = {**job["sample"], "pose": {"mode": "grasp", "grasp": draw.grasp.id}, "object": record,
                     **({"accessory": "none"} if left_off else {})}
    return {**out, "bodies": [hand, held], "grasp": {"type": draw.grasp.type, "id": draw.grasp.id,
                                                     "figures": draw.figures}}


def worn_accessory(job: dict) -> tuple[str, str | None]:
    """(the accessory id a hand on an object wears: the job's, or 'none' when its kind is in LEFT_OFF; that kind
    left off, or None)."""
    kind = job["sample"].get("accessory")
    return ("none", kind) if kind in LEFT_OFF else (job["accessory"], None)


def _choose(u: float, n: int) -> int:
    return min(int(u * n), n - 1)
