"""UsdSkel authoring of the MANO rig: skeleton, skinned mesh, pose-corrective blend shapes, gesture animation.

How MANO maps onto UsdSkel (so that UsdSkel's own maths reproduces `forward` exactly):

- Joint frames are world-aligned: bind transforms (skeleton space) and rest transforms (parent space) are pure
  translations, to the rest joint centres J = J_regressor @ v_template and to J_i - J_parent. A joint's animated
  local transform is then [R_i, J_i - J_parent], MANO's own, so its skeleton-space transform is MANO's A_i and
  UsdSkel's skinning transform inverse(bind_i) * A_i is MANO's G_i = A_i [I, -J_i].
- Pose correctives are blend shapes, which UsdSkel applies to the rest points before skinning, as MANO does. With
  `full` correctives blend shape k is posedirs[:, :, k] and its weight is the pose feature f_k = (R_i - I)_rc;
  these are as often negative as positive. Offsets below `sparse_tol` are left out (sparse pointIndices); the
  largest dropped magnitude and the worst-case position error it can cause are returned.
- Gf matrices act on row vectors, so every matrix authored here is the transpose of its column-vector form, and
  GfQuatf arrays are laid out (x, y, z, w) in memory, the reverse of rotations.py's (w, x, y, z).

Shapes: V vertices, F faces, J = 16 joints, K blend shapes, G gestures (one time sample each, time code k for
gesture k).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdSkel, Vt

from darthand.export.common import (Correctives, influences_needed, local_translations, top_k_influences,
                                    xyzw_quaternions)
from darthand.model.anatomy import rest_joints
from darthand.model.hand_model import HandModel
from darthand.model.layout import JOINT_NAMES, NUM_JOINTS
from darthand.model.rotations import axis_angle_to_matrix
from darthand.model.topology import vertex_normals

SPARSE_TOL = 1e-9  # metres: blend-shape offsets shorter than this are not written


@dataclass(frozen=True)
class RigStats:
    """What `define_rig` wrote: counts and the error bounds of what it left out."""

    influences: int              # joint influences per vertex
    blend_shapes: int            # number of BlendShape prims
    blend_shape_points: int      # total pointIndices over all shapes
    dropped_offset_max: float    # metres: longest offset left out of a sparse blend shape
    dropped_error_bound: float   # metres: max_v sum_k max_t |weight_k(t)| |dropped offset_vk| over the samples
    gestures: tuple[str, ...]

    def as_dict(self) -> dict:
        return {**self.__dict__, "gestures": list(self.gestures)}


# ------------------------------------------------------------------------------------------------ numpy -> Vt


def vec3f(a: np.ndarray) -> Vt.Vec3fArray:
    return Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(a, dtype=np.float32).reshape(-1, 3))


def matrices(m: np.ndarray) -> Vt.Matrix4dArray:
    """(N, 4, 4) column-vector transforms -> GfMatrix4d array (row-vector form, i.e. transposed)."""
    return Vt.Matrix4dArray.FromNumpy(np.ascontiguousarray(np.swapaxes(m, -1, -2), dtype=np.float64))


def quaternions(q_xyzw: np.ndarray) -> Vt.QuatfArray:
    """(N, 4) unit quaternions (x, y, z, w), GfQuatf's memory layout -> GfQuatf array."""
    return Vt.QuatfArray.FromNumpy(np.ascontiguousarray(q_xyzw, dtype=np.float32))


def translations(t: np.ndarray) -> np.ndarray:
    """(N, 4, 4) pure translations by t (N, 3)."""
    m = np.tile(np.eye(4), (len(t), 1, 1))
    m[:, :3, 3] = t
    return m


# ------------------------------------------------------------------------------------------------ skeleton


def joint_paths(parents: np.ndarray, names=JOINT_NAMES) -> list[str]:
    """UsdSkel joint paths, e.g. 'wrist/index1/index2/index3', in joint order (parents before children)."""
    paths: list[str] = []
    for i, p in enumerate(parents):
        paths.append(names[i] if p < 0 else f"{paths[p]}/{names[i]}")
    return paths


def define_skeleton(stage: Usd.Stage, path: Sdf.Path, model: HandModel) -> UsdSkel.Skeleton:
    """A Skeleton of the 16 joints with world-aligned bind and rest transforms (pure translations)."""
    joints = rest_joints(model)
    skel = UsdSkel.Skeleton.Define(stage, path)
    skel.CreateJointsAttr(Vt.TokenArray(joint_paths(model.parents)))
    skel.CreateJointNamesAttr(Vt.TokenArray(list(JOINT_NAMES)))
    skel.CreateBindTransformsAttr(matrices(translations(joints)))
    skel.CreateRestTransformsAttr(matrices(translations(local_translations(joints, model.parents))))
    return skel


# ------------------------------------------------------------------------------------------------ mesh


def define_mesh(stage: Usd.Stage, path: Sdf.Path, vertices: np.ndarray, faces: np.ndarray,
                uvs: np.ndarray | None = None, faces_uv: np.ndarray | None = None) -> UsdGeom.Mesh:
    """A triangle mesh (rest points, vertex normals, face-varying indexed `st`), no subdivision."""
    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr(vec3f(vertices))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(faces), 3, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(faces.astype(np.int32).reshape(-1)))
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
    mesh.CreateNormalsAttr(vec3f(vertex_normals(vertices, faces)))
    mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    mesh.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(*vertices.min(0)), Gf.Vec3f(*vertices.max(0))]))
    if uvs is not None:
        st = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray,
                                                     UsdGeom.Tokens.faceVarying)
        st.Set(Vt.Vec2fArray.FromNumpy(np.ascontiguousarray(uvs, dtype=np.float32)))
        st.SetIndices(Vt.IntArray.FromNumpy(faces_uv.astype(np.int32).reshape(-1)))
    return mesh


def bind_skin(prim: Usd.Prim, weights: np.ndarray | None, influences: int | None,
              joint: int | None = None) -> int:
    """Author skel:jointIndices/jointWeights on `prim`; returns the influences per point.

    weights (N, J): skinned, the `influences` strongest per point sorted descending and renormalised, but never more
    than the point with the most non-zero weights has (None: that many, which loses nothing). joint: rigid binding
    instead, every point follows that one joint (constant interpolation, one influence).
    """
    binding = UsdSkel.BindingAPI.Apply(prim)
    binding.CreateGeomBindTransformAttr(Gf.Matrix4d(1.0))
    if joint is not None:
        binding.CreateJointIndicesPrimvar(True, 1).Set(Vt.IntArray([int(joint)]))
        binding.CreateJointWeightsPrimvar(True, 1).Set(Vt.FloatArray([1.0]))
        return 1
    needed = influences_needed(weights)
    k = needed if influences is None else min(influences, needed)
    idx, w = top_k_influences(weights, k)
    binding.CreateJointIndicesPrimvar(False, k).Set(Vt.IntArray.FromNumpy(idx.reshape(-1)))
    binding.CreateJointWeightsPrimvar(False, k).Set(Vt.FloatArray.FromNumpy(w.astype(np.float32).reshape(-1)))
    return k


# ------------------------------------------------------------------------------------------------ blend shapes


def sparse_offsets(offsets: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Point indices (n,), offsets (n, 3) of the points of one shape (V, 3) whose offset is at least `tol` long,
    and the lengths (V,) of the offsets dropped (0 where kept)."""
    length = np.linalg.norm(offsets, axis=1)
    keep = length >= tol
    return np.flatnonzero(keep), offsets[keep], np.where(keep, 0.0, length)


def define_blend_shapes(stage: Usd.Stage, mesh: UsdGeom.Mesh, correctives: Correctives,
                        max_weights: np.ndarray | None = None,
                        sparse_tol: float = SPARSE_TOL) -> tuple[int, float, float]:
    """One BlendShape prim per corrective under `mesh`, bound with skel:blendShapes / skel:blendShapeTargets.

    max_weights (K,): the largest |weight| each shape takes (in the animation), used to bound the error of the
    dropped offsets (None: not bounded, nan). Returns (points written, longest dropped offset, dropped error
    bound) in metres.
    """
    if correctives.count == 0:
        return 0, 0.0, 0.0
    binding = UsdSkel.BindingAPI(mesh.GetPrim())
    targets, written, dropped_max = [], 0, 0.0
    bound = np.zeros(correctives.offsets.shape[0])
    for k, name in enumerate(correctives.names):
        idx, off, dropped = sparse_offsets(correctives.offsets[:, :, k], sparse_tol)
        shape = UsdSkel.BlendShape.Define(stage, mesh.GetPath().AppendChild(name))
        shape.CreateOffsetsAttr(vec3f(off))
        shape.CreatePointIndicesAttr(Vt.IntArray.FromNumpy(idx.astype(np.int32)))
        targets.append(shape.GetPath())
        written += len(idx)
        dropped_max = max(dropped_max, float(dropped.max(initial=0.0)))
        if max_weights is not None:
            bound += abs(max_weights[k]) * dropped
    binding.CreateBlendShapesAttr(Vt.TokenArray(list(correctives.names)))
    binding.CreateBlendShapeTargetsRel().SetTargets(targets)
    return written, dropped_max, float(bound.max(initial=0.0)) if max_weights is not None else float("nan")


# ------------------------------------------------------------------------------------------------ animation


def define_animation(stage: Usd.Stage, path: Sdf.Path, model: HandModel, correctives: Correctives,
                     names: list[str], poses: np.ndarray) -> UsdSkel.Animation:
    """A SkelAnimation with one time sample per gesture (time code k = gesture k).

    poses (G, 48) axis-angle. Translations are the rest local translations and scales 1 (constant, default
    values); rotations are the quaternions of MANO's R_i; blendShapeWeights are the correctives' weights of R
    (the pose feature itself for `full`). The gesture names are in customData 'darthand:gestures' (index = time).
    """
    rotations = axis_angle_to_matrix(np.asarray(poses, dtype=np.float64).reshape(-1, NUM_JOINTS, 3))
    quats = xyzw_quaternions(rotations)                                     # (G, 16, 4) x, y, z, w
    weights = correctives.weights(rotations).astype(np.float32)             # (G, K)
    anim = UsdSkel.Animation.Define(stage, path)
    anim.CreateJointsAttr(Vt.TokenArray(joint_paths(model.parents)))
    anim.CreateTranslationsAttr(vec3f(local_translations(rest_joints(model), model.parents)))
    anim.CreateScalesAttr(Vt.Vec3hArray.FromNumpy(np.ones((NUM_JOINTS, 3), np.float16)))
    rot_attr = anim.CreateRotationsAttr()
    for t, q in enumerate(quats):
        rot_attr.Set(quaternions(q), Usd.TimeCode(t))
    if correctives.count:
        anim.CreateBlendShapesAttr(Vt.TokenArray(list(correctives.names)))
        bsw = anim.CreateBlendShapeWeightsAttr()
        for t, w in enumerate(weights):
            bsw.Set(Vt.FloatArray.FromNumpy(w), Usd.TimeCode(t))
    anim.GetPrim().SetCustomDataByKey("darthand:gestures", Vt.StringArray(list(names)))
    return anim


# ------------------------------------------------------------------------------------------------ the rig


def define_rig(stage: Usd.Stage, root: Sdf.Path, model: HandModel, correctives: Correctives,
               names: list[str], poses: np.ndarray, influences: int | None = None,
               sparse_tol: float = SPARSE_TOL) -> RigStats:
    """Under the SkelRoot at `root`: Skeleton `Skel`, SkelAnimation `Gestures`, Mesh `Hand` with its blend shapes.

    The skeleton is bound on the SkelRoot (inherited by every mesh below it, accessories included) and the
    animation on the skeleton.
    """
    skel_root = UsdSkel.Root.Define(stage, root)
    skel = define_skeleton(stage, root.AppendChild("Skel"), model)
    anim = define_animation(stage, root.AppendChild("Gestures"), model, correctives, names, poses)
    UsdSkel.BindingAPI.Apply(skel_root.GetPrim()).CreateSkeletonRel().SetTargets([skel.GetPath()])
    UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])

    mesh = define_mesh(stage, root.AppendChild("Hand"), model.v_template, model.faces, model.uvs, model.faces_uv)
    k = bind_skin(mesh.GetPrim(), model.weights, influences)
    max_w = np.abs(correctives.weights(axis_angle_to_matrix(
        np.asarray(poses, dtype=np.float64).reshape(-1, NUM_JOINTS, 3)))).max(axis=0) if correctives.count else []
    written, dropped_max, bound = define_blend_shapes(stage, mesh, correctives, max_w, sparse_tol)
    return RigStats(k, correctives.count, written, dropped_max, bound, tuple(names))
