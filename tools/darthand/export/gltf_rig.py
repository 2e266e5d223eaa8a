"""The hand's rig in glTF: joint nodes, the skin, skin influences, and skinned meshes with corrective morph targets.

Mapping of MANO onto glTF's skinning (glTF 2.0 spec, "Skins" and "Morph Targets"):

    joint node i      oriented bone frames O_i (export/skeleton.py, model/bones.py: +Y along the bone, X the
                      flexion axis): translation O_parent^T (J_i - J_parent) (J_0 for the wrist), rest rotation
                      O_parent^T O_i, animated rotation O_parent^T R_i O_i (unit quaternions stored x, y, z, w),
                      no scale. The node's global matrix is then M_i = A_i [O_i | 0] (A_i MANO's), at rest
                      [O_i | J_i]. Blender's importer (bone heuristic 'Blender', its default) draws each bone along
                      its node's +Y, so bones lie along the fingers.
    inverse bind      IBM_i = [O_i | J_i]^-1, so jointMatrix_i = M_i IBM_i = G_i, MANO's skinning transform.
    morph targets     one POSITION delta per exported blend shape (sparse accessors: only the vertices it moves);
                      mesh weights = the encoded corrective weights of the pose, in [0, 1]
                      (export/blendshapes.py). glTF adds them before skinning, exactly where MANO adds its pose
                      offsets.
    JOINTS_n/WEIGHTS_n  sets of 4 influences, strongest first, summing to 1 over all sets.

The hand's node `<Side>Hand` is the scene root: it draws the hand mesh (primitive 0: the hand, its vertex order
the model's after UV-seam splitting; primitive 1: the forearm cap) with the skin, has no transform (the spec
ignores a skinned mesh node's own) and holds the joint hierarchy as its child, so that Blender makes it the
armature object and puts the mesh under it without an extra empty.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pygltflib as gl

from darthand.export.gltf_document import GltfDocument
from darthand.export.influences import influences_needed, top_k_influences
from darthand.export.skeleton import Skeleton, xyzw_quaternions
from darthand.model.hand_model import HandModel
from darthand.model.topology import vertex_normals

INFLUENCES_PER_SET = 4


@dataclass(frozen=True)
class SkinnedSurface:
    """A triangle mesh bound to the hand's skeleton, with one vertex per glTF vertex (UV seams already split).

    positions (N, 3) float64 rest positions, metres; normals (N, 3); texcoords (N, 2) in glTF's convention
    (origin at the image's top-left) or None; faces (F, 3) int64; weights (N, 16) float64 dense skin weights;
    offsets (N, 3, K) float64 corrective blend shapes (K = 0 for none); source (N,) int64 the model vertex each
    glTF vertex copies, or None.
    """

    name: str
    positions: np.ndarray
    normals: np.ndarray
    texcoords: np.ndarray | None
    faces: np.ndarray
    weights: np.ndarray
    offsets: np.ndarray
    source: np.ndarray | None = None


def split_uv_vertices(faces: np.ndarray, faces_uv: np.ndarray | None = None,
                      uvs: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """Per-vertex UVs for formats without per-corner attributes (glTF): vertices on a UV seam are duplicated.

    faces (F, 3), faces_uv (F, 3) per-corner indices into uvs (T, 2), or both None. Returns source (N,) int64, the
    input vertex each output vertex copies (positions, weights, correctives are gathered through it); uvs (N, 2)
    or None; faces (F, 3) int64 into the N output vertices. Output vertices are the distinct (vertex, uv index)
    corner pairs (without UVs: the vertices the faces use), ordered by vertex then uv index, so a mesh without
    seams or unused vertices keeps its vertex order. Vertices no face uses are dropped.
    """
    faces = np.asarray(faces, dtype=np.int64)
    if uvs is None:
        source, inverse = np.unique(faces, return_inverse=True)
        return source, None, inverse.reshape(faces.shape)
    pairs = np.stack([faces.reshape(-1), np.asarray(faces_uv, dtype=np.int64).reshape(-1)], axis=1)
    unique, inverse = np.unique(pairs, axis=0, return_inverse=True)
    return unique[:, 0].copy(), np.asarray(uvs)[unique[:, 1]], inverse.reshape(faces.shape)


def gltf_texcoords(uvs: np.ndarray) -> np.ndarray:
    """glTF texture coordinates (u, 1 - v) from the model's UVs (u, v): v runs up from the image's bottom row in the
    model (see texture_files' UV convention), down from its top row in glTF."""
    uv = np.asarray(uvs, dtype=np.float64)
    return np.stack([uv[:, 0], 1.0 - uv[:, 1]], axis=1)


def split_surface(name: str, vertices: np.ndarray, faces: np.ndarray, uvs: np.ndarray | None,
                  faces_uv: np.ndarray | None, weights: np.ndarray, offsets: np.ndarray) -> SkinnedSurface:
    """A `SkinnedSurface` from per-corner UV data, split along UV seams by `split_uv_vertices` (vertices
    no face uses are dropped: they would have no normal).

    Normals are computed on the unsplit mesh first, so a UV seam does not become a shading seam.
    """
    normals = vertex_normals(vertices, faces)
    source, uv, corners = split_uv_vertices(faces, faces_uv, uvs)
    return SkinnedSurface(name, vertices[source], normals[source], None if uv is None else gltf_texcoords(uv),
                          corners, weights[source], offsets[source], source)


def hand_surface(model: HandModel, offsets: np.ndarray, name: str = "hand") -> SkinnedSurface:
    """The model's mesh as a `SkinnedSurface` carrying the corrective blend shapes `offsets` (V, 3, K)."""
    return split_surface(name, model.v_template, model.faces, model.uvs, model.faces_uv, model.weights, offsets)


# ------------------------------------------------------------------------------------------------ skeleton


def add_skeleton(doc: GltfDocument, skeleton: Skeleton, parent: int) -> list[int]:
    """Joint nodes in MANO order with their rest translations and rotations, the root joint a child of the node
    `parent`. Returns the node ids."""
    translations, rotations = skeleton.translations, xyzw_quaternions(skeleton.rest_rotations)
    ids = [doc.add("nodes", gl.Node(name=name, translation=[float(x) for x in translations[i]],
                                    rotation=[float(x) for x in rotations[i]]))
           for i, name in enumerate(skeleton.names)]
    for i in range(1, len(ids)):
        doc.gltf.nodes[ids[skeleton.parents[i]]].children.append(ids[i])
    doc.gltf.nodes[parent].children.append(ids[0])
    return ids


def add_skin(doc: GltfDocument, joint_nodes: list[int], skeleton: Skeleton, name: str) -> int:
    """The skin over `joint_nodes` with inverse bind matrices [O_i | J_i]^-1 (column-major float32)."""
    ibm = np.linalg.inv(skeleton.bind)
    columns = ibm.transpose(0, 2, 1).reshape(len(ibm), 16).astype(np.float32)
    acc = doc.accessor(columns, target=None, matrix=True, name=f"{name}_inverse_bind")
    return doc.add("skins", gl.Skin(name=name, inverseBindMatrices=acc, joints=list(joint_nodes),
                                    skeleton=joint_nodes[0]))


# ------------------------------------------------------------------------------------------------ influences


def influence_count(weights: np.ndarray, influences: int | None) -> int:
    """Influence slots to store: `influences` rounded up to whole sets of 4, or for None ('all') as many as the
    vertex with the most non-zero weights needs (so nothing is pruned)."""
    if influences is None:
        influences = influences_needed(weights)
    return INFLUENCES_PER_SET * -(-influences // INFLUENCES_PER_SET)


def influence_sets(weights: np.ndarray, influences: int | None) -> tuple[np.ndarray, np.ndarray]:
    """glTF JOINTS/WEIGHTS data: joints (N, 4 s) uint8 and weights (N, 4 s) float32, s sets.

    The `influences` strongest joints per vertex (None: all non-zero ones), renormalised; the float32 rounding
    residual of each row is put on its strongest weight so the stored row sums to 1 as closely as float32 allows
    (the validator checks the sum). Empty slots have joint 0 and weight 0.
    """
    slots = influence_count(weights, influences)
    keep = slots if influences is None else influences
    idx, w = top_k_influences(weights, keep)
    if keep < slots:
        pad = slots - keep
        idx = np.concatenate([idx, np.zeros((len(idx), pad), idx.dtype)], axis=1)
        w = np.concatenate([w, np.zeros((len(w), pad))], axis=1)
    w32 = w.astype(np.float32)
    residual = 1.0 - w32[:, 1:].astype(np.float64).sum(axis=1)
    w32[:, 0] = np.where(w[:, 0] > 0, residual, 0.0).astype(np.float32)
    return idx.astype(np.uint8), w32


# ------------------------------------------------------------------------------------------------ meshes


def add_surface_mesh(doc: GltfDocument, surface: SkinnedSurface, *, influences: int | None, material: int | None,
                     target_names: tuple[str, ...] = (), extensions: dict | None = None,
                     vertex_ids: bool = True, skinned: bool = True, name: str | None = None,
                     more: list | tuple = ()) -> int:
    """A mesh named `name` (default surface.name) with one primitive for `surface` (`surface_primitive`) and the
    primitives `more` after it; morph target names in mesh.extras.targetNames, default weights 0."""
    primitive = surface_primitive(doc, surface, influences=influences, material=material, extensions=extensions,
                                  vertex_ids=vertex_ids, skinned=skinned)
    mesh = gl.Mesh(name=name or surface.name, primitives=[primitive, *more])
    if primitive.targets:
        mesh.weights = [0.0] * len(primitive.targets)
        mesh.extras = {"targetNames": list(target_names)}
    return doc.add("meshes", mesh)


def surface_primitive(doc: GltfDocument, surface: SkinnedSurface, *, influences: int | None, material: int | None,
                      extensions: dict | None = None, vertex_ids: bool = True,
                      skinned: bool = True) -> gl.Primitive:
    """A primitive for `surface`: POSITION, NORMAL, TEXCOORD_0, JOINTS_n/WEIGHTS_n (if `skinned`), morph targets
    (POSITION deltas) and, with `vertex_ids`, the source model vertex of every glTF vertex as the
    application-specific attribute _VERTEX_ID."""
    attributes = gl.Attributes(
        POSITION=doc.accessor(surface.positions.astype(np.float32), minmax=True, name=f"{surface.name}_position"),
        NORMAL=doc.accessor(surface.normals.astype(np.float32), name=f"{surface.name}_normal"))
    if surface.texcoords is not None:
        attributes.TEXCOORD_0 = doc.accessor(surface.texcoords.astype(np.float32), name=f"{surface.name}_uv")
    joints, weights = influence_sets(surface.weights, influences) if skinned else (np.zeros((0, 0)), np.zeros((0, 0)))
    for s in range(joints.shape[1] // INFLUENCES_PER_SET):
        cols = slice(INFLUENCES_PER_SET * s, INFLUENCES_PER_SET * (s + 1))
        setattr(attributes, f"JOINTS_{s}", doc.accessor(joints[:, cols], name=f"{surface.name}_joints{s}"))
        setattr(attributes, f"WEIGHTS_{s}", doc.accessor(weights[:, cols], name=f"{surface.name}_weights{s}"))
    if vertex_ids and surface.source is not None:
        # Floats, not shorts: vertex attribute elements must fill 4 bytes, and float32 holds ids up to 2^24 exactly.
        attributes._VERTEX_ID = doc.accessor(surface.source.astype(np.float32), name=f"{surface.name}_vertex_id")
    # Correctives are local (a finger joint moves a quarter of the hand), so targets are stored sparse.
    targets = [gl.Attributes(POSITION=doc.sparse_accessor(surface.offsets[:, :, k], name=f"{surface.name}_target{k}"))
               for k in range(surface.offsets.shape[2])]
    return gl.Primitive(attributes=attributes, indices=doc.indices(surface.faces), material=material,
                        targets=targets, extensions=extensions or {})


def add_skinned_node(doc: GltfDocument, name: str, mesh: int, skin: int) -> int:
    """An untransformed root node drawing `mesh` with `skin`."""
    node = doc.add("nodes", gl.Node(name=name, mesh=mesh, skin=skin))
    doc.gltf.scenes[0].nodes.append(node)
    return node
