"""A textured Embree preview of accessories on the hand (tiles of the catalogue's contact sheet).

model/preview.py draws one untextured mesh; accessories need several meshes and their base-colour textures, so
this draws: an orthographic camera, first-hit rays through embreex (trimesh's ray interface), textured base colour,
a headlight Lambert term and a highlight scaled by metallic. Tiling and PNG writing use model/preview.py.
"""

from __future__ import annotations

import numpy as np
import trimesh

SKIN = np.array([0.62, 0.42, 0.33])   # linear


def render_view(meshes: list[dict], centre, view_dir, up, extent: float, size: int = 256) -> np.ndarray:
    """(size, size, 3) float32 linear RGB image of `meshes` seen along `view_dir` (orthographic, `extent` metres
    across).

    meshes: dicts with vertices (N, 3), faces (F, 3), and either "color" (3,) linear or
    "uvs" (T, 2) + "faces_uv" (F, 3) + "texture" (H, W, 3) linear, and optional "metallic" (scalar).
    """
    d = np.asarray(view_dir, float) / np.linalg.norm(view_dir)
    u = np.cross(d, up)
    u /= np.linalg.norm(u)
    v = np.cross(u, d)
    verts, faces, owner, offset = [], [], [], 0
    for k, m in enumerate(meshes):
        verts.append(m["vertices"])
        faces.append(m["faces"] + offset)
        owner.append(np.full(len(m["faces"]), k))
        offset += len(m["vertices"])
    owner = np.concatenate(owner)
    scene = trimesh.Trimesh(np.concatenate(verts), np.concatenate(faces), process=False)
    s = (np.arange(size) + 0.5) / size - 0.5
    gx, gy = np.meshgrid(s * extent, -s * extent)
    origins = np.asarray(centre) - d * extent * 2 + gx[..., None] * u + gy[..., None] * v
    origins = origins.reshape(-1, 3)
    dirs = np.tile(d, (len(origins), 1))
    tri, ray, loc = scene.ray.intersects_id(origins, dirs, multiple_hits=False, return_locations=True)
    img = np.tile(np.array([0.02, 0.02, 0.025]), (len(origins), 1))
    if len(tri):
        normals = scene.face_normals[tri]
        normals[np.einsum("ij,j->i", normals, d) > 0] *= -1
        lam = np.clip(-normals @ d, 0, 1)
        base = np.zeros((len(tri), 3))
        metallic = np.zeros(len(tri))
        face_start = np.cumsum([0] + [len(m["faces"]) for m in meshes])
        for k, m in enumerate(meshes):
            sel = owner[tri] == k
            if not sel.any():
                continue
            local = tri[sel] - face_start[k]
            if "texture" in m:
                bary = trimesh.triangles.points_to_barycentric(
                    m["vertices"][m["faces"][local]], loc[sel])
                uv = np.einsum("ij,ijk->ik", bary, m["uvs"][m["faces_uv"][local]])
                tex = m["texture"]
                h, w = tex.shape[:2]
                px = np.clip((uv[:, 0] * w).astype(int), 0, w - 1)
                py = np.clip(((1 - uv[:, 1]) * h).astype(int), 0, h - 1)
                base[sel] = tex[py, px]
            else:
                base[sel] = m.get("color", SKIN)
            metallic[sel] = m.get("metallic", 0.0)
        spec = lam ** 40
        shade = base * (0.25 + 0.75 * lam)[:, None] + (0.5 * metallic + 0.08)[:, None] * spec[:, None]
        img[ray] = shade
    return img.reshape(size, size, 3).astype(np.float32)
