"""Edits that break a copy of a good package, one defect each: the broken-fixture corpus.

USD edits go through Sdf on the copy's layers (payload.usdc holds the rig: /Hand/Hand, /Hand/Skel; texture/<id>.usda
holds /Skin/...Texture shaders; accessory/<id>.usdc holds /Accessory/Geom). glTF edits change the JSON and patch
accessor bytes in the binary buffer (hand: mesh 0, joints: nodes 0..15, the ring: a child node of joint 5).
"""

from __future__ import annotations

import json
import shutil
import struct
from pathlib import Path

import numpy as np
from pxr import Sdf, Vt

ROOT = "/RightHand"
HAND, SKEL = f"{ROOT}/RightHandMesh", f"{ROOT}/RightHandSkeleton"
ALBEDO, ROUGH = "/Skin/AlbedoTexture", "/Skin/RoughnessTexture"
GEOM = "/Accessory/Right_{}"      # an accessory's mesh in its layer, by accessory id
COMPONENT = {5121: np.uint8, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


def copy_package(src: Path, dst: Path) -> Path:
    """A copy (new inodes) of a package folder or file inside dst; returns the copy's path."""
    dst.mkdir(parents=True, exist_ok=True)
    target = dst / src.name
    if src.is_dir():
        shutil.copytree(src, target)
    else:
        for f in src.parent.iterdir():            # a .gltf brings its .bin and textures/
            if f.is_dir():
                shutil.copytree(f, dst / f.name)
            else:
                shutil.copy(f, dst / f.name)
    return target


# ------------------------------------------------------------------------------------------------ USD


def edit(path: Path, fn) -> None:
    """fn(layer) on the layer at `path`, saved."""
    layer = Sdf.Layer.FindOrOpen(str(path))
    fn(layer)
    assert layer.Save(), path


def array(layer: Sdf.Layer, prop: str) -> np.ndarray:
    return np.array(layer.GetAttributeAtPath(prop).default)


def set_array(layer: Sdf.Layer, prop: str, values) -> None:
    attr = layer.GetAttributeAtPath(prop)
    kind = type(attr.default)
    attr.default = kind(list(values)) if kind is Vt.TokenArray else kind.FromNumpy(np.ascontiguousarray(values))


def change(layer: Sdf.Layer, prop: str, fn) -> None:
    """Replace the array attribute `prop` by fn(its value)."""
    set_array(layer, prop, fn(array(layer, prop)))


def remove_property(layer: Sdf.Layer, prop: str) -> None:
    path = Sdf.Path(prop)
    spec = layer.GetPrimAtPath(path.GetPrimPath())
    spec.RemoveProperty(spec.properties[path.name])


def face_corners(layer: Sdf.Layer, mesh: str = HAND) -> np.ndarray:
    return array(layer, f"{mesh}.faceVertexIndices").reshape(-1, 3)


def set_faces(layer: Sdf.Layer, corners: np.ndarray, uv_corners: np.ndarray, mesh: str = HAND) -> None:
    """Triangles and their face-varying `st` indices (kept consistent, so only the intended defect shows)."""
    set_array(layer, f"{mesh}.faceVertexCounts", np.full(len(corners), 3, np.int32))
    set_array(layer, f"{mesh}.faceVertexIndices", corners.reshape(-1).astype(np.int32))
    set_array(layer, f"{mesh}.primvars:st:indices", uv_corners.reshape(-1).astype(np.int32))


def edit_faces(layer: Sdf.Layer, fn) -> None:
    """fn(faces (F, 3), uv faces (F, 3)) -> (faces, uv faces) on the hand."""
    faces, uv = face_corners(layer), array(layer, f"{HAND}.primvars:st:indices").reshape(-1, 3)
    set_faces(layer, *fn(faces.copy(), uv.copy()))


def add_fin(layer: Sdf.Layer) -> None:
    """A new point and a face on an existing edge: that edge gets three faces."""
    faces = face_corners(layer)
    a, b = faces[30, 0], faces[30, 1]
    points = array(layer, f"{HAND}.points")
    new = len(points)
    set_array(layer, f"{HAND}.points", np.vstack([points, points[a] + [0.0, 0.01, 0.0]]).astype(np.float32))
    for prop in ("primvars:skel:jointIndices", "primvars:skel:jointWeights"):
        values = array(layer, f"{HAND}.{prop}")
        k = len(values) // len(points)
        set_array(layer, f"{HAND}.{prop}", np.concatenate([values, values[a * k:(a + 1) * k]]))
    normals = array(layer, f"{HAND}.normals")
    set_array(layer, f"{HAND}.normals", np.vstack([normals, normals[a]]).astype(np.float32))
    uv = array(layer, f"{HAND}.primvars:st:indices").reshape(-1, 3)
    set_faces(layer, np.vstack([faces, [a, b, new]]), np.vstack([uv, uv[30]]))


def rotation_z(deg: float) -> np.ndarray:
    t = np.radians(deg)
    return np.array([[np.cos(t), -np.sin(t), 0], [np.sin(t), np.cos(t), 0], [0, 0, 1.0]])


def scale_matrix(layer: Sdf.Layer, prop: str, joint: int) -> None:
    """Scale the 3x3 block of one GfMatrix4d of an array by 1.1: no longer a rigid transform."""
    def fn(m):
        m = m.copy()
        m[joint, :3, :3] *= 1.1
        return m
    change(layer, prop, fn)


def add_variant(layer: Sdf.Layer, set_name: str, new: str, like: str) -> None:
    """A new variant `new` in `set_name` on the root prim, with the same content as variant `like`."""
    prim = layer.GetPrimAtPath(ROOT)
    vset = prim.variantSets[set_name]
    variant = Sdf.VariantSpec(vset, new)
    src = vset.variants[like].primSpec
    for child in src.nameChildren:
        dst = Sdf.PrimSpec(variant.primSpec, child.name, child.specifier, child.typeName)
        for item in child.payloadList.prependedItems:
            dst.payloadList.Prepend(item)
        for grand in child.nameChildren:
            g = Sdf.PrimSpec(dst, grand.name, grand.specifier, grand.typeName)
            for item in grand.referenceList.prependedItems:
                g.referenceList.Prepend(item)


def set_payload(layer: Sdf.Layer, variant_prim: str, asset: str) -> None:
    spec = layer.GetPrimAtPath(variant_prim)
    spec.payloadList.ClearEdits()
    spec.payloadList.Prepend(Sdf.Payload(asset))


# ------------------------------------------------------------------------------------------------ glTF


def read_glb(path: Path) -> tuple[dict, bytearray]:
    data = path.read_bytes()
    json_len = struct.unpack("<I", data[12:16])[0]
    doc = json.loads(data[20:20 + json_len])
    bin_len = struct.unpack("<I", data[20 + json_len:24 + json_len])[0]
    return doc, bytearray(data[28 + json_len:28 + json_len + bin_len])


def write_glb(path: Path, doc: dict, blob: bytes) -> None:
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    blob = bytes(blob) + b"\0" * (-len(blob) % 4)
    doc_len = 12 + 8 + len(text) + 8 + len(blob)
    path.write_bytes(struct.pack("<4sII", b"glTF", 2, doc_len) + struct.pack("<II", len(text), 0x4E4F534A) + text
                     + struct.pack("<II", len(blob), 0x004E4942) + blob)


def accessor(doc: dict, blob: bytearray, index: int) -> np.ndarray:
    """A writable view of a dense, tightly packed accessor inside `blob`."""
    acc = doc["accessors"][index]
    view = doc["bufferViews"][acc["bufferView"]]
    dtype, width = np.dtype(COMPONENT[acc["componentType"]]), WIDTH[acc["type"]]
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    return np.frombuffer(memoryview(blob)[start:start + acc["count"] * width * dtype.itemsize],
                         dtype).reshape(acc["count"], width)


def edit_glb(path: Path, fn) -> None:
    """fn(doc, blob) edits the JSON and/or patches the buffer in place."""
    doc, blob = read_glb(path)
    fn(doc, blob)
    write_glb(path, doc, blob)


def edit_gltf(path: Path, fn) -> None:
    doc = json.loads(path.read_text())
    bin_path = path.parent / doc["buffers"][0]["uri"]
    blob = bytearray(bin_path.read_bytes())
    fn(doc, blob)
    path.write_text(json.dumps(doc))
    bin_path.write_bytes(bytes(blob))


def hand_attr(doc: dict, name: str) -> int:
    return doc["meshes"][0]["primitives"][0]["attributes"][name] if name != "indices" else \
        doc["meshes"][0]["primitives"][0]["indices"]


def ring_node(doc: dict) -> int:
    return next(i for i, n in enumerate(doc["nodes"]) if n.get("name", "").startswith("Right_ring_"))


def node_parent(doc: dict, child: int) -> int:
    return next(i for i, n in enumerate(doc["nodes"]) if child in n.get("children", []))


def reparent(doc: dict, child: int, new_parent: int | None) -> None:
    old = node_parent(doc, child)
    doc["nodes"][old]["children"].remove(child)
    if not doc["nodes"][old]["children"]:
        del doc["nodes"][old]["children"]
    if new_parent is None:
        doc["scenes"][0]["nodes"].append(child)
    else:
        doc["nodes"][new_parent].setdefault("children", []).append(child)
