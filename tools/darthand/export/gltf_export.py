"""glTF 2.0 export of a hand model: `export_gltf(model, out, ...)` writes a .glb or a .gltf package.

What one file holds (see gltf_rig, gltf_materials, gltf_animation, gltf_accessories for each part):
    - the root node `<Side>Hand` drawing the hand mesh `<Side>HandMesh` with the skin `<Side>HandSkeleton`, and
      under it the joint nodes (MANO order and names) with oriented bone frames (+Y along the bone);
    - the hand mesh: primitive 0 the hand, split along UV seams, with JOINTS_n/WEIGHTS_n (4 influences by
      default), its pose correctives as morph targets with weights in [0, 1] (correctives.export_correctives and
      blendshapes.py, the same as the USD export) and the source vertex of every glTF vertex (_VERTEX_ID);
      primitive 1 the forearm cap (model/cap.py), skinned, with the same morph targets; after the correctives, the
      shape dials (shape_dials.py: the shape directions, weights 0 = the built shape; the clips key them at 0, as
      a glTF weights channel keys every target, so an engine dials them with no clip driving the weights);
    - a PBR skin material per texture variant, switched with KHR_materials_variants;
    - one animation per gesture (joint rotations + morph weights) holding the gesture for its whole length;
    - accessories: rigid ones under their joint node, gloves skinned by the same skin;
    - asset.extras.darthand: side, options, conventions (frame, origin, bones), the blend-shape encoding table.

`.glb` embeds everything (images in the binary chunk): the single-file asset. `.gltf` writes `<stem>.bin` and the
images under `textures/` beside it with relative URIs: the variants package, where each loader fetches only the
images of the variant it shows.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pygltflib as gl

from darthand.errors import InputError
from darthand.accessories.loader import Accessory, check_accessory
from darthand.export.conventions import asset_conventions
from darthand.export.correctives import Correctives, channel_offsets, export_correctives, option_errors
from darthand.export.gestures import gesture_poses
from darthand.export.gltf_accessories import add_accessory
from darthand.export.gltf_animation import add_gesture_animation, add_key_times
from darthand.export.gltf_document import GltfDocument
from darthand.export.gltf_materials import MaterialBuilder, add_variants, variant_mappings
from darthand.export.gltf_rig import (add_skeleton, add_skin, add_surface_mesh, hand_surface, influence_count,
                                      split_surface, surface_primitive)
from darthand.export.options import check_export_options
from darthand.export.shape_dials import DIAL_RANGE, ShapeDials, dial_error, shape_dials
from darthand.export.skeleton import Skeleton, export_skeleton
from darthand.export.texture_files import check_textures_fit
from darthand.model.cap import forearm_cap
from darthand.model.hand_model import HandModel
from darthand.model.layout import JOINT_NAMES, NUM_JOINTS
from darthand.textures.loader import TextureSet


@dataclass(frozen=True)
class GltfOptions:
    """What the exported asset models.

    influences: 4, 8 or None (all non-zero influences); correctives: 'full' | 'pca:K' | 'pose-pca:K' | 'none';
    texture_size: downsize textures to this many pixels (longer side), None keeps them; clip_seconds: length of
    each gesture clip; vertex_ids: store each glTF vertex's model vertex (_VERTEX_ID); shape_dials: the range of
    delta beta the shape-direction morph targets reach (shape_dials.py; 0: none).
    """

    influences: int | None = 4
    correctives: str = "full"
    texture_size: int | None = None
    clip_seconds: float = 1.0
    vertex_ids: bool = True
    shape_dials: float = DIAL_RANGE

    def check(self) -> None:
        check_export_options(self.influences, self.correctives, self.texture_size)
        if not self.clip_seconds > 0:
            raise InputError("clip_seconds must be positive")


@dataclass
class GltfExport:
    """What `export_gltf` wrote: files, counts, and the names an engine will show."""

    files: list[str]
    vertices: int                 # glTF vertices of the hand (after UV-seam splitting)
    model_vertices: int
    faces: int
    morph_targets: int            # corrective morph targets (the shape dials' follow them: shape_targets)
    influence_slots: int          # JOINTS/WEIGHTS slots per vertex (4 per set)
    correctives: str
    variants: list[str] = field(default_factory=list)
    animations: list[str] = field(default_factory=list)
    accessories: list[str] = field(default_factory=list)
    # max posed vertex error (m) over the exported gestures of the pruned influences / compressed correctives
    influence_error_m: float = 0.0
    corrective_error_m: float = 0.0
    shape_targets: int = 0                             # morph targets of the shape dials
    shape_dials: dict = field(default_factory=dict)   # ShapeDials.as_dict with the dial error over the gestures


def export_gltf(model: HandModel, out: str | Path, *, options: GltfOptions = GltfOptions(),
                textures: list[TextureSet] | tuple = (), accessories: list[Accessory] | tuple = (),
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
    dials = shape_dials(model, options.shape_dials)
    dial_record = dials.as_dict(dial_error(model, dials, poses))
    prefix = model.side.capitalize()
    root_name = name or f"{prefix}Hand"

    doc = GltfDocument()
    doc.gltf.asset.extras = {"darthand": {
        "side": model.side, "correctives": correctives.mode, "influences": options.influences or "all",
        "model_vertices": model.num_vertices, "joint_names": list(JOINT_NAMES), "gestures": list(names),
        "conventions": asset_conventions(model), "blend_shapes": correctives.encoding.as_dict(),
        "shape_dials": {**dial_record, "blend_shapes": dials.encoding.as_dict()},
        "primitives": ["hand", "forearm_cap"]}}
    skeleton = export_skeleton(model)
    hand_node = doc.add("nodes", gl.Node(name=root_name))
    doc.gltf.scenes[0].nodes.append(hand_node)
    joint_nodes = add_skeleton(doc, skeleton, hand_node)
    skin = add_skin(doc, joint_nodes, skeleton, name=f"{prefix}HandSkeleton")

    package_dir = out.parent if out.suffix.lower() == ".gltf" else None
    materials = MaterialBuilder(doc, package_dir, options.texture_size)
    skin_materials = [materials.skin_material(t, name=f"{prefix}HandSkin_{t.id}") for t in textures] or \
        [materials.skin_material(None, name=f"{prefix}HandSkin")]
    extensions = None
    if len(textures) > 1:
        add_variants(doc, [t.id for t in textures])
        extensions = variant_mappings(skin_materials)

    surface = hand_surface(model, morph_offsets(correctives, correctives.offsets, dials, model.shapedirs),
                           name=f"{prefix}HandMesh")
    cap = forearm_cap(model)
    cap_surface = split_surface(f"{prefix}ForearmCap", cap.vertices, cap.faces, cap.uvs, cap.faces_uv, cap.weights,
                                morph_offsets(correctives,
                                              channel_offsets(cap.posedirs, correctives, len(cap.vertices)),
                                              dials, cap.shapedirs))
    # The cap's _VERTEX_ID continues after the hand's: V + cap vertex.
    assert cap_surface.source is not None                         # split_surface maps every vertex to its source
    cap_surface = dataclasses.replace(cap_surface, source=cap_surface.source + model.num_vertices)
    cap_primitive = surface_primitive(doc, cap_surface, influences=options.influences, material=skin_materials[0],
                                      extensions=extensions, vertex_ids=options.vertex_ids)
    mesh = add_surface_mesh(doc, surface, influences=options.influences, material=skin_materials[0],
                            target_names=correctives.names + dials.encoding.names, extensions=extensions,
                            vertex_ids=options.vertex_ids,
                            more=[cap_primitive])
    doc.gltf.nodes[hand_node].mesh, doc.gltf.nodes[hand_node].skin = mesh, skin
    morph_nodes = [hand_node] if correctives.count else []
    extra_targets = {hand_node: dials.count}

    for acc in accessories:
        node, morphs = add_accessory(doc, acc, materials=materials, joint_nodes=joint_nodes, skeleton=skeleton,
                                     skin=skin, influences=options.influences, correctives=correctives,
                                     prefix=prefix)
        if morphs:
            morph_nodes.append(node)

    _add_animations(doc, names, poses, skeleton, joint_nodes, morph_nodes, correctives, options, extra_targets)
    written = doc.write(out) + materials.image_files
    errors = option_errors(model, correctives, options.influences, poses)
    return GltfExport(
        files=[str(p) for p in written], vertices=len(surface.positions), model_vertices=model.num_vertices,
        faces=len(surface.faces), morph_targets=correctives.count, shape_targets=dials.count,
        influence_slots=influence_count(model.weights, options.influences), correctives=correctives.mode,
        variants=[t.id for t in textures] if len(textures) > 1 else [], animations=list(names),
        accessories=[a.id for a in accessories], shape_dials=dial_record, **errors)


def _add_animations(doc: GltfDocument, names: list[str], poses: np.ndarray, skeleton: Skeleton,
                    joint_nodes: list[int], morph_nodes: list[int], correctives: Correctives,
                    options: GltfOptions, extra_targets: dict[int, int] | None = None) -> None:
    if len(names) != len(poses):
        raise InputError(f"gestures: {len(names)} names for {len(poses)} poses")
    if not len(names):
        return
    times = add_key_times(doc, options.clip_seconds)
    for gesture, pose in zip(names, poses):
        add_gesture_animation(doc, gesture, pose, skeleton, joint_nodes, morph_nodes, correctives, times,
                              extra_targets)


def morph_offsets(correctives: Correctives, channels: np.ndarray, dials: ShapeDials,
                  shapedirs: np.ndarray) -> np.ndarray:
    """(N, 3, S + D) morph targets of a surface: its corrective shapes (of corrective channels (N, 3, K)), then its
    shape dials (of its shape directions (N, 3, B))."""
    shapes = correctives.shape_offsets(channels) if correctives.count else np.zeros((len(shapedirs), 3, 0))
    return np.concatenate([shapes, dials.shape_offsets(shapedirs)], axis=2)
