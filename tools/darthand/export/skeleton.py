"""The exported skeleton: MANO's 16 joints with oriented bone frames (model/bones.py), as both writers author it.

Joint i's rest transform relative to its parent is [O_parent^T O_i | O_parent^T (J_i - J_parent)] and its bind
transform (skeleton space) [O_i | J_i]; animated, its local rotation is O_parent^T R_i O_i (MANO's R_i) with the
translation unchanged. The skinning transform (animated skeleton-space transform times inverse bind) is then MANO's
G_i whatever the frames, so every engine poses the mesh exactly as `forward` does, while DCC tools show bones along
the fingers.

Gf matrices and glTF both store quaternions (x, y, z, w); rotations.py's are (w, x, y, z).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from darthand.model import bones
from darthand.model.anatomy import rest_joints
from darthand.model.hand_model import HandModel
from darthand.model.layout import JOINT_NAMES, NUM_JOINTS
from darthand.model.rotations import axis_angle_to_matrix, matrix_to_quaternion


@dataclass(frozen=True)
class Skeleton:
    """names (16,), parents (16,), joints (16, 3) rest joint centres (metres), frames (16, 3, 3) bone rest frames
    O_i (columns X, Y, Z), lengths (16,) bone lengths (metres)."""

    names: tuple[str, ...]
    parents: np.ndarray
    joints: np.ndarray
    frames: np.ndarray
    lengths: np.ndarray

    @property
    def bind(self) -> np.ndarray:
        """(16, 4, 4) column-vector bind transforms [O_i | J_i] (skeleton space)."""
        return bones.bind_matrices(self.joints, self.frames)

    @property
    def translations(self) -> np.ndarray:
        """(16, 3) constant local translations O_parent^T (J_i - J_parent)."""
        return bones.node_translations(self.joints, self.frames, self.parents)

    @property
    def rest_rotations(self) -> np.ndarray:
        """(16, 3, 3) rest local rotations O_parent^T O_i."""
        return bones.rest_node_rotations(self.frames, self.parents)

    def rest_local(self) -> np.ndarray:
        """(16, 4, 4) column-vector rest transforms relative to the parent."""
        m = np.tile(np.eye(4), (NUM_JOINTS, 1, 1))
        m[:, :3, :3] = self.rest_rotations
        m[:, :3, 3] = self.translations
        return m

    def local_rotations(self, poses: np.ndarray) -> np.ndarray:
        """(B, 16, 3, 3) local joint rotations O_parent^T R_i O_i of MANO axis-angle poses (B, 48)."""
        R = axis_angle_to_matrix(np.asarray(poses, dtype=np.float64).reshape(-1, NUM_JOINTS, 3))
        return bones.node_rotations(R, self.frames, self.parents)

    def local_quaternions(self, poses: np.ndarray) -> np.ndarray:
        """(B, 16, 4) the local rotations as unit quaternions (x, y, z, w)."""
        return xyzw_quaternions(self.local_rotations(poses))


def export_skeleton(model: HandModel) -> Skeleton:
    """The oriented skeleton of `model`'s rest template."""
    return Skeleton(tuple(JOINT_NAMES), np.asarray(model.parents), rest_joints(model), bones.bone_frames(model),
                    bones.bone_lengths(model))


def xyzw_quaternions(rotations: np.ndarray) -> np.ndarray:
    """(..., 4) unit quaternions (x, y, z, w) of rotation matrices (..., 3, 3): the layout of glTF rotations and of
    GfQuatf in memory (rotations.py's are w, x, y, z)."""
    q = matrix_to_quaternion(np.asarray(rotations, dtype=np.float64))
    return np.concatenate([q[..., 1:], q[..., :1]], axis=-1)
