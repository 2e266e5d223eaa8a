"""Synthetic MANO-layout models built by the tests themselves (the real MANO files are licensed).

`tube_hand` is a capped tube along -X (fingers toward -X, wrist opening at +X) with a 16-vertex boundary loop at
the wrist end, 16 joints laid out like a hand's, distance-based skin weights, random small correctives and shape
directions. It is not a hand, but it has every property the rig relies on: one wrist boundary loop, a closed
manifold elsewhere, consistent outward winding, a sparse regressor, UVs.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from darthand.model.hand_model import HandModel
from darthand.model.layout import MANO_PARENTS, NUM_JOINTS, NUM_POSE_FEATURES

RING = 16


def tube_mesh(n_rings: int = 12, radius: float = 0.03, length: float = 0.18):
    """Vertices (n_rings*16 + 1, 3) and outward faces of a tube along -X, open at x = 0, capped at x = -length.

    Ring 0 (vertices 0..15) is the open wrist loop at x = 0; the last vertex is the cap apex.
    """
    angles = 2 * np.pi * np.arange(RING) / RING
    xs = -np.linspace(0.0, length, n_rings)
    rings = [np.stack([np.full(RING, x), radius * np.cos(angles), radius * np.sin(angles)], 1) for x in xs]
    verts = np.concatenate(rings + [np.array([[-length - radius * 0.5, 0.0, 0.0]])])
    faces = []
    for r in range(n_rings - 1):
        for k in range(RING):
            a, b = r * RING + k, r * RING + (k + 1) % RING
            c, d = a + RING, b + RING
            faces += [(a, c, b), (b, c, d)]
    apex = len(verts) - 1
    last = (n_rings - 1) * RING
    faces += [(last + k, apex, last + (k + 1) % RING) for k in range(RING)]
    faces = np.array(faces, dtype=np.int64)
    return verts, _orient_outward(verts, faces)


def _orient_outward(verts, faces):
    """Flip all faces if the signed volume is negative (the tube is open, but nearly closed at the wrist)."""
    a, b, c = verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]]
    if np.einsum("ij,ij->i", a, np.cross(b, c)).sum() < 0:
        faces = faces[:, ::-1].copy()
    return faces


def joint_positions(length: float = 0.18) -> np.ndarray:
    """(16, 3) joint centres inside the tube, in MANO order, each chain running toward -X."""
    j = np.zeros((NUM_JOINTS, 3))
    j[0] = [-0.01, 0, 0]
    chains = {1: 0.012, 4: 0.004, 7: -0.012, 10: -0.004, 13: 0.02}  # first joint of each finger -> z offset
    for first, z in chains.items():
        for k in range(3):
            j[first + k] = [-0.06 - 0.035 * k, -0.005 * k, z]
    return j


def tube_hand(seed: int = 0, n_betas: int = 4, corrective_scale: float = 1e-3, with_uvs: bool = True) -> HandModel:
    """A small MANO-layout model with random but reproducible weights, correctives and shape directions."""
    rng = np.random.default_rng(seed)
    verts, faces = tube_mesh()
    V = len(verts)
    joints = joint_positions()
    d2 = ((verts[:, None, :] - joints[None]) ** 2).sum(-1)
    w = np.exp(-d2 / (2 * 0.02 ** 2))
    w[:, 0] += 1e-3
    w /= w.sum(1, keepdims=True)
    # Regressor: each joint is an average of its 4 nearest vertices, then corrected so R @ v == joints exactly.
    rows, cols, vals = [], [], []
    for i in range(NUM_JOINTS):
        near = np.argsort(d2[:, i])[:4]
        rows += [i] * 4
        cols += list(near)
        vals += [0.25] * 4
    regressor = sp.csr_matrix((vals, (rows, cols)), shape=(NUM_JOINTS, V))
    uvs = faces_uv = None
    if with_uvs:
        theta = np.arctan2(verts[:, 2], verts[:, 1]) % (2 * np.pi)
        uvs = np.stack([theta / (2 * np.pi), -verts[:, 0] / 0.2], 1).clip(0, 1)
        faces_uv = faces.copy()
    return HandModel.create(
        source="tube_hand",
        v_template=verts,
        faces=faces,
        weights=w,
        posedirs=corrective_scale * rng.standard_normal((V, 3, NUM_POSE_FEATURES)),
        J_regressor=regressor,
        parents=MANO_PARENTS,
        shapedirs=1e-3 * rng.standard_normal((V, 3, n_betas)),
        hands_mean=0.1 * rng.standard_normal(45),
        hands_components=np.linalg.qr(rng.standard_normal((45, 45)))[0].T,
        tip_ids=[V - 1, V - 2, V - 3, V - 4, V - 5],
        uvs=uvs,
        faces_uv=faces_uv,
        face_labels=np.zeros(len(faces), dtype=np.int8),
        meta={"name": "tube_hand", "seed": seed},
    )


CYL_RADIUS, CYL_LENGTH, CYL_RINGS, CYL_BLEND = 0.01, 0.16, 41, 0.04


def two_bone_cylinder() -> HandModel:
    """Tube along -X, radius 1 cm, 16 cm; joint 0 at x = 0, joint 1 at x = -8 cm on the axis; joint 1's weight
    ramps linearly 0 -> 1 over the 4 cm around it; the other joints carry no weight."""
    verts, faces = tube_mesh(CYL_RINGS, CYL_RADIUS, CYL_LENGTH)
    w1 = np.clip((-verts[:, 0] - (CYL_LENGTH / 2 - CYL_BLEND / 2)) / CYL_BLEND, 0, 1)
    weights = np.zeros((len(verts), NUM_JOINTS))
    weights[:, 0], weights[:, 1] = 1 - w1, w1
    ring_of = np.full(NUM_JOINTS, CYL_RINGS - 1)
    ring_of[0], ring_of[1] = 0, (CYL_RINGS - 1) // 2
    rows = np.repeat(np.arange(NUM_JOINTS), RING)
    cols = (ring_of[:, None] * RING + np.arange(RING)).ravel()
    regressor = sp.csr_matrix((np.full(len(rows), 1 / RING), (rows, cols)), shape=(NUM_JOINTS, len(verts)))
    return HandModel.create(source="two_bone_cylinder", v_template=verts, faces=faces, weights=weights,
                            posedirs=np.zeros((len(verts), 3, NUM_POSE_FEATURES)), J_regressor=regressor,
                            parents=MANO_PARENTS, tip_ids=[len(verts) - 1] * 5)
