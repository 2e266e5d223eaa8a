"""The packages in Blender: import seconds, the error of what Blender evaluates against `forward`, package sizes and
export seconds, for the USD package, the .glb and the Blender-native .blend (untextured, the model's gestures).

Headline: the largest error over every gesture of Blender's default USD import, then its glTF import (the
4-influence pruning error beside it), and the .blend's error over random bone poses. Blender runs in
.venv-blender (`make blender`); without it the module reports why it was skipped.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks._common import bench_model

RANDOM_POSES = 8


def run() -> dict:
    from darthand.export.blender_engine import BlenderUnavailable, blender_evaluate, blender_python
    from darthand.export.blender_rig import export_blend
    from darthand.export.gestures import gesture_poses
    from darthand.export.gltf_export import export_gltf
    from darthand.export.influences import pruned_model
    from darthand.export.usd_asset import export_usd
    from darthand.model import bones
    from darthand.model.anatomy import sample_poses
    from darthand.model.forward import forward
    from darthand.model.layout import JOINT_NAMES
    from darthand.model.rotations import matrix_to_quaternion

    try:
        blender_python()
    except BlenderUnavailable as e:
        return {"skipped": str(e)}
    model, source = bench_model()
    names, poses = gesture_poses(model)
    truth = forward(model, poses).vertices
    out: dict = {"model": source, "gestures": len(names)}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        t = time.perf_counter()
        info = export_usd(model, tmp / "usd", gestures=(names, poses))
        usd_write = time.perf_counter() - t
        usd = blender_evaluate(tmp / "usd" / info["interface"], frames=range(len(names)))
        usd_err = [_mm(usd.vertices[f"frame_{i}"]["RightHandMesh" if model.side == "right" else "LeftHandMesh"],
                       truth[i]) for i in range(len(names))]

        t = time.perf_counter()
        export_gltf(model, tmp / "hand.glb", gestures=(names, poses))
        glb_write = time.perf_counter() - t
        glb = blender_evaluate(tmp / "hand.glb", actions=True)
        mesh = glb.info["meshes"][0]
        ids = np.asarray(glb.info["vertex_ids"][mesh]).astype(int)
        hand = ids < model.num_vertices
        glb_err = [_mm(glb.vertices[f"action_{n}"][mesh][hand], truth[i][ids[hand]]) for i, n in enumerate(names)]
        pruned = forward(pruned_model(model, 4), poses).vertices
        prune_err = [_mm(pruned[i], truth[i]) for i in range(len(names))]

        t = time.perf_counter()
        export_blend(model, tmp / "hand.blend", gestures=(names, poses))
        blend_write = time.perf_counter() - t
        rng = np.random.default_rng(2022)
        random = sample_poses(model, RANDOM_POSES, rng)
        random[:, :3] = rng.normal(0, 0.6, (RANDOM_POSES, 3))
        q = matrix_to_quaternion(bones.bone_rotations(random, bones.bone_frames(model)))
        blend = blender_evaluate(tmp / "hand.blend", bone_poses={
            f"p{i}": {n: q[i, j].tolist() for j, n in enumerate(JOINT_NAMES)} for i in range(RANDOM_POSES)})
        mesh_b = blend.info["meshes"][0]
        posed = forward(model, random).vertices
        blend_err = [_mm(blend.vertices[f"p{i}"][mesh_b], posed[i]) for i in range(RANDOM_POSES)]

        out["usd_max_error_mm"] = max(usd_err)
        out["gltf_max_error_mm"] = max(glb_err)
        out["gltf_pruning_error_mm"] = max(prune_err)
        out["blend_bone_pose_max_error_mm"] = max(blend_err)
        out["per_gesture"] = [{"gesture": n, "usd_mm": round(usd_err[i], 6), "gltf_mm": round(glb_err[i], 6),
                               "pruning_mm": round(prune_err[i], 6)} for i, n in enumerate(names)]
        out["usd"] = {"payload_bytes": info["files"]["payload.usdc"], "package_bytes": sum(info["files"].values()),
                      "blend_shapes": info["rig"]["blend_shapes"], "write_s": round(usd_write, 3),
                      "blender_import_s": round(usd.info["import_seconds"], 3)}
        out["gltf"] = {"bytes": (tmp / "hand.glb").stat().st_size, "write_s": round(glb_write, 3),
                       "blender_import_s": round(glb.info["import_seconds"], 3)}
        out["blend"] = {"bytes": (tmp / "hand.blend").stat().st_size, "write_s": round(blend_write, 3),
                        "blender_open_s": round(blend.info["import_seconds"], 3)}
    return out


def _mm(a, b) -> float:
    return 1000 * float(np.linalg.norm(np.asarray(a) - np.asarray(b), axis=-1).max())
