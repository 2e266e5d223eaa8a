"""Read a composed USD stage into validate.asset's neutral form: meshes (points, triangles, UVs, skin, blend
shapes), skeletons and texture references. Nothing here writes: stages are opened with their own anonymous
session layer, which is the only layer variant selections are made in.

Face numbers in findings are triangle numbers after fan-triangulating the polygons (the same as the polygon
numbers for the triangle meshes darthand writes).
"""

from __future__ import annotations

import os
import posixpath
import re
import zipfile
from pathlib import Path
from typing import Callable

import numpy as np
from pxr import Ar, Sdf, Tf, Usd, UsdGeom, UsdShade, UsdSkel

from darthand.export.usd_validate import select_variants
from darthand.validate.asset import BlendShape, Limits, Mesh, Package, Skeleton, Skin, TextureRef
from darthand.validate.findings import Finding, finding

COLOR_INPUTS = {"diffuseColor", "emissiveColor", "specularColor"}
ACCESSORY_PRIM = "Accessory"
KIND_KEY = "darthand:kind"

Label = Callable[[Sdf.Path], str]


class Unreadable(Exception):
    """The file cannot be read at all; the message is one line naming the reason."""


def tf_message(e: Exception) -> str:
    """The first quoted reason of a Tf error (USD's messages carry file, line and function before it)."""
    text = str(e)
    reasons = re.findall(r" : '([^']+)'", text)
    return reasons[0] if reasons else " ".join(text.split())[:300]


def open_stage(path: Path, selections: dict[str, str] | None = None) -> Usd.Stage:
    """The stage of `path` with every payload loaded, after selecting `selections` on its default prim (in the
    session layer). Unreadable when USD cannot open it."""
    try:
        stage = Usd.Stage.Open(str(path), Usd.Stage.LoadNone)
    except Tf.ErrorException as e:
        raise Unreadable(tf_message(e)) from None
    if stage is None:
        raise Unreadable("USD cannot open it")
    if selections:
        select_variants(stage, selections)
    stage.Load()
    return stage


# ------------------------------------------------------------------------------------------------ arrays


def _array(attr, dtype, width: int | None = None) -> np.ndarray | None:
    """The attribute's default value (else its first time sample, as DCC exports often write) as a numpy array;
    None when it has neither."""
    if not attr or not attr.HasValue():
        return None
    value = attr.Get()
    if value is None:
        value = attr.Get(Usd.TimeCode.EarliestTime())
    if value is None:
        return None
    a = np.asarray(value, dtype=dtype)
    return a.reshape(-1, width) if width else a.reshape(-1)


def _matrices(value) -> np.ndarray:
    """(J, 4, 4) column-vector matrices from a GfMatrix4d array (row-vector form)."""
    if value is None:
        return np.zeros((0, 4, 4))
    return np.swapaxes(np.asarray(value, dtype=np.float64).reshape(-1, 4, 4), -1, -2)


def triangulate(counts: np.ndarray) -> np.ndarray:
    """(F, 3) corner numbers (into faceVertexIndices) of the fan triangles of polygons with `counts` corners.
    A polygon of 1 or 2 corners becomes one zero-area triangle, so the mesh rules report it as degenerate."""
    if len(counts) and (counts == 3).all():
        return np.arange(3 * len(counts), dtype=np.int64).reshape(-1, 3)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    n_tri = np.maximum(counts - 2, 0)
    poly = np.repeat(np.arange(len(counts)), n_tri)
    k = np.arange(n_tri.sum()) - np.repeat(np.cumsum(n_tri) - n_tri, n_tri)
    s = starts[poly]
    fans = np.stack([s, s + k + 1, s + k + 2], axis=1)
    short = np.flatnonzero((counts >= 1) & (counts < 3))
    stubs = np.stack([starts[short], starts[short] + counts[short] - 1, starts[short] + counts[short] - 1], axis=1)
    return np.concatenate([fans, stubs]).astype(np.int64)


# ------------------------------------------------------------------------------------------------ meshes


def read_meshes(stage: Usd.Stage, pkg: Package, label: Label, limits: Limits, under: Sdf.Path | None = None,
                accessory_id: str | None = None, claims_correctives: bool = False) -> list[Finding]:
    """Append every Mesh (under `under`, default everywhere) to pkg.meshes; returns the reader's findings."""
    out: list[Finding] = []
    start = stage.GetPrimAtPath(under) if under is not None else stage.GetPseudoRoot()
    if not start:
        return out
    xf_cache = UsdGeom.XformCache(Usd.TimeCode.Default())
    for prim in Usd.PrimRange(start):
        if not prim.IsA(UsdGeom.Mesh):
            continue
        role = "accessory" if is_accessory(prim) else \
            "cap" if prim.GetCustomDataByKey("darthand:role") == "forearm_cap" else "hand"
        mesh, found = read_mesh(prim, role, label, limits, xf_cache)
        out += found
        if mesh is not None:
            mesh.accessory_id = accessory_id if role == "accessory" else None
            mesh.claims_correctives = claims_correctives and role == "hand"
            pkg.meshes.append(mesh)
    return out


def is_accessory(prim: Usd.Prim) -> bool:
    p = prim
    while p and not p.IsPseudoRoot():
        if p.GetName() == ACCESSORY_PRIM or p.GetCustomDataByKey(KIND_KEY) or \
                p.GetCustomDataByKey("darthand:role") == "accessory":
            return True
        p = p.GetParent()
    return False


def read_mesh(prim: Usd.Prim, role: str, label: Label, limits: Limits,
              xf_cache: UsdGeom.XformCache) -> tuple[Mesh | None, list[Finding]]:
    where = label(prim.GetPath())
    geom = UsdGeom.Mesh(prim)
    points = _array(geom.GetPointsAttr(), np.float64, 3)
    counts = _array(geom.GetFaceVertexCountsAttr(), np.int64)
    indices = _array(geom.GetFaceVertexIndicesAttr(), np.int64)
    if points is None:
        return None, []
    if len(points) > limits.max_points:
        return None, [finding("file.array-too-large", where, f"{len(points)} points, above the limit of "
                              f"{limits.max_points}; the mesh is not checked")]
    counts = np.zeros(0, np.int64) if counts is None else counts
    indices = np.zeros(0, np.int64) if indices is None else indices
    if len(counts) > limits.max_faces:
        return None, [finding("file.array-too-large", where, f"{len(counts)} faces, above the limit of "
                              f"{limits.max_faces}; the mesh is not checked")]
    if (counts < 0).any() or counts.sum() != len(indices):
        return None, [finding("file.malformed", where, f"faceVertexCounts sum to {int(counts.sum())} but there are "
                              f"{len(indices)} faceVertexIndices")]
    corners = triangulate(counts)
    m = np.asarray(xf_cache.GetLocalToWorldTransform(prim), dtype=np.float64)
    if not np.allclose(m, np.eye(4)):
        points = points @ m[:3, :3] + m[3, :3]
    mesh = Mesh(where, role, points, indices[corners] if len(indices) else np.zeros((0, 3), np.int64))
    out = read_uvs(prim, mesh, corners, indices, where)
    mesh.skin, found = read_skin(prim, len(points), where, limits)
    out += found
    mesh.blend_shapes, found = read_blend_shapes(prim, label, where, limits)
    out += found
    return mesh, out


def read_uvs(prim: Usd.Prim, mesh: Mesh, corners: np.ndarray, indices: np.ndarray, where: str) -> list[Finding]:
    """mesh.uvs / uv_faces from the `st` primvar (or the first texCoord2f[] primvar)."""
    api = UsdGeom.PrimvarsAPI(prim)
    pv = api.GetPrimvar("st")
    if not (pv and pv.HasValue()):
        pv = next((p for p in api.GetPrimvarsWithValues()
                   if p.GetTypeName() == Sdf.ValueTypeNames.TexCoord2fArray), None)
    if pv is None:
        return []
    values = np.asarray(pv.Get(), dtype=np.float64).reshape(-1, 2)
    interp = pv.GetInterpolation()
    per = np.asarray(pv.GetIndices(), dtype=np.int64).reshape(-1) if pv.IsIndexed() else np.arange(len(values))
    if interp == UsdGeom.Tokens.faceVarying:
        expected, uv_faces = len(indices), per[corners] if len(per) == len(indices) else None
    elif interp in (UsdGeom.Tokens.vertex, UsdGeom.Tokens.varying):
        expected, uv_faces = len(mesh.points), per[mesh.faces] if len(per) == len(mesh.points) else None
    else:
        return []
    if uv_faces is None:
        return [finding("mesh.uv-index", where, f"primvar {pv.GetPrimvarName()} ({interp}) has {len(per)} "
                        f"entries, expected {expected}")]
    mesh.uvs, mesh.uv_faces = values, uv_faces
    return []


def read_skin(prim: Usd.Prim, num_points: int, where: str, limits: Limits) -> tuple[Skin | None, list[Finding]]:
    binding = UsdSkel.BindingAPI(prim)
    ji, jw = binding.GetJointIndicesPrimvar(), binding.GetJointWeightsPrimvar()
    has_i, has_w = bool(ji and ji.HasValue()), bool(jw and jw.HasValue())
    if not has_i and not has_w:
        return None, []
    broken = Skin(np.zeros((0, 1), np.int64), np.zeros((0, 1)), broken=True)
    if has_i != has_w:
        return broken, [finding("rig.skin-layout", where, "has joint " + ("indices without weights" if has_i else
                                                                         "weights without indices"))]
    idx, w = np.asarray(ji.Get(), dtype=np.int64), np.asarray(jw.Get(), dtype=np.float64)
    if max(idx.size, w.size) > limits.max_elements:
        return broken, [finding("file.array-too-large", where, f"{idx.size} joint indices, above the limit")]
    k, kw = max(1, ji.GetElementSize()), max(1, jw.GetElementSize())
    rigid = ji.GetInterpolation() == UsdGeom.Tokens.constant
    if (ji.GetInterpolation() != jw.GetInterpolation() or k != kw or idx.size % k or w.size % kw or
            (not rigid and ji.GetInterpolation() != UsdGeom.Tokens.vertex)):
        return broken, [finding("rig.skin-layout", where, f"joint indices ({ji.GetInterpolation()}, elementSize {k}, "
                              f"{idx.size} values) and weights ({jw.GetInterpolation()}, elementSize {kw}, "
                              f"{w.size} values) do not match")]
    if not rigid and k == 1 and idx.size and (idx == idx[0]).all() and (w == 1).all():
        # every point on one joint with weight 1 (how darthand writes rigid accessories: per point, which
        # Blender's importer reads, rather than constant): the same binding as a constant one
        return Skin(idx[:1].reshape(1, 1), w[:1].reshape(1, 1), True, joint_count(binding)), []
    return Skin(idx.reshape(-1, k), w.reshape(-1, kw), rigid, joint_count(binding)), []


def joint_count(binding: UsdSkel.BindingAPI) -> int:
    """Joints the prim's indices refer to: its own skel:joints order, else its skeleton's joints, else MANO's 16."""
    own = binding.GetJointsAttr()
    if own and own.HasValue():
        return len(own.Get())
    skel = binding.GetInheritedSkeleton()
    joints = skel.GetJointsAttr().Get() if skel else None
    return len(joints) if joints else 16


def read_blend_shapes(prim: Usd.Prim, label: Label, where: str,
                      limits: Limits) -> tuple[list[BlendShape], list[Finding]]:
    binding = UsdSkel.BindingAPI(prim)
    attr = binding.GetBlendShapesAttr()
    names = list(attr.Get() or []) if attr and attr.HasValue() else []
    targets = binding.GetBlendShapeTargetsRel().GetTargets() if binding.GetBlendShapeTargetsRel() else []
    if not names and not targets:
        return [], []
    if len(names) != len(targets):
        return [], [finding("rig.blendshape-layout", where, f"{len(names)} skel:blendShapes names for "
                            f"{len(targets)} skel:blendShapeTargets")]
    shapes, out, total = [], [], 0
    for name, target in zip(names, targets):
        shape = UsdSkel.BlendShape(prim.GetStage().GetPrimAtPath(target))
        if not shape:
            out.append(finding("rig.blendshape-layout", label(target), f"blend shape {name!r} targets "
                               f"{target}, which is not a BlendShape"))
            continue
        offsets = _array(shape.GetOffsetsAttr(), np.float64, 3)
        offsets = np.zeros((0, 3)) if offsets is None else offsets
        total += offsets.size
        if total > limits.max_elements:
            return [], out + [finding("file.array-too-large", where, "blend-shape offsets exceed the array limit; "
                                      "blend shapes are not checked")]
        pi_attr = shape.GetPointIndicesAttr()
        pi = _array(pi_attr, np.int64) if pi_attr and pi_attr.HasValue() else None
        shapes.append(BlendShape(str(name), label(target), offsets, pi))
    return shapes, out


# ------------------------------------------------------------------------------------------------ skeletons


def read_skeletons(stage: Usd.Stage, pkg: Package, label: Label, limits: Limits) -> list[Finding]:
    out = []
    for prim in stage.Traverse():
        if not prim.IsA(UsdSkel.Skeleton):
            continue
        skel = UsdSkel.Skeleton(prim)
        where = label(prim.GetPath())
        joints = [str(j) for j in (skel.GetJointsAttr().Get() or [])]
        if len(joints) > limits.max_elements:
            out.append(finding("file.array-too-large", where, f"{len(joints)} joints"))
            continue
        topology = UsdSkel.Topology(joints)
        ok, why = topology.Validate()
        if not ok:
            out.append(finding("rig.hierarchy", where, f"the joint paths do not form a tree ({why})"))
        names_attr = skel.GetJointNamesAttr()
        names = [str(n) for n in names_attr.Get()] if names_attr and names_attr.HasValue() else []
        if len(names) != len(joints):
            names = [j.rsplit("/", 1)[-1] for j in joints]
        pkg.skeletons.append(Skeleton(where, names, np.asarray(topology.GetParentIndices(), dtype=np.int64),
                                      _matrices(skel.GetBindTransformsAttr().Get()),
                                      _matrices(skel.GetRestTransformsAttr().Get())))
    return out


# ------------------------------------------------------------------------------------------------ textures


def read_textures(stage: Usd.Stage, pkg: Package, label: Label, under: Sdf.Path | None = None) -> list[Finding]:
    """Append a TextureRef for every UsdUVTexture's file input (under `under`, default everywhere), with the role
    of the input it feeds. Returns no findings (the texture rules judge the references later)."""
    roles: dict[Sdf.Path, str] = {}
    textures = []
    start = stage.GetPrimAtPath(under) if under is not None else stage.GetPseudoRoot()
    for prim in (Usd.PrimRange(start) if start else []):
        if not prim.IsA(UsdShade.Shader):
            continue
        shader = UsdShade.Shader(prim)
        sid = shader.GetShaderId()
        if sid == "UsdUVTexture":
            textures.append(shader)
        elif sid == "UsdPreviewSurface":
            for inp in shader.GetInputs():
                for source in inp.GetConnectedSources()[0]:
                    role = "color" if inp.GetBaseName() in COLOR_INPUTS else "data"
                    path = source.source.GetPath()
                    if role == "color" or path not in roles:     # a texture feeding any colour input is colour
                        roles[path] = role
    for shader in textures:
        inp = shader.GetInput("file")
        if not inp:
            continue
        attr = inp.GetAttr()
        value = attr.Get()
        asset = value.path if value is not None else ""
        spec = next((s for s in attr.GetPropertyStack(Usd.TimeCode.Default()) if s.HasDefaultValue()), None)
        cs_input = shader.GetInput("sourceColorSpace")
        cs = str(cs_input.Get()) if cs_input and cs_input.Get() is not None else ""
        ref = TextureRef(label(shader.GetPath()), asset, role=roles.get(shader.GetPath(), "unknown"), color_space=cs)
        if asset and spec is not None:
            locate(ref, spec.layer, pkg)
        pkg.textures.append(ref)
    return []


def locate(ref: TextureRef, layer: Sdf.Layer, pkg: Package) -> None:
    """Set ref.file (lexical path, '..' kept resolved but symlinks not followed) or, inside a usdz, ref.member and
    ref.data."""
    identifier = layer.identifier
    if pkg.format == "usdz":
        inner = Ar.SplitPackageRelativePathOuter(identifier)[1] if Ar.IsPackageRelativePath(identifier) else ""
        if os.path.isabs(ref.asset):
            return
        member = posixpath.normpath(posixpath.join(posixpath.dirname(inner), ref.asset))
        ref.member = member
        try:
            with zipfile.ZipFile(pkg.file) as z:
                if member in z.namelist():
                    ref.data = z.read(member)
                    ref.file = pkg.file
        except (OSError, zipfile.BadZipFile):
            pass
        return
    base = os.path.dirname(layer.realPath or identifier)
    ref.file = Path(os.path.normpath(ref.asset if os.path.isabs(ref.asset) else os.path.join(base, ref.asset)))
