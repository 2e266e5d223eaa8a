"""Repacking the hand's part of hm08's body atlas into its own square atlas.

The islands keep their shape and their relative texel density (one rotation and one uniform scale for all, one
translation each): xatlas packs them (`Atlas.add_uv_mesh`, which takes the given UVs as the charts) with a margin
in texels at the target resolution, and the importer picks the common rotation that fills the square best, since
the main island (palm and back unwrapped together around splayed fingers) is far from square.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import xatlas
from scipy.sparse.csgraph import connected_components

from darthand.errors import DarthandError


def repack(uvs: np.ndarray, faces_uv: np.ndarray, resolution: int = 2048, padding: int = 4,
           angle_step_deg: float = 5.0, search_resolution: int = 256) -> tuple[np.ndarray, np.ndarray, dict]:
    """New (T', 2) UVs in [0, 1]^2 and (F, 3) indices for the islands of `uvs` (T, 2) / `faces_uv` (F, 3).

    resolution: texture size the margin is meant for; padding: empty texels kept around every island at that size.
    The rotation is chosen every `angle_step_deg` degrees on a coarse packing at `search_resolution`.
    Returns also a report: island count, rotation (degrees), the fraction of the square covered.
    """
    used, local = np.unique(faces_uv, return_inverse=True)
    local = local.reshape(faces_uv.shape)
    pts = uvs[used]
    labels = uv_islands(local, len(used))
    best = None
    for angle in np.arange(0.0, 180.0, angle_step_deg):
        rotated = rotate_islands(pts, labels, np.radians(angle))
        scale = search_resolution / resolution
        tpu = _texels_per_unit(rotated, local, search_resolution)
        packed, size = _pack(rotated, local, labels, tpu, max(1, round(padding * scale)), brute_force=False)
        fill = _coverage(packed, local, size)
        if best is None or fill > best[0]:
            best = (fill, angle, rotated)
    assert best is not None, "angle_step_deg must be in (0, 180)"
    _, angle, rotated = best
    # Pack again at the density that makes the longer side exactly `resolution` texels, so `padding` is in texels.
    tpu = _texels_per_unit(rotated, local, resolution)
    for _ in range(8):
        packed, size = _pack(rotated, local, labels, tpu, padding)
        if max(size) <= resolution:
            break
        tpu *= 0.98 * resolution / max(size)
    offset = (resolution - np.array(size)) / 2.0  # centre the layout in the square
    out = (packed + offset) / resolution
    if out.min() < 0 or out.max() > 1:
        raise DarthandError("UV repacking left the unit square")
    report = {"islands": int(labels.max() + 1), "rotation_deg": float(angle), "resolution": int(resolution),
              "padding_texels": int(padding), "coverage": float(_coverage(out * resolution, local, (resolution,) * 2))}
    return out, local.astype(np.int64), report


def uv_islands(faces_uv: np.ndarray, n_uvs: int) -> np.ndarray:
    """(T,) island label of each UV coordinate: UVs connected through the faces that use them."""
    a = np.repeat(np.arange(len(faces_uv)), 3)
    graph = sp.coo_matrix((np.ones(len(a)), (a, faces_uv.reshape(-1))), shape=(len(faces_uv), n_uvs)).tocsr()
    _, labels = connected_components(graph.T @ graph, directed=False)
    return labels


def rotate_islands(uvs: np.ndarray, labels: np.ndarray, angle: float) -> np.ndarray:
    """Rotate every island by `angle` (radians) about its own centroid."""
    c, s = np.cos(angle), np.sin(angle)
    rot = np.array([[c, -s], [s, c]])
    out = np.empty_like(uvs)
    for k in np.unique(labels):
        m = labels == k
        centre = uvs[m].mean(0)
        out[m] = (uvs[m] - centre) @ rot.T + centre
    return out


def _texels_per_unit(uvs: np.ndarray, faces_uv: np.ndarray, resolution: int) -> float:
    """A density at which the islands' total area would cover about 60% of the square (a first guess that the
    packing pass corrects)."""
    area = np.abs(_signed_areas(uvs, faces_uv)).sum()
    return float(np.sqrt(0.6 * resolution ** 2 / area))


def _pack(uvs: np.ndarray, faces_uv: np.ndarray, labels: np.ndarray, texels_per_unit: float, padding: int,
          brute_force: bool = True):
    """Translate the islands (no rotation, no rescaling between them) into one atlas: texel coordinates (T, 2) and
    the atlas size (width, height) in texels.

    xatlas places the charts but stretches each by up to a texel to whole-texel extents; the islands are then put
    back at exactly `texels_per_unit` from the corner xatlas gave them, which only shrinks them inside their place.
    """
    atlas = xatlas.Atlas()
    atlas.add_uv_mesh(uvs.astype(np.float32), faces_uv.astype(np.uint32))
    pack = xatlas.PackOptions()
    pack.padding = padding
    pack.bilinear = True
    pack.bruteForce = brute_force
    pack.rotate_charts = False
    pack.rotate_charts_to_axis = False
    pack.texels_per_unit = texels_per_unit
    atlas.generate(xatlas.ChartOptions(), pack)
    if atlas.atlas_count != 1:
        raise DarthandError(f"UV repacking produced {atlas.atlas_count} atlases instead of one")
    vmapping, indices, packed = atlas.get_mesh(0)
    if not np.array_equal(vmapping[indices], faces_uv):
        raise DarthandError("UV repacking changed the faces' UV corners")
    if len(vmapping) != len(uvs) or len(np.unique(vmapping)) != len(uvs):
        raise DarthandError("UV repacking split an island (a UV shared by two charts)")
    placed = np.zeros((len(uvs), 2))
    placed[vmapping] = packed.astype(np.float64) * np.array([atlas.width, atlas.height])
    out = np.empty_like(placed)
    for k in np.unique(labels):
        m = labels == k
        out[m] = (uvs[m] - uvs[m].min(0)) * texels_per_unit + placed[m].min(0)
    return out, (int(atlas.width), int(atlas.height))


def _coverage(texels: np.ndarray, faces_uv: np.ndarray, size) -> float:
    """Islands' area over the area of the square that holds the atlas."""
    return float(np.abs(_signed_areas(texels, faces_uv)).sum() / max(size) ** 2)


def _signed_areas(uvs: np.ndarray, faces_uv: np.ndarray) -> np.ndarray:
    a, b, c = uvs[faces_uv[:, 0]], uvs[faces_uv[:, 1]], uvs[faces_uv[:, 2]]
    return 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1]))
