"""Import a package into Blender with its importer's default options and read back what Blender computes.

Run by export/blender_engine.py as `python evaluate.py SPEC.json` with Blender's Python. SPEC:

    file       .usda/.usdc/.usd, .glb/.gltf or .blend
    out        npz to write: for every evaluation k and mesh object, `k/<object name>` (N, 3) world positions
               in Blender's frame (metres, Z up), plus `info` (JSON text)
    frames     optional list of scene frames to evaluate (labels `frame_<f>`)
    actions    optional: evaluate every action (glTF clips) at its first frame (labels `action_<name>`)
    bone_poses optional {label: {bone name: [w, x, y, z]}}: pose-bone rotations set on the armature (labels as given)

`info` holds the import seconds, every object (name, type, parent, data name), materials, actions, the armature's
bones (head, tail, roll matrix in armature space) and each mesh's shape-key slider ranges.
"""

import json
import os
import sys
import time

import bpy
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from scene import assign_action, open_package  # noqa: E402


def main(spec_path):
    spec = json.load(open(spec_path))
    t0 = time.perf_counter()
    open_package(spec["file"])
    seconds = time.perf_counter() - t0
    scene = bpy.context.scene
    # Skinned meshes and meshes parented to the armature or its bones (rigid accessories)
    meshes = [o for o in scene.objects if o.type == "MESH" and (
        any(m.type == "ARMATURE" for m in o.modifiers) or (o.parent is not None and o.parent.type == "ARMATURE"))]
    arma = next((o for o in scene.objects if o.type == "ARMATURE"), None)
    out = {}

    def grab(label):
        depsgraph = bpy.context.evaluated_depsgraph_get()
        for obj in meshes:
            ev = obj.evaluated_get(depsgraph)
            mesh = ev.to_mesh()
            co = np.empty(3 * len(mesh.vertices))
            mesh.vertices.foreach_get("co", co)
            m = np.array(ev.matrix_world)
            co = co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
            ev.to_mesh_clear()
            out[f"{label}/{obj.name}"] = co

    grab("import")
    for f in spec.get("frames", []):
        scene.frame_set(int(f))
        grab(f"frame_{f}")
    if spec.get("actions"):
        for action in bpy.data.actions:
            assign_action(action, arma, meshes)
            scene.frame_set(int(action.frame_range[1 if spec.get("action_frame") == "last" else 0]))
            grab(f"action_{action.name}")
    if spec.get("bone_poses") and arma.animation_data is not None:
        arma.animation_data.action = None          # posing by hand: no action overriding the bones
    for label, pose in (spec.get("bone_poses") or {}).items():
        for name, q in pose.items():
            pb = arma.pose.bones[name]
            pb.rotation_mode = "QUATERNION"
            pb.rotation_quaternion = q
        grab(label)
    info = {
        "blender": bpy.app.version_string, "import_seconds": seconds,
        "objects": [{"name": o.name, "type": o.type, "parent": o.parent.name if o.parent else None,
                     "data": o.data.name if o.data else None} for o in scene.objects],
        "materials": [m.name for m in bpy.data.materials],
        "actions": [a.name for a in bpy.data.actions],
        "frames": [scene.frame_start, scene.frame_end],
        "meshes": [o.name for o in meshes],
        "shape_keys": {o.name: [[k.name, k.slider_min, k.slider_max] for k in o.data.shape_keys.key_blocks[1:]]
                       for o in meshes if o.data.shape_keys},
        "vertex_ids": {o.name: o.data.attributes["_VERTEX_ID"].data.foreach_get("value", a) or a.tolist()
                       for o in meshes if "_VERTEX_ID" in o.data.attributes
                       for a in [np.empty(len(o.data.vertices), np.float32)]},
    }
    if arma is not None:
        info["armature"] = arma.name
        info["armature_matrix"] = np.array(arma.matrix_world).tolist()
        info["bones"] = {b.name: {"head": list(b.head_local), "tail": list(b.tail_local),
                                  "matrix": np.array(b.matrix_local).tolist(), "parent": b.parent.name if b.parent
                                  else None} for b in arma.data.bones}
    np.savez(spec["out"], info=np.array(json.dumps(info)), **out)


if __name__ == "__main__":
    main(sys.argv[-1])
