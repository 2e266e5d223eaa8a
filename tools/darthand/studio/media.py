"""What the page shows besides the package itself, made on first request and cached under BUILD/studio/cache:
texture and accessory thumbnails, each accessory as a small glTF bound to the hand's skeleton, background images.

Thumbnails reuse the stages' own preview drawing (textures/sheet.py: the textured hand's back and palm, as the
texture contact sheet; accessories/preview.py: the accessory on the rest hand, as the accessory contact sheet).
An accessory's glTF is written with the export stage's parts (skeleton, skin, accessory), so it carries the same
joint names, bind matrices, corrective shapes and materials as an exported package would: the page moves its rigid
mesh onto the hand's joint node and binds a glove to the hand's skeleton.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from darthand.accessories.preview import render_view
from darthand.dataset.backgrounds import background_pixels, decode_image
from darthand.export.correctives import export_correctives
from darthand.export.gltf_accessories import add_accessory
from darthand.export.gltf_document import GltfDocument
from darthand.export.gltf_materials import MaterialBuilder
from darthand.export.gltf_rig import add_skeleton, add_skin
from darthand.export.influences import parse_influences
from darthand.export.skeleton import export_skeleton
from darthand.model.topology import vertex_normals
from darthand.render.image import write_png
from darthand.textures import sheet
from darthand.textures.color import encode_srgb8
from darthand.textures.imageio import read_small

THUMB_SIZE = 96
BACKGROUND_SIZE = 512


def cached_file(path: Path, make) -> bytes:
    """The bytes of `path`, made by make(path) first if it does not exist (atomic writers: a half-made file is
    never seen)."""
    if not path.is_file():
        path.parent.mkdir(parents=True, exist_ok=True)
        make(path)
    return path.read_bytes()


# ------------------------------------------------------------------------------------------------ thumbnails


def texture_thumbnail(side, texture_id: str, path: Path) -> None:
    """Write the THUMB_SIZE PNG of the hand wearing a texture (back above, palm below)."""
    maps = _preview_maps(side)
    albedo = read_small(side.source.textures[texture_id].albedo, 256)[..., :3]
    write_png(path, sheet.thumbnail(np.ascontiguousarray(albedo), maps))


def _preview_maps(side):
    if side.preview is None:
        m = side.model
        mesh = {"vertices": m.v_template, "faces": m.faces, "uvs": m.uvs, "faces_uv": m.faces_uv,
                "vertex_normals": vertex_normals(m.v_template, m.faces)}
        side.preview = sheet.preview_maps(mesh, THUMB_SIZE)
    return side.preview


def accessory_thumbnail(side, accessory_id: str, path: Path) -> None:
    """Write the THUMB_SIZE PNG of an accessory on the rest hand, framed on the accessory."""
    acc = side.source.accessories[accessory_id]
    model = side.model
    mesh = {"vertices": acc.vertices, "faces": acc.faces, "metallic": float(acc.material.get("metallic", 0.0))}
    if acc.uvs is not None and acc.base_color_png is not None:
        mesh.update(uvs=acc.uvs, faces_uv=acc.faces_uv, texture=decode_image(str(acc.base_color_png)))
    else:
        mesh["color"] = np.asarray(acc.material.get("base_color", (0.8, 0.8, 0.8))[:3], np.float64)
    lo, hi = acc.vertices.min(0), acc.vertices.max(0)
    extent = 1.5 * float(np.linalg.norm(hi - lo))
    image = render_view([{"vertices": model.v_template, "faces": model.faces}, mesh], 0.5 * (lo + hi),
                        (-0.3, -1.0, -0.5), (-1.0, 0.0, 0.0), extent, THUMB_SIZE)
    write_png(path, encode_srgb8(image))


# ------------------------------------------------------------------------------------------------ accessories


def accessory_glb(side, accessory_id: str, package: dict) -> bytes:
    """A GLB holding the hand's skeleton (same joint nodes and skin as the package) and one accessory, exported with
    the package's influences and corrective encoding (its asset.extras.darthand)."""
    import pygltflib as gl

    extras = package.get("asset", {}).get("extras", {}).get("darthand", {})
    model = side.model
    prefix = model.side.capitalize()
    doc = GltfDocument()
    skeleton = export_skeleton(model)
    root = doc.add("nodes", gl.Node(name=f"{prefix}Hand"))
    doc.gltf.scenes[0].nodes.append(root)
    joints = add_skeleton(doc, skeleton, root)
    skin = add_skin(doc, joints, skeleton, name=f"{prefix}HandSkeleton")
    add_accessory(doc, side.source.accessories[accessory_id], materials=MaterialBuilder(doc), joint_nodes=joints,
                  skeleton=skeleton, skin=skin, influences=parse_influences(str(extras.get("influences", 4))),
                  correctives=export_correctives(model, extras.get("correctives", "full")), prefix=prefix)
    return doc.glb_bytes()


# ------------------------------------------------------------------------------------------------ backgrounds


def background_image(spec: dict, path: Path, size: int = BACKGROUND_SIZE) -> None:
    """Write the size x size sRGB PNG of a background spec (dataset/backgrounds.py) as a dataset frame of that size
    would show it."""
    pixels, _ = background_pixels(spec, size, size)
    write_png(path, encode_srgb8(pixels))
