"""What every package states about itself (USD: the root prim's customData and asset.json; glTF: asset.extras), so
that a consumer, the studio page in JavaScript included, can pose it with darthand's convention."""

from __future__ import annotations

from darthand.model import bones
from darthand.model.anatomy import rest_joints
from darthand.model.hand_model import HandModel
from darthand.model.layout import JOINT_NAMES, MANO_PARENTS


def asset_conventions(model: HandModel) -> dict:
    """Units, frame, origin, joint order and the bone / pose convention of a package of `model` (JSON-able)."""
    wrist = rest_joints(model)[0]
    return {
        "units": "metres",
        "frame": f"MANO's canonical frame of a {model.side} hand at rest: fingers toward "
                 f"{'-X' if model.side == 'right' else '+X'}, thumb toward +Z, palm facing -Y, wrist near "
                 f"{'+X' if model.side == 'right' else '-X'}; USD upAxis Y, glTF +Y up (importers rotate to Z-up)",
        "origin": "the model's origin (MANO's), not the wrist joint; the wrist joint's rest centre is "
                  f"{[round(float(x), 6) for x in wrist]} (metres)",
        "joint_names": list(JOINT_NAMES),
        "joint_parents": [int(p) for p in MANO_PARENTS],
        "pose": "darthand poses and labels are MANO axis-angle per joint relative to the flat hand (48 values)",
        "bones": bones.CONVENTION,
        "conversion": "darthand.model.bones.bone_rotations(pose, frames) / mano_pose(bone_rotations, frames)",
    }
