"""A persistent Cycles renderer: run with Blender's Python as `python cycles_worker.py`; render/cycles.py starts it
and sends it one JSON request a line on stdin, and it answers one JSON line per request on its stdout (Blender's own
output goes to stderr).

    {"cmd": "render", "arrays": NPZ, "out": EXR, "width", "height", "samples", "seed", "threads", "denoise",
     "camera": {...}, "surfaces": [...], "lights": [...], "world": {...}}
                                                  -> {"ok": true, "seconds": wall s, "cpu_seconds": CPU s}
    {"cmd": "quit"}                                                          -> exits
    a failure                                                                -> {"ok": false, "error": "one line"}

Everything is already in Blender's frame (Z up, metres): render/cycles.py converts. The scene is built once; each
request updates it: a surface's mesh in place when its vertex count and faces are unchanged (else a new mesh), its
materials (made once per key), the camera, the lights (made again: a few) and the world. The output is a multilayer
EXR with the Combined pass (linear, premultiplied, denoised when asked; film transparent so alpha is coverage) and
the Environment pass (the world seen by each pixel's camera ray, behind everything).

NPZ arrays per surface k: v{k} (N, 3) float32 vertices, n{k} (N, 3) float32 vertex normals, f{k} (F, 3) int32
faces, uv{k} (3F, 2) float32 per-corner UVs (optional), mi{k} (F,) int32 material slot per face (0, or 1 for a
surface's second material, e.g. nails).
"""

import json
import os
import sys
import time

import bpy
import numpy as np
from mathutils import Matrix

STATE: dict = {"meshes": {}, "faces": {}, "materials": {}, "images": {}, "lights": []}
KEEP_MATERIALS = 16        # materials kept for later frames (a catalogue texture is 16-64 MB in Blender's memory)


def main():
    reply = os.fdopen(os.dup(1), "w", buffering=1)
    os.dup2(2, 1)                         # Cycles prints progress on stdout: keep it out of the answers
    setup_scene()
    for line in sys.stdin:
        request = json.loads(line)
        if request.get("cmd") == "quit":
            break
        t, cpu = time.perf_counter(), time.process_time()
        try:
            render(request)
            answer = {"ok": True, "seconds": time.perf_counter() - t, "cpu_seconds": time.process_time() - cpu}
        except Exception as e:            # reported to the caller as one line; the worker keeps serving
            answer = {"ok": False, "error": f"{type(e).__name__}: {str(e).strip().splitlines()[0][:300]}"}
        reply.write(json.dumps(answer) + "\n")


def setup_scene():
    """An empty scene rendered by Cycles on the CPU to a multilayer EXR: box pixel filter of one pixel (a pixel's
    value is the average over its area, as the fast renderer's coverage), transparent film, Environment pass."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.pixel_filter_type = "BOX"
    scene.cycles.filter_width = 1.0
    scene.render.film_transparent = True
    scene.render.resolution_percentage = 100
    scene.view_layers[0].use_pass_environment = True
    settings = scene.render.image_settings
    settings.media_type = "MULTI_LAYER_IMAGE"
    settings.file_format = "OPEN_EXR_MULTILAYER"
    settings.color_depth = "32"
    settings.exr_codec = "ZIP"
    scene.render.threads_mode = "FIXED"
    camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    scene.collection.objects.link(camera)
    scene.camera = camera
    world = bpy.data.worlds.new("world")
    scene.world = world


def render(request):
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = int(request["width"]), int(request["height"])
    scene.cycles.samples = int(request["samples"])
    scene.cycles.seed = int(request["seed"])
    scene.cycles.use_denoising = bool(request["denoise"])
    if request["denoise"]:
        scene.cycles.denoiser = "OPENIMAGEDENOISE"
    scene.render.threads = int(request["threads"])
    set_camera(scene.camera, request["camera"])
    forget_materials({m["key"] for s in request["surfaces"] for m in s["materials"]})
    with np.load(request["arrays"]) as arrays:
        set_surfaces(scene, request["surfaces"], arrays)
    set_lights(scene, request["lights"])
    set_world(scene.world, request["world"])
    scene.render.filepath = request["out"]
    bpy.ops.render.render(write_still=True)


# ------------------------------------------------------------------------------------------------ camera


def set_camera(obj, spec):
    """spec: matrix (4, 4) camera -> world (Blender's camera axes: x right, y up, looking down -z), lens_mm,
    sensor_mm (the sensor's width: fit 'HORIZONTAL'), shift_x, shift_y (fractions of the image width), aspect
    [x, y] (pixel aspect), clip [near, far] metres."""
    obj.matrix_world = Matrix(spec["matrix"])
    cam = obj.data
    cam.type = "PERSP"
    cam.sensor_fit = "HORIZONTAL"
    cam.sensor_width = float(spec["sensor_mm"])
    cam.lens = float(spec["lens_mm"])
    cam.shift_x, cam.shift_y = float(spec["shift_x"]), float(spec["shift_y"])
    cam.clip_start, cam.clip_end = (float(c) for c in spec["clip"])
    scene = bpy.context.scene
    scene.render.pixel_aspect_x, scene.render.pixel_aspect_y = (float(a) for a in spec["aspect"])


# ------------------------------------------------------------------------------------------------ surfaces


def set_surfaces(scene, surfaces, arrays):
    """One object per surface name: its mesh updated in place when its faces are the same, else replaced (a left
    and a right hand have the same counts but opposite windings and corner UVs); objects of surfaces not in this
    frame are hidden."""
    shown = set()
    for k, spec in enumerate(surfaces):
        name = spec["name"]
        shown.add(name)
        v, n, f = arrays[f"v{k}"], arrays[f"n{k}"], arrays[f"f{k}"]
        uv = arrays[f"uv{k}"] if f"uv{k}" in arrays.files else None
        obj = STATE["meshes"].get(name)
        if obj is None:
            obj = bpy.data.objects.new(name, bpy.data.meshes.new(name))
            scene.collection.objects.link(obj)
            STATE["meshes"][name] = obj
        mesh = obj.data
        if len(mesh.vertices) != len(v) or not np.array_equal(STATE["faces"].get(name), f):
            old = mesh
            mesh = new_mesh(name, len(v), f, uv is not None)
            obj.data = mesh
            bpy.data.meshes.remove(old)
            STATE["faces"][name] = np.array(f)
        update_mesh(mesh, v, n, uv, arrays[f"mi{k}"])
        set_materials(mesh, spec["materials"])
        obj.hide_render = False
    for name, obj in STATE["meshes"].items():
        if name not in shown:
            obj.hide_render = True


def new_mesh(name, count, faces, with_uv):
    """A triangle mesh of `count` vertices (at the origin until update_mesh places them) and `faces` (F, 3)."""
    faces = np.asarray(faces, np.int32)
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(int(count))
    mesh.loops.add(faces.size)
    mesh.loops.foreach_set("vertex_index", faces.ravel())
    mesh.polygons.add(len(faces))
    mesh.polygons.foreach_set("loop_start", np.arange(0, faces.size, 3, dtype=np.int32))
    mesh.polygons.foreach_set("use_smooth", np.ones(len(faces), bool))
    if with_uv:
        mesh.uv_layers.new(name="uv")
    mesh.update(calc_edges=True)
    return mesh


def update_mesh(mesh, vertices, normals, uv, material_index):
    """Place the vertices, the darthand vertex normals (custom normals: shading as the fast renderer's), UVs and
    the per-face material slots."""
    if len(mesh.vertices) != len(vertices):
        raise ValueError(f"surface {mesh.name}: {len(vertices)} vertices for a mesh of {len(mesh.vertices)}")
    mesh.vertices.foreach_set("co", np.ascontiguousarray(vertices, np.float32).ravel())
    if uv is not None and mesh.uv_layers:
        mesh.uv_layers[0].data.foreach_set("uv", np.ascontiguousarray(uv, np.float32).ravel())
    mesh.polygons.foreach_set("material_index", np.ascontiguousarray(material_index, np.int32))
    mesh.update()
    mesh.normals_split_custom_set_from_vertices(np.ascontiguousarray(normals, np.float32).reshape(-1, 3))


def forget_materials(keep):
    """Past KEEP_MATERIALS, remove the materials this frame does not use, then the images nothing uses."""
    if len(STATE["materials"]) <= KEEP_MATERIALS:
        return
    for key in [k for k in STATE["materials"] if k not in keep]:
        bpy.data.materials.remove(STATE["materials"].pop(key))
    for key in [k for k, img in STATE["images"].items() if img.users == 0]:
        bpy.data.images.remove(STATE["images"].pop(key))


def set_materials(mesh, specs):
    if [m.name if m else None for m in mesh.materials] == [s["key"] for s in specs]:
        return
    mesh.materials.clear()
    for spec in specs:
        mesh.materials.append(material(spec))


def material(spec):
    """The Principled BSDF material of a spec (made once per key): base (colour) and roughness, metallic (data),
    each {"image": PNG} or {"value": ...}; ior; specular_level; subsurface None or {"radius": [r, g, b],
    "scale": metres}."""
    if spec["key"] in STATE["materials"]:
        return STATE["materials"][spec["key"]]
    mat = bpy.data.materials.new(spec["key"])
    tree = material_tree(mat)
    bsdf = next(n for n in tree.nodes if n.type == "BSDF_PRINCIPLED")
    connect(tree, bsdf, "Base Color", spec["base"], "sRGB")
    connect(tree, bsdf, "Roughness", spec["roughness"], "Non-Color")
    connect(tree, bsdf, "Metallic", spec["metallic"], "Non-Color")
    bsdf.inputs["IOR"].default_value = float(spec["ior"])
    bsdf.inputs["Specular IOR Level"].default_value = float(spec["specular_level"])
    sss = spec.get("subsurface")
    bsdf.inputs["Subsurface Weight"].default_value = 1.0 if sss else 0.0
    if sss:
        bsdf.subsurface_method = "RANDOM_WALK_SKIN"
        bsdf.inputs["Subsurface Radius"].default_value = [float(r) for r in sss["radius"]]
        bsdf.inputs["Subsurface Scale"].default_value = float(sss["scale"])
    STATE["materials"][spec["key"]] = mat
    return mat


def material_tree(mat):
    """The material's node tree with a Principled BSDF (Blender 5 makes one for a new material; older, use_nodes)."""
    if mat.node_tree is None:
        mat.use_nodes = True
    return mat.node_tree


def connect(tree, bsdf, socket, spec, colorspace):
    """Feed a BSDF input a constant or an image texture (UV mapped, clamped at the edges like the fast renderer's
    lookups)."""
    if "value" in spec:
        value = spec["value"]
        target = bsdf.inputs[socket]
        target.default_value = (*value, 1.0) if isinstance(value, list) else float(value)
        return
    node = tree.nodes.new("ShaderNodeTexImage")
    node.image = image(spec["image"], colorspace)
    node.interpolation = "Linear"
    node.extension = "EXTEND"
    tree.links.new(node.outputs["Color"], bsdf.inputs[socket])


def image(path, colorspace):
    key = (path, colorspace)
    if key not in STATE["images"]:
        img = bpy.data.images.load(path)
        img.colorspace_settings.name = colorspace
        STATE["images"][key] = img
    return STATE["images"][key]


# ------------------------------------------------------------------------------------------------ lights, world


def set_lights(scene, specs):
    """Replace the lights: {"type": "SUN" | "POINT", "color" (3,) in [0, 1], "energy" (W/m^2 for a sun, W for a
    point light), "matrix" (4, 4) light -> world (a sun shines along its -z), "shadows"}."""
    for obj in STATE["lights"]:
        data = obj.data
        bpy.data.objects.remove(obj)
        bpy.data.lights.remove(data)
    STATE["lights"] = []
    for k, spec in enumerate(specs):
        data = bpy.data.lights.new(f"light{k}", spec["type"])
        data.color = spec["color"]
        data.energy = float(spec["energy"])
        data.use_shadow = bool(spec["shadows"])
        if spec["type"] == "SUN":
            data.angle = 0.0                   # the fast renderer's lights are ideal: hard shadows
        else:
            data.shadow_soft_size = 0.0
            data.use_soft_falloff = False      # a point light's plain inverse-square law
        obj = bpy.data.objects.new(f"light{k}", data)
        obj.matrix_world = Matrix(spec["matrix"])
        scene.collection.objects.link(obj)
        STATE["lights"].append(obj)


def set_world(world, spec):
    """The world's radiance: {"ambient": [r, g, b]} plus, with "environment": {"map": EXR/HDR path, "rotation":
    (3,) XYZ Euler radians of the Mapping node (world direction -> map direction), "scale": [r, g, b]} the map's
    radiance times scale. Rebuilt every frame (a few nodes)."""
    tree = world_tree(world)
    tree.nodes.clear()
    out = tree.nodes.new("ShaderNodeOutputWorld")
    background = tree.nodes.new("ShaderNodeBackground")
    background.inputs["Strength"].default_value = 1.0
    tree.links.new(background.outputs["Background"], out.inputs["Surface"])
    ambient = [float(a) for a in spec["ambient"]]
    env = spec.get("environment")
    if env is None:
        background.inputs["Color"].default_value = (*ambient, 1.0)
        return
    coords = tree.nodes.new("ShaderNodeTexCoord")
    mapping = tree.nodes.new("ShaderNodeMapping")
    mapping.vector_type = "VECTOR"
    mapping.inputs["Rotation"].default_value = env["rotation"]
    texture = tree.nodes.new("ShaderNodeTexEnvironment")
    texture.image = image(env["map"], "Linear Rec.709")
    texture.interpolation = "Linear"
    scale = tree.nodes.new("ShaderNodeVectorMath")
    scale.operation = "MULTIPLY"
    scale.inputs[1].default_value = [float(s) for s in env["scale"]]
    add = tree.nodes.new("ShaderNodeVectorMath")
    add.operation = "ADD"
    add.inputs[1].default_value = ambient
    tree.links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
    tree.links.new(mapping.outputs["Vector"], texture.inputs["Vector"])
    tree.links.new(texture.outputs["Color"], scale.inputs[0])
    tree.links.new(scale.outputs["Vector"], add.inputs[0])
    tree.links.new(add.outputs["Vector"], background.inputs["Color"])


def world_tree(world):
    if world.node_tree is None:
        world.use_nodes = True
    return world.node_tree


if __name__ == "__main__":
    main()
