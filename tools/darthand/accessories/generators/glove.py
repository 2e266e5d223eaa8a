"""Gloves: a shell over the hand that deforms with it.

The glove is the hand's own surface (up to a cuff on the forearm; fingerless gloves also stop partway along each
proximal phalanx) offset along smoothed vertex normals twice -- an inner layer `clearance` off the skin and an outer
layer `clearance + thickness` off it -- joined at every boundary by a rim, so it is a closed solid. Each glove
vertex copies the skinning weights, correctives and shape directions of the hand vertex it came from, so the glove
poses with the hand's own forward pass. Texture coordinates are the hand's; the texture is procedural per style.
Unlike the rigid generators this one needs the hand model: `glove(model, params, rng)`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from darthand.accessories import textures as tx
from darthand.accessories.fit import RING_JOINTS, wrist_axis
from darthand.accessories.mesh import AccessoryMesh
from darthand.model.anatomy import bone_ends, rest_joints
from darthand.model.hand_model import HandModel
from darthand.model.layout import FACE_LABEL_IDS, FINGER_JOINTS
from darthand.model.topology import directed_edges, signed_volume, vertex_normals

STYLES = ("latex", "wool", "leather", "fingerless", "gardening")


def glove(model: HandModel, params: dict, rng: np.random.Generator, texture_size: int = 512) -> AccessoryMesh:
    """A glove of params["style"] with params["thickness"], params["clearance"] and params["cuff"] (metres from
    the wrist joint along the forearm); fingerless gloves cut at params["cut"] (fraction of the proximal phalanx).

    The returned mesh's `skin` holds weights (N, 16), posedirs (N, 3, 135), shapedirs (N, 3, S), source_vertex (N,)
    (the hand vertex each glove vertex follows), layer (N,) (0 outer, 1 inner) and inner_faces (F,) bool.
    """
    cut = float(params.get("cut", 0.5)) if params["style"] == "fingerless" else None
    keep_v = covered_vertices(model, float(params["cuff"]), cut)
    faces = manifold_subset(model.faces, keep_v[model.faces].all(1))
    used = np.unique(model.faces[faces])
    normals = smoothed_normals(model.v_template, model.faces, iterations=int(params.get("smooth", 3)))
    c, t = float(params["clearance"]), float(params["thickness"])
    base = model.v_template[used]
    outer, inner = base + (c + t) * normals[used], base + c * normals[used]
    remap = np.full(model.num_vertices, -1)
    remap[used] = np.arange(len(used))
    n = len(used)
    f = remap[model.faces[faces]]
    rim = rim_faces(f, n)
    all_faces = np.concatenate([f, f[:, ::-1] + n, rim])
    verts = np.concatenate([outer, inner])
    # UVs: the hand's per-corner UVs for both layers; a rim corner takes the UV its vertex has in its boundary face.
    uvs, fuv_hand = _hand_uvs(model)
    fuv = fuv_hand[faces]
    rim_uv = _rim_uvs(f, fuv, rim, n)
    all_fuv = np.concatenate([fuv, fuv[:, ::-1], rim_uv])
    if signed_volume(verts, all_faces) < 0:
        all_faces, all_fuv = all_faces[:, ::-1].copy(), all_fuv[:, ::-1].copy()
    src = np.concatenate([used, used])
    skin = {"weights": model.weights[src], "posedirs": model.posedirs[src], "shapedirs": model.shapedirs[src],
            "source_vertex": src, "layer": np.repeat(np.array([0, 1], np.int8), n),
            "inner_faces": np.concatenate([np.zeros(len(f), bool), np.ones(len(f), bool), np.zeros(len(rim), bool)])}
    textures, material = _look(model, params, rng, texture_size, faces)
    dims = {"thickness": t, "clearance": c, "cuff": float(params["cuff"]), "covered_faces": int(len(faces))}
    return AccessoryMesh(verts, all_faces.astype(np.int64), uvs, all_fuv.astype(np.int64), material, textures, dims,
                         skin=skin)


def covered_vertices(model: HandModel, cuff: float, cut: float | None) -> np.ndarray:
    """(V,) bool: hand vertices the glove covers -- those before the cuff, minus (if `cut` is given) those past
    `cut` of the way along each finger's proximal phalanx or on the phalanges beyond it."""
    j0, axis = wrist_axis(model)
    keep = (model.v_template - j0) @ axis <= cuff
    if cut is None:
        return keep
    joints = rest_joints(model)
    ends = bone_ends(model, joints)
    dominant = np.argmax(model.weights, axis=1)
    for finger, chain in FINGER_JOINTS.items():
        j = RING_JOINTS[finger]
        distal = [k for k in chain if k > j]
        seg = ends[j] - joints[j]
        t = (model.v_template - joints[j]) @ seg / (seg @ seg)
        keep &= ~np.isin(dominant, distal)
        keep &= ~((dominant == j) & (t > cut))
    return keep


def manifold_subset(faces: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """Indices of the kept faces after removing, repeatedly, the faces at vertices where the kept region's
    boundary is pinched (two boundary loops through one vertex), so the boundary is a set of simple loops."""
    keep = keep.copy()
    while True:
        f = faces[keep]
        d = directed_edges(f)
        key = np.sort(d, axis=1)
        _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
        boundary = d[cnt[inv.reshape(-1)] == 1]
        out_deg = np.bincount(boundary[:, 0], minlength=faces.max() + 1)
        pinched = np.where(out_deg > 1)[0]
        if len(pinched) == 0:
            return np.where(keep)[0]
        keep &= ~np.isin(faces, pinched).any(1)


def rim_faces(f: np.ndarray, n: int) -> np.ndarray:
    """Two triangles per boundary edge (a -> b of the outer layer) joining it to the inner layer (vertex + n)."""
    d = directed_edges(f)
    key = np.sort(d, axis=1)
    _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    a, b = d[cnt[inv.reshape(-1)] == 1].T
    return np.concatenate([np.stack([b, a, a + n], 1), np.stack([b, a + n, b + n], 1)])


def _rim_uvs(f: np.ndarray, fuv: np.ndarray, rim: np.ndarray, n: int) -> np.ndarray:
    """Per-corner UV indices of the rim faces: each corner takes its vertex's UV in the face owning the edge."""
    d = directed_edges(f)
    corner_uv = np.stack([fuv, np.roll(fuv, -1, axis=1)], -1).reshape(-1, 2)   # UV ids of (a, b) per directed edge
    lookup = {(int(a), int(b)): (int(ua), int(ub)) for (a, b), (ua, ub) in zip(d, corner_uv)}
    out = np.empty_like(rim)
    half = len(rim) // 2
    for i in range(half):
        b, a = int(rim[i, 0]), int(rim[i, 1])
        ua, ub = lookup[(a, b)]
        out[i] = (ub, ua, ua)
        out[half + i] = (ub, ua, ub)
    return out


def smoothed_normals(vertices: np.ndarray, faces: np.ndarray, iterations: int = 3) -> np.ndarray:
    """Area-weighted vertex normals averaged with their one-ring `iterations` times (softens offsets at creases)."""
    n = vertex_normals(vertices, faces)
    e = directed_edges(faces)
    V = len(vertices)
    adj = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(V, V)).tocsr()
    adj = ((adj + adj.T) > 0).astype(float) + sp.eye(V)
    for _ in range(iterations):
        n = adj @ n
        n /= np.linalg.norm(n, axis=1, keepdims=True)
    return n


def _hand_uvs(model: HandModel) -> tuple[np.ndarray, np.ndarray]:
    """The hand's UVs, or (for a model without them) a planar map of its x, z coordinates."""
    if model.uvs is not None and model.faces_uv is not None:
        return model.uvs, model.faces_uv
    v = model.v_template[:, [0, 2]]
    uv = (v - v.min(0)) / np.maximum(np.ptp(v, axis=0), 1e-9)
    return uv, model.faces


def _look(model: HandModel, params: dict, rng, size: int, faces: np.ndarray):
    style = params["style"]
    color = params.get("color", (0.1, 0.2, 0.6))
    if style == "latex":
        base, mr = tx.rubber(color, rng, size, roughness=float(params.get("roughness", 0.35)))
    elif style == "wool":
        base, mr = tx.knit(color, rng, size)
    elif style == "leather":
        base, mr = tx.leather(color, rng, size, stitch_color=None)
    elif style == "fingerless":
        base, mr = (tx.knit(color, rng, size) if params.get("material", "wool") == "wool"
                    else tx.leather(color, rng, size, stitch_color=None))
    elif style == "gardening":
        base, mr = tx.fabric(color, color, rng, size, stripes=0)
        palm = palm_mask(model, faces, size)
        coat = np.asarray(params.get("palm_color", (0.5, 0.05, 0.03)), np.float32)
        base[palm] = coat * (1 + 0.05 * tx.noise(rng, size, 2.0))[palm][:, None]
        mr[palm, 1] = 0.5
    else:
        raise ValueError(f"unknown glove style {style!r}")
    material = {"kind": style, "base_color": list(map(float, color)), "metallic": 0.0,
                "roughness": float(np.median(mr[..., 1]))}
    return {"base_color": np.clip(base, 0, 1).astype(np.float32), "metallic_roughness": mr}, material


def palm_mask(model: HandModel, faces: np.ndarray, size: int) -> np.ndarray:
    """(size, size) bool: texels covered by the palm-side faces (palm, finger_palmar labels) in UV space;
    without labels, faces whose normal points to the palm side (-Y)."""
    uvs, fuv = _hand_uvs(model)
    if model.face_labels is not None and (model.face_labels[faces] >= 0).any():
        lab = model.face_labels[faces]
        sel = faces[(lab == FACE_LABEL_IDS["palm"]) | (lab == FACE_LABEL_IDS["finger_palmar"])]
    else:
        t = model.v_template[model.faces[faces]]
        nrm = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        sel = faces[nrm[:, 1] < 0]
    return rasterise(uvs[fuv[sel]], size)


def rasterise(tri_uv: np.ndarray, size: int) -> np.ndarray:
    """(size, size) bool mask of the texels whose centres fall in any of the UV triangles (T, 3, 2)."""
    mask = np.zeros((size, size), bool)
    px = tri_uv[..., 0] * size - 0.5
    py = (1 - tri_uv[..., 1]) * size - 0.5
    for (x0, x1, x2), (y0, y1, y2) in zip(px, py):
        c0, c1 = int(max(np.floor(min(x0, x1, x2)), 0)), int(min(np.ceil(max(x0, x1, x2)), size - 1))
        r0, r1 = int(max(np.floor(min(y0, y1, y2)), 0)), int(min(np.ceil(max(y0, y1, y2)), size - 1))
        if c1 < c0 or r1 < r0:
            continue
        yy, xx = np.mgrid[r0:r1 + 1, c0:c1 + 1]
        den = (y1 - y2) * (x0 - x2) + (x2 - x1) * (y0 - y2)
        if abs(den) < 1e-12:
            continue
        l0 = ((y1 - y2) * (xx - x2) + (x2 - x1) * (yy - y2)) / den
        l1 = ((y2 - y0) * (xx - x2) + (x0 - x2) * (yy - y2)) / den
        inside = (l0 >= -1e-9) & (l1 >= -1e-9) & (1 - l0 - l1 >= -1e-9)
        mask[r0:r1 + 1, c0:c1 + 1] |= inside
    return mask
