"""A small object catalogue for the scene tests, from trimesh's primitives (a box, a sphere, a cylinder) at known
sizes: objects/loader.ObjectItems (drawn with creases split, as the catalogue's are), and the catalogue written in
its file format (catalog.json + one npz per object) for the loader."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import trimesh

from darthand.objects.loader import ObjectItem

SPHERE_RADIUS = 0.035
BOX_SIZE = (0.06, 0.04, 0.10)
CYLINDER = (0.03, 0.12)            # radius, height


def _item(object_id: str, category: str, mesh: trimesh.Trimesh, colour) -> ObjectItem:
    mesh.apply_translation(-mesh.bounds.mean(axis=0))
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    parts = ({"name": "body", "base_color": list(colour), "roughness": 0.45, "metallic": 0.0},)
    return ObjectItem(object_id, category, object_id, "procedural", "CC0-1.0", np.asarray(mesh.vertices, np.float64),
                      np.asarray(mesh.faces, np.int32), np.zeros(len(mesh.faces), np.int16), parts,
                      tuple(float(x) for x in mesh.extents), ())


def toy_items() -> list[ObjectItem]:
    """The box, the sphere and the cylinder (ids box_01, ball_01, bottle_01)."""
    return [_item("box_01", "box", trimesh.creation.box(BOX_SIZE), (0.6, 0.15, 0.1)),
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
