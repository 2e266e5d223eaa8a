"""The held objects the studio offers: the object catalogue (build/objects) and the grasp catalogue (build/grasps)
beside the build, or named by `darthand studio --objects-catalog --grasps-catalog`.

The page lists the objects by category with a thumbnail each (objects/preview.object_tile, the contact sheet's
drawing), an object's grasps for the hand's side, and gets an object's mesh as plain arrays (the renderer's drawn
parts: crease-split, object frame, metres). A grasp the page picks is refitted on the server to the side's model
(grasps/refit.refit_grasp, as dataset/objects.py refits it per frame) once and kept: its joint angles pose the page's
hand and its placement puts the object in the hand's model frame, in the live view and in the exported job.
"""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np

from darthand.errors import InputError
from darthand.fileio import read_json
from darthand.grasps.loader import Grasp, catalog_file, load_grasp_catalog
from darthand.grasps.refit import FittedGrasp, object_field, refit_grasp
from darthand.model.anatomy import axis_angle_to_angles, rest_joints
from darthand.model.hand_model import HandModel
from darthand.model.rotations import axis_angle_to_matrix
from darthand.objects.preview import object_tile
from darthand.render.image import write_png
from darthand.render.objects import ObjectLibrary
from darthand.studio.request_error import RequestError
from darthand.textures.color import encode_srgb8

THUMB_SIZE = 96


def find_catalogs(root: Path, objects=None, grasps=None) -> tuple[Path, Path] | None:
    """The (object, grasp) catalogue files: the options' when given (InputError naming a missing one), else
    objects/ and grasps/ in the build folder `root`; None when the build has none of them (the page then hides its
    object controls)."""
    if objects is None and grasps is None:
        found = catalog_file(root / "objects"), catalog_file(root / "grasps")
        return found if all(p.is_file() for p in found) else None
    objects_file = catalog_file(objects if objects is not None else root / "objects")
    grasps_file = catalog_file(grasps if grasps is not None else objects_file.parent.parent / "grasps")
    for option, path in (("--objects-catalog", objects_file), ("--grasps-catalog", grasps_file)):
        if not path.is_file():
            raise InputError(f"{option}: no catalogue at {path}")
    return objects_file, grasps_file


class StudioObjects:
    """The object and grasp catalogues opened for the studio. models: {side: HandModel} of the build's sides (the
    hands grasps are refitted to); `library` is what render/api.Renderer(objects=...) draws from."""

    def __init__(self, objects: Path, grasps: Path, models: dict):
        self.objects_file, self.grasps_file = Path(objects), Path(grasps)
        self.library = ObjectLibrary.load(self.objects_file)
        self.items = self.library.items
        self.models = models
        self.grasps: dict[str, dict[str, Grasp]] = {side: {} for side in models}
        for grasp in load_grasp_catalog(self.grasps_file, objects=list(self.items)):
            if grasp.side in self.grasps:
                self.grasps[grasp.side][grasp.id] = grasp
        self._approach = _approaches(self.grasps_file)
        self._fitted: dict = {}
        self._fields: dict = {}
        self._lock = threading.Lock()

    # ---------------------------------------------------------------------------------------------- checks

    def item(self, object_id):
        if object_id not in self.items:
            raise RequestError(404, f"object {object_id!r} is not in the object catalogue")
        return self.items[object_id]

    def grasp(self, side: str, object_id: str, grasp_id) -> Grasp:
        """The catalogue grasp `grasp_id` of the object on `side` (RequestError 404 otherwise)."""
        grasp = self.grasps.get(side, {}).get(grasp_id)
        if grasp is None or grasp.object_id != object_id:
            raise RequestError(404, f"grasp {grasp_id!r} is not a {side} grasp of object {object_id!r} in the grasp "
                                    "catalogue")
        return grasp

    # ---------------------------------------------------------------------------------------------- the page

    def listing(self) -> dict:
        """{'categories': sorted names, 'objects': [{id, category, name, size_m, grasps: {side: [{id, type,
        approach}]}}]} in catalogue order, only objects with a grasp on some side."""
        by_object: dict = {}
        for side, grasps in self.grasps.items():
            for g in grasps.values():
                entry = {"id": g.id, "type": g.type, "approach": self._approach.get(g.id, 0)}
                by_object.setdefault(g.object_id, {}).setdefault(side, []).append(entry)
        objects = [{"id": i.id, "category": i.category, "name": i.name, "size_m": [float(s) for s in i.size_m],
                    "grasps": by_object[i.id]} for i in self.items.values() if i.id in by_object]
        return {"categories": sorted({o["category"] for o in objects}), "objects": objects}

    def mesh(self, object_id: str) -> dict:
        """The object's drawn parts as plain arrays for the live view: per part its name, flat positions and normals
        (metres, object frame), triangle indices, linear base colour, roughness and metallic; a textured part
        (its base colour times the object's albedo, `albedo` true) is given per triangle corner with its uvs, since
        its uv triangles index their own array."""
        parts = []
        for p in self.item(object_id).drawn_parts():
            doc = {"name": p.name, "color": list(p.base_color), "roughness": p.roughness, "metallic": p.metallic,
                   "albedo": p.base_color_png is not None}
            if doc["albedo"]:
                corners = p.faces.reshape(-1)
                doc.update(positions=_flat(p.vertices[corners]), normals=_flat(p.normals[corners]),
                           uvs=_flat(p.uvs[p.faces_uv.reshape(-1)]), indices=list(range(len(corners))))
            else:
                doc.update(positions=_flat(p.vertices), normals=_flat(p.normals), indices=p.faces.reshape(-1).tolist())
            parts.append(doc)
        return {"id": object_id, "parts": parts}

    def albedo(self, object_id: str) -> Path:
        """The object's albedo image (sRGB PNG; RequestError 404 when it has none)."""
        path = self.item(object_id).base_color_png
        if path is None or not Path(path).is_file():
            raise RequestError(404, f"object {object_id!r} has no albedo image")
        return Path(path)

    def thumbnail(self, object_id: str, path: Path) -> None:
        """Write the THUMB_SIZE sRGB PNG of the object alone (the contact sheet's drawing)."""
        i = self.item(object_id)
        image = object_tile(i.vertices, i.faces, i.face_part, list(i.parts), i.uvs, i.faces_uv, i.base_color_png,
                            size=THUMB_SIZE)
        write_png(path, encode_srgb8(image))

    # ---------------------------------------------------------------------------------------------- grasps

    def fitted(self, side: str, object_id: str, grasp_id: str) -> FittedGrasp:
        """The grasp refitted to the side's model, made once (refits are deterministic, so the live view, the render
        and the export see the same placement)."""
        grasp = self.grasp(side, object_id, grasp_id)
        key = (side, grasp_id)
        with self._lock:
            if key not in self._fitted:
                item = self.item(object_id)
                if object_id not in self._fields:
                    self._fields[object_id] = object_field(item)
                try:
                    self._fitted[key] = refit_grasp(self.models[side], item, grasp, self._fields[object_id])
                except InputError as e:
                    raise RequestError(422, str(e)) from None
            return self._fitted[key]

    def grasp_document(self, side: str, object_id: str, grasp_id: str) -> dict:
        """What the page poses with: the refitted grasp's joint angles (16 x 3 degrees, model/anatomy.py), its
        placement (4 x 4, object frame -> the hand's model frame, metres) at those angles, the root joint's rest
        centre the object turns about with the wrist (`pivot`, metres: held_placement), type, whether it is within
        the catalogue's bounds and its penetration (mm)."""
        fit = self.fitted(side, object_id, grasp_id)
        model = self.models[side]
        angles = np.rad2deg(axis_angle_to_angles(model, np.asarray(fit.pose, np.float64).reshape(16, 3)))
        return {"side": side, "object": object_id, "grasp": grasp_id, "type": self.grasps[side][grasp_id].type,
                "angles_deg": np.round(angles, 6).tolist(), "placement": np.round(fit.placement, 9).tolist(),
                "pivot": np.round(rest_joints(model)[0], 9).tolist(),
                "ok": fit.ok, "penetration_max_mm": round(1000 * fit.penetration_max_m, 3)}

    def held_placement(self, side: str, held: dict, pose: np.ndarray) -> np.ndarray:
        """(4, 4) object frame -> the hand's model frame of the held object ({id, grasp}) when the hand takes `pose`
        (48,) MANO axis-angle: the refitted grasp's placement carried by the root joint's rotation from the grasp's
        pose to `pose` about the root joint's rest centre, as the hand itself turns (wrist edits keep the grip)."""
        fit = self.fitted(side, held["id"], held["grasp"])
        return root_motion(self.models[side], fit.pose, pose) @ fit.placement

    def placed_vertices(self, side: str, held: dict, pose: np.ndarray) -> np.ndarray:
        """(N, 3) the held object's vertices ({id, grasp}) in the hand's model frame (metres) for the hand's
        `pose` (held_placement)."""
        P = self.held_placement(side, held, pose)
        return self.item(held["id"]).vertices @ P[:3, :3].T + P[:3, 3]

    def grasp_record(self, side: str, object_id: str, grasp_id: str) -> dict:
        """The job's grasp record (dataset/objects.object_job's): type, id and the refit's figures."""
        fit = self.fitted(side, object_id, grasp_id)
        return {"type": self.grasps[side][grasp_id].type, "id": grasp_id,
                "figures": {"penetration_max_mm": round(1000 * fit.penetration_max_m, 3),
                            "penetration_p99_mm": round(1000 * fit.penetration_p99_m, 3)}}


def root_motion(model: HandModel, from_pose: np.ndarray, to_pose: np.ndarray) -> np.ndarray:
    """(4, 4) the rigid motion of the hand's model frame that takes the root joint's rotation of `from_pose` to that
    of `to_pose` (48,) about the root joint's rest centre (metres): T(c) R_to R_from^T T(-c)."""
    R = axis_angle_to_matrix(np.stack([np.asarray(from_pose, np.float64)[:3], np.asarray(to_pose, np.float64)[:3]]))
    c = rest_joints(model)[0]
    motion = np.eye(4)
    motion[:3, :3] = R[1] @ R[0].T
    motion[:3, 3] = c - motion[:3, :3] @ c
    return motion


def _approaches(grasps_file: Path) -> dict:
    """{grasp id: approach index} from the catalogue's entries."""
    doc = read_json(grasps_file, "grasp catalogue")
    return {g["id"]: int(g.get("approach", 0)) for g in doc.get("grasps", [])}


def _flat(a: np.ndarray) -> list:
    return np.round(np.asarray(a, np.float64).reshape(-1), 6).tolist()
