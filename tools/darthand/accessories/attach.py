"""Rigid attachment: an accessory bound to one joint keeps a fixed transform relative to it.

The bind is (joint j, rest 4x4 mapping the accessory's local frame to the model's rest frame). The forward pass's
skinning transform G_j moves any rest point rigidly bound to joint j, so the posed placement is G_j @ rest.
"""

from __future__ import annotations

import numpy as np

from darthand.model.forward import pose_feature, skin


def posed_placement(transforms: np.ndarray, joint: int, rest: np.ndarray) -> np.ndarray:
    """(B, 4, 4) local-to-world placements for skinning transforms (B, 16, 4, 4)."""
    return transforms[:, joint] @ rest


def apply(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Points (N, 3) moved by one (4, 4) or a batch (B, 4, 4) of transforms -> (N, 3) or (B, N, 3)."""
    return points @ np.swapaxes(matrix[..., :3, :3], -1, -2) + matrix[..., None, :3, 3]


def to_local(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    """World points (..., N, 3) in the frame of a rigid transform (..., 4, 4) (its inverse applied)."""
    return (points - matrix[..., None, :3, 3]) @ matrix[..., :3, :3]


def axis_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance (...,) from points (..., 3) to the lines through a and b (..., 3)."""
    d = b - a
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    r = points - a
    return np.linalg.norm(r - (r * d).sum(-1, keepdims=True) * d, axis=-1)


def pose_skinned(vertices: np.ndarray, weights: np.ndarray, posedirs: np.ndarray, rotations: np.ndarray,
                 transforms: np.ndarray) -> np.ndarray:
    """(B, N, 3) a skinned accessory (a glove) posed like the hand: its own correctives, then the forward pass's
    linear blend skinning with the hand's transforms. vertices (N, 3), weights (N, 16), posedirs (N, 3, 135),
    rotations (B, 16, 3, 3), transforms (B, 16, 4, 4) from `forward`."""
    B, N = rotations.shape[0], len(vertices)
    offsets = (pose_feature(rotations) @ posedirs.transpose(2, 1, 0).reshape(-1, 3 * N)).reshape(B, 3, N)
    return skin(np.ascontiguousarray(weights.T), transforms, vertices.T[None] + offsets)
