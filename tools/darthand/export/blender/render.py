"""Render a package in Blender (Cycles on the CPU or EEVEE), to look at it and to compare engines: run with Blender's
Python as `python render.py SPEC.json`.

SPEC: file (.blend, .glb/.gltf or USD), out (PNG), engine ('CYCLES' | 'BLENDER_EEVEE'), size [w, h] pixels,
samples, gesture (an action name suffix to assign, e.g. 'fist'; glTF: the clip name), texture (optional PNG that
replaces every image texture's file), camera: {location, target} in Blender's frame (metres, Z up), lens (mm).
A sun and a soft world light the hand; the background is transparent.
"""

import json
import os
import sys

import bpy
from mathutils import Vector

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from scene import assign_action, open_package  # noqa: E402


def main(spec_path):
    spec = json.load(open(spec_path))
    open_package(spec["file"])
    scene = bpy.context.scene
    arma = next(o for o in scene.objects if o.type == "ARMATURE")
    if spec.get("gesture"):
        action = next(a for a in bpy.data.actions if a.name.endswith(spec["gesture"]))
        assign_action(action, arma, [o for o in scene.objects if o.type == "MESH"])
        scene.frame_set(int(action.frame_range[0]))
    if spec.get("texture"):
        for image in bpy.data.images:
            if image.source == "FILE" or image.packed_file:
                if image.packed_file:
                    image.unpack(method="REMOVE")
                image.filepath = spec["texture"]
                image.reload()
                image.colorspace_settings.name = "sRGB"      # an albedo, whatever the file's metadata says
    for obj in [o for o in scene.objects if o.type == "MESH" and o.name == "Icosphere"]:
        obj.hide_render = True                    # the glTF importer's bone shape
    cam_data = bpy.data.cameras.new("Camera")
    cam_data.lens = spec.get("lens", 85.0)
    cam = bpy.data.objects.new("Camera", cam_data)
    scene.collection.objects.link(cam)
    cam.location = spec["camera"]["location"]
    direction = Vector(spec["camera"]["target"]) - cam.location
    cam.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()
    scene.camera = cam
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy = 3.0
    sun.rotation_euler = (0.7, 0.2, 0.6)
    scene.collection.objects.link(sun)
    world = bpy.data.worlds.new("World")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.6
    scene.world = world
    scene.render.engine = spec.get("engine", "CYCLES")
    if scene.render.engine == "CYCLES":
        scene.cycles.device = "CPU"
        scene.cycles.samples = spec.get("samples", 32)
    else:
        scene.eevee.taa_render_samples = spec.get("samples", 16)
    scene.render.resolution_x, scene.render.resolution_y = spec["size"]
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = True
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_mode = "RGBA"
    scene.render.filepath = spec["out"]
    bpy.ops.render.render(write_still=True)


if __name__ == "__main__":
    main(sys.argv[-1])
