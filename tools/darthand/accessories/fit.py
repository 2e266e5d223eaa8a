"""Size and place rigid accessories on a hand: measure the section where the accessory sits, add a clearance.

Rings sit on a proximal phalanx (a fraction `t` from the joint toward its child), centred on the section's smallest
enclosing circle; their bore radius is that circle's radius plus the clearance. Watches and bracelets sit on the
forearm extension `offset` metres from the wrist joint along the forearm axis, on the section's smallest enclosing
axis-aligned ellipse grown by the clearance. Sections are cut at several planes across the accessory's width, so the
bore clears the hand over its whole width.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from darthand.accessories.measure import enclosing_circle, enclosing_ellipse, section_points
from darthand.accessories.mesh import frame_matrix
from darthand.errors import InputError
from darthand.model.anatomy import bone_ends, palm_normal, rest_joints
from darthand.model.hand_model import HandModel
from darthand.model.layout import FACE_LABEL_IDS, FINGERS
from darthand.model.wrist import loop_frame, wrist_loop

# The proximal phalanx of each finger is the bone of this joint (MANO's thumb chain starts at the CMC joint 13).
RING_JOINTS = {"thumb": 14, "index": 1, "middle": 4, "ring": 10, "pinky": 7}
WRIST_JOINT = 0
SLAB_PLANES = 5


@dataclass(frozen=True)
class Fit:
    """Where and how big: `rest` maps the accessory's local frame to the model's rest frame; `bone` is the bone
    frame the section was measured in (origin on the bone axis); `bore` holds inner_radius (rings) or
    inner_a, inner_b (wrist items), metres; `section` the measured (K, 2) points in the accessory's own plane
    coordinates; `axis_distance` the distance from the accessory centre to the bone axis (m)."""

    joint: int
    rest: np.ndarray
    bone: np.ndarray
    bore: dict
    section: np.ndarray
    axis_distance: float


def finger_frame(model: HandModel, finger: str, t: float = 0.5) -> np.ndarray:
    """Bone frame on `finger`'s proximal phalanx, `t` of the way from its joint to the next."""
    if finger not in RING_JOINTS:
        raise InputError(f"finger: {finger!r} is not one of {', '.join(FINGERS)}")
    j = RING_JOINTS[finger]
    joints = rest_joints(model)
    start, end = joints[j], bone_ends(model, joints)[j]
    axis = end - start
    return frame_matrix(start + t * axis, axis, dorsal_direction(model, finger, axis))


def wrist_axis(model: HandModel) -> tuple[np.ndarray, np.ndarray]:
    """The wrist joint (3,) and the unit forearm direction (3,): the wrist-enhanced model's open end faces it."""
    centre, axis, _ = loop_frame(model, wrist_loop(model))
    return rest_joints(model)[WRIST_JOINT], axis


def wrist_frame(model: HandModel, offset: float) -> np.ndarray:
    """Bone frame on the forearm, `offset` metres from the wrist joint along the forearm axis, +Y dorsal."""
    j0, axis = wrist_axis(model)
    return frame_matrix(j0 + offset * axis, axis, -palm_normal(model))


def dorsal_direction(model: HandModel, finger: str, axis: np.ndarray) -> np.ndarray:
    """Unit direction of the finger's back (nail side), orthogonal to `axis`.

    The back of the hand (-palm normal) for the fingers; for the thumb, whose nail faces sideways, the mean normal
    of the nail faces near its tip when the model labels nails, else the back of the hand.
    """
    a = axis / np.linalg.norm(axis)
    d = -palm_normal(model)
    if finger == "thumb" and model.face_labels is not None:
        nails = np.where(model.face_labels == FACE_LABEL_IDS["nail"])[0]
        tip = model.v_template[model.tip_ids[0]]
        tri = model.v_template[model.faces[nails]]
        near = nails[np.linalg.norm(tri.mean(1) - tip, axis=1) < 0.015]
        if 0 < len(near) < 0.2 * model.num_faces:
            t = model.v_template[model.faces[near]]
            n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]).sum(0)
            n -= np.dot(n, a) * a
            if np.linalg.norm(n) > 1e-12:
                d = n
    d = d - np.dot(d, a) * a
    norm = np.linalg.norm(d)
    if norm < 1e-9:
        raise InputError(f"{model.meta.get('source', 'model')}: the {finger}'s bone is parallel to the palm "
                         "normal; its dorsal side is undefined")
    return d / norm


def finger_faces(model: HandModel, joint: int) -> np.ndarray:
    """(F,) bool: faces whose three vertices are skinned mostly to `joint` or the joint after it."""
    child = np.where(model.parents == joint)[0]
    dominant = np.argmax(model.weights, axis=1)
    own = np.isin(dominant, np.concatenate([[joint], child]))
    return own[model.faces].all(1)


def slab_offsets(width: float, planes: int = SLAB_PLANES) -> np.ndarray:
    """Plane positions across an accessory of `width` metres (both faces and evenly in between)."""
    return np.linspace(-width / 2, width / 2, planes)


def fit_ring(model: HandModel, finger: str, width: float, clearance: float, t: float = 0.5,
             what: str = "ring") -> Fit:
    """Bore radius = radius of the smallest circle around the finger's section (over the band's width)
    + clearance; the ring is centred on that circle, in the plane perpendicular to the bone."""
    bone = finger_frame(model, finger, t)
    pts = section_points(model.v_template, model.faces, bone, slab_offsets(width), what,
                         own_faces=finger_faces(model, RING_JOINTS[finger]), skip_open=True)
    centre, radius = enclosing_circle(pts)
    return _placed(RING_JOINTS[finger], bone, centre, {"inner_radius": radius + clearance}, pts)


def fit_wrist(model: HandModel, offset: float, width: float, clearance: float, what: str = "wrist item") -> Fit:
    """Bore half-axes = the smallest axis-aligned ellipse around the forearm section (over the item's width),
    each grown by the clearance; centred on the section."""
    bone = wrist_frame(model, offset)
    pts = section_points(model.v_template, model.faces, bone, slab_offsets(width), what)
    centre, a, b = enclosing_ellipse(pts)
    return _placed(WRIST_JOINT, bone, centre, {"inner_a": a + clearance, "inner_b": b + clearance}, pts)


def _placed(joint: int, bone: np.ndarray, centre2d: np.ndarray, bore: dict, pts: np.ndarray) -> Fit:
    rest = bone.copy()
    rest[:3, 3] = bone[:3, 3] + centre2d[0] * bone[:3, 1] + centre2d[1] * bone[:3, 2]
    return Fit(joint, rest, bone, bore, pts - centre2d, float(np.linalg.norm(centre2d)))
