"""The forward pass: MANO's linear blend skinning, batched, in float32 or float64.

Exactly MANO's order (Romero et al. 2017; smplx's `lbs`): shape blend, joint regression from the shaped template,
rotations from axis-angle, pose feature flatten(R_i - I) for i = 1..15, corrective offsets, kinematic chain,
linear blend skinning. Written here rather than taken from smplx because smplx needs PyTorch; the maths is laid out
so each step is one short function, and the two large products (correctives, blended transforms) are single BLAS
matrix products over the whole batch.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np

from darthand.budget import check_memory
from darthand.errors import InputError
from darthand.model.hand_model import HandModel
from darthand.model.layout import KEYPOINT_ORDERS, NUM_JOINTS
from darthand.model.rotations import axis_angle_to_matrix, check_finite_pose


# Largest magnitudes accepted at the API: poses in radians (MANO's are within +-pi; 1e4 keeps float32 maths
# finite), betas in standard deviations of the shape space (MANO's are within +-5), translations in metres.
MAX_MAGNITUDE = {"pose": 1e4, "betas": 100.0, "trans": 1e4}


@dataclass(frozen=True)
class Posed:
    """The result of `forward` for a batch of B poses (metres, the model's frame)."""

    vertices: np.ndarray    # (B, V, 3)
    joints: np.ndarray      # (B, 16, 3) posed joint centres
    keypoints: np.ndarray   # (B, 21, 3) joints and fingertips in the requested order
    rotations: np.ndarray   # (B, 16, 3, 3) local rotations R_i (R_0 is the global wrist rotation)
    transforms: np.ndarray  # (B, 16, 4, 4) skinning transforms G_i: a rest point x bound to joint i goes to G_i [x, 1]

    @property
    def world_rotations(self) -> np.ndarray:
        """(B, 16, 3, 3) accumulated rotation of each joint's frame."""
        return self.transforms[:, :, :3, :3]


def forward(model: HandModel, pose, betas=None, *, flat_hand_mean: bool = True, ncomps: int | None = None,
            trans=None, dtype=np.float64, keypoint_order: str = "mano", correctives: bool = True) -> Posed:
    """Pose `model`.

    pose: axis-angle, (B, 48), (B, 16, 3) or (48,); with `ncomps`, (B, 3 + ncomps): global rotation then PCA
        coefficients of the finger pose over `hands_components[:ncomps]`.
    betas: (B, S) or (S,) shape coefficients, S <= model.num_betas (missing ones are zero).
    flat_hand_mean: True poses relative to the flat hand (pose 0 = flat); False adds `hands_mean` to the finger
        pose, as MANO does by default.
    trans: (B, 3) or (3,) global translation in metres, added last.
    dtype: np.float32 (fast path) or np.float64.
    """
    dtype = np.dtype(dtype)
    if dtype not in (np.float32, np.float64):
        raise InputError(f"dtype: {dtype} is not supported, use float32 or float64")
    aa = full_pose(model, pose, flat_hand_mean=flat_hand_mean, ncomps=ncomps).astype(dtype, copy=False)
    B = aa.shape[0]
    # vertices, posed and shaped templates, correctives and the skinning temporaries: about 6 (B, V, 3) arrays
    check_memory(f"posing {B} poses of a {model.num_vertices}-vertex model",
                 6 * B * model.num_vertices * 3 * dtype.itemsize)
    arrays = _prepared(model, dtype)
    v_shaped, joints = shape_blend(model, arrays, betas, B, dtype)         # (1|B, 3, V), (1|B, 16, 3)
    rotations = axis_angle_to_matrix(aa)                                   # (B, 16, 3, 3)
    if correctives:
        v_posed = corrective_offsets(arrays, rotations)
        v_posed += v_shaped
    else:
        v_posed = v_shaped
    transforms, posed_joints = kinematic_chain(rotations, joints, model.parents)  # (B, 16, 4, 4), (B, 16, 3)
    vertices = skin(arrays["weights_T"], transforms, v_posed)              # (B, V, 3)
    if trans is not None:
        t = _batch(trans, (3,), B, "trans").astype(dtype, copy=False)[:, None, :]
        vertices = vertices + t
        posed_joints = posed_joints + t
        transforms = transforms.copy()
        transforms[:, :, :3, 3] += t
    keypoints = select_keypoints(posed_joints, vertices, model.tip_ids, keypoint_order)
    return Posed(vertices, posed_joints, keypoints, rotations, transforms)


def full_pose(model: HandModel, pose, *, flat_hand_mean: bool = True, ncomps: int | None = None) -> np.ndarray:
    """(B, 16, 3) axis-angle of every joint from a pose in any accepted layout; rejects NaN/Inf with its index."""
    p = np.asarray(pose)
    if not np.issubdtype(p.dtype, np.number):
        raise InputError(f"pose: expected numbers, got dtype {p.dtype}")
    p = p.astype(np.float64 if p.dtype.kind in "iub" else p.dtype, copy=False)
    if ncomps is not None:
        if not 1 <= ncomps <= model.hands_components.shape[0]:
            raise InputError(f"ncomps: {ncomps} is outside 1..{model.hands_components.shape[0]}")
        p = p.reshape(1, -1) if p.ndim == 1 else p
        if p.ndim != 2 or p.shape[1] != 3 + ncomps:
            raise InputError(f"pose: shape {p.shape} does not match ncomps={ncomps} (expected (B, {3 + ncomps}))")
        check_finite_pose(p)
        fingers = p[:, 3:] @ model.hands_components[:ncomps].astype(p.dtype)
        p = np.concatenate([p[:, :3], fingers], axis=1)
    elif p.ndim == 1:
        p = p.reshape(1, -1)
    if p.shape[-2:] == (NUM_JOINTS, 3) and p.ndim == 3:
        p = p.reshape(p.shape[0], -1)
    if p.ndim != 2 or p.shape[1] != 3 * NUM_JOINTS:
        raise InputError(f"pose: shape {p.shape} is not (B, 48), (B, 16, 3) or (48,)")
    check_finite_pose(p)
    with np.errstate(invalid="ignore"):
        big = np.abs(p) > MAX_MAGNITUDE["pose"]
    if big.any():
        b, k = np.unravel_index(int(np.argmax(big)), p.shape)
        raise InputError(f"pose: value {p[b, k]:g} at [{b}, {k}] is beyond +-{MAX_MAGNITUDE['pose']:g} radians "
                         "(an axis-angle rotation needs at most pi)")
    if not flat_hand_mean:
        p = p.copy()
        p[:, 3:] += model.hands_mean.astype(p.dtype)
    return p.reshape(-1, NUM_JOINTS, 3)


def shape_blend(model: HandModel, arrays: dict, betas, B: int, dtype) -> tuple[np.ndarray, np.ndarray]:
    """Shaped template, coordinate-major (1 or B, 3, V), and its regressed joints (1 or B, 16, 3).

    Without betas the batch shares one template (leading dimension 1, broadcast later), which saves the per-pose
    regression.
    """
    if betas is None:
        return arrays["v_template"][None], arrays["joints"][None]
    b = _batch(betas, None, B, "betas").astype(dtype, copy=False)
    S = b.shape[1]
    if S > model.num_betas:
        raise InputError(f"betas: {S} given but the model has {model.num_betas} shape directions")
    offsets = (b @ arrays["shapedirs_T"][:S]).reshape(b.shape[0], 3, -1)
    # J = R (v_template + shapedirs beta) = J_template + (R shapedirs) beta: the joints' own small blend.
    joints = arrays["joints"][None] + (b @ arrays["shape_joints"][:S]).reshape(b.shape[0], -1, 3)
    return arrays["v_template"][None] + offsets, joints


def pose_feature(rotations: np.ndarray) -> np.ndarray:
    """(B, 135) corrective feature flatten(R_i - I), i = 1..15, from (B, 16, 3, 3) rotations."""
    B = rotations.shape[0]
    return (rotations[:, 1:] - np.eye(3, dtype=rotations.dtype)).reshape(B, 9 * (rotations.shape[1] - 1))


def corrective_offsets(arrays: dict, rotations: np.ndarray) -> np.ndarray:
    """(B, 3, V) pose-corrective offsets, coordinate-major: one (B, 135) x (135, 3V) product."""
    B = rotations.shape[0]
    return (pose_feature(rotations) @ arrays["posedirs_T"]).reshape(B, 3, arrays["weights_T"].shape[1])


def kinematic_chain(rotations: np.ndarray, joints: np.ndarray, parents: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(B, 16, 4, 4) skinning transforms G_i = A_i [I, -J_i], A_i = A_parent [R_i, J_i - J_parent], and the posed
    joint centres (B, 16, 3) (the translations of A_i).

    rotations: (B, 16, 3, 3); joints: (1 or B, 16, 3) rest joint centres. Joints of one depth are composed together
    (three levels for MANO), so the chain costs a few batched products instead of 15.
    """
    B, dtype = rotations.shape[0], rotations.dtype
    joints = np.broadcast_to(joints, (B,) + joints.shape[1:])
    rel = joints.copy()
    rel[:, 1:] -= joints[:, parents[1:]]
    world_R = np.empty_like(rotations)
    world_t = np.empty((B, NUM_JOINTS, 3), dtype)
    world_R[:, 0], world_t[:, 0] = rotations[:, 0], joints[:, 0]
    for level in _levels(parents):
        par = parents[level]
        world_R[:, level] = world_R[:, par] @ rotations[:, level]
        world_t[:, level] = world_t[:, par] + np.einsum("bjik,bjk->bji", world_R[:, par], rel[:, level])
    G = np.zeros((B, NUM_JOINTS, 4, 4), dtype)
    G[:, :, :3, :3] = world_R
    G[:, :, :3, 3] = world_t - np.einsum("bjik,bjk->bji", world_R, joints)
    G[:, :, 3, 3] = 1
    return G, world_t


def skin(weights_T: np.ndarray, transforms: np.ndarray, v_posed: np.ndarray, chunk: int = 32) -> np.ndarray:
    """(B, V, 3) linear blend skinning: sum_j w_vj G_j [v, 1].

    weights_T (16, V); transforms (B, 16, 4, 4); v_posed (1 or B, 3, V), coordinate-major. Per chunk of poses the
    blended transforms come from one (12 n, 16) x (16, V) product, laid out (n, 3, 4, V) so that applying them is
    contiguous multiply-adds; chunks keep those temporaries in cache (about 5x faster than one pass at B = 1024).
    """
    B, V = transforms.shape[0], weights_T.shape[1]
    G = np.ascontiguousarray(transforms[:, :, :3, :].reshape(B, NUM_JOINTS, 12).transpose(0, 2, 1))
    G = G.reshape(B * 12, NUM_JOINTS)
    dtype = transforms.dtype
    out = np.empty((B, V, 3), dtype=dtype)
    # Scratch buffers reused across chunks: fresh temporaries of this size cost page faults on every call.
    T_buf = np.empty((chunk * 12, V), dtype=dtype)
    blended_buf = np.empty((chunk, 3, V), dtype=dtype)
    term_buf = np.empty((chunk, 3, V), dtype=dtype)
    for s in range(0, B, chunk):
        e = min(B, s + chunk)
        n = e - s
        T = np.matmul(G[12 * s:12 * e], weights_T, out=T_buf[:12 * n]).reshape(n, 3, 4, V)
        v = v_posed[s:e] if v_posed.shape[0] > 1 else v_posed
        blended, term = blended_buf[:n], term_buf[:n]
        np.copyto(blended, T[:, :, 3])
        for k in range(3):
            np.multiply(T[:, :, k], v[:, None, k], out=term)
            blended += term
        out[s:e] = blended.transpose(0, 2, 1)
    return out


def select_keypoints(joints: np.ndarray, vertices: np.ndarray, tip_ids: np.ndarray, order: str) -> np.ndarray:
    """(B, 21, 3): the 16 joints then the 5 tip vertices (thumb..pinky), permuted into a named order."""
    if order not in KEYPOINT_ORDERS:
        raise InputError(f"keypoint_order: {order!r} is not one of {sorted(KEYPOINT_ORDERS)}")
    kp = np.concatenate([joints, vertices[:, tip_ids]], axis=1)
    return kp[:, KEYPOINT_ORDERS[order]]


def _levels(parents: np.ndarray) -> list[np.ndarray]:
    """Joints grouped by depth below the root (root excluded), in order."""
    depth = np.zeros(len(parents), dtype=np.int64)
    for i in range(1, len(parents)):
        depth[i] = depth[parents[i]] + 1
    return [np.flatnonzero(depth == d) for d in range(1, depth.max() + 1)]


def _batch(x, tail: tuple | None, B: int, name: str) -> np.ndarray:
    """Broadcast a per-batch or shared argument to (B, ...), checking finiteness."""
    a = np.asarray(x, dtype=np.float64) if np.asarray(x).dtype.kind in "iub" else np.asarray(x)
    if a.ndim == 1:
        a = a[None]
    if a.ndim != 2 or (tail is not None and a.shape[1:] != tail) or a.shape[0] not in (1, B):
        raise InputError(f"{name}: shape {np.asarray(x).shape} does not fit a batch of {B}")
    if a.dtype.kind not in "biuf":
        raise InputError(f"{name}: expected real numbers, got dtype {a.dtype}")
    with np.errstate(invalid="ignore"):
        bad = ~(np.abs(a) <= MAX_MAGNITUDE[name])
    if bad.any():
        i, j = np.unravel_index(int(np.argmax(bad)), a.shape)
        what = "non-finite value" if not np.isfinite(a[i, j]) else f"value beyond +-{MAX_MAGNITUDE[name]:g}"
        raise InputError(f"{name}: {what} {a[i, j]} at [{i}, {j}]")
    return np.broadcast_to(a, (B, a.shape[1]))


_CACHE: "weakref.WeakKeyDictionary[HandModel, dict]" = weakref.WeakKeyDictionary()


def _prepared(model: HandModel, dtype) -> dict:
    """Per-model arrays in the layout and dtype the products want, built once per (model, dtype)."""
    per_model = _CACHE.setdefault(model, {})
    key = np.dtype(dtype).str
    if key not in per_model:
        V = model.num_vertices
        per_model[key] = {
            "v_template": np.ascontiguousarray(model.v_template.T, dtype=dtype),       # (3, V)
            "joints": (model.J_regressor @ model.v_template).astype(dtype),          # (16, 3)
            "weights_T": np.ascontiguousarray(model.weights.T, dtype=dtype),         # (16, V)
            # (K, 3V) coordinate-major: offsets come out as (B, 3, V).
            "posedirs_T": np.ascontiguousarray(model.posedirs.transpose(2, 1, 0).reshape(-1, 3 * V), dtype=dtype),
            "shapedirs_T": np.ascontiguousarray(model.shapedirs.transpose(2, 1, 0).reshape(-1, 3 * V), dtype=dtype),
            # (S, 16 * 3): the joints' shape directions, J_regressor applied to each of the surface's.
            "shape_joints": np.einsum("jv,vcs->sjc", model.J_regressor.toarray(), model.shapedirs).reshape(
                model.num_betas, 3 * model.J_regressor.shape[0]).astype(dtype),
        }
    return per_model[key]
