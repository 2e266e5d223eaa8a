"""Anatomical pose space: per-joint twist/spread/bend axes, joint limits, and conversion to and from MANO axis-angle.

Every joint i has an orthonormal, right-handed frame F_i (columns: twist, spread, bend axes, written in the model's
rest frame) derived from the rest template:

    twist   t = unit bone direction, joint -> child joint (-> the fingertip vertex for the distal joints,
               wrist -> middle-finger MCP for the root)
    bend    b = unit(t x n), n the joint's palmar direction: a positive rotation about b turns the bone toward n,
               i.e. a positive bend (flexion) curls the digit toward its palmar side
    spread  s = b x t (n made orthogonal to the bone): a positive spread moves the bone toward -b

The palmar direction n is the palm normal (least-squares plane of the wrist and finger MCPs, facing -Y in MANO's
frame) for the wrist, the four fingers and the thumb's CMC; there a positive bend curls toward the palm (-Y) and a
positive spread moves the digit toward the little-finger side (for the thumb CMC: toward the index finger). The
thumb's MCP and IP flex toward the thumb's own pad, which in a resting hand faces the index finger, not the palm:
for them n is the thumb pad direction, minus the mean normal of the thumb's nail faces (`face_labels`), or, for a
model without nail labels, the palm normal rolled about the thumb bone by THUMB_PAD_ROLL_DEG.

Anatomical angles (..., 16, 3) are [twist, spread, bend] in radians, composed in the joint frame as
R_local = R_bend R_spread R_twist (intrinsic Z-Y-X Euler angles of the frame), so MANO's local rotation is
R_i = F_i R_local F_i^T. Because MANO's local rotations act in the parent's (rotated) rest frame, a joint's frame
follows its parent: e.g. a thumb CMC twist rotates the planes in which the MCP and IP bend.

Mirroring: for a left hand (`model.side == "left"`, the x -> -x image of a right hand) the twist and spread axes
are negated. With that choice the same angles give the mirror-image pose (MANO's conjugation by diag(-1, 1, 1)),
bend keeps its meaning (flexion curls toward the palm on both hands) and the frames stay right-handed.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from darthand.errors import InputError
from darthand.model.hand_model import HandModel
from darthand.model.layout import FACE_LABEL_IDS, FINGER_JOINTS, FINGERS, JOINT_NAMES, NUM_JOINTS
from darthand.model.per_model import per_model
from darthand.model.rotations import axis_angle_to_matrix, matrix_to_axis_angle
from darthand.model.topology import face_joints

AXES = ("twist", "spread", "bend")
PALM_JOINTS = (0, 1, 4, 7, 10)  # wrist and the four finger MCPs: the palm plane
THUMB_PAD_JOINTS = (14, 15)     # thumb MCP and IP flex toward the thumb pad
# Roll (degrees, right-handed about the thumb bone of a right hand) from the palm normal to the thumb pad direction,
# for models without nail labels; measured on the open hand (-78 deg at the IP joint).
THUMB_PAD_ROLL_DEG = -80.0

# Joint limits in degrees, (low, high) per axis, for a right or left hand alike (angles are mirror-symmetric).
# Fingers: MCP bend 0..90 with 15 deg of hyperextension (a flat hand pressed down), spread +-15 (pinky +-20);
# PIP/DIP bend 0..100 / 0..90 and, since they are hinges, only a few degrees of twist and spread, kept non-zero
# so that poses sampled in this space exercise every pose-corrective direction. Thumb: CMC twist +-45.
# The root (wrist) limits describe the wrist joint (pronation/supination, radial/ulnar deviation, flexion);
# MANO's joint 0 is the global orientation, so the root is left at zero unless asked for.
_FINGER = {
    1: ((-10, 10), (-15, 15), (-15, 90)),   # MCP
    2: ((-5, 5), (-5, 5), (0, 100)),        # PIP
    3: ((-5, 5), (-5, 5), (-5, 90)),        # DIP
}
_THUMB = {
    1: ((-45, 45), (-30, 30), (-20, 60)),   # CMC (trapeziometacarpal)
    2: ((-10, 10), (-10, 10), (-10, 60)),   # MCP
    3: ((-5, 5), (-5, 5), (-20, 90)),       # IP
}
LIMITS: dict[str, tuple[tuple[float, float], ...]] = {"wrist": ((-90, 90), (-30, 20), (-70, 80))}
for _finger in FINGERS:
    for _k, _j in enumerate(FINGER_JOINTS[_finger]):
        _table = _THUMB if _finger == "thumb" else _FINGER
        _lim = _table[_k + 1]
        if _finger == "pinky" and _k == 0:
            _lim = (_lim[0], (-20, 20), _lim[2])
        LIMITS[JOINT_NAMES[_j]] = _lim


def limits_radians() -> np.ndarray:
    """(16, 3, 2) joint limits in radians: [joint, axis (twist, spread, bend), (low, high)], MANO joint order."""
    return np.deg2rad(np.array([LIMITS[name] for name in JOINT_NAMES], dtype=np.float64))


# ------------------------------------------------------------------------------------------------ frames


def rest_joints(model: HandModel) -> np.ndarray:
    """(16, 3) joint centres of the rest template (zero shape)."""
    return np.asarray(model.J_regressor @ model.v_template)


def bone_ends(model: HandModel, joints: np.ndarray | None = None) -> np.ndarray:
    """(16, 3) the point each joint's bone points at: its child joint, the fingertip vertex for distal joints,
    the middle-finger MCP for the root."""
    joints = rest_joints(model) if joints is None else joints
    ends = np.empty((NUM_JOINTS, 3))
    ends[0] = joints[FINGER_JOINTS["middle"][0]]
    for finger, tip in zip(FINGERS, model.tip_ids):
        chain = FINGER_JOINTS[finger]
        ends[list(chain[:-1])] = joints[list(chain[1:])]
        ends[chain[-1]] = model.v_template[tip]
    return ends


def palm_normal(model: HandModel, joints: np.ndarray | None = None) -> np.ndarray:
    """(3,) unit normal of the least-squares plane through the wrist and the finger MCPs, oriented toward -Y
    (MANO's palm side, for either hand)."""
    joints = rest_joints(model) if joints is None else joints
    pts = joints[list(PALM_JOINTS)]
    n = np.linalg.svd(pts - pts.mean(0))[2][-1]
    return -n if n[1] > 0 else n


def thumb_pad_direction(model: HandModel, bone: np.ndarray, palm: np.ndarray) -> np.ndarray:
    """(3,) unit direction the thumb pad faces, orthogonal to `bone` (3,): minus the mean normal of the thumb's
    nail faces; the palm normal rolled by THUMB_PAD_ROLL_DEG about the bone if the model has no usable nail labels.
    """
    if model.face_labels is not None:
        thumb = np.isin(face_joints(model.faces, model.weights), FINGER_JOINTS["thumb"])
        nails = thumb & (model.face_labels == FACE_LABEL_IDS["nail"])
        v = model.v_template[model.faces[nails]]
        normals = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        total = np.linalg.norm(normals, axis=1).sum()
        n = -normals.sum(0)
        n -= (n @ bone) * bone
        if nails.any() and np.linalg.norm(n) > 0.5 * total:  # a nail, not a whole tube labelled 'nail'
            return n / np.linalg.norm(n)
    roll = np.deg2rad(THUMB_PAD_ROLL_DEG) * (-1 if model.side == "left" else 1)
    return Rotation.from_rotvec(roll * bone).apply(palm - (palm @ bone) * bone)


def joint_frames(model: HandModel) -> np.ndarray:
    """(16, 3, 3) orthonormal right-handed frame per joint; columns are the twist, spread and bend axes in the
    model's rest frame (see the module docstring). A copy of the model's own (3.7 ms to work out: a dataset wears a
    ring on each ring frame's new shape of the same model)."""
    return _joint_frames(model).copy()


@per_model
def _joint_frames(model: HandModel) -> np.ndarray:
    joints = rest_joints(model)
    t = bone_ends(model, joints) - joints
    length = np.linalg.norm(t, axis=1)
    if (length < 1e-9).any():
        j = int(np.argmin(length))
        raise InputError(f"{model.meta.get('source', 'model')}: joint {JOINT_NAMES[j]} coincides with its child, "
                         "its bone direction is undefined")
    t /= length[:, None]
    n = np.tile(palm_normal(model, joints), (NUM_JOINTS, 1))
    for j in THUMB_PAD_JOINTS:
        n[j] = thumb_pad_direction(model, t[j], n[j])
    b = np.cross(t, n)
    b_len = np.linalg.norm(b, axis=1)
    if (b_len < 1e-6).any():
        j = int(np.argmin(b_len))
        raise InputError(f"{model.meta.get('source', 'model')}: bone of joint {JOINT_NAMES[j]} is parallel to its "
                         "palmar direction, its bend axis is undefined")
    b /= b_len[:, None]
    s = np.cross(b, t)
    frames = np.stack([t, s, b], axis=-1)
    if model.side == "left":
        frames[:, :, :2] *= -1
    return frames


# ------------------------------------------------------------------------------------------------ conversion


def angles_to_matrix(angles) -> np.ndarray:
    """(..., 3, 3) local rotations R_bend R_spread R_twist in the joint frame from angles (..., 3) radians."""
    a = np.asarray(angles, dtype=np.float64)
    flat = a.reshape(-1, 3)[:, ::-1]  # intrinsic Z-Y-X: bend, spread, twist
    return Rotation.from_euler("ZYX", flat).as_matrix().reshape(a.shape[:-1] + (3, 3))


def matrix_to_angles(R) -> np.ndarray:
    """Inverse of `angles_to_matrix` (..., 3) [twist, spread, bend]; exact for |spread| < 90 deg."""
    R = np.asarray(R, dtype=np.float64)
    flat = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_euler("ZYX")[:, ::-1]
    return flat.reshape(R.shape[:-2] + (3,))


def angles_to_axis_angle(model: HandModel, angles, frames: np.ndarray | None = None) -> np.ndarray:
    """MANO axis-angle (..., 16, 3) from anatomical angles (..., 16, 3) [twist, spread, bend], radians.

    frames: `joint_frames(model)`, computed if not given.
    """
    a = _check_angles(angles)
    F = joint_frames(model) if frames is None else frames
    R = F @ angles_to_matrix(a) @ np.swapaxes(F, -1, -2)
    return matrix_to_axis_angle(R)


def axis_angle_to_angles(model: HandModel, pose, frames: np.ndarray | None = None) -> np.ndarray:
    """Anatomical angles (..., 16, 3) [twist, spread, bend], radians, from MANO axis-angle (..., 16, 3) or (..., 48).

    Exact inverse of `angles_to_axis_angle` for |spread| < 90 deg (all joint limits are well inside).
    """
    p = np.asarray(pose, dtype=np.float64)
    if p.shape[-1] == 3 * NUM_JOINTS:
        p = p.reshape(p.shape[:-1] + (NUM_JOINTS, 3))
    if p.shape[-2:] != (NUM_JOINTS, 3):
        raise InputError(f"pose: shape {p.shape} is not (..., 48) or (..., 16, 3)")
    F = joint_frames(model) if frames is None else frames
    R_local = np.swapaxes(F, -1, -2) @ axis_angle_to_matrix(p) @ F
    return matrix_to_angles(R_local)


def _check_angles(angles) -> np.ndarray:
    a = np.asarray(angles, dtype=np.float64)
    if a.shape[-2:] != (NUM_JOINTS, 3):
        raise InputError(f"angles: shape {a.shape} is not (..., 16, 3)")
    if not np.isfinite(a).all():
        raise InputError("angles: contains a non-finite value")
    return a


# ------------------------------------------------------------------------------------------------ limits, sampling


def within_limits(angles, tol: float = 1e-9) -> np.ndarray:
    """(..., 16, 3) bool: each angle (radians) inside its joint limit, with a tolerance of `tol` radians."""
    a = _check_angles(angles)
    lim = limits_radians()
    return (a >= lim[..., 0] - tol) & (a <= lim[..., 1] + tol)


def sample_angles(n: int, rng: np.random.Generator, scale: float = 1.0, include_root: bool = False) -> np.ndarray:
    """(n, 16, 3) angles drawn uniformly and independently per axis within the limits scaled by `scale` about
    zero (the rest pose); the root is zero unless `include_root`."""
    lim = limits_radians() * scale
    a = rng.uniform(lim[..., 0], lim[..., 1], size=(n, NUM_JOINTS, 3))
    if not include_root:
        a[:, 0] = 0.0
    return a


def sample_poses(model: HandModel, n: int, rng: np.random.Generator, scale: float = 1.0,
                 include_root: bool = False) -> np.ndarray:
    """(n, 48) MANO axis-angle poses sampled uniformly within the anatomical limits (see `sample_angles`)."""
    a = sample_angles(n, rng, scale, include_root)
    return angles_to_axis_angle(model, a).reshape(n, 3 * NUM_JOINTS)
