"""Dual-quaternion skinning (Kavan et al. 2008, "Geometric skinning with approximate dual quaternion blending").

Used as the volume-preserving target the pose correctives are fitted to: the same rest shape, weights and joint
transforms G_i as the forward pass's LBS (taken from `forward(...).transforms`), but each vertex blends its joints'
rigid transforms as unit dual quaternions, so a twisted or bent joint keeps the skin's cross-section instead of
collapsing it (LBS's candy wrapper). Written here because none of the project's libraries skins with dual
quaternions; the quaternion conversions come from `rotations`.

A unit dual quaternion (q, d) represents the rigid map x -> R(q) x + t with d = 1/2 (0, t) q. Blending: per vertex,
b = sum_j w_j s_j (q_j, d_j), with s_j = +-1 chosen so that every q_j lies in the hemisphere of the vertex's
dominant joint (q and -q are the same rotation; without this the blend could cancel), then b / |b_q|.
"""

from __future__ import annotations

import numpy as np

from darthand.model.forward import forward, pose_feature
from darthand.model.hand_model import HandModel
from darthand.model.rotations import matrix_to_quaternion


def transforms_to_dual_quaternions(G: np.ndarray) -> np.ndarray:
    """(..., 8) unit dual quaternions [q (w, x, y, z), d (w, x, y, z)] of rigid transforms G (..., 4, 4)."""
    q = matrix_to_quaternion(G[..., :3, :3])
    t = G[..., :3, 3]
    w, v = q[..., :1], q[..., 1:]
    # d = 1/2 (0, t) q = 1/2 (-t.v, w t + t x v)
    d_w = -0.5 * np.sum(t * v, axis=-1, keepdims=True)
    d_v = 0.5 * (w * t + np.cross(t, v))
    return np.concatenate([q, d_w, d_v], axis=-1)


def blend_dual_quaternions(weights: np.ndarray, dq: np.ndarray) -> np.ndarray:
    """(B, V, 8) normalised per-vertex blends of joint dual quaternions dq (B, J, 8) with weights (V, J).

    Antipodality: joint j enters vertex v's blend with the sign of q_j . q_dom(v), dom(v) = argmax_j w_vj.
    """
    dominant = np.argmax(weights, axis=1)                                   # (V,)
    dots = np.einsum("bjk,bik->bji", dq[..., :4], dq[..., :4])              # (B, J, J) q_j . q_i
    signs = np.where(dots[:, dominant] >= 0, 1.0, -1.0)                     # (B, V, J)
    blended = np.einsum("bvj,bjk->bvk", signs * weights[None], dq)          # (B, V, 8)
    norm = np.linalg.norm(blended[..., :4], axis=-1, keepdims=True)
    return blended / norm


def apply_dual_quaternions(dq: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(..., 3) points transformed by unit dual quaternions dq (..., 8)."""
    w, v = dq[..., :1], dq[..., 1:4]
    d_w, d_v = dq[..., 4:5], dq[..., 5:8]
    # Rotation by q: p + 2 w (v x p) + 2 v x (v x p); translation t = 2 vec(d q*) = 2 (w d_v - d_w v + v x d_v).
    c = np.cross(v, points)
    rotated = points + 2 * (w * c + np.cross(v, c))
    return rotated + 2 * (w * d_v - d_w * v + np.cross(v, d_v))


def dqs(model: HandModel, pose, betas=None, *, flat_hand_mean: bool = True, trans=None, correctives: bool = False,
        chunk: int = 16) -> np.ndarray:
    """(B, V, 3) float64 vertices of `model` posed by dual-quaternion skinning.

    pose, betas, flat_hand_mean, trans: as for `forward`. correctives: add the model's pose-corrective offsets to the
    rest shape first (off by default: DQS is the target the correctives are fitted to). Poses are processed
    `chunk` at a time to bound the (chunk, V, 16) temporaries.
    """
    posed = forward(model, pose, betas, flat_hand_mean=flat_hand_mean, trans=trans, correctives=False)
    rest = rest_vertices(model, betas, posed.rotations if correctives else None)
    dq = transforms_to_dual_quaternions(posed.transforms)                   # (B, 16, 8)
    B = dq.shape[0]
    out = np.empty((B, model.num_vertices, 3))
    for s in range(0, B, chunk):
        e = min(B, s + chunk)
        blended = blend_dual_quaternions(model.weights, dq[s:e])
        out[s:e] = apply_dual_quaternions(blended, rest[s:e] if rest.shape[0] > 1 else rest)
    return out


def rest_vertices(model: HandModel, betas=None, rotations: np.ndarray | None = None) -> np.ndarray:
    """(1 or B, V, 3) rest shape: template + shape blend (betas (B, S) or (S,)) + correctives of `rotations`."""
    v = model.v_template[None]
    if betas is not None:
        b = np.atleast_2d(np.asarray(betas, dtype=np.float64))
        v = v + np.einsum("vcs,bs->bvc", model.shapedirs[:, :, :b.shape[1]], b)
    if rotations is not None:
        v = v + np.einsum("vck,bk->bvc", model.posedirs, pose_feature(rotations))
    return v
