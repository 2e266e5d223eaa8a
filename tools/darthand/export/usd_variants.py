"""The asset's variant sets: `texture` (one skin material per catalogue entry) and `accessory` (`none` + one per
catalogue accessory).

Each variant's content is a layer of its own inside the package, so selecting a variant opens only that layer:

    texture/<id>.usda     a Material `Skin` (UsdPreviewSurface), its images in texture/<id>/
    accessory/<id>.usdc   an Xform `Accessory` holding the accessory mesh `<Side>_<id>` bound to the hand's skeleton
                          and its material `<Side>_<id>_material`, its images in accessory/<id>/

On the asset's root prim the `texture` variant `<id>` references texture/<id>.usda onto <root>/<Side>HandSkin (the
hand and cap meshes are bound to that path), the `accessory` variant `<id>` payloads accessory/<id>.usdc onto
<root>/<Side>HandAccessory, and the `gesture` variant `<name>` points the skeleton's animationSource at the
gesture's SkelAnimation (`all`: every gesture in turn, one per time code). The accessory mesh inherits the skeleton
binding from the SkelRoot: a rigid accessory follows one joint (constant-interpolation joint influence, weight 1),
a skinned one (a glove) has per-point influences.
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
from pxr import Sdf, Usd, UsdGeom

from darthand.accessories.loader import Accessory, accessory_factors, check_accessory
from darthand.errors import InputError
from darthand.export.correctives import Correctives, channel_offsets
from darthand.export.texture_files import place_texture
from darthand.export.usd_materials import MaterialSpec, bind_material, define_material
from darthand.export.usd_skel import ALL_GESTURES, SPARSE_TOL, RigNames, bind_skin, define_blend_shapes, define_mesh
from darthand.textures.loader import TextureSet

_VARIANT_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_-]*$")


def skin_material(texture: TextureSet) -> MaterialSpec:
    """The hand's material for one texture variant (source file paths)."""
    return MaterialSpec(albedo=str(texture.albedo), roughness=str(texture.roughness) if texture.roughness else None,
                        wrap="clamp")


def accessory_material(acc: Accessory) -> MaterialSpec:
    """An accessory's material: its textures, with the catalogue's constants as fallbacks (source file paths)."""
    color, metallic, roughness = accessory_factors(acc)
    return MaterialSpec(
        albedo=str(acc.base_color_png) if acc.base_color_png else None,
        metallic_roughness=str(acc.metallic_roughness_png) if acc.metallic_roughness_png else None,
        base_color=color[:3], roughness_value=roughness, metallic_value=metallic)


def check_variant_id(name: str, what: str) -> str:
    """Variant ids become USD variant names and file names: letters, digits, '_' and '-' (not first)."""
    if not _VARIANT_NAME.match(name):
        raise InputError(f"{what} id {name!r}: must be letters, digits, '_' and '-' (not first)")
    return name


# ------------------------------------------------------------------------------------------------ files


def package_material(spec: MaterialSpec, folder: Path, rel: str, size: int | None = None) -> MaterialSpec:
    """Copy `spec`'s texture files into `folder` and return the spec with asset paths `./<rel>/<file name>`."""
    changes: dict = {}
    for field in ("albedo", "roughness", "metallic_roughness", "normal"):
        src = getattr(spec, field)
        if src:
            name = Path(src).name
            place_texture(src, folder / name, size, srgb=field == "albedo")
            changes[field] = f"./{rel}/{name}"
    return dataclasses.replace(spec, **changes)


def new_layer_stage(path: Path, default_prim: str) -> Usd.Stage:
    """A new stage on `path` with the package's stage metadata (metres, +Y up)."""
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    stage.GetRootLayer().defaultPrim = default_prim
    return stage


def write_texture_variant(package: Path, vid: str, material: MaterialSpec, size: int | None = None) -> str:
    """texture/<id>.usda (Material `Skin`) and its images; returns the layer's package-relative path."""
    check_variant_id(vid, "texture")
    spec = package_material(material, package / "texture" / vid, vid, size)
    stage = new_layer_stage(package / "texture" / f"{vid}.usda", "Skin")
    define_material(stage, Sdf.Path("/Skin"), spec)
    stage.GetRootLayer().Save()
    return f"texture/{vid}.usda"


def write_accessory_variant(package: Path, acc: Accessory, correctives: Correctives, influences: int | None = None,
                            size: int | None = None, sparse_tol: float = SPARSE_TOL, prefix: str = "Right") -> str:
    """accessory/<id>.usdc (Xform `Accessory` with Mesh `<prefix>_<id>` and Material `<prefix>_<id>_material`) and
    its images.

    A skinned accessory with its own correctives gets them as blend shapes in the hand's corrective basis, with
    the hand's blend-shape names, so the hand's animation drives them.
    """
    vid = check_variant_id(acc.id, "accessory")
    check_accessory(acc, f"accessory {vid}")
    spec = package_material(accessory_material(acc), package / "accessory" / vid, vid, size)
    stage = new_layer_stage(package / "accessory" / f"{vid}.usdc", "Accessory")
    root = UsdGeom.Xform.Define(stage, "/Accessory")
    if acc.kind:
        root.GetPrim().SetCustomDataByKey("darthand:kind", acc.kind)
    mesh = define_mesh(stage, Sdf.Path(f"/Accessory/{prefix}_{vid}"), np.asarray(acc.vertices, np.float64),
                       np.asarray(acc.faces), acc.uvs, acc.faces_uv)
    mesh.GetPrim().SetCustomDataByKey("darthand:role", "accessory")
    bind_skin(mesh.GetPrim(), acc.weights, influences, joint=acc.parent_joint)
    if acc.skinned:
        offsets = channel_offsets(acc.posedirs, correctives, len(acc.vertices))
        if offsets.shape[2]:
            define_blend_shapes(stage, mesh, correctives, offsets, None, sparse_tol)
    material = define_material(stage, Sdf.Path(f"/Accessory/{prefix}_{vid}_material"), spec)
    bind_material(mesh.GetPrim(), material.GetPath())
    stage.GetRootLayer().Save()
    return f"accessory/{vid}.usdc"


# ------------------------------------------------------------------------------------------------ variant sets


def add_texture_variants(layer: Sdf.Layer, root: Sdf.Path, material: str, layers: dict[str, str],
                         default: str) -> None:
    """Variant set `texture` on `root`: variant id references the layer layers[id] onto <root>/<material>."""
    vset = _variant_set(layer, root, "texture", default)
    for vid, rel in layers.items():
        variant = Sdf.VariantSpec(vset, vid)
        skin = Sdf.PrimSpec(variant.primSpec, material, Sdf.SpecifierDef, "Material")
        skin.referenceList.Prepend(Sdf.Reference(f"./{rel}"))


def add_accessory_variants(layer: Sdf.Layer, root: Sdf.Path, prefix: str, layers: dict[str, str],
                           default: str = "none") -> None:
    """Variant set `accessory` on `root`: `none` (empty) and one variant per accessory payloading layers[id] onto
    <root>/<prefix>HandAccessory."""
    vset = _variant_set(layer, root, "accessory", default)
    Sdf.VariantSpec(vset, "none")
    for vid, rel in layers.items():
        variant = Sdf.VariantSpec(vset, vid)
        acc = Sdf.PrimSpec(variant.primSpec, f"{prefix}HandAccessory", Sdf.SpecifierDef, "Xform")
        acc.payloadList.Prepend(Sdf.Payload(f"./{rel}"))


def add_gesture_variants(layer: Sdf.Layer, root: Sdf.Path, names: RigNames, gestures: list[str]) -> None:
    """Variant set `gesture` on `root`: `all` (default: every gesture in turn, time code k = gesture k) and one
    variant per gesture, each pointing the skeleton's animationSource at that SkelAnimation."""
    vset = _variant_set(layer, root, "gesture", ALL_GESTURES)
    for vid, anim in [(ALL_GESTURES, names.timeline)] + [(g, names.gesture(g)) for g in gestures]:
        variant = Sdf.VariantSpec(vset, vid)
        skel = Sdf.PrimSpec(variant.primSpec, names.skeleton, Sdf.SpecifierOver)
        rel = Sdf.RelationshipSpec(skel, "skel:animationSource", custom=False)
        rel.targetPathList.Prepend(root.AppendChild(anim))


def _variant_set(layer: Sdf.Layer, root: Sdf.Path, name: str, default: str) -> Sdf.VariantSetSpec:
    prim = layer.GetPrimAtPath(root)
    vset = Sdf.VariantSetSpec(prim, name)
    prim.variantSetNameList.Append(name)
    prim.variantSelections[name] = default
    return vset
