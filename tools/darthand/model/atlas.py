"""UV layouts: keep a template's own UVs, or make a deterministic xatlas atlas for a model without them (MANO),
and find the UV seams.

UV convention (the OBJ/USD one): (0, 0) is the bottom-left corner of the image, so the texel in row r, column c
of a `res` x `res` image has its centre at uv = ((c + 0.5) / res, 1 - (r + 0.5) / res). glTF's texture
coordinates are (u, 1 - v).
"""

from __future__ import annotations

import numpy as np
import xatlas

from darthand.errors import InputError
from darthand.model.hand_model import HandModel

ATLAS_VERSION = 1


def atlas_padding(res: int) -> int:
    """Gutter between charts, in texels of a `res` x `res` atlas: enough that mip level log2(padding) still keeps
    neighbouring charts apart (8 texels at 2048, 16 at 4096), at least 2."""
    return max(2, int(res) // 256)


def ensure_uvs(model: HandModel, res: int = 2048) -> HandModel:
    """`model` unchanged if it has UVs, else a copy with an xatlas atlas packed for a `res` x `res` texture.

    The atlas is deterministic (fixed chart and pack options, single atlas); `meta["uv_atlas"]` records how it
    was made so that the exporters and the texture build can tell it apart from an artist's layout.
    """
    if model.has_uvs:
        return model
    uvs, faces_uv = compute_atlas(model.v_template, model.faces, res)
    meta = dict(model.meta, uv_atlas={"generator": "xatlas", "xatlas_version": xatlas.__version__,
                                      "resolution": int(res), "padding": atlas_padding(res),
                                      "version": ATLAS_VERSION})
    return model.replace(uvs=uvs, faces_uv=faces_uv, meta=meta)


def compute_atlas(vertices: np.ndarray, faces: np.ndarray, res: int) -> tuple[np.ndarray, np.ndarray]:
    """An xatlas atlas of the mesh (V, 3), (F, 3) filling one `res` x `res` texture.

    Returns uvs (T, 2) in [0, 1] (bottom-left origin) and faces_uv (F, 3), face order kept. The texel density
    is the largest (to 0.1%) at which xatlas packs every chart into the one square.
    """
    vertices = np.ascontiguousarray(vertices, dtype=np.float32)
    faces32 = np.ascontiguousarray(faces, dtype=np.uint32)
    first = _generate(vertices, faces32, res, texels_per_unit=0.0)
    fits = lambda a: a.atlas_count == 1 and a.width <= res and a.height <= res  # noqa: E731
    # Largest texel density (texels per metre) that still packs into one atlas: grow, then bisect.
    lo, hi = 0.0, first.texels_per_unit * res / max(first.width, first.height)
    best = None
    for _ in range(20):
        atlas = _generate(vertices, faces32, res, texels_per_unit=hi)
        if not fits(atlas):
            break
        lo, best, hi = hi, atlas, hi * 1.25
    for _ in range(10):
        mid = 0.5 * (lo + hi)
        atlas = _generate(vertices, faces32, res, texels_per_unit=mid)
        if fits(atlas):
            lo, best = mid, atlas
        else:
            hi = mid
    if best is None:
        raise InputError(f"xatlas could not pack the mesh ({len(faces)} faces) into one {res}x{res} atlas")
    atlas = best
    vmap, indices, uv = atlas[0]
    if not np.array_equal(vmap[indices], faces):
        raise InputError("xatlas changed the face order; cannot map its UVs back to the model's faces")
    # The binding normalises by the atlas' own width/height; rescale to the res x res square, v up.
    px = uv.astype(np.float64) * [atlas.width, atlas.height]
    uvs = np.stack([px[:, 0] / res, 1.0 - px[:, 1] / res], 1)
    return uvs, indices.astype(np.int64)


def _generate(vertices, faces, res, texels_per_unit):
    atlas = xatlas.Atlas()
    atlas.add_mesh(vertices, faces)
    chart = xatlas.ChartOptions()
    chart.fix_winding = True
    pack = xatlas.PackOptions()
    pack.resolution = int(res)
    pack.padding = atlas_padding(res)
    pack.texels_per_unit = float(texels_per_unit)
    pack.bilinear = True
    pack.blockAlign = False
    pack.bruteForce = False
    pack.rotate_charts = True
    atlas.generate(chart, pack)
    return atlas


def seam_edges(faces: np.ndarray, faces_uv: np.ndarray, uvs: np.ndarray):
    """Mesh edges shared by two faces whose UV corners differ (the cuts of the layout).

    Returns a dict of arrays over E seam edges:
        vertices  (E, 2)     int64, the edge's two vertex ids (a < b)
        faces     (E, 2)     int64, the two faces
        uv        (E, 2, 2, 2) float64, uv[e, s, k] is the UV of vertex k of the edge as seen from face s
    """
    faces = np.asarray(faces)
    faces_uv = np.asarray(faces_uv)
    F = len(faces)
    corner = np.array([[0, 1], [1, 2], [2, 0]])
    a = faces[:, corner[:, 0]].ravel()
    b = faces[:, corner[:, 1]].ravel()
    ta = faces_uv[:, corner[:, 0]].ravel()
    tb = faces_uv[:, corner[:, 1]].ravel()
    face = np.repeat(np.arange(F), 3)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    t_lo = np.where(a < b, ta, tb)
    t_hi = np.where(a < b, tb, ta)
    order = np.lexsort((face, hi, lo))
    lo, hi, t_lo, t_hi, face = lo[order], hi[order], t_lo[order], t_hi[order], face[order]
    same = (lo[1:] == lo[:-1]) & (hi[1:] == hi[:-1])
    pair = np.nonzero(same)[0]
    pair = pair[~np.isin(pair - 1, pair) & ~np.isin(pair + 1, pair)]  # exactly two faces per edge
    i, j = pair, pair + 1
    uv = np.asarray(uvs, dtype=np.float64)
    uv_i = np.stack([uv[t_lo[i]], uv[t_hi[i]]], 1)
    uv_j = np.stack([uv[t_lo[j]], uv[t_hi[j]]], 1)
    cut = np.abs(uv_i - uv_j).max(axis=(1, 2)) > 1e-9
    return {"vertices": np.stack([lo[i], hi[i]], 1)[cut], "faces": np.stack([face[i], face[j]], 1)[cut],
            "uv": np.stack([uv_i, uv_j], 1)[cut]}
