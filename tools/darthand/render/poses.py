"""The renderer's pose argument: nothing (the flat hand), a named gesture, a pose file, or a MANO vector."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from darthand.errors import InputError
from darthand.model.forward import MAX_MAGNITUDE
from darthand.model.gestures import model_gestures
from darthand.model.hand_model import HandModel
from darthand.model.layout import NUM_JOINTS
from darthand.model.poses import load_pose_file


def resolve_pose(model: HandModel, pose, index: int = 0, cache: dict | None = None) -> tuple[np.ndarray, str | None]:
    """(48,) float64 MANO axis-angle relative to the flat hand, and the gesture name (None unless named).

    pose: None (flat hand, zeros); a gesture name (one of the model's gestures, `model.gestures.model_gestures`);
        a pose file path (schemas/pose.schema.json; pose number `index` of it); or 48 numbers.
    cache: a dict the caller keeps per model, gesture name -> pose (reading and converting a gesture costs ms).
    """
    if pose is None:
        return np.zeros(3 * NUM_JOINTS), None
    if isinstance(pose, (str, Path)):
        name = str(pose)
        if cache is not None and name in cache:
            return cache[name].copy(), name
        gestures = model_gestures(model)
        if name in gestures.names:
            vec = gestures.pose(name)
            if cache is not None:
                cache[name] = vec.copy()
            return vec, name
        path = Path(name)
        if not path.is_file():
            raise InputError(f"pose: {name!r} is neither a gesture ({', '.join(gestures.names)}) nor a pose file")
        poses = pose_file_vectors(model, path)
        if not 0 <= index < len(poses):
            raise InputError(f"{path}: has {len(poses)} poses, no pose number {index}")
        return poses[index], None
    vec = np.asarray(pose, dtype=np.float64).reshape(-1)
    if vec.shape != (3 * NUM_JOINTS,):
        raise InputError(f"pose: a MANO pose has {3 * NUM_JOINTS} numbers, got {vec.size}")
    limit = MAX_MAGNITUDE["pose"]
    with np.errstate(invalid="ignore"):
        bad = ~(np.abs(vec) <= limit)
    if bad.any():
        i = int(np.argmax(bad))
        raise InputError(f"pose: value {vec[i]} at index {i} is not a finite number within +-{limit:g} radians")
    return vec, None


def pose_file_vectors(model: HandModel, path) -> np.ndarray:
    """(N, 48) float64 the poses of a pose file (schemas/pose.schema.json) relative to the flat hand (the model's
    hands_mean added where the file is relative to it); a file with betas is refused (the renderer poses the
    model as built)."""
    poses, betas, flat_hand_mean = load_pose_file(path)
    if betas is not None:
        raise InputError(f"{path}: field 'betas' is not supported by the renderer (shape the model instead)")
    poses = np.array(poses, np.float64)
    if not flat_hand_mean:
        poses[:, 3:] += model.hands_mean
    return poses
