"""Objects a hand holds, drawn: an object catalogue's items (objects/loader.ObjectItem) as posed Surfaces.

Each item is drawn part by part (ObjectItem.drawn_parts: crease-split vertices, smooth normals elsewhere), one
Surface per part with role 'object' and a metallic-roughness ('pbr') Material: the part's linear base colour
(multiplying its sRGB texture when the item has one), roughness and metallic. A part is a rigid surface
(Surface.local in the object frame, Surface.transform the placement), so its ray-tracing structure is built once
per object and reused for every frame, and it casts and receives shadows and ambient occlusion as the hand's
accessories do.

Units and frames: metres; a placement (4, 4 rigid) maps the object frame to the world.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from darthand.errors import InputError
from darthand.objects.loader import load_object_catalog
from darthand.render.subject import Material, Surface
from darthand.render.texture import constant_texture, load_maps

ROLE = "object"


@dataclass(frozen=True, eq=False)
class HeldObject:
    """One placed object of a frame: its catalogue item, placement (4, 4) float64 object frame -> world, and its
    drawn surfaces (one per part, in the world)."""

    item: Any
    placement: np.ndarray
    surfaces: tuple

    def vertices(self) -> np.ndarray:
        """(N, 3) float64 the item's closed mesh placed in the world (labels and contacts use it, not the drawn
        parts)."""
        P = self.placement
        return np.asarray(self.item.vertices, np.float64) @ P[:3, :3].T + P[:3, 3]

    def corners(self) -> np.ndarray:
        """(8, 3) float64 the corners of the item's bounding box in its frame, placed in the world (x fastest)."""
        v = np.asarray(self.item.vertices, np.float64)
        lo, hi = v.min(axis=0), v.max(axis=0)
        box = np.array([[(lo, hi)[i & 1][0], (lo, hi)[i >> 1 & 1][1], (lo, hi)[i >> 2 & 1][2]] for i in range(8)])
        P = self.placement
        return box @ P[:3, :3].T + P[:3, 3]


class ObjectLibrary:
    """The items of an object catalogue by id, with each item's parts as the renderer draws them (built on first
    use and kept: the same local arrays every frame, so the rigid surfaces' ray-tracing structures are reused)."""

    def __init__(self, items):
        self.items = {item.id: item for item in items}
        self._parts: dict = {}

    @classmethod
    def load(cls, catalog) -> "ObjectLibrary":
        """The library of an object catalogue (catalog.json or its folder)."""
        path = Path(catalog)
        if not (path / "catalog.json" if path.is_dir() else path).is_file():
            raise InputError(f"{path}: no object catalogue there (build it: `make build/objects/catalog.json`)")
        return cls(load_object_catalog(path))

    def item(self, object_id: str):
        """The catalogue item `object_id` (InputError naming it when the catalogue has none)."""
        if object_id not in self.items:
            raise InputError(f"object {object_id!r} is not in the object catalogue")
        return self.items[object_id]

    def placed(self, object_id: str, placement) -> HeldObject:
        """The object `object_id` drawn at `placement` (4, 4) rigid, object frame -> world."""
        P = np.asarray(placement, np.float64)
        return HeldObject(self.item(object_id), P, tuple(placed_part(part, P) for part in self._drawn(object_id)))

    def _drawn(self, object_id: str) -> list:
        """[(name, local (n, 3) float32, faces, normals, uvs, faces_uv, Material)] of the item's drawn parts."""
        if object_id not in self._parts:
            item = self.item(object_id)
            self._parts[object_id] = [
                (f"{item.id}/{p.name}", np.ascontiguousarray(p.vertices, np.float32),
                 np.ascontiguousarray(p.faces, np.int32), np.ascontiguousarray(p.normals, np.float32),
                 None if p.uvs is None else np.ascontiguousarray(p.uvs, np.float32),
                 None if p.faces_uv is None else np.ascontiguousarray(p.faces_uv, np.int32), part_material(p))
                for p in item.drawn_parts()]
        return self._parts[object_id]


def placed_part(part: tuple, P: np.ndarray) -> Surface:
    """One drawn part (ObjectLibrary._drawn's tuple) as a rigid Surface at placement P (4, 4)."""
    name, local, faces, normals, uvs, faces_uv, material = part
    R, t = P[:3, :3], P[:3, 3]
    vertices = (local.astype(np.float64) @ R.T + t).astype(np.float32)
    world_normals = (normals.astype(np.float64) @ R.T).astype(np.float32)
    return Surface(name, vertices, faces, world_normals, material, uvs, faces_uv, None, ROLE, None, local, P)


def part_material(part) -> Material:
    """A drawn part's metallic-roughness Material: its base colour (linear), multiplying its sRGB texture when it
    has one and UVs to read it with."""
    base = np.asarray(part.base_color, np.float32)[:3]
    maps = constant_texture(base)
    if part.base_color_png is not None and part.uvs is not None:
        maps = load_maps(part.base_color_png)
        if maps.decode is not None:
            table = maps.decode.copy()
            table[:3] *= base[:, None]
            maps = maps.with_decode(table)
    return Material("pbr", maps, None, float(part.roughness), None, float(part.metallic), name=part.name)
