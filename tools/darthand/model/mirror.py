"""Mirroring between right and left hands: x -> -x for geometry, conjugation by M = diag(-1, 1, 1) for rotations.

A rotation about axis n by theta becomes, under conjugation M R M, a rotation about det(M) M n = (n_x, -n_y, -n_z)
by theta, so axis-angle vectors map component-wise by (1, -1, -1). The corrective feature (R - I)_ab picks up the
sign s_a s_b (s = (-1, 1, 1)), and each offset's x component flips with the geometry.
"""

from __future__ import annotations

import numpy as np

from darthand.model.hand_model import HandModel
from darthand.model.layout import NUM_JOINTS

_S = np.array([-1.0, 1.0, 1.0])
_AA_SIGN = np.array([1.0, -1.0, -1.0])
_FEATURE_SIGN = np.tile(np.outer(_S, _S).reshape(-1), NUM_JOINTS - 1)   # (135,), flatten(R_i - I) order


def mirror_pose(pose) -> np.ndarray:
    """Mirror axis-angle pose(s) of shape (..., 48) or (..., 16, 3): (x, y, z) -> (x, -y, -z) per joint."""
    p = np.asarray(pose, dtype=np.float64 if np.asarray(pose).dtype.kind in "iub" else None)
    return (p.reshape(p.shape[:-1] + (-1, 3)) * _AA_SIGN).reshape(p.shape)


def mirror_points(points: np.ndarray) -> np.ndarray:
    """Points (..., 3) of the mirror-image hand: x -> -x."""
    return np.asarray(points) * _S


def mirror_posedirs(posedirs: np.ndarray) -> np.ndarray:
    """Pose correctives (N, 3, 135) of the mirror-image hand: each offset's x flips, each feature (R - I)_ab picks
    up the sign s_a s_b."""
    return np.asarray(posedirs) * _S[None, :, None] * _FEATURE_SIGN[None, None, :]


def mirror_model(model: HandModel) -> HandModel:
    """The mirror image of `model` (right <-> left): mirrored pose on it gives mirrored vertices."""
    flip = [0, 2, 1]   # reverses each triangle's winding, keeping its first corner
    comps = model.hands_components
    fields = dict(
        v_template=mirror_points(model.v_template),
        faces=model.faces[:, flip],
        shapedirs=model.shapedirs * _S[None, :, None],
        posedirs=mirror_posedirs(model.posedirs),
        hands_mean=mirror_pose(model.hands_mean),
        hands_components=mirror_pose(comps),
        side="left" if model.side == "right" else "right",
    )
    if model.faces_uv is not None:
        fields["faces_uv"] = model.faces_uv[:, flip]
    meta = dict(model.meta)
    meta["mirrored_from"] = model.side
    return model.replace(**fields, meta=meta)
