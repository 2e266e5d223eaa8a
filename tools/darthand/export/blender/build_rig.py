"""Write the Blender-native rig (.blend) from the arrays export/blender_rig.py prepared: run with Blender's Python as
`python build_rig.py SPEC.json`.

SPEC: out (.blend path), arrays (npz path), names (object / armature / material names), joint names and parents,
gesture names, texture (albedo PNG or null). The npz holds, all in Blender's Z-up frame (metres):
    vertices (V, 3), faces (F, 3), uvs (F, 3, 2) per corner, weights (V, 16)
    cap_vertices (C, 3), cap_faces, cap_uvs (L, 3, 2) or empty, cap_weights (C, 16)
    shapes (V, 3, 135), cap_shapes (C, 3, 135): corrective offsets per bone-frame channel g = flatten(Q_j - I)
        (joint j = 1..15, row-major), Q_j the pose bone's local rotation
    heads (16, 3), tails (16, 3), z_axes (16, 3): bones (head, tail, bone Z axis for the roll)
    gesture_quats (G, 16, 4): pose-bone rotation quaternions (w, x, y, z) per gesture

Each shape key is driven by its bone's rotation: a driver of type 'simple expression' (evaluated without Python, so
it runs in files opened with auto-run scripts off) reads the bone's local rotation as a quaternion (w, x, y, z)
through Transform Channel variables (any rotation mode) and computes (Q - I)_ab, e.g. -2*(y*y+z*z) for (0, 0).
"""

import json
import sys

import bpy
import numpy as np

# (Q - I)_ab of a unit quaternion (w, x, y, z), as driver expressions.
Q_MINUS_I = {
    (0, 0): "-2*(y*y+z*z)", (0, 1): "2*(x*y-w*z)", (0, 2): "2*(x*z+w*y)",
    (1, 0): "2*(x*y+w*z)", (1, 1): "-2*(x*x+z*z)", (1, 2): "2*(y*z-w*x)",
    (2, 0): "2*(x*z-w*y)", (2, 1): "2*(y*z+w*x)", (2, 2): "-2*(x*x+y*y)",
}


def main(spec_path):
    spec = json.load(open(spec_path))
    a = dict(np.load(spec["arrays"]))
    names = spec["names"]
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.unit_settings.system = "METRIC"

    arma_data = bpy.data.armatures.new(names["skeleton"])
    arma = bpy.data.objects.new(names["root"], arma_data)
    scene.collection.objects.link(arma)
    bpy.context.view_layer.objects.active = arma
    bpy.ops.object.mode_set(mode="EDIT")
    bones = []
    for j, name in enumerate(spec["joint_names"]):
        eb = arma_data.edit_bones.new(name)
        eb.head, eb.tail = a["heads"][j].tolist(), a["tails"][j].tolist()
        eb.align_roll(a["z_axes"][j].tolist())
        parent = spec["parents"][j]
        if parent >= 0:
            eb.parent = bones[parent]
        bones.append(eb)
    bpy.ops.object.mode_set(mode="OBJECT")
    for pb in arma.pose.bones:
        pb.rotation_mode = "QUATERNION"

    material = skin_material(names["material"], spec.get("texture"))
    hand = skinned_mesh(names["hand"], a["vertices"], a["faces"], a["uvs"], a["weights"], spec["joint_names"], arma,
                        material)
    cap = skinned_mesh(names["cap"], a["cap_vertices"], a["cap_faces"], a["cap_uvs"], a["cap_weights"],
                       spec["joint_names"], arma, material)
    for obj, shapes in ((hand, a["shapes"]), (cap, a["cap_shapes"])):
        add_corrective_keys(obj, shapes, arma, spec["joint_names"])

    arma.animation_data_create()
    for g, gesture in enumerate(spec["gestures"]):
        action = bpy.data.actions.new(f"{names['root']}_{gesture}")
        action.use_fake_user = True
        arma.animation_data.action = action
        for pb in arma.pose.bones:
            pb.rotation_quaternion = a["gesture_quats"][g, spec["joint_names"].index(pb.name)].tolist()
            pb.keyframe_insert("rotation_quaternion", frame=1)
        action.asset_mark()
        action.asset_data.description = f"darthand gesture '{gesture}' (MANO pose, exact with the correctives)"
    arma.animation_data.action = bpy.data.actions[f"{names['root']}_{spec['gestures'][0]}"]
    scene.frame_set(1)
    bpy.context.preferences.filepaths.save_version = 0          # no .blend1 backup beside the output
    bpy.ops.wm.save_as_mainfile(filepath=spec["out"], compress=True)


def skinned_mesh(name, vertices, faces, uvs, weights, joint_names, arma, material):
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(vertices.tolist(), [], faces.tolist())
    if uvs.size:
        layer = mesh.uv_layers.new(name="UVMap")
        layer.data.foreach_set("uv", uvs.reshape(-1))
    mesh.materials.append(material)
    mesh.shade_smooth()
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    obj.parent = arma
    for j, joint in enumerate(joint_names):
        group = obj.vertex_groups.new(name=joint)
        for v in np.flatnonzero(weights[:, j] > 0):
            group.add([int(v)], float(weights[v, j]), "REPLACE")
    mod = obj.modifiers.new("Armature", "ARMATURE")
    mod.object = arma
    return obj


def add_corrective_keys(obj, shapes, arma, joint_names):
    """One shape key per bone-frame channel (signed, slider -2..2), driven by its bone's rotation."""
    basis = obj.shape_key_add(name="Basis")
    rest = np.empty(3 * len(obj.data.vertices))
    basis.data.foreach_get("co", rest)
    for k in range(shapes.shape[2]):
        j, (r, c) = 1 + k // 9, divmod(k % 9, 3)
        key = obj.shape_key_add(name=f"pose_{joint_names[j]}_q{r}{c}", from_mix=False)
        key.slider_min, key.slider_max = -2.0, 2.0
        key.data.foreach_set("co", rest + shapes[:, :, k].reshape(-1))
        driver = key.driver_add("value").driver
        driver.type = "SCRIPTED"
        for comp, axis in zip("wxyz", ("ROT_W", "ROT_X", "ROT_Y", "ROT_Z")):
            var = driver.variables.new()
            var.name, var.type = comp, "TRANSFORMS"
            target = var.targets[0]
            target.id, target.bone_target = arma, joint_names[j]
            target.transform_type, target.rotation_mode = axis, "QUATERNION"
            target.transform_space = "LOCAL_SPACE"
        driver.expression = Q_MINUS_I[(r, c)]


def skin_material(name, texture):
    material = bpy.data.materials.new(name)
    material.use_nodes = True
    bsdf = material.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Roughness"].default_value = 0.5
    if texture:
        image = bpy.data.images.load(texture)
        image.pack()
        node = material.node_tree.nodes.new("ShaderNodeTexImage")
        node.image = image
        material.node_tree.links.new(node.outputs["Color"], bsdf.inputs["Base Color"])
    else:
        bsdf.inputs["Base Color"].default_value = (0.56, 0.36, 0.27, 1.0)
    return material


if __name__ == "__main__":
    main(sys.argv[-1])
