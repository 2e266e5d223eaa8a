"""Accessories in a glTF hand: rigid ones (rings, watches, bracelets) as child nodes of their joint, gloves as
skinned meshes sharing the hand's skin.

A rigid accessory is authored fitted to the rest hand (hand rest frame, metres). Under joint node j its vertices are
stored in the joint's rest bone frame, O_j^T (v - J_j); the node's global matrix M_j = A_j [O_j | 0] then moves
them to A_j (v - J_j) = G_j v, exactly where the rig carries a point bound rigidly to joint j.

A glove is a skinned surface with its own skin weights (V, 16) and optionally its own pose correctives (V, 3, 135,
MANO's layout); those are exported in the same corrective basis as the hand (`correctives.channel_offsets`), so the
gesture animations' `weights` channels drive both.
"""

from __future__ import annotations

import numpy as np
import pygltflib as gl

from darthand.accessories.loader import Accessory, accessory_factors
from darthand.export.correctives import Correctives, channel_offsets
from darthand.export.gltf_document import GltfDocument
from darthand.export.gltf_materials import MaterialBuilder
from darthand.export.gltf_rig import add_skinned_node, add_surface_mesh, split_surface
from darthand.export.skeleton import Skeleton


def add_accessory(doc: GltfDocument, acc: Accessory, *, materials: MaterialBuilder, joint_nodes: list[int],
                  skeleton: Skeleton, skin: int, influences: int | None, correctives: Correctives,
                  vertex_ids: bool = False, prefix: str = "Right") -> tuple[int, bool]:
    """Add `acc` to the document as node and mesh `<prefix>_<id>`; returns (its node, whether the node carries morph
    targets)."""
    material = accessory_material(acc, materials, f"{prefix}_{acc.id}_material")
    name = f"{prefix}_{acc.id}"
    if acc.skinned:
        channels = channel_offsets(acc.posedirs, correctives, len(acc.vertices))
        offsets = correctives.shape_offsets(channels) if channels.shape[2] else np.zeros((len(acc.vertices), 3, 0))
        assert acc.weights is not None, "a skinned accessory has weights"
        surface = split_surface(name, acc.vertices, acc.faces, acc.uvs, acc.faces_uv, acc.weights, offsets)
        mesh = add_surface_mesh(doc, surface, influences=influences, material=material,
                                target_names=correctives.names if offsets.shape[2] else (), vertex_ids=vertex_ids)
        node = add_skinned_node(doc, name, mesh, skin)
        doc.gltf.nodes[node].extras = {"darthand": {"accessory": acc.id}}
        return node, offsets.shape[2] > 0
    j = acc.parent_joint
    assert j is not None, "a rigid accessory follows one joint"
    local = (acc.vertices - skeleton.joints[j]) @ skeleton.frames[j]
    surface = split_surface(name, local, acc.faces, acc.uvs, acc.faces_uv, np.zeros((len(local), 0)),
                            np.zeros((len(local), 3, 0)))
    mesh = add_surface_mesh(doc, surface, influences=None, material=material, vertex_ids=False, skinned=False)
    node = doc.add("nodes", gl.Node(name=name, mesh=mesh, extras={"darthand": {"accessory": acc.id}}))
    doc.gltf.nodes[joint_nodes[j]].children.append(node)
    return node, False


def accessory_material(acc: Accessory, materials: MaterialBuilder, name: str) -> int:
    """The accessory's PBR material. glTF multiplies factors with textures, so a textured channel gets factor 1
    (the texture already holds the colour / metallic / roughness the accessories stage baked)."""
    color, metallic, roughness = accessory_factors(acc)
    textured_mr = acc.metallic_roughness_png is not None
    return materials.pbr_material(
        name, (1.0, 1.0, 1.0, 1.0) if acc.base_color_png is not None else color,
        1.0 if textured_mr else metallic, 1.0 if textured_mr else roughness,
        acc.base_color_png, acc.metallic_roughness_png)
