"""glTF 2.0 export of a hand model: `export_gltf(model, out, ...)` writes a .glb or a .gltf package.

What one file holds (see gltf_rig, gltf_materials, gltf_animation, gltf_accessories for each part):
    - the joint nodes (MANO order and names) and one skin with inverse bind matrices T(-J_i);
    - the hand mesh, split along UV seams, with JOINTS_n/WEIGHTS_n (4 influences by default), its pose correctives
      as morph targets (`full`: 135, `pca:K` / `pose-pca:K`: K, `none`; common.export_correctives, the same
      correctives as the USD export) and the source vertex of every glTF vertex (_VERTEX_ID);
    - a PBR skin material per texture variant, switched with KHR_materials_variants;
    - one animation per gesture (joint rotations + morph weights), from rest to the gesture;
    - accessories: rigid ones under their joint node, gloves skinned by the same skin.

`.glb` embeds everything (images in the binary chunk): the single-file asset. `.gltf` writes `<stem>.bin` and the
images under `textures/` beside it with relative URIs: the variants package, where each loader fetches only the
images of the variant it shows.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from darthand.errors import InputError
from darthand.export.common import (Accessory, Correctives, TextureSet, check_accessory, check_export_options,
                                    check_textures_fit, export_correctives, gesture_poses, option_errors)
from darthand.export.gltf_accessories import add_accessory
from darthand.export.gltf_animation import add_gesture_animation, add_key_times
from darthand.export.gltf_document import GltfDocument
from darthand.export.gltf_materials import MaterialBuilder, add_variants, variant_mappings
from darthand.export.gltf_rig import (add_skeleton, add_skin, add_skinned_node, add_surface_mesh, hand_surface,
                                      influence_count)
from darthand.model.anatomy import rest_joints
from darthand.model.hand_model import HandModel
from darthand.model.layout import JOINT_NAMES, NUM_JOINTS


@dataclass(frozen=True)
class GltfOptions:
    """What the exported asset models.

    influences: 4, 8 or None (all non-zero influences); correctives: 'full' | 'pca:K' | 'pose-pca:K' | 'none';
    texture_size: downsize textures to this many pixels (longer side), None keeps them; clip_keys, clip_seconds:
    keyframes and length of each gesture clip; vertex_ids: store each glTF vertex's model vertex (_VERTEX_ID).
    """

    influences: int | None = 4
    correctives: str = "full"
    texture_size: int | None = None
    clip_keys: int = 5
    clip_seconds: float = 1.0
    vertex_ids: bool = True

    def check(self) -> None:
        check_export_options(self.influences, self.correctives, self.texture_size)
        if self.clip_keys < 1 or self.clip_seconds <= 0:
            raise InputError("clip_keys must be at least 1 and clip_seconds positive")


@dataclass
class GltfExport:
    """What `export_gltf` wrote: files, counts, and the names an engine will show."""

    files: list[str]
    vertices: int                 # glTF vertices of the hand (after UV-seam splitting)
    model_vertices: int
    faces: int
    morph_targets: int
    influence_slots: int          # JOINTS/WEIGHTS slots per vertex (4 per set)
    correctives: str
    variants: list[str] = field(default_factory=list)
    animations: list[str] = field(default_factory=list)
    accessories: list[str] = field(default_factory=list)
    # max posed vertex error (m) over the exported gestures of the pruned influences / compressed correctives
    influence_error_m: float = 0.0
    corrective_error_m: float = 0.0


def export_gltf(model: HandModel, out: str | Path, *, options: GltfOptions = GltfOptions(),
                textures: list[TextureSet] = (), accessories: list[Accessory] = (),
                gestures: tuple[list[str], np.ndarray] | None = None, name: str | None = None) -> GltfExport:
    """Write `model` as glTF 2.0 to `out` (.glb: one file; .gltf: JSON + .bin + textures/ beside it).

    textures: skin texture variants, the first is the default (none: an untextured skin material; more than one:
    KHR_materials_variants). gestures: (names, poses (G, 48)); default: the project's named gestures.
    """
    out = Path(out)
    if out.suffix.lower() not in (".glb", ".gltf"):
        raise InputError(f"{out}: the output must end in .glb or .gltf")
    options.check()
    check_textures_fit(model, textures)
    for acc in accessories:
        check_accessory(acc)
    names, poses = gesture_poses(model) if gestures is None else gestures
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3 * NUM_JOINTS)
    correctives = export_correctives(model, options.correctives)
    side = name or f"{model.side}_hand"

    doc = GltfDocument()
    doc.gltf.asset.extras = {"darthand": {"side": model.side, "correctives": correctives.mode,
                                          "influences": options.influences or "all",
                                          "model_vertices": model.num_vertices, "joint_names": list(JOINT_NAMES)}}
    joints = rest_joints(model)
    joint_nodes = add_skeleton(doc, model.parents, joints, JOINT_NAMES)
    skin = add_skin(doc, joint_nodes, joints)

    package_dir = out.parent if out.suffix.lower() == ".gltf" else None
    materials = MaterialBuilder(doc, package_dir, options.texture_size)
    skin_materials = [materials.skin_material(t, name=f"skin_{t.id}") for t in textures] or \
        [materials.skin_material(None)]
    extensions = None
    if len(textures) > 1:
        add_variants(doc, [t.id for t in textures])
        extensions = variant_mappings(skin_materials)

    surface = hand_surface(model, correctives.offsets, name=side)
    mesh = add_surface_mesh(doc, surface, influences=options.influences, material=skin_materials[0],
                            target_names=correctives.names, extensions=extensions, vertex_ids=options.vertex_ids)
    hand_node = add_skinned_node(doc, side, mesh, skin)
    morph_nodes = [hand_node] if correctives.count else []

    for acc in accessories:
        node, morphs = add_accessory(doc, acc, materials=materials, joint_nodes=joint_nodes, rest_joints=joints,
                                     skin=skin, influences=options.influences, correctives=correctives)
        if morphs:
            morph_nodes.append(node)

    _add_animations(doc, names, poses, joint_nodes, morph_nodes, correctives, options)
    written = doc.write(out) + materials.image_files
    errors = option_errors(model, correctives, options.influences, poses)
    return GltfExport(
        files=[str(p) for p in written], vertices=len(surface.positions), model_vertices=model.num_vertices,
        faces=len(surface.faces), morph_targets=correctives.count,
        influence_slots=influence_count(model.weights, options.influences), correctives=correctives.mode,
        variants=[t.id for t in textures] if len(textures) > 1 else [], animations=list(names),
        accessories=[a.id for a in accessories], **errors)


def _add_animations(doc: GltfDocument, names: list[str], poses: np.ndarray, joint_nodes: list[int],
                    morph_nodes: list[int], correctives: Correctives, options: GltfOptions) -> None:
    if len(names) != len(poses):
        raise InputError(f"gestures: {len(names)} names for {len(poses)} poses")
    if not len(names):
        return
    times = add_key_times(doc, options.clip_keys, options.clip_seconds)
    for gesture, pose in zip(names, poses):
        add_gesture_animation(doc, gesture, pose, joint_nodes, morph_nodes, correctives, times)
