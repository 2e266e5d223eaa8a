"""A small object catalogue for the scene tests, from trimesh's primitives (a box, a sphere, a cylinder) at known
sizes: items with objects/loader.ObjectItem's fields and drawn_parts() (the contract of issue 30), and the catalogue
written in its file format (catalog.json + one npz per object) for the loader."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

from darthand.model.topology import vertex_normals

SPHERE_RADIUS = 0.035
BOX_SIZE = (0.06, 0.04, 0.10)
CYLINDER = (0.03, 0.12)            # radius, height


@dataclass(frozen=True)
class ToyPart:
    name: str
    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    uvs: np.ndarray | None
    faces_uv: np.ndarray | None
    base_color: tuple
    roughness: float
    metallic: float
    base_color_png: Path | None = None


@dataclass(frozen=True, eq=False)
class ToyItem:
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
    grasps: tuple = ()
    uvs: np.ndarray | None = None
    faces_uv: np.ndarray | None = None
    base_color_png: Path | None = None
    flat: bool = field(default=False)

    def drawn_parts(self) -> list:
        part = self.parts[0]
        if self.flat:          # a box: every face its own corners, its normal
            v = self.vertices[self.faces].reshape(-1, 3).astype(np.float32)
            f = np.arange(len(v), dtype=np.int32).reshape(-1, 3)
            n = np.repeat(trimesh.Trimesh(self.vertices, self.faces, process=False).face_normals, 3, axis=0)
        else:
            v, f = self.vertices.astype(np.float32), self.faces.astype(np.int32)
            n = vertex_normals(v, f)
        return [ToyPart(part["name"], v, f, np.asarray(n, np.float32), None, None, tuple(part["base_color"]),
                        part["roughness"], part["metallic"])]


def _item(object_id: str, category: str, mesh: trimesh.Trimesh, colour, flat=False) -> ToyItem:
    mesh.apply_translation(-mesh.bounds.mean(axis=0))
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    parts = ({"name": "body", "base_color": list(colour), "roughness": 0.45, "metallic": 0.0},)
    return ToyItem(object_id, category, object_id, "procedural", "CC0-1.0", np.asarray(mesh.vertices, np.float64),
                   np.asarray(mesh.faces, np.int32), np.zeros(len(mesh.faces), np.int16), parts,
                   tuple(float(x) for x in mesh.extents), flat=flat)


def toy_items() -> list[ToyItem]:
    """The box, the sphere and the cylinder (ids box_01, ball_01, bottle_01)."""
    return [_item("box_01", "box", trimesh.creation.box(BOX_SIZE), (0.6, 0.15, 0.1), flat=True),
            _item("ball_01", "ball", trimesh.creation.icosphere(4, SPHERE_RADIUS), (0.1, 0.35, 0.7)),
            _item("bottle_01", "bottle", trimesh.creation.cylinder(CYLINDER[0], CYLINDER[1], sections=48),
                  (0.15, 0.5, 0.2))]


def write_catalog(folder: Path, items=None) -> Path:
    """The catalogue of `items` (default toy_items()) in the objects stage's format; returns catalog.json's path."""
    folder.mkdir(parents=True, exist_ok=True)
    objects = []
    for item in items or toy_items():
        np.savez(folder / f"{item.id}.npz", vertices=item.vertices, faces=item.faces, face_part=item.face_part)
        objects.append({"id": item.id, "category": item.category, "name": item.name, "source": item.source,
                        "licence": item.licence, "licence_file": None, "size_m": list(item.size_m),
                        "grasps": list(item.grasps), "files": {"npz": f"{item.id}.npz", "base_color": None},
                        "parts": list(item.parts)})
    path = folder / "catalog.json"
    path.write_text(json.dumps({"format": "darthand-objects", "format_version": 1, "seed": 0, "objects": objects,
                                "skipped": [], "contact_sheet": "contact_sheet.png"}, indent=1))
    return path
