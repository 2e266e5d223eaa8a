"""A small preview renderer for contact sheets: orthographic embreex ray casting, headlight Lambert shading.

Meant for a person to look at a posed hand or accessory (build/template/gestures.png, the accessory and render
contact sheets), not for training images: no textures, no shadows, one ray per sub-pixel. It sits in `model`
because the template, accessories and render stages all use it; the full renderer is the `render` stage.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenImageIO as oiio
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from darthand.errors import DarthandError
from darthand.fileio import atomic_path
from darthand.model.topology import vertex_normals

SKIN = (0.80, 0.55, 0.45)          # linear RGB
HIGHLIGHT = (0.90, 0.02, 0.02)
BACKGROUND = (0.02, 0.02, 0.025)
# Directions from the hand toward the camera, MANO's frame (fingers -X, thumb +Z, palm -Y).
VIEWS = {
    "dorsal": (0.0, 1.0, 0.0),
    "palmar": (0.0, -1.0, 0.0),
    "radial": (0.0, 0.0, 1.0),      # from the thumb side: flexion seen edge-on
    "ulnar": (0.0, 0.0, -1.0),
    "three_quarter": (0.25, 0.75, 0.6),
}
_UP_HINT = np.array([-1.0, 0.0, 0.0])  # fingers point up in the image


def camera_basis(view, side: str = "right") -> np.ndarray:
    """(3, 3) rows right, up, forward (the ray direction) of a camera looking along -`view`.

    For a left hand (x -> -x) the named views and the up direction are mirrored, so both hands are seen alike.
    """
    mirror = np.array([-1.0, 1.0, 1.0]) if side == "left" else np.ones(3)
    to_camera = np.asarray(VIEWS[view] if isinstance(view, str) else view, dtype=np.float64) * mirror
    forward = -to_camera / np.linalg.norm(to_camera)
    up = _UP_HINT * mirror
    hint = up if abs(forward @ up) < 0.95 else np.array([0.0, 1.0, 0.0])
    right = np.cross(forward, hint)
    right /= np.linalg.norm(right)
    return np.stack([right, np.cross(right, forward), forward])


def render_mesh(vertices: np.ndarray, faces: np.ndarray, *, view="three_quarter", size: int = 256,
                face_colors: np.ndarray | None = None, supersample: int = 2, margin: float = 0.06,
                side: str = "right", frame: np.ndarray | None = None) -> np.ndarray:
    """(size, size, 3) float32 linear RGB image of a mesh (V, 3), (F, 3) framed to fit, orthographic.

    view: a name in VIEWS or a direction (3,) from the hand toward the camera; side: see `camera_basis`.
    frame: points (P, 3) to frame instead of the mesh (the same points for several meshes draw them at one scale).

    face_colors: (F, 3) linear RGB per face (default skin). Shading: ambient + Lambert from a light at the camera,
    two-sided, with interpolated vertex normals.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    basis = camera_basis(view, side)
    cam = (vertices if frame is None else np.asarray(frame, dtype=np.float64)) @ basis.T   # right, up, depth
    lo, hi = cam.min(0), cam.max(0)
    centre = 0.5 * (lo + hi)
    extent = (hi - lo)[:2].max() * (1 + 2 * margin)
    n = size * supersample
    pixel = extent / n
    jj, ii = np.meshgrid(np.arange(n), np.arange(n))
    x = centre[0] + (jj.ravel() + 0.5 - n / 2) * pixel
    y = centre[1] - (ii.ravel() + 0.5 - n / 2) * pixel
    z = np.full_like(x, lo[2] - 1.0)
    origins = np.stack([x, y, z], 1) @ basis                                # back to model coordinates
    directions = np.broadcast_to(basis[2], origins.shape)

    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene, vertices.astype(np.float32), faces.astype(np.int32))
    hit = scene.run(origins.astype(np.float32), np.ascontiguousarray(directions, dtype=np.float32), output=1)
    prim = hit["primID"]
    found = prim >= 0

    image = np.empty((n * n, 3))
    image[:] = BACKGROUND
    f = faces[prim[found]]
    u, v = hit["u"][found, None].astype(np.float64), hit["v"][found, None].astype(np.float64)
    vn = vertex_normals(vertices, faces)
    normal = (1 - u - v) * vn[f[:, 0]] + u * vn[f[:, 1]] + v * vn[f[:, 2]]
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-30)
    lambert = np.abs(normal @ basis[2])[:, None]
    colors = np.asarray(SKIN if face_colors is None else face_colors, dtype=np.float64)
    colors = colors[prim[found]] if colors.ndim == 2 else colors
    image[found] = colors * (0.12 + 0.88 * lambert)
    image = image.reshape(n, n, 3).astype(np.float32)
    return _resize(image, size) if supersample > 1 else image


def _resize(image: np.ndarray, size: int) -> np.ndarray:
    buf = oiio.ImageBuf(np.ascontiguousarray(image))
    out = oiio.ImageBufAlgo.resize(buf, roi=oiio.ROI(0, size, 0, size, 0, 1, 0, 3))
    pixels = out.get_pixels(oiio.FLOAT)
    assert pixels is not None, out.geterror()
    return pixels.reshape(size, size, 3)


def contact_sheet(images: list[np.ndarray], labels: list[str], cols: int, label_height: int = 22,
                  pad: int = 4) -> np.ndarray:
    """(H, W, 3) float32 grid of equally sized images (h, w, 3), `cols` per row, each with its label below."""
    if not images:
        raise DarthandError("contact sheet: no images")
    h, w = images[0].shape[:2]
    rows = -(-len(images) // cols)
    cell_h, cell_w = h + label_height + pad, w + pad
    sheet = oiio.ImageBuf(oiio.ImageSpec(cols * cell_w + pad, rows * cell_h + pad, 3, oiio.FLOAT))
    oiio.ImageBufAlgo.fill(sheet, (0.2, 0.2, 0.2))
    for k, (img, label) in enumerate(zip(images, labels)):
        y0, x0 = pad + (k // cols) * cell_h, pad + (k % cols) * cell_w
        sheet.set_pixels(oiio.ROI(x0, x0 + w, y0, y0 + h, 0, 1, 0, 3), np.ascontiguousarray(img, dtype=np.float32))
        oiio.ImageBufAlgo.render_text(sheet, x0 + 4, y0 + h + label_height - 6, label, 16, "", (1.0, 1.0, 1.0))
    pixels = sheet.get_pixels(oiio.FLOAT)
    assert pixels is not None, sheet.geterror()
    return pixels.reshape(sheet.spec().height, sheet.spec().width, 3)


def write_png(path: str | Path, image: np.ndarray) -> None:
    """Write a linear RGB float image (H, W, 3) as an 8-bit sRGB PNG, atomically."""
    buf = oiio.ImageBuf(np.ascontiguousarray(image, dtype=np.float32))
    srgb = oiio.ImageBufAlgo.colorconvert(buf, "linear", "sRGB")
    if srgb.has_error:
        raise DarthandError(f"{path}: colour conversion failed: {srgb.geterror()}")
    with atomic_path(path) as tmp:
        if not srgb.write(str(tmp), oiio.UINT8):
            raise DarthandError(f"{path}: could not write PNG: {srgb.geterror()}")
