"""The named gestures a package carries as animations: the one place export looks gesture poses up, so that how
gestures are obtained (assets_src/poses, retargeted per model) changes here only."""

from __future__ import annotations

import numpy as np

from darthand.model.gestures import model_gestures
from darthand.model.hand_model import HandModel
from darthand.model.layout import NUM_JOINTS

REST_GESTURE = "flat"


def gesture_poses(model: HandModel) -> tuple[list[str], np.ndarray]:
    """Names and MANO axis-angle poses (G, 48) of the model's named gestures (`model.gestures.model_gestures`:
    fitted to it by the model build, else assets_src/poses/*.json).

    Sorted by name except that `flat` (the rest pose) comes first, so that an animation's first frame is the rest
    pose. Without any gesture the animation holds only the rest pose: (['rest'], zeros (1, 48)).
    """
    gestures = model_gestures(model)
    names, poses = list(gestures.names), gestures.poses
    if not names:
        return ["rest"], np.zeros((1, 3 * NUM_JOINTS))
    order = sorted(range(len(names)), key=lambda i: (names[i] != REST_GESTURE, names[i]))
    return [names[i] for i in order], np.asarray(poses, dtype=np.float64)[order]


