"""Gestures as glTF animations: one clip per gesture that holds the gesture for its whole length.

A clip has two keyframes, at t = 0 and t = duration, both the gesture: the rotation channels of the 16 joint nodes
hold their local rotations O_parent^T R_i O_i (skeleton.py) and a `weights` channel per corrective-carrying mesh
node holds the encoded corrective weights (in [0, 1]). An engine's default looping playback (three.js's
AnimationMixer, Blender's timeline) therefore shows the gesture itself at every time, never a ramp from the flat
hand, and equals the rig's pose exactly.
"""

from __future__ import annotations

import numpy as np
import pygltflib as gl

from darthand.export.correctives import Correctives
from darthand.export.gltf_document import GltfDocument
from darthand.export.skeleton import Skeleton

KEYS = 2   # keyframes per clip, both the gesture


def add_gesture_animation(doc: GltfDocument, name: str, pose: np.ndarray, skeleton: Skeleton, joint_nodes: list[int],
                          morph_nodes: list[int], correctives: Correctives, times: int,
                          extra_targets: dict[int, int] | None = None) -> int:
    """An animation named `name` holding one gesture pose (48,) (MANO axis-angle); `times` is the accessor of the key
    times (shared by all gestures). extra_targets: {node: n} nodes whose mesh has n morph targets after the
    correctives (the hand's shape dials), held at weight 0 (a glTF weights channel keys every target). Returns the
    animation index."""
    keys = doc.gltf.accessors[times].count
    quats = np.repeat(skeleton.local_quaternions(pose).astype(np.float32), keys, axis=0)      # (keys, 16, 4)
    anim = gl.Animation(name=name)
    for j, node in enumerate(joint_nodes):
        out = doc.accessor(np.ascontiguousarray(quats[:, j]), target=None, name=f"{name}_{j}_rotation")
        anim.samplers.append(gl.AnimationSampler(input=times, output=out, interpolation=gl.ANIM_LINEAR))
        anim.channels.append(gl.AnimationChannel(sampler=len(anim.samplers) - 1,
                                                 target=gl.AnimationChannelTarget(node=node, path="rotation")))
    if correctives.count and morph_nodes:
        weights = np.repeat(correctives.weights_of_poses(pose).astype(np.float32), keys, axis=0)     # (keys, S)
        samplers: dict[int, int] = {}
        for node in morph_nodes:
            extra = (extra_targets or {}).get(node, 0)
            if extra not in samplers:
                padded = np.concatenate([weights, np.zeros((keys, extra), np.float32)], axis=1).reshape(-1)
                out = doc.accessor(padded, target=None, name=f"{name}_weights" + (f"_{extra}" if extra else ""))
                anim.samplers.append(gl.AnimationSampler(input=times, output=out, interpolation=gl.ANIM_LINEAR))
                samplers[extra] = len(anim.samplers) - 1
            anim.channels.append(gl.AnimationChannel(sampler=samplers[extra],
                                                     target=gl.AnimationChannelTarget(node=node, path="weights")))
    return doc.add("animations", anim)


def add_key_times(doc: GltfDocument, duration: float) -> int:
    """The shared input accessor: KEYS times evenly spaced over [0, duration] seconds."""
    return doc.accessor(np.linspace(0.0, duration, KEYS).astype(np.float32), target=None, minmax=True,
                        name="gesture_key_times")
