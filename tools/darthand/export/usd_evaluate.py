"""Pose a written USD asset with OpenUSD's own UsdSkel maths: what usdview, Omniverse or Houdini compute.

This is the independent check of the export: nothing here uses darthand's rig. For every skinnable prim under
a SkelRoot, at each time code: blend shapes (BlendShapeQuery, weights from the bound SkelAnimation remapped to the
prim's blend-shape order), then linear blend skinning (SkeletonQuery skinning transforms, SkinningQuery).
"""

from __future__ import annotations

import numpy as np
from pxr import Usd, UsdGeom, UsdSkel

from darthand.errors import DarthandError


def skinned_points(stage: Usd.Stage, times=None) -> dict[str, np.ndarray]:
    """{prim path: (T, N, 3) float64 deformed points in skeleton space} for every skinned point-based prim.

    times: time codes (default: every time sample of the bound animations' rotations, or [default time]).
    """
    cache = UsdSkel.Cache()
    out: dict[str, np.ndarray] = {}
    for prim in stage.Traverse():
        if not prim.IsA(UsdSkel.Root):
            continue
        root = UsdSkel.Root(prim)
        cache.Populate(root, Usd.PrimDefaultPredicate)
        for binding in cache.ComputeSkelBindings(root, Usd.PrimDefaultPredicate):
            skel_query = cache.GetSkelQuery(binding.GetSkeleton())
            ts = animation_times(skel_query) if times is None else list(times)
            for skinning in binding.GetSkinningTargets():
                out[str(skinning.GetPrim().GetPath())] = _deform(skel_query, skinning, ts)
    return out


def animation_times(skel_query: UsdSkel.SkeletonQuery) -> list:
    """Time codes of the joint-transform samples of the skeleton's animation (default time if none)."""
    anim = skel_query.GetAnimQuery()
    samples = list(anim.GetJointTransformTimeSamples()) if anim else []
    return samples or [Usd.TimeCode.Default()]


def _deform(skel_query: UsdSkel.SkeletonQuery, skinning: UsdSkel.SkinningQuery, times) -> np.ndarray:
    prim = skinning.GetPrim()
    points_attr = UsdGeom.PointBased(prim).GetPointsAttr()
    anim = skel_query.GetAnimQuery()
    shapes = UsdSkel.BlendShapeQuery(UsdSkel.BindingAPI(prim)) if skinning.HasBlendShapes() else None
    if shapes is not None:
        point_indices = shapes.ComputeBlendShapePointIndices()
        sub_offsets = shapes.ComputeSubShapePointOffsets()
    result = []
    for t in times:
        t = Usd.TimeCode(t)
        points = points_attr.Get(t)
        if shapes is not None and anim:
            weights = anim.ComputeBlendShapeWeights(t)
            mapper = skinning.GetBlendShapeMapper()
            if mapper is not None and not mapper.IsNull():
                weights = mapper.Remap(weights)
            sub_w, shape_idx, sub_idx = shapes.ComputeSubShapeWeights(weights)
            if not shapes.ComputeDeformedPoints(sub_w, shape_idx, sub_idx, point_indices, sub_offsets, points):
                raise DarthandError(f"{prim.GetPath()}: UsdSkel could not apply the blend shapes at time {t}")
        xforms = skel_query.ComputeSkinningTransforms(t)
        if not skinning.ComputeSkinnedPoints(xforms, points, t):
            raise DarthandError(f"{prim.GetPath()}: UsdSkel could not skin the points at time {t}")
        result.append(np.asarray(points, dtype=np.float64))
    return np.stack(result)


