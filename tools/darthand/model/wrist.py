"""DART's wrist alignment: extend a MANO-layout hand's wrist opening into a short forearm.

DART (Gao et al., NeurIPS 2022) extrudes 4 rings of MANO's 16-vertex wrist loop (778 -> 842 vertices, 1538 -> 1666
faces) and aligns the model: W[new] = W[777], P[new] = 0, regressor columns zero for the new vertices. The first V
vertices therefore pose exactly as before. Implemented here for any MANO-layout model.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from darthand.errors import InputError
from darthand.model.hand_model import HandModel
from darthand.model.layout import FACE_LABEL_IDS
from darthand.model.topology import boundary_loops

MANO_ANCHOR = 777  # the vertex DART copies weights from on MANO's 778-vertex mesh


def add_wrist(model: HandModel, rings: int = 4, length: float | None = None, taper: float = 1.0,
              anchor: int | None = None, smooth: bool = False) -> HandModel:
    """The wrist-enhanced model: `rings` rings of the wrist loop extruded along the forearm direction.

    length: forearm extension in metres (default: the loop's mean radius, about 4 cm on MANO's hand).
    taper: radius of the last ring relative to the loop (rings in between interpolate linearly).
    anchor: vertex whose weights every new vertex copies (default: 777 on a 778-vertex model, otherwise the loop
        vertex whose weights are most concentrated on the wrist joint).
    smooth: instead of copying the anchor, ring k of n starts from its own loop vertex's weights and blends them
        linearly to the pure root weight, so the forearm does not follow the palm's finger-driven deformation.
    """
    if rings < 1:
        raise InputError(f"rings: must be at least 1, got {rings}")
    if taper <= 0 or (length is not None and length <= 0):
        raise InputError("length and taper must be positive")
    loop = wrist_loop(model)
    left = model.side == "left"
    if left:  # walk the loop as its right-hand image runs, so the new vertices come in the same order either side
        loop = np.roll(loop[::-1], 1)
    centre, axis, radius = loop_frame(model, loop)
    length = radius if length is None else length
    new_vertices = extrude_rings(model.v_template[loop], centre, axis, rings, length, taper)
    V, L = model.num_vertices, len(loop)
    ring_ids = np.concatenate([loop[None], V + np.arange(rings * L).reshape(rings, L)])   # (rings+1, L)
    new_faces = ring_faces(ring_ids)[:, [0, 2, 1] if left else [0, 1, 2]]
    anchor = default_anchor(model, loop) if anchor is None else anchor
    if not 0 <= anchor < V:
        raise InputError(f"anchor: vertex {anchor} is outside 0..{V - 1}")
    fields = dict(
        v_template=np.concatenate([model.v_template, new_vertices]),
        faces=np.concatenate([model.faces, new_faces]),
        weights=np.concatenate([model.weights, ring_weights(model, loop, anchor, rings, smooth)]),
        posedirs=np.concatenate([model.posedirs, np.zeros((rings * L,) + model.posedirs.shape[1:])]),
        J_regressor=sp.hstack([model.J_regressor, sp.csr_matrix((model.J_regressor.shape[0], rings * L))]).tocsr(),
        shapedirs=np.concatenate([model.shapedirs, ring_shapedirs(model.shapedirs[loop], axis, rings, taper)]),
    )
    if model.has_uvs:
        fields["uvs"], fields["faces_uv"] = wrist_uvs(model, ring_ids, length, radius, left)
    if model.face_labels is not None:
        fields["face_labels"] = np.concatenate(
            [model.face_labels, np.full(len(new_faces), FACE_LABEL_IDS["wrist"], np.int8)])
    meta = dict(model.meta)
    meta["wrist"] = {"rings": rings, "ring_size": int(L), "base_vertices": V, "base_faces": model.num_faces,
                     "length_m": float(length), "taper": float(taper), "anchor": int(anchor), "smooth": bool(smooth),
                     "loop": loop.tolist()}
    return model.replace(**fields, meta=meta)


def wrist_loop(model: HandModel) -> np.ndarray:
    """The boundary loop nearest the wrist joint, ordered along its faces' edges."""
    try:
        loops = boundary_loops(model.faces)
    except ValueError as e:
        raise InputError(f"{model.meta.get('source', 'model')}: field 'faces' has a pinched boundary ({e})") from None
    if not loops:
        raise InputError(f"{model.meta.get('source', 'model')}: the mesh has no boundary loop (no wrist opening)")
    wrist = (model.J_regressor @ model.v_template)[0]
    return min(loops, key=lambda lp: np.linalg.norm(model.v_template[lp].mean(0) - wrist))


def loop_frame(model: HandModel, loop: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Loop centroid (3,), unit forearm direction (3,) and mean radius (m).

    The direction is the normal of the loop's least-squares plane, pointing away from the hand's centroid.
    """
    pts = model.v_template[loop]
    centre = pts.mean(0)
    axis = np.linalg.svd(pts - centre)[2][2]
    if np.dot(axis, centre - model.v_template.mean(0)) < 0:
        axis = -axis
    radius = float(np.linalg.norm((pts - centre) - np.outer((pts - centre) @ axis, axis), axis=1).mean())
    return centre, axis, radius


def extrude_rings(loop_pts: np.ndarray, centre: np.ndarray, axis: np.ndarray, rings: int, length: float,
                  taper: float) -> np.ndarray:
    """(rings * L, 3) new vertices, ring by ring.

    Ring k of n moves the loop k/n of `length` along `axis`, flattens it toward the loop's plane by k/n (the
    forearm end is planar) and scales its radius by 1 + (taper - 1) k/n.
    """
    rel = loop_pts - centre
    in_plane = rel - np.outer(rel @ axis, axis)
    out = []
    for k in range(1, rings + 1):
        t = k / rings
        shaped = (1 - t) * rel + t * in_plane
        out.append(centre + (1 + (taper - 1) * t) * shaped + axis * (length * t))
    return np.concatenate(out)


def ring_shapedirs(loop_dirs: np.ndarray, axis: np.ndarray, rings: int, taper: float) -> np.ndarray:
    """(rings * L, 3, S) shape directions of the new vertices from the loop's (L, 3, S).

    With the forearm axis and length held at the template's, `extrude_rings` is linear in the loop's positions
    (the centre is their mean, the flattening a projection), so extruding the loop's shape directions with the
    length term dropped gives directions under which a shaped hand's rings are exactly the rings extruded from its
    shaped loop: a wider wrist widens the forearm, and the forearm stays attached and planar-ended.
    """
    d = np.moveaxis(loop_dirs, 2, 0)                                     # (S, L, 3)
    centre = d.mean(axis=1, keepdims=True)
    rel = d - centre
    in_plane = rel - (rel @ axis)[..., None] * axis
    out = [centre + (1 + (taper - 1) * k / rings) * ((1 - k / rings) * rel + (k / rings) * in_plane)
           for k in range(1, rings + 1)]
    return np.moveaxis(np.concatenate(out, axis=1), 0, 2)


def ring_faces(ring_ids: np.ndarray) -> np.ndarray:
    """(2 * rings * L, 3) triangles joining consecutive rings of `ring_ids` (rings+1, L).

    The loop runs along its faces' directed edges (a -> b), so the new face on that edge runs b -> a: winding
    stays consistent with the hand.
    """
    a, b = ring_ids[:-1], np.roll(ring_ids[:-1], -1, axis=1)
    c, d = ring_ids[1:], np.roll(ring_ids[1:], -1, axis=1)
    tris = np.stack([np.stack([b, a, c], -1), np.stack([b, c, d], -1)], axis=2)   # (rings, L, 2, 3)
    return tris.reshape(-1, 3)


def default_anchor(model: HandModel, loop: np.ndarray) -> int:
    """DART's vertex 777 on MANO's mesh; otherwise the loop vertex with the largest wrist weight."""
    if model.num_vertices == 778:
        return MANO_ANCHOR
    return int(loop[np.argmax(model.weights[loop, 0])])


def ring_weights(model: HandModel, loop: np.ndarray, anchor: int, rings: int, smooth: bool) -> np.ndarray:
    """(rings * L, 16) skin weights of the new vertices."""
    L = len(loop)
    if not smooth:
        return np.tile(model.weights[anchor], (rings * L, 1))
    root = np.zeros(model.weights.shape[1])
    root[0] = 1.0
    t = (np.arange(1, rings + 1) / rings)[:, None, None]
    return ((1 - t) * model.weights[loop][None] + t * root).reshape(rings * L, -1)


def wrist_uvs(model: HandModel, ring_ids: np.ndarray, length: float, radius: float,
              left: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """UVs and faces_uv for the model with the wrist: the rings get a rectangle of their own in the atlas.

    The rectangle is `meta['wrist_uv_band']` = [u0, v0, u1, v1] when the template reserved one; otherwise the
    existing UVs are scaled uniformly into [0, s]^2 and the rings take the strip v in [s, 1] (u around the loop,
    v along the forearm), its height matching the hand's texel density. A seam runs along the wrist loop, as
    anywhere two UV islands meet.
    """
    uvs = model.uvs
    assert uvs is not None and model.faces_uv is not None, "wrist UVs extend the model's own"
    band = model.meta.get("wrist_uv_band")
    if band is None:
        h = float(np.clip(length / (2 * np.pi * radius), 0.05, 0.25))
        s = 1.0 - h
        uvs = uvs * s
        band = [0.0, s, 1.0, 1.0]
    u0, v0, u1, v1 = band
    n_rings, L = ring_ids.shape
    # (n_rings, L + 1) grid: the extra column closes the loop at u = u1.
    u = np.linspace(u0, u1, L + 1)
    v = np.linspace(v0, v1, n_rings)
    grid = np.stack(np.meshgrid(u, v), -1).reshape(-1, 2)
    base = len(uvs)
    idx = base + np.arange(n_rings * (L + 1)).reshape(n_rings, L + 1)
    a, b = idx[:-1, :-1], idx[:-1, 1:]
    c, d = idx[1:, :-1], idx[1:, 1:]
    faces_uv = np.stack([np.stack([b, a, c], -1), np.stack([b, c, d], -1)], axis=2).reshape(-1, 3)
    if left:  # as the ring faces: wound the other way
        faces_uv = faces_uv[:, [0, 2, 1]]
    return np.concatenate([uvs, grid]), np.concatenate([model.faces_uv, faces_uv])
