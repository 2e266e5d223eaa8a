"""The gestures of a model: the named gestures as fitted to it, or as authored when it carries no fit.

`darthand model build` fits every named gesture to the model it builds (model/gesture_fit) and records the result
in the model file, `meta["gestures"]` (`GESTURES_FORMAT`): per gesture its angles in the layout of the pose files
(joint -> twist/spread/bend degrees), the contacts it means, what the fit changed and whether it resolved. Every
stage that poses a model in a named gesture -- export, accessories, the renderer, datasets -- takes it from
`model_gestures(model)`, so they all show the same, collision-free hand. A model without a record (the committed
open hand, a MANO pickle loaded directly) gets the authored angles of assets_src/poses.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from darthand.errors import InputError
from darthand.model.anatomy import AXES, angles_to_axis_angle, joint_frames
from darthand.model.hand_model import HandModel
from darthand.model.layout import JOINT_NAMES, NUM_JOINTS
from darthand.model.poses import gesture_angles, list_gestures

GESTURES_FORMAT = "darthand-fitted-gestures"
GESTURES_VERSION = 1


@dataclass(frozen=True)
class Gestures:
    """Named gestures on one model. angles (G, 16, 3) radians [twist, spread, bend]; poses (G, 48) MANO
    axis-angle on that model (flat_hand_mean=True); fitted: whether they were fitted to it."""

    names: tuple[str, ...]
    angles: np.ndarray
    poses: np.ndarray
    fitted: bool

    def index(self, name: str) -> int:
        if name not in self.names:
            raise InputError(f"gesture {name!r}: not a gesture of this model (known: {', '.join(self.names)})")
        return self.names.index(name)

    def pose(self, name: str) -> np.ndarray:
        """(48,) MANO axis-angle of one gesture."""
        return self.poses[self.index(name)].copy()

    def angles_of(self, name: str) -> np.ndarray:
        """(16, 3) radians of one gesture."""
        return self.angles[self.index(name)].copy()


def model_gestures(model: HandModel, names: list[str] | None = None,
                   poses_dir: str | Path | None = None) -> Gestures:
    """The named gestures of `model` (all, or `names` in that order): those fitted to it (`meta["gestures"]`),
    else the authored ones of assets_src/poses. poses_dir: read the authored gestures there instead (no fit).

    A fit belongs to one geometry: `model.shaped(betas)` keeps its base's record, so fit a shaped hand anew with
    `gesture_fit.with_fitted_gestures(model.shaped(betas))` before asking it for its gestures."""
    record = fitted_record(model) if poses_dir is None else None
    if record is not None:
        available = sorted(record["gestures"])
        chosen = available if names is None else list(names)
        for name in chosen:
            if name not in record["gestures"]:
                raise InputError(f"gesture {name!r}: not a gesture of {model.meta.get('source', 'this model')} "
                                 f"(known: {', '.join(available)})")
        angles = np.stack([joints_to_angles(record["gestures"][n]["joints"]) for n in chosen]) if chosen else \
            np.zeros((0, NUM_JOINTS, 3))
    else:
        chosen = list_gestures(poses_dir) if names is None else list(names)
        angles = np.stack([gesture_angles(n, poses_dir) for n in chosen]) if chosen else np.zeros((0, NUM_JOINTS, 3))
    frames = joint_frames(model)
    poses = angles_to_axis_angle(model, angles, frames).reshape(len(chosen), 3 * NUM_JOINTS)
    return Gestures(tuple(chosen), angles, poses, record is not None)


def fitted_record(model: HandModel) -> dict | None:
    """The model's fitted-gesture record (`meta["gestures"]`), None if it has none; InputError if unreadable."""
    record = model.meta.get("gestures")
    if record is None:
        return None
    source = model.meta.get("source", "model")
    if not isinstance(record, dict) or record.get("format") != GESTURES_FORMAT:
        raise InputError(f"{source}: field 'meta.gestures' is not a {GESTURES_FORMAT} record")
    if int(record.get("version", 0)) > GESTURES_VERSION:
        raise InputError(f"{source}: field 'meta.gestures.version' is {record['version']}, this darthand reads up "
                         f"to {GESTURES_VERSION}")
    if not isinstance(record.get("gestures"), dict):
        raise InputError(f"{source}: field 'meta.gestures.gestures' is missing")
    return record


def angles_to_joints(angles: np.ndarray) -> dict:
    """{joint: {axis: degrees}} of the non-zero angles (16, 3) radians: the pose files' layout."""
    deg = np.rad2deg(np.asarray(angles, dtype=np.float64))
    return {JOINT_NAMES[j]: {AXES[a]: float(deg[j, a]) for a in range(3) if deg[j, a] != 0.0}
            for j in range(NUM_JOINTS) if np.any(deg[j] != 0.0)}


def joints_to_angles(joints: dict) -> np.ndarray:
    """(16, 3) radians from {joint: {axis: degrees}}; InputError naming a bad joint, axis or value."""
    angles = np.zeros((NUM_JOINTS, 3))
    for joint, values in joints.items():
        if joint not in JOINT_NAMES or not isinstance(values, dict):
            raise InputError(f"fitted gestures: {joint!r} is not a joint name with axis values")
        for axis, deg in values.items():
            if axis not in AXES or not isinstance(deg, (int, float)) or not np.isfinite(deg):
                raise InputError(f"fitted gestures: {joint}.{axis} = {deg!r} is not a finite angle")
            angles[JOINT_NAMES.index(joint), AXES.index(axis)] = np.deg2rad(deg)
    return angles
