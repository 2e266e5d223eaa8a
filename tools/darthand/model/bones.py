"""Oriented bones: the rest frame of every joint as DCC tools and engines expect it, and the one conversion between
MANO's per-joint axis-angle and a bone's local rotation.

darthand's API, labels and pose files keep MANO's convention: joint i's pose is an axis-angle R_i in a frame that is
world-aligned at rest (the model's frame). The exported skeletons (USD, glTF, the Blender rig) give every joint an
oriented rest frame O_i instead (columns X, Y, Z written in the model's rest frame, right-handed):

    Y   along the bone: unit(bone end - joint), the bone end being the child joint, the fingertip vertex for the
        distal joints, the middle-finger MCP for the wrist (`anatomy.bone_ends`), so Blender draws each bone along
        its finger (a Blender bone points along its local +Y)
    X   the bend (flexion) axis of `anatomy.joint_frames`: a positive rotation about X curls the digit toward its
        palmar side (the palm for fingers and the thumb CMC, the thumb pad for the thumb MCP and IP), on right and
        left hands alike
    Z   X x Y: the spread axis (sideways), up to sign; rotation about Y twists the bone

The bone's length is |bone end - joint|. A pose bone's local rotation Q_i (Blender's `rotation_quaternion`, the
rotation of the bone relative to its rest orientation, in its own rest frame) relates to MANO's R_i by

    Q_i = O_i^T R_i O_i        R_i = O_i Q_i O_i^T

(proof: the posed world frame of bone i is W_i = C_i O_i with C_i the product of MANO's rotations along the chain;
Blender composes W_i = W_parent (O_parent^T O_i) Q_i, which gives C_i O_i = C_parent O_i Q_i, and C_i = C_parent R_i).
In node terms (glTF node rotation, USD joint local transform) the local rotation of joint i relative to its parent
is  L_i = O_parent^T R_i O_i = (O_parent^T O_i) Q_i,  with O_parent = I for the root, and the local translation is
the constant O_parent^T (J_i - J_parent).  `bone_rotations` / `mano_rotations` convert one way and the other;
`node_rotations` gives L_i.

Shapes: (..., 16, 3) axis-angle, (..., 16, 3, 3) rotation matrices; frames (16, 3, 3).
"""

from __future__ import annotations

import numpy as np

from darthand.model.anatomy import bone_ends, joint_frames, rest_joints
from darthand.model.hand_model import HandModel
from darthand.model.layout import NUM_JOINTS
from darthand.model.rotations import axis_angle_to_matrix, matrix_to_axis_angle

CONVENTION = ("bone frames: Y along the bone (joint -> child joint / fingertip), X the flexion axis (positive X "
              "rotation curls toward the palm), Z = X x Y; bone local rotation Q_i = O_i^T R_i O_i with R_i MANO's "
              "axis-angle rotation of joint i and O_i the bone's rest frame (columns X, Y, Z in the model frame)")


def bone_frames(model: HandModel) -> np.ndarray:
    """(16, 3, 3) rest frame O_i of every bone: columns X (flexion axis), Y (along the bone), Z = X x Y, in the
    model's rest frame. Orthonormal, det +1, for right and left hands."""
    frames = joint_frames(model)                 # columns twist, spread, bend (twist, spread negated on a left hand)
    joints = rest_joints(model)
    y = bone_ends(model, joints) - joints
    y /= np.linalg.norm(y, axis=1, keepdims=True)
    x = frames[:, :, 2]
    x = x - (x * y).sum(1, keepdims=True) * y    # already orthogonal; removes rounding
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    return np.stack([x, y, np.cross(x, y)], axis=-1)


def bone_lengths(model: HandModel) -> np.ndarray:
    """(16,) metres from each joint to its bone end (child joint, fingertip vertex, middle MCP for the wrist)."""
    joints = rest_joints(model)
    return np.linalg.norm(bone_ends(model, joints) - joints, axis=1)


def bone_rotations(pose, frames: np.ndarray) -> np.ndarray:
    """(..., 16, 3, 3) bone-local rotations Q_i = O_i^T R_i O_i of MANO axis-angle poses (..., 48) or (..., 16, 3)."""
    R = axis_angle_to_matrix(_joint_axis_angle(pose))
    return np.swapaxes(frames, -1, -2) @ R @ frames


def mano_rotations(bone_rots, frames: np.ndarray) -> np.ndarray:
    """(..., 16, 3, 3) MANO rotations R_i = O_i Q_i O_i^T of bone-local rotations Q (..., 16, 3, 3)."""
    return frames @ np.asarray(bone_rots, dtype=np.float64) @ np.swapaxes(frames, -1, -2)


def mano_pose(bone_rots, frames: np.ndarray) -> np.ndarray:
    """(..., 48) MANO axis-angle pose of bone-local rotations Q (..., 16, 3, 3): the inverse of `bone_rotations`."""
    aa = matrix_to_axis_angle(mano_rotations(bone_rots, frames))
    return aa.reshape(aa.shape[:-2] + (3 * NUM_JOINTS,))


def rest_node_rotations(frames: np.ndarray, parents: np.ndarray) -> np.ndarray:
    """(16, 3, 3) rest local rotation of each joint relative to its parent, O_parent^T O_i (O_0 for the root)."""
    parent = np.where(np.asarray(parents)[:, None, None] < 0, np.eye(3), frames[np.maximum(parents, 0)])
    return np.swapaxes(parent, -1, -2) @ frames


def node_rotations(rotations: np.ndarray, frames: np.ndarray, parents: np.ndarray) -> np.ndarray:
    """(..., 16, 3, 3) local rotation L_i = O_parent^T R_i O_i of joint nodes for MANO rotations R (..., 16, 3, 3)."""
    parent = np.where(np.asarray(parents)[:, None, None] < 0, np.eye(3), frames[np.maximum(parents, 0)])
    return np.swapaxes(parent, -1, -2) @ np.asarray(rotations, dtype=np.float64) @ frames


def node_translations(joints: np.ndarray, frames: np.ndarray, parents: np.ndarray) -> np.ndarray:
    """(16, 3) constant local translation of each joint node: O_parent^T (J_i - J_parent) (J_0 for the root)."""
    parents = np.asarray(parents)
    rel = np.array(joints, dtype=np.float64)
    rel[1:] -= rel[parents[1:]]
    parent = np.where(parents[:, None, None] < 0, np.eye(3), frames[np.maximum(parents, 0)])
    return np.einsum("jba,jb->ja", parent, rel)


def bind_matrices(joints: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """(16, 4, 4) column-vector bind transforms [O_i | J_i]: bone space -> model space at rest."""
    m = np.tile(np.eye(4), (len(joints), 1, 1))
    m[:, :3, :3] = frames
    m[:, :3, 3] = joints
    return m


def _joint_axis_angle(pose) -> np.ndarray:
    p = np.asarray(pose, dtype=np.float64)
    if p.shape[-1] == 3 * NUM_JOINTS:
        p = p.reshape(p.shape[:-1] + (NUM_JOINTS, 3))
    return p
