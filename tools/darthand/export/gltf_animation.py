"""Gestures as glTF animations: a short clip from the rest pose to the gesture, one per gesture.

Each clip has `keys` keyframes at t = 0 .. duration. Keyframe k holds the pose s_k * pose (s_k = k / (keys - 1)) as
joint rotations (rotation channels of all 16 joint nodes; glTF slerps between keys, and since s * axis-angle is the
slerp of the identity and the full rotation, every in-between rotation is exact) and the corrective weights of that
pose (a `weights` channel per corrective-carrying mesh node; linear between keys, exact at the keys). The last key is
the gesture itself, where an engine's result equals the rig's.
"""

from __future__ import annotations

import numpy as np
import pygltflib as gl

from darthand.export.common import Correctives, xyzw_quaternions
from darthand.export.gltf_document import GltfDocument
from darthand.model.layout import NUM_JOINTS
from darthand.model.rotations import axis_angle_to_matrix


def clip_poses(pose: np.ndarray, keys: int) -> np.ndarray:
    """(keys, 16, 3) axis-angle keyframes s_k * pose from rest (s = 0) to the gesture (s = 1)."""
    s = np.linspace(0.0, 1.0, keys) if keys > 1 else np.ones(1)
    return s[:, None, None] * np.asarray(pose, dtype=np.float64).reshape(1, NUM_JOINTS, 3)


def add_gesture_animation(doc: GltfDocument, name: str, pose: np.ndarray, joint_nodes: list[int],
                          morph_nodes: list[int], correctives: Correctives, times: int) -> int:
    """An animation named `name` for one gesture pose (48,); `times` is the accessor of the key times (shared by
    all gestures). Returns the animation index."""
    keys = doc.gltf.accessors[times].count
    rotations = axis_angle_to_matrix(clip_poses(pose, keys))                       # (keys, 16, 3, 3)
    quats = xyzw_quaternions(rotations).astype(np.float32)                        # (keys, 16, 4)
    anim = gl.Animation(name=name)
    for j, node in enumerate(joint_nodes):
        out = doc.accessor(np.ascontiguousarray(quats[:, j]), target=None, name=f"{name}_{j}_rotation")
        anim.samplers.append(gl.AnimationSampler(input=times, output=out, interpolation=gl.ANIM_LINEAR))
        anim.channels.append(gl.AnimationChannel(sampler=len(anim.samplers) - 1,
                                                 target=gl.AnimationChannelTarget(node=node, path="rotation")))
    if correctives.count and morph_nodes:
        weights = correctives.weights(rotations).astype(np.float32).reshape(-1)    # keys x K, key-major
        out = doc.accessor(weights, target=None, name=f"{name}_weights")
        anim.samplers.append(gl.AnimationSampler(input=times, output=out, interpolation=gl.ANIM_LINEAR))
        for node in morph_nodes:
            anim.channels.append(gl.AnimationChannel(sampler=len(anim.samplers) - 1,
                                                     target=gl.AnimationChannelTarget(node=node, path="weights")))
    return doc.add("animations", anim)


def add_key_times(doc: GltfDocument, keys: int, duration: float) -> int:
    """The shared input accessor: `keys` times evenly spaced over [0, duration] seconds."""
    t = np.linspace(0.0, duration, keys) if keys > 1 else np.array([duration])
    return doc.accessor(t.astype(np.float32), target=None, minmax=True, name="gesture_key_times")
