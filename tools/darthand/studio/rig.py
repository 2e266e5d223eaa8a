"""What the page needs to pose a side's glTF package exactly as darthand poses the model, from the model itself.

The page turns slider angles into MANO rotations and those into glTF joint-node rotations and corrective weights:

    R_i = F_i R_bend R_spread R_twist F_i^T         (model/anatomy.py: F_i the joint's twist/spread/bend frame)
    L_i = O_parent^T R_i O_i                        (model/bones.py: O_i the bone's rest frame; the node rotation)
    corrective channel pose_<joint>_r<r><c> = (R_i - I)[r, c], each shape's weight clip(value / scale, 0, 1)
                                                    (the package's asset.extras.darthand.blend_shapes table)

so it needs F_i, O_i, the joint limits and the gestures' angles; the blend-shape table it reads from the package.
Gestures come from export/gestures.py (the one lookup export uses), turned into angles for the sliders.
"""

from __future__ import annotations

import numpy as np

from darthand.export.gestures import gesture_poses
from darthand.model.anatomy import AXES, axis_angle_to_angles, joint_frames, limits_radians
from darthand.model.bones import bone_frames
from darthand.model.hand_model import HandModel
from darthand.model.layout import JOINT_NAMES


def rig_document(model: HandModel) -> dict:
    """The side's rig for the page: joint names and parents, frames F (16, 3, 3) and O (16, 3, 3) as nested lists
    (rows of the matrices, columns the axes), limits in degrees (16, 3, 2), gestures {name: angles in degrees
    (16, 3)} in library order (the rest pose first)."""
    names, poses = gesture_poses(model)
    F = joint_frames(model)
    angles = np.rad2deg(axis_angle_to_angles(model, poses, F))
    return {
        "side": model.side,
        "joints": list(JOINT_NAMES),
        "parents": [int(p) for p in model.parents],
        "axes": list(AXES),
        "joint_frames": F.tolist(),
        "bone_frames": bone_frames(model).tolist(),
        "limits_deg": np.rad2deg(limits_radians()).tolist(),
        "gestures": {name: a.tolist() for name, a in zip(names, angles)},
        "gesture_order": list(names),
    }
