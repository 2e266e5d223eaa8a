"""Reading the objects stage's catalogue (build/objects/catalog.json): the objects a hand holds, as the grasp fit and
the renderer use them. The objects stage owns how its catalogue is read; other stages import from here.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from darthand.errors import InputError
from darthand.fileio import file_in, read_npz
from darthand.objects.creases import split_at_creases
from darthand.schemas import read_catalog

SCHEMA = "object_catalog.schema.json"


@dataclass(frozen=True)
class DrawnPart:
    """One part as the renderer draws it: vertices split where faces meet at a crease (flat sides stay flat), smooth
    normals elsewhere. vertices (n, 3) float32 metres, object frame; faces (f, 3) int32 counter-clockwise seen from
    outside; normals (n, 3) float32 unit, outward; uvs (t, 2) float32 and faces_uv (f, 3) int32 or None;
    base_color linear RGB (multiplies base_color_png, sRGB, when there is one); roughness, metallic in [0, 1]."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    uvs: np.ndarray | None
    faces_uv: np.ndarray | None
    base_color: tuple
    roughness: float
    metallic: float
    base_color_png: Path | None


@dataclass(frozen=True)
class ObjectItem:
    """One catalogue object. vertices (N, 3) float64 metres in the object frame (origin at the bounding box's
    centre, +z the object's axis or thin axis); faces (F, 3) int32, a closed, outward-wound mesh; face_part (F,)
    int16 index into `parts` (dicts: name, base_color linear RGB, roughness, metallic, and `textured` (default
    true) when the object has a texture); size_m the bounding box's extents (metres); grasps: taxonomy names this
    object suits; uvs (T, 2) float32 + faces_uv (F, 3) int32 when its textured parts show base_color_png (sRGB,
    multiplied by the part's base_color)."""

    id: str
    category: str
    name: str
    source: str
    licence: str
    vertices: np.ndarray
    faces: np.ndarray
    face_part: np.ndarray
    parts: tuple
    size_m: tuple
    grasps: tuple[str, ...]
    uvs: np.ndarray | None = None
    faces_uv: np.ndarray | None = None
    base_color_png: Path | None = None

    def drawn_parts(self, crease_deg: float = 35.0) -> list[DrawnPart]:
        """Each part's faces as the renderer draws them: vertices split where neighbouring faces turn by more than
        `crease_deg` degrees (a box's edges, a card's rim), area-weighted normals elsewhere."""
        out = []
        for k, part in enumerate(self.parts):
            sel = np.flatnonzero(self.face_part == k)
            if not len(sel):
                continue
            verts, faces, normals = split_at_creases(self.vertices, self.faces[sel], crease_deg)
            uvs, faces_uv = None, None
            if self.uvs is not None and self.faces_uv is not None and part.get("textured", True):
                uvs, faces_uv = self.uvs.astype(np.float32), np.ascontiguousarray(self.faces_uv[sel], np.int32)
            out.append(DrawnPart(
                name=str(part["name"]), vertices=verts.astype(np.float32), faces=faces.astype(np.int32),
                normals=normals.astype(np.float32), uvs=uvs,
                faces_uv=faces_uv, base_color=tuple(float(c) for c in part["base_color"]),
                roughness=float(part["roughness"]), metallic=float(part["metallic"]),
                base_color_png=self.base_color_png if faces_uv is not None else None))
        return out


def load_object_catalog(path: str | Path, ids=None) -> list[ObjectItem]:
    """Objects of an objects-stage catalogue (build/objects/catalog.json, or its folder), in catalogue order; `ids`
    selects some (InputError naming the first unknown one). The file must validate against
    schemas/object_catalog.schema.json; each object's npz is checked for shapes and index ranges."""
    path, data = read_catalog(path, "objects", SCHEMA)
    entries = data["objects"]
    if ids is not None:
        wanted = list(ids)
        known = {e["id"] for e in entries}
        missing = [i for i in wanted if i not in known]
        if missing:
            raise InputError(f"{path}: no object with id {missing[0]!r}")
        entries = [e for e in entries if e["id"] in set(wanted)]
    return [_entry_item(path, e) for e in entries]


def object_ids(path: str | Path) -> list[str]:
    """The catalogue's object ids, in order."""
    _, data = read_catalog(path, "objects", SCHEMA)
    return [e["id"] for e in data["objects"]]


def _entry_item(path: Path, entry: dict) -> ObjectItem:
    files = entry["files"]
    mesh_path = file_in(path.parent, files["npz"], "object mesh", must_exist=False)
    arrays = read_npz(mesh_path, "object mesh", ("vertices", "faces", "face_part"))
    png = files.get("base_color")
    item = ObjectItem(
        id=entry["id"], category=entry["category"], name=entry["name"], source=entry["source"],
        licence=entry["licence"], vertices=np.asarray(arrays["vertices"], np.float64),
        faces=np.asarray(arrays["faces"], np.int32), face_part=np.asarray(arrays["face_part"], np.int16),
        parts=tuple(dict(p) for p in entry["parts"]), size_m=tuple(float(s) for s in entry["size_m"]),
        grasps=tuple(entry["grasps"]),
        uvs=np.asarray(arrays["uvs"], np.float32) if "uvs" in arrays else None,
        faces_uv=np.asarray(arrays["faces_uv"], np.int32) if "faces_uv" in arrays else None,
        base_color_png=None if png is None else file_in(path.parent, png, "object texture", must_exist=False))
    check_item(item, str(mesh_path))
    return item


def check_item(item: ObjectItem, source: str) -> None:
    """InputError naming the object and field when its arrays are inconsistent."""
    where = f"{source}: object {item.id!r}"
    n, f = len(item.vertices), len(item.faces)
    if item.vertices.ndim != 2 or item.vertices.shape[1] != 3 or item.faces.ndim != 2 or item.faces.shape[1] != 3:
        raise InputError(f"{where}: vertices and faces must be (N, 3) and (F, 3)")
    if f and (item.faces.min() < 0 or item.faces.max() >= n):
        raise InputError(f"{where}: faces index a vertex outside 0..{n - 1}")
    if item.face_part.shape != (f,) or (f and (item.face_part.min() < 0 or item.face_part.max() >= len(item.parts))):
        raise InputError(f"{where}: face_part must be ({f},) indices into its {len(item.parts)} parts")
    if (item.uvs is None) != (item.faces_uv is None):
        raise InputError(f"{where}: uvs and faces_uv must be given together")
    if item.faces_uv is not None and item.uvs is not None:
        if item.faces_uv.shape != item.faces.shape:
            raise InputError(f"{where}: faces_uv has shape {item.faces_uv.shape}, expected {item.faces.shape}")
        if f and (item.faces_uv.min() < 0 or item.faces_uv.max() >= len(item.uvs)):
            raise InputError(f"{where}: faces_uv index a uv outside 0..{len(item.uvs) - 1}")
