"""Per-face semantic labels (layout.FACE_LABELS): nail, palm, dorsum, finger_palmar, finger_dorsal, wrist.

- nail: the faces MPFB's fingernail mask covers in hm08's own UV atlas (the mask is drawn in that atlas, so this is
  read off the source rather than guessed from geometry);
- wrist: the forearm part, past the wrist joint along the forearm axis;
- palm / dorsum: the rest of the wrist joint's segment and the thumb's metacarpal (thumb1), split by the palm normal:
  palm where the surface, its normals smoothed over about a centimetre, faces -Y. (Splitting by position instead
  speckles the hand's sides, whose bumps straddle any plane; the smoothed normals give one clean border.);
- finger_palmar / finger_dorsal: each finger segment split by the side of its bend plane (the plane through the
  bone that contains the bend axis), palm side being away from the nail.
A face belongs to the segment of the joint with the largest summed skin weight over its corners.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from darthand.model.layout import FACE_LABEL_IDS, FINGER_JOINTS
from darthand.model.topology import face_joints

PALM_NORMAL = np.array([0.0, -1.0, 0.0])  # MANO's frame: the palm faces -Y


def nail_coverage(uvs: np.ndarray, faces_uv: np.ndarray, mask: np.ndarray, samples: int = 4) -> np.ndarray:
    """(F,) fraction of each face's area where `mask` (H, W; row 0 at v = 1) is above one half.

    The fraction is estimated on a regular barycentric grid of (samples+1)(samples+2)/2 points per face.
    """
    i, j = np.meshgrid(np.arange(samples + 1), np.arange(samples + 1), indexing="ij")
    keep = i + j <= samples
    bary = np.stack([i[keep], j[keep], samples - i[keep] - j[keep]], 1) / samples  # (S, 3)
    pts = np.einsum("sk,fkd->fsd", bary, uvs[faces_uv])  # (F, S, 2)
    H, W = mask.shape
    col = np.clip((pts[..., 0] * W).astype(np.int64), 0, W - 1)
    row = np.clip(((1.0 - pts[..., 1]) * H).astype(np.int64), 0, H - 1)
    return (mask[row, col] > 0.5).mean(1)


def smoothed_face_normals(vertices: np.ndarray, faces: np.ndarray, iterations: int) -> np.ndarray:
    """(F, 3) area-weighted face normals averaged `iterations` times over the faces sharing a vertex (not unit)."""
    n = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]])
    incidence = sp.csr_matrix((np.ones(faces.size), (np.repeat(np.arange(len(faces)), 3), faces.reshape(-1))))
    neighbours = (incidence @ incidence.T).tocsr()
    neighbours.data[:] = 1.0
    average = sp.diags(1.0 / np.asarray(neighbours.sum(1)).ravel()) @ neighbours
    for _ in range(iterations):
        n = average @ n
    return n


def label_faces(vertices: np.ndarray, faces: np.ndarray, weights: np.ndarray, joints: np.ndarray,
                bone_palmar: np.ndarray, nail: np.ndarray, forearm_axis: np.ndarray,
                normal_smoothing: int = 10) -> np.ndarray:
    """(F,) int8 label ids.

    vertices (V, 3), faces (F, 3), weights (V, 16), joints (16, 3); bone_palmar (16, 3) palm-side direction of
    each joint's bone (row 0 the palm normal); nail (F,) bool; forearm_axis (3,) unit, pointing from the wrist
    toward the elbow.
    """
    centres = vertices[faces].mean(1)
    segment = face_joints(faces, weights)
    metacarpal = np.isin(segment, (0, FINGER_JOINTS["thumb"][0]))
    finger_palm_side = np.einsum("fd,fd->f", centres - joints[segment], bone_palmar[segment]) > 0
    palm_facing = smoothed_face_normals(vertices, faces, normal_smoothing) @ PALM_NORMAL > 0
    palm_side = np.where(metacarpal, palm_facing, finger_palm_side)
    ids = FACE_LABEL_IDS
    labels = np.where(metacarpal, np.where(palm_side, ids["palm"], ids["dorsum"]),
                      np.where(palm_side, ids["finger_palmar"], ids["finger_dorsal"]))
    forearm = (segment == 0) & ((centres - joints[0]) @ forearm_axis > 0)
    labels[forearm] = ids["wrist"]
    labels[nail] = ids["nail"]
    return labels.astype(np.int8)
