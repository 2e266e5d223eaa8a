"""UsdSkel authoring of the MANO rig: skeleton, skinned meshes, pose-corrective blend shapes, gesture animations.

How MANO maps onto UsdSkel (so that UsdSkel's own maths reproduces `forward` exactly):

- Joints carry oriented bone frames O_i (export/skeleton.py, model/bones.py: Y along the bone, X the flexion axis):
  bind transforms (skeleton space) are [O_i | J_i], rest transforms (parent space) [O_parent^T O_i |
  O_parent^T (J_i - J_parent)], and an animated joint's local rotation is O_parent^T R_i O_i. Its skeleton-space
  transform is then A_i [O_i | 0] (A_i MANO's) and UsdSkel's skinning transform inverse(bind_i) * that is MANO's
  G_i = A_i [I, -J_i].
- Pose correctives are blend shapes, which UsdSkel applies to the rest points before skinning, as MANO does. Each
  corrective channel (a pose-feature entry (R_i - I)_rc for `full`) is split into shapes whose weights stay in
  [0, 1] (export/blendshapes.py), so importers that clamp weights (Blender) need no fix-up. Offsets below
  `sparse_tol` are left out (sparse pointIndices); the largest dropped magnitude and the worst-case position error
  it can cause are returned.
- Shape dials (shape_dials.py): the shape directions as more blend shapes after the correctives, not driven by the
  animations (weight 0, the built shape), for a user to dial; the joints stay the built shape's.
- Gestures: one SkelAnimation per gesture (the pose at the default time, no time samples) and one with every
  gesture in turn (time code k = gesture k); the interface's `gesture` variant set points the skeleton's
  animationSource at one of them.
- Gf matrices act on row vectors, so every matrix authored here is the transpose of its column-vector form, and
  GfQuatf arrays are laid out (x, y, z, w) in memory, the reverse of rotations.py's (w, x, y, z).

Shapes: V vertices, F faces, J = 16 joints, K corrective channels, S blend shapes, G gestures.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdSkel, Vt

from darthand.export.correctives import Correctives, channel_offsets
from darthand.export.influences import influences_needed, top_k_influences
from darthand.export.shape_dials import ShapeDials
from darthand.export.skeleton import Skeleton, export_skeleton
from darthand.model.cap import forearm_cap
from darthand.model.hand_model import HandModel
from darthand.model.layout import JOINT_NAMES, NUM_JOINTS
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
    prims: dict              # role -> prim path: skeleton, hand, cap, material, gesture animations

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


# ------------------------------------------------------------------------------------------------ skeleton


def joint_paths(parents: np.ndarray, names=JOINT_NAMES) -> list[str]:
    """UsdSkel joint paths, e.g. 'wrist/index1/index2/index3', in joint order (parents before children)."""
    paths: list[str] = []
    for i, p in enumerate(parents):
        paths.append(names[i] if p < 0 else f"{paths[p]}/{names[i]}")
    return paths


def define_skeleton(stage: Usd.Stage, path: Sdf.Path, skeleton: Skeleton) -> UsdSkel.Skeleton:
    """A Skeleton of the 16 joints with oriented bind and rest transforms (see the module docstring)."""
    skel = UsdSkel.Skeleton.Define(stage, path)
    skel.CreateJointsAttr(Vt.TokenArray(joint_paths(skeleton.parents)))
    skel.CreateJointNamesAttr(Vt.TokenArray(list(skeleton.names)))
    skel.CreateBindTransformsAttr(matrices(skeleton.bind))
    skel.CreateRestTransformsAttr(matrices(skeleton.rest_local()))
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
        assert faces_uv is not None, "uvs come with faces_uv"
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
    instead, every point follows that one joint with weight 1, written per point (one influence): Blender's USD
    importer ignores constant-interpolation joint influences, so a constant binding would leave the accessory
    behind.
    """
    binding = UsdSkel.BindingAPI.Apply(prim)
    binding.CreateGeomBindTransformAttr(Gf.Matrix4d(1.0))
    if joint is not None:
        n = len(UsdGeom.Mesh(prim).GetPointsAttr().Get())
        binding.CreateJointIndicesPrimvar(False, 1).Set(Vt.IntArray.FromNumpy(np.full(n, int(joint), np.int32)))
        binding.CreateJointWeightsPrimvar(False, 1).Set(Vt.FloatArray.FromNumpy(np.ones(n, np.float32)))
        return 1
    assert weights is not None, "a skinned binding has weights"
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


def define_blend_shapes(stage: Usd.Stage, mesh: UsdGeom.Mesh, correctives: Correctives, channel_offsets: np.ndarray,
                        max_weights: np.ndarray | None = None, sparse_tol: float = SPARSE_TOL,
                        dials: ShapeDials | None = None,
                        shapedirs: np.ndarray | None = None) -> tuple[int, float, float]:
    """One BlendShape prim per exported shape under `mesh`, bound with skel:blendShapes / skel:blendShapeTargets.

    channel_offsets (N, 3, K): the mesh's corrective channels, encoded here into the S shapes of `correctives`.
    max_weights (S,): the largest weight each shape takes (in the animations), used to bound the error of the
    dropped offsets (None: not bounded, nan). dials, shapedirs (N, 3, B): the shape dials (shape_dials.py) and the
    mesh's shape directions, written after the correctives (their weights bounded by 1). Returns (points written,
    longest dropped offset, dropped error bound) in metres.
    """
    names = list(correctives.names)
    offsets = correctives.shape_offsets(channel_offsets) if correctives.count else \
        np.zeros((len(channel_offsets), 3, 0))
    if dials is not None and dials.count:
        names += dials.encoding.names
        offsets = np.concatenate([offsets, dials.shape_offsets(shapedirs)], axis=2)
        if max_weights is not None:
            max_weights = np.concatenate([np.asarray(max_weights, dtype=np.float64).reshape(-1), np.ones(dials.count)])
    if not names:
        return 0, 0.0, 0.0
    binding = UsdSkel.BindingAPI(mesh.GetPrim())
    targets, written, dropped_max = [], 0, 0.0
    bound = np.zeros(offsets.shape[0])
    for k, name in enumerate(names):
        idx, off, dropped = sparse_offsets(offsets[:, :, k], sparse_tol)
        shape = UsdSkel.BlendShape.Define(stage, mesh.GetPath().AppendChild(name))
        shape.CreateOffsetsAttr(vec3f(off))
        shape.CreatePointIndicesAttr(Vt.IntArray.FromNumpy(idx.astype(np.int32)))
        targets.append(shape.GetPath())
        written += len(idx)
        dropped_max = max(dropped_max, float(dropped.max(initial=0.0)))
        if max_weights is not None:
            bound += abs(max_weights[k]) * dropped
    binding.CreateBlendShapesAttr(Vt.TokenArray(names))
    binding.CreateBlendShapeTargetsRel().SetTargets(targets)
    return written, dropped_max, float(bound.max(initial=0.0)) if max_weights is not None else float("nan")


# ------------------------------------------------------------------------------------------------ animation


def define_animation(stage: Usd.Stage, path: Sdf.Path, skeleton: Skeleton, correctives: Correctives,
                     poses: np.ndarray, timeline: bool) -> UsdSkel.Animation:
    """A SkelAnimation of MANO axis-angle poses (G, 48): at the default time for one pose (timeline False, G = 1),
    else one time sample per pose (time code k = pose k).

    Translations are the joints' constant local translations and scales 1 (default values); rotations the local
    joint rotations O_parent^T R_i O_i; blendShapeWeights the correctives' encoded weights (in [0, 1]).
    """
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3 * NUM_JOINTS)
    quats = skeleton.local_quaternions(poses)                               # (G, 16, 4) x, y, z, w
    weights = correctives.weights_of_poses(poses).astype(np.float32)        # (G, S)
    anim = UsdSkel.Animation.Define(stage, path)
    anim.CreateJointsAttr(Vt.TokenArray(joint_paths(skeleton.parents)))
    anim.CreateTranslationsAttr(vec3f(skeleton.translations))
    anim.CreateScalesAttr(Vt.Vec3hArray.FromNumpy(np.ones((NUM_JOINTS, 3), np.float16)))
    times = [Usd.TimeCode(t) for t in range(len(poses))] if timeline else [Usd.TimeCode.Default()]
    rot_attr = anim.CreateRotationsAttr()
    for t, q in zip(times, quats):
        rot_attr.Set(quaternions(q), t)
    if correctives.count:
        anim.CreateBlendShapesAttr(Vt.TokenArray(list(correctives.names)))
        bsw = anim.CreateBlendShapeWeightsAttr()
        for t, w in zip(times, weights):
            bsw.Set(Vt.FloatArray.FromNumpy(w), t)
    return anim


# ------------------------------------------------------------------------------------------------ the rig


@dataclass(frozen=True)
class RigNames:
    """Prim names under the asset's root, chosen so that a DCC import of a right and a left hand into one scene
    has no collisions (Blender names objects, armatures, actions and materials after them)."""

    prefix: str                   # 'Right' or 'Left'

    @classmethod
    def for_side(cls, side: str) -> "RigNames":
        return cls(side.capitalize())

    @property
    def root(self) -> str:
        return f"{self.prefix}Hand"

    @property
    def skeleton(self) -> str:
        return f"{self.prefix}HandSkeleton"

    @property
    def hand(self) -> str:
        return f"{self.prefix}HandMesh"

    @property
    def cap(self) -> str:
        return f"{self.prefix}ForearmCap"

    @property
    def material(self) -> str:
        return f"{self.prefix}HandSkin"

    @property
    def timeline(self) -> str:
        return f"{self.prefix}HandGestures"

    def gesture(self, name: str) -> str:
        return f"{self.prefix}Hand_{name}"


ALL_GESTURES = "all"   # the `gesture` variant whose animation holds every gesture in turn


def define_rig(stage: Usd.Stage, root: Sdf.Path, model: HandModel, correctives: Correctives,
               names: list[str], poses: np.ndarray, influences: int | None = None,
               sparse_tol: float = SPARSE_TOL, dials: ShapeDials | None = None) -> RigStats:
    """Under the SkelRoot at `root`: the Skeleton, one SkelAnimation per gesture and one of all gestures in turn,
    the hand Mesh with its blend shapes and the forearm cap Mesh (RigNames give the prim names).

    The skeleton is bound on the SkelRoot (inherited by every mesh below it, accessories included); its
    animationSource (the timeline) is authored here and switched by the interface's `gesture` variant set.
    """
    rig_names = RigNames.for_side(model.side)
    skeleton = export_skeleton(model)
    skel_root = UsdSkel.Root.Define(stage, root)
    skel = define_skeleton(stage, root.AppendChild(rig_names.skeleton), skeleton)
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3 * NUM_JOINTS)
    anims = {ALL_GESTURES: define_animation(stage, root.AppendChild(rig_names.timeline), skeleton, correctives,
                                            poses, timeline=True)}
    for name, pose in zip(names, poses):
        anims[name] = define_animation(stage, root.AppendChild(rig_names.gesture(name)), skeleton, correctives,
                                       pose[None], timeline=False)
    anims[ALL_GESTURES].GetPrim().SetCustomDataByKey("darthand:gestures", Vt.StringArray(list(names)))
    UsdSkel.BindingAPI.Apply(skel_root.GetPrim()).CreateSkeletonRel().SetTargets([skel.GetPath()])
    UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets(
        [anims[ALL_GESTURES].GetPath()])

    max_w = correctives.weights_of_poses(poses).max(axis=0) if correctives.count else np.zeros(0)
    mesh = define_mesh(stage, root.AppendChild(rig_names.hand), model.v_template, model.faces, model.uvs,
                       model.faces_uv)
    mesh.GetPrim().SetCustomDataByKey("darthand:role", "hand")
    k = bind_skin(mesh.GetPrim(), model.weights, influences)
    written, dropped_max, bound = define_blend_shapes(stage, mesh, correctives, correctives.offsets, max_w, sparse_tol,
                                                      dials, model.shapedirs)

    cap = forearm_cap(model)
    cap_mesh = define_mesh(stage, root.AppendChild(rig_names.cap), cap.vertices, cap.faces, cap.uvs, cap.faces_uv)
    cap_mesh.GetPrim().SetCustomDataByKey("darthand:role", "forearm_cap")
    bind_skin(cap_mesh.GetPrim(), cap.weights, influences)
    define_blend_shapes(stage, cap_mesh, correctives, channel_offsets(cap.posedirs, correctives, len(cap.vertices)),
                        max_w, sparse_tol, dials, cap.shapedirs)
    prims = {"skeleton": str(skel.GetPath()), "hand": str(mesh.GetPath()), "forearm_cap": str(cap_mesh.GetPath()),
             "material": str(root.AppendChild(rig_names.material)),
             "animations": {n: str(a.GetPath()) for n, a in anims.items()}}
    shapes = correctives.count + (dials.count if dials is not None else 0)
    return RigStats(k, shapes, written, dropped_max, bound, tuple(names), prims)
