"""Rig rules: the skeleton, the skin influences and the blend shapes, on numpy arrays.

    rig.no-skeleton / rig.no-skin   the hand has no skeleton, or its mesh no joint influences
    rig.joint-count, rig.hierarchy  16 joints with MANO's parents [-1, 0, 1, 2, 0, 4, ...]
    rig.joint-names (warning)       the names wrist, index1, ... (engines and retargeting find joints by name)
    rig.bind-transform              bind transforms (skeleton space) are rigid: a rotation (orthonormal, det +1)
                                    and a translation; darthand's joints carry oriented bone frames
                                    (model/bones.py), which skinning maps back onto MANO exactly
    rig.rest-transform              rest transforms (parent space) are rigid
    rig.bind-rest-mismatch          bind_i = bind_parent(i) @ rest_i, within TRANSFORM_TOLERANCE
    rig.skin-layout, rig.joint-index, rig.weights-nonfinite, rig.weights-negative, rig.weights-sum
                                    influences: sizes agree, indices in 0..J-1, weights finite, >= 0, sum 1 +- 1e-6
    rig.blendshape-layout, rig.blendshape-nonfinite, rig.blendshape-index, rig.blendshape-duplicate-index
                                    blend shapes: offsets finite, point indices in range and unique
    rig.correctives-missing         a mesh that claims MANO's pose correctives (the package says so, or it has any
                                    shape named pose_<joint>_rRC_pos|neg) has the shapes of all 135 channels
"""

from __future__ import annotations

import re

import numpy as np

from darthand.export.blendshapes import encode_channels
from darthand.export.correctives import corrective_names, pose_feature_ranges
from darthand.model.layout import JOINT_NAMES, MANO_PARENTS, NUM_JOINTS
from darthand.validate.asset import Mesh, Package, Skeleton
from darthand.validate.findings import Finding, examples, finding

WEIGHT_SUM_TOLERANCE = 1e-6
TRANSFORM_TOLERANCE = 1e-5           # metres for translations, absolute for rotation entries
CORRECTIVE_NAME = re.compile(r"^pose_[a-z]+\d_r\d\d_(pos|neg)$")


def check_rig(pkg: Package) -> list[Finding]:
    """Skeleton rules on every skeleton; skin and blend-shape rules on every mesh."""
    out: list[Finding] = []
    hands = pkg.hand_meshes
    if hands and not pkg.skeletons:
        out.append(finding("rig.no-skeleton", hands[0].path, "no skeleton is bound to the hand"))
    for skel in pkg.skeletons:
        out += check_skeleton(skel)
    for mesh in pkg.meshes:
        if not mesh.layout_ok:
            continue
        if mesh.skin is None:
            if mesh.role == "hand":
                out.append(finding("rig.no-skin", mesh.path, "the hand mesh has no joint indices / weights"))
        elif not mesh.skin.broken:
            out += check_skin(mesh)
        out += check_blend_shapes(mesh)
    return out


# ------------------------------------------------------------------------------------------------ skeleton


def check_skeleton(skel: Skeleton) -> list[Finding]:
    out = []
    J = len(skel.names)
    if J != NUM_JOINTS:
        out.append(finding("rig.joint-count", skel.path, f"has {J} joints, MANO's hand has {NUM_JOINTS}"))
    elif not np.array_equal(skel.parents, MANO_PARENTS):
        bad = np.flatnonzero(skel.parents != MANO_PARENTS)
        out.append(finding("rig.hierarchy", skel.path, f"joints whose parent differs from MANO's: {examples(bad)} "
                           f"(joint {bad[0]}, {skel.names[bad[0]]}, has parent {skel.parents[bad[0]]}, MANO's "
                           f"{MANO_PARENTS[bad[0]]})"))
    elif list(skel.names) != list(JOINT_NAMES):
        i = next(k for k, (a, b) in enumerate(zip(skel.names, JOINT_NAMES)) if a != b)
        out.append(finding("rig.joint-names", skel.path, f"joint {i} is named {skel.names[i]!r}, MANO's is "
                           f"{JOINT_NAMES[i]!r}"))
    for name, rule, mats in (("bind", "rig.bind-transform", skel.bind), ("rest", "rig.rest-transform", skel.rest)):
        if mats.shape != (J, 4, 4):
            out.append(finding(rule, skel.path, f"has {len(mats)} {name} transforms for {J} joints"))
            continue
        bad = np.flatnonzero(~is_rigid(mats))
        if len(bad):
            out.append(finding(rule, skel.path, f"{name} transforms that are not rigid (rotation and translation): "
                               f"joints {examples(bad)} (first: {skel.names[bad[0]]})"))
    if skel.bind.shape == skel.rest.shape == (J, 4, 4) and J:
        err = chain_error(skel)
        bad = np.flatnonzero(~(err <= TRANSFORM_TOLERANCE))
        if len(bad):
            first = f"joint {bad[0]}, {skel.names[bad[0]]}, is off by {err[bad[0]]:.3g}"
            out.append(finding("rig.bind-rest-mismatch", skel.path, "joints whose bind transform is not their "
                               f"parent's bind times their rest transform: {examples(bad)} ({first})"))
    return out


def is_rigid(m: np.ndarray) -> np.ndarray:
    """(J,) True where the column-vector transform (J, 4, 4) is finite and rigid: an orthonormal 3x3 block with
    determinant +1, and a last row (0, 0, 0, 1)."""
    finite = np.isfinite(m).all(axis=(1, 2))
    R = np.where(finite[:, None, None], m[:, :3, :3], 0.0)
    orthonormal = np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)).max(axis=(1, 2)) <= TRANSFORM_TOLERANCE
    proper = np.abs(np.linalg.det(R) - 1.0) <= TRANSFORM_TOLERANCE
    row_ok = np.abs(np.where(finite[:, None], m[:, 3, :], 0.0) - [0, 0, 0, 1]).max(axis=1) <= TRANSFORM_TOLERANCE
    return finite & orthonormal & proper & row_ok


def chain_error(skel: Skeleton) -> np.ndarray:
    """(J,) max |bind_i - bind_parent @ rest_i| (the root's parent: `root_parent`, identity by default)."""
    above = np.eye(4) if skel.root_parent is None else skel.root_parent
    parents = np.asarray(skel.parents)
    composed = np.empty_like(skel.bind)
    for i, p in enumerate(parents):
        base = skel.bind[p] if 0 <= p < len(parents) else above
        composed[i] = base @ skel.rest[i]
    with np.errstate(invalid="ignore"):
        return np.abs(composed - skel.bind).max(axis=(1, 2))


# ------------------------------------------------------------------------------------------------ skin


def check_skin(mesh: Mesh) -> list[Finding]:
    skin = mesh.skin
    assert skin is not None, "called for skinned meshes"
    idx, w = skin.indices, skin.weights
    rows = 1 if skin.rigid else len(mesh.points)
    if idx.shape != w.shape or idx.ndim != 2 or idx.shape[0] != rows:
        return [finding("rig.skin-layout", mesh.path, f"joint indices {idx.shape} and weights {w.shape} do not "
                        f"give one row per {'prim' if skin.rigid else 'point'} ({rows} rows)")]
    out = []
    # A rigid accessory's joint is judged by the accessory rules (acc.bad-joint).
    if not (skin.rigid and mesh.role == "accessory"):
        bad = np.flatnonzero(((idx < 0) | (idx >= skin.num_joints)).any(axis=1))
        if len(bad):
            j = idx[bad[0]][(idx[bad[0]] < 0) | (idx[bad[0]] >= skin.num_joints)][0]
            out.append(finding("rig.joint-index", mesh.path, f"points using joints outside "
                               f"0..{skin.num_joints - 1}: {examples(bad)} (point {bad[0]} uses joint {j})"))
    finite = np.isfinite(w).all(axis=1)
    if not finite.all():
        bad = np.flatnonzero(~finite)
        out.append(finding("rig.weights-nonfinite", mesh.path, f"points with NaN or infinite weights: "
                           f"{examples(bad)}"))
    negative = np.flatnonzero((w < 0).any(axis=1) & finite)
    if len(negative):
        out.append(finding("rig.weights-negative", mesh.path, f"points with negative weights: "
                           f"{examples(negative)} (point {negative[0]}: {w[negative[0]].min():.3g})"))
    total = w.sum(axis=1)
    off = np.flatnonzero(finite & (np.abs(total - 1.0) > WEIGHT_SUM_TOLERANCE))
    if len(off):
        out.append(finding("rig.weights-sum", mesh.path, f"points whose weights do not sum to 1: "
                           f"{examples(off)} (point {off[0]}: {total[off[0]]:.9g})"))
    return out


# ------------------------------------------------------------------------------------------------ blend shapes


def check_blend_shapes(mesh: Mesh) -> list[Finding]:
    out = []
    N = len(mesh.points)
    nonfinite, out_of_range, repeated = [], [], []
    for shape in mesh.blend_shapes:
        offsets, pi = shape.offsets, shape.point_indices
        if offsets.ndim != 2 or offsets.shape[1] != 3 or (pi is None and len(offsets) != N) or \
                (pi is not None and len(pi) != len(offsets)):
            out.append(finding("rig.blendshape-layout", shape.path, f"{len(offsets)} offsets for "
                               f"{N if pi is None else len(pi)} {'points' if pi is None else 'point indices'}"))
            continue
        if not np.isfinite(offsets).all():
            nonfinite.append(shape)
        if pi is not None and len(pi):
            if pi.min() < 0 or pi.max() >= N:
                out_of_range.append(shape)
            if len(np.unique(pi)) != len(pi):
                repeated.append(shape)
    for rule, shapes, what in (("rig.blendshape-nonfinite", nonfinite, "NaN or infinite offsets"),
                               ("rig.blendshape-index", out_of_range, f"point indices outside 0..{N - 1}"),
                               ("rig.blendshape-duplicate-index", repeated, "a point index listed twice")):
        if shapes:
            names = ", ".join(s.name for s in shapes[:3]) + (f", ... ({len(shapes)} in all)" if len(shapes) > 3
                                                             else "")
            out.append(finding(rule, shapes[0].path, f"blend shapes of {mesh.path} with {what}: {names}"))
    return out + check_correctives(mesh)


def check_correctives(mesh: Mesh) -> list[Finding]:
    names = {s.name for s in mesh.blend_shapes}
    if not (mesh.claims_correctives or any(CORRECTIVE_NAME.match(n) for n in names)):
        return []
    missing = [n for n in corrective_shape_names() if n not in names]
    if not missing:
        return []
    more = ", ..." if len(missing) > 3 else ""
    return [finding("rig.correctives-missing", mesh.path, f"claims MANO's 135 pose correctives but lacks "
                    f"{len(missing)} of their {len(corrective_shape_names())} shapes: {', '.join(missing[:3])}{more}")]


def corrective_shape_names() -> tuple[str, ...]:
    """The blend-shape names of the full correctives (each channel's _pos and _neg shapes, export/blendshapes.py)."""
    return encode_channels(corrective_names(), *pose_feature_ranges()).names
