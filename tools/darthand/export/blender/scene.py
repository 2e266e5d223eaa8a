"""What the Blender-side scripts share (runs inside Blender's Python: bpy, no darthand): opening a package the way
a user does, and assigning a gesture's action to the armature and the shape keys."""

import bpy


def open_package(path: str) -> None:
    """An empty scene, then `path` opened (.blend) or imported with the importer's default options (glTF, USD)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    if path.endswith(".blend"):
        bpy.ops.wm.open_mainfile(filepath=path)
    elif path.endswith((".glb", ".gltf")):
        bpy.ops.import_scene.gltf(filepath=path)
    else:
        bpy.ops.wm.usd_import(filepath=path)


def assign_action(action, arma, meshes) -> None:
    """Make `action` the active one of the armature and of the meshes' shape keys, each with its own slot (Blender
    5's slotted actions: a glTF clip holds a slot for the armature and one for the shape keys)."""
    for owner in [arma] + [o.data.shape_keys for o in meshes if o.data.shape_keys]:
        ad = owner.animation_data if owner is not None else None
        if ad is None:
            continue
        slot = next((s for s in action.slots if s.target_id_type == ("OBJECT" if owner is arma else "KEY")), None)
        ad.action = action
        if slot is not None:
            ad.action_slot = slot
