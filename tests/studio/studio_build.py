"""A small build folder for the studio's tests, laid out as `make assets` lays one out: the open hand's
wrist-enhanced models (build/model/<side>.npz), a three-texture catalogue, an accessory catalogue with a rigid ring
and a skinned glove, and each side's glTF variants package, written by the export stage itself.
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "export"))

from export_catalogs import write_accessory_catalog, write_png, write_texture_catalog  # noqa: E402

from darthand.accessories.loader import Accessory  # noqa: E402
from darthand.model.anatomy import rest_joints  # noqa: E402
from darthand.model.layout import JOINT_NAMES  # noqa: E402

# Flat colours (sRGB 0..255) under catalogue-style ids <tone>_<category>_<nn>: the texture a test switches to must
# change the live view visibly.
TEXTURES = {"light_freckles_00": (236, 200, 176), "dark_tattoos_00": (92, 58, 40), "medium_moles_00": (190, 140, 100)}
RING, GLOVE = "ring_01_test_gold", "glove_01_test_index"
SRGB = {RING: (255, 196, 86), GLOVE: (50, 90, 204)}        # flat base-colour textures (no UVs: one texel is read)


def make_build(root: Path) -> Path:
    """Write the build under `root` and return it."""
    from darthand.export.gltf_export import export_gltf
    from darthand.model.load import load_model
    from darthand.model.mirror import mirror_model
    from darthand.model.npz_io import save_npz
    from darthand.model.wrist import add_wrist
    from darthand.textures.loader import load_texture_catalog

    right = add_wrist(load_model("open"))
    models = {"right": right, "left": mirror_model(right)}
    for side, model in models.items():
        save_npz(model, root / "model" / f"{side}.npz")
    images = root / "sources"
    variants = [(tid, write_png(images / f"{tid}.png", rgb, size=64), None) for tid, rgb in TEXTURES.items()]
    catalog = write_texture_catalog(root / "textures", variants)
    accessories = [replace(a, base_color_png=write_png(images / f"{a.id}.png", SRGB[a.id], size=8))
                   for a in (ring(right), glove(right))]
    write_accessory_catalog(root / "accessories", accessories)
    textures = load_texture_catalog(catalog)
    for side, model in models.items():
        export_gltf(model, root / "gltf" / side / f"{side}.gltf", textures=textures)
    return root


def ring(model) -> Accessory:
    """A torus around the ring finger's proximal bone, rigid on joint ring1, clear of the skin."""
    joints = rest_joints(model)
    j = JOINT_NAMES.index("ring1")
    a, b = joints[j], joints[j + 1]
    axis = (b - a) / np.linalg.norm(b - a)
    centre = a + 0.45 * (b - a)
    u = np.cross(axis, [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    skin = model.v_template[np.abs((model.v_template - centre) @ axis) < 0.003]
    near = skin[np.linalg.norm(skin - centre, axis=1) < 0.02]
    radius = float(np.linalg.norm((near - centre) - np.outer((near - centre) @ axis, axis), axis=1).max()) + 0.0015
    n, m, tube = 48, 12, 0.0016
    s, t = np.meshgrid(np.arange(n) * 2 * np.pi / n, np.arange(m) * 2 * np.pi / m, indexing="ij")
    ring_dir = np.cos(s)[..., None] * u + np.sin(s)[..., None] * v
    pts = centre + (radius + tube * np.cos(t))[..., None] * ring_dir + (tube * np.sin(t))[..., None] * axis
    i, k = np.meshgrid(np.arange(n), np.arange(m), indexing="ij")
    q00, q10, q11, q01 = (i * m + k), ((i + 1) % n * m + k), ((i + 1) % n * m + (k + 1) % m), (i * m + (k + 1) % m)
    faces = np.concatenate([np.stack([q00, q10, q11], -1).reshape(-1, 3), np.stack([q00, q11, q01], -1).reshape(-1, 3)])
    return Accessory(RING, pts.reshape(-1, 3), faces, parent_joint=j, kind="ring",
                     material={"base_color": [1.0, 0.77, 0.34], "metallic": 1.0, "roughness": 0.25})


def glove(model) -> Accessory:
    """A skinned sleeve over the index finger: its faces pushed 1.5 mm out along the vertex normals, with the hand's
    skin weights and correctives."""
    from darthand.model.topology import vertex_normals

    index = [JOINT_NAMES.index(n) for n in ("index1", "index2", "index3")]
    keep = np.isin(model.weights.argmax(1), index)
    faces = model.faces[keep[model.faces].all(1)]
    used = np.unique(faces)
    remap = np.full(model.num_vertices, -1)
    remap[used] = np.arange(len(used))
    normals = vertex_normals(model.v_template, model.faces)[used]
    return Accessory(GLOVE, model.v_template[used] + 0.0015 * normals, remap[faces], weights=model.weights[used],
                     posedirs=model.posedirs[used], kind="glove",
                     material={"base_color": [0.2, 0.35, 0.8], "metallic": 0.0, "roughness": 0.7})


# ------------------------------------------------------------------------------------------------ environment maps

UNIFORM_RADIANCE = 0.5                   # the uniform map's value (linear)


def direction_map(width: int = 256) -> np.ndarray:
    """(width / 2, width, 3) float32 equirectangular map whose texel holds 0.5 + 0.5 * d_E, d_E the unit direction
    that texel stands for in issue 28's convention (environment frame E, z up): the map centre column looks along
    -x, v = 1 is the top row. A view of it shows, per pixel, the direction it looked up."""
    height = width // 2
    u = (np.arange(width) + 0.5) / width
    v = 1 - (np.arange(height) + 0.5) / height                 # rows top to bottom
    azimuth = (u - 0.5) * 2 * np.pi                            # = atan2(d_y, -d_x)
    elevation = (v - 0.5) * np.pi                              # = atan2(d_z, hypot(d_x, d_y))
    el, az = np.meshgrid(elevation, azimuth, indexing="ij")
    d = np.stack([-np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=-1)
    return (0.5 + 0.5 * d).astype(np.float32)


def write_float_image(path: Path, pixels: np.ndarray) -> Path:
    """Write float pixels as .exr or .hdr (by suffix) with OpenImageIO."""
    import OpenImageIO as oiio

    path.parent.mkdir(parents=True, exist_ok=True)
    buf = oiio.ImageBuf(np.ascontiguousarray(pixels, np.float32))
    assert buf.write(str(path)), buf.geterror()
    return path


def make_environments(folder: Path) -> Path:
    """A --environments folder: two good maps (directions.hdr: direction_map(); uniform.hdr: UNIFORM_RADIANCE
    everywhere), and three bad ones: broken.exr (not an image), wide.exr (3:1), nan.exr (2:1 holding a NaN)."""
    write_float_image(folder / "directions.hdr", direction_map())
    write_float_image(folder / "uniform.hdr", np.full((32, 64, 3), UNIFORM_RADIANCE, np.float32))
    (folder / "broken.exr").write_bytes(b"this is not an OpenEXR file")
    write_float_image(folder / "wide.exr", np.ones((16, 48, 3), np.float32))
    nan = np.ones((16, 32, 3), np.float32)
    nan[3, 5, 1] = np.nan
    write_float_image(folder / "nan.exr", nan)
    (folder / "notes.txt").write_text("not a map: not listed")
    return folder
