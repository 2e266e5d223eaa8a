"""The objects' contact sheet: each object drawn alone by the accessories' Embree preview (orthographic, headlight,
textured base colour), labelled with its id and size."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from darthand.accessories.preview import render_view
from darthand.accessories.textures import srgb_to_linear
from darthand.model.preview import contact_sheet, write_png
from darthand.textures.imageio import read_image

VIEW = (-0.45, -0.8, -0.55)      # from the front left, above: a card's or phone's face and a mug's handle show


def object_tile(vertices: np.ndarray, faces: np.ndarray, face_part: np.ndarray, parts: list[dict],
                uvs: np.ndarray | None = None, faces_uv: np.ndarray | None = None, texture: Path | None = None,
                size: int = 192) -> np.ndarray:
    """(size, size, 3) linear RGB view of one object (metres, object frame), its parts in their colours, the
    textured part's base colour multiplied by its texture."""
    image = None if texture is None else srgb_to_linear(read_image(texture)[..., :3] / 255.0)
    meshes = []
    for k, p in enumerate(parts):
        sel = face_part == k
        if not sel.any():
            continue
        m = {"vertices": vertices, "faces": faces[sel], "metallic": float(p["metallic"]),
             "color": np.asarray(p["base_color"], float)}
        if image is not None and faces_uv is not None:
            m.update(uvs=uvs, faces_uv=faces_uv[sel], texture=image * np.asarray(p["base_color"], float))
        meshes.append(m)
    extent = float(np.ptp(vertices, axis=0).max()) * 1.2
    return render_view(meshes, np.zeros(3), VIEW, (0.0, 0.0, 1.0), extent, size)


def size_label(item_id: str, size_m) -> str:
    """'<id> 80x114x95mm': the extents in millimetres (a decimal below 1 cm)."""
    dims = "x".join(f"{s * 1000:.0f}" if s >= 0.01 else f"{s * 1000:.1f}" for s in size_m)
    return f"{item_id} {dims}mm"


def write_sheet(path: Path, tiles: list[np.ndarray], labels: list[str], cols: int = 8) -> None:
    """The tiles in a grid, `cols` per row, as an sRGB PNG."""
    write_png(path, contact_sheet(tiles, labels, cols=cols))
