"""The Blender-native rig: a .blend written through bpy (Blender's own Python module), in which the pose correctives
follow the bones.

Why a .blend rather than an add-on that rigs an imported USD/glTF: opening a file is what Blender users expect, it
needs nothing installed or enabled, and its drivers are 'simple expressions' that Blender evaluates without Python,
so they work in files opened with auto-run scripts off (an add-on would need installing, and Python drivers would
need trusting the file). USD and glTF have no pose-space deformers; they keep the baked gesture animations.

What the file holds (Blender's frame: Z up, the USD/glTF importers' orientation; names as in the other packages):
    armature object `<Side>Hand` (data `<Side>HandSkeleton`): 16 bones along the fingers (model/bones.py frames:
        +Y along the bone, X the flexion axis), pose bones in quaternion mode;
    mesh `<Side>HandMesh` (the model's vertex order) and `<Side>ForearmCap`, skinned by vertex groups named after
        the joints, with 135 shape keys `pose_<joint>_q<a><b>` each driven by its bone: the MANO correctives
        re-expressed in the bone's frame. MANO adds sum P_j flatten(R_j - I) with R_j = O_j Q_j O_j^T (Q_j the
        pose bone's local rotation), which is linear in flatten(Q_j - I): shape key (j, a, b) holds
        sum_rc P_j[rc] O_j[r, a] O_j[c, b] and its driver computes (Q_j - I)_ab from the bone's quaternion;
    material `<Side>HandSkin` with the default texture packed in;
    one action per gesture `<Side>Hand_<gesture>` (marked as pose assets, so the Pose Library lists them), the
        first (the flat hand) assigned.

Posing any bone by hand therefore gives exactly MANO's vertices (tests: random bone poses against `forward`).
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

import numpy as np

from darthand.export.blender_engine import run_script
from darthand.export.gestures import gesture_poses
from darthand.fileio import atomic_path
from darthand.model import bones
from darthand.model.anatomy import bone_ends, rest_joints
from darthand.model.cap import forearm_cap
from darthand.model.hand_model import HandModel
from darthand.model.layout import JOINT_NAMES, NUM_JOINTS
from darthand.model.rotations import matrix_to_quaternion

# Model frame (Y up) -> Blender frame (Z up): (x, y, z) -> (x, -z, y), as Blender's USD and glTF importers rotate.
TO_BLENDER = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def bone_frame_correctives(posedirs: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """(N, 3, 135) correctives per bone-frame channel flatten(Q_j - I), j = 1..15, from MANO's posedirs (N, 3, 135)
    per flatten(R_j - I): D_j[:, :, (a, b)] = sum_rc P_j[:, :, (r, c)] O_j[r, a] O_j[c, b]."""
    P = np.asarray(posedirs, dtype=np.float64).reshape(len(posedirs), 3, NUM_JOINTS - 1, 9)
    M = np.einsum("jra,jcb->jrcab", frames[1:], frames[1:]).reshape(NUM_JOINTS - 1, 9, 9)
    return np.einsum("nkjs,jst->nkjt", P, M).reshape(len(posedirs), 3, -1)


def rig_arrays(model: HandModel, poses: np.ndarray) -> dict:
    """The arrays build_rig.py reads (see its docstring), in Blender's frame."""
    C = TO_BLENDER
    frames = bones.bone_frames(model)
    joints = rest_joints(model)
    cap = forearm_cap(model)

    def corner_uvs(uvs, faces_uv):
        return np.zeros((0, 3, 2)) if uvs is None else np.asarray(uvs)[faces_uv]

    q = matrix_to_quaternion(bones.bone_rotations(poses, frames))                 # (G, 16, 4) w, x, y, z
    return {
        "vertices": model.v_template @ C.T, "faces": model.faces, "weights": model.weights,
        "uvs": corner_uvs(model.uvs, model.faces_uv),
        "cap_vertices": cap.vertices @ C.T, "cap_faces": cap.faces, "cap_weights": cap.weights,
        "cap_uvs": corner_uvs(cap.uvs, cap.faces_uv),
        "shapes": np.einsum("ab,nbk->nak", C, bone_frame_correctives(model.posedirs, frames)),
        "cap_shapes": np.einsum("ab,nbk->nak", C, bone_frame_correctives(cap.posedirs, frames)),
        "heads": joints @ C.T, "tails": bone_ends(model, joints) @ C.T, "z_axes": frames[:, :, 2] @ C.T,
        "gesture_quats": q,
    }


def export_blend(model: HandModel, out: str | os.PathLike, *, texture: str | os.PathLike | None = None,
                 gestures: tuple[list[str], np.ndarray] | None = None) -> dict:
    """Write the Blender-native rig of `model` to `out` (.blend) through Blender's Python; returns what was written.
    texture: the albedo PNG to pack (None: a constant skin colour)."""
    out = Path(out)
    names, poses = gesture_poses(model) if gestures is None else (list(gestures[0]), np.asarray(gestures[1]))
    prefix = model.side.capitalize()
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="darthand-blend-") as tmp, atomic_path(out) as part:
        arrays = Path(tmp) / "rig.npz"
        np.savez(arrays, **rig_arrays(model, poses))
        spec = {"out": str(part), "arrays": str(arrays),
                "names": {"root": f"{prefix}Hand", "skeleton": f"{prefix}HandSkeleton", "hand": f"{prefix}HandMesh",
                          "cap": f"{prefix}ForearmCap", "material": f"{prefix}HandSkin"},
                "joint_names": list(JOINT_NAMES), "parents": [int(p) for p in model.parents],
                "gestures": names, "texture": str(Path(texture).resolve()) if texture else None}
        run_script("build_rig.py", spec)
    info = {"file": str(out), "bytes": out.stat().st_size, "gestures": names, "shape_keys": 135,
            "convention": bones.CONVENTION}
    out.with_suffix(".json").write_text(json.dumps(info, indent=2))
    return info
