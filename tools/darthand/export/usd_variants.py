"""The asset's variant sets: `texture` (one skin material per catalogue entry) and `accessory` (`none` + one per
catalogue accessory).

Each variant's content is a layer of its own inside the package, so selecting a variant opens only that layer:

    texture/<id>.usda     a Material `Skin` (UsdPreviewSurface), its images in texture/<id>/
    accessory/<id>.usdc   an Xform `Accessory`: the accessory mesh bound to the hand's skeleton, and its material,
                          its images in accessory/<id>/

On the asset's root prim the `texture` variant `<id>` references texture/<id>.usda onto <root>/Looks/Skin (the
hand mesh is bound to that path) and the `accessory` variant `<id>` payloads accessory/<id>.usdc onto
<root>/Accessory. The accessory mesh inherits the skeleton binding from the SkelRoot: a rigid accessory follows
one joint (constant-interpolation joint influence, weight 1), a skinned one (a glove) has per-point influences.
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
from pxr import Sdf, Usd, UsdGeom

from darthand.errors import InputError
from darthand.export.common import (Accessory, Correctives, TextureSet, accessory_factors, accessory_offsets,
                                    check_accessory, place_texture)
from darthand.export.usd_materials import MaterialSpec, bind_material, define_material
from darthand.export.usd_skel import SPARSE_TOL, bind_skin, define_blend_shapes, define_mesh

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
    changes = {}
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
                            size: int | None = None, sparse_tol: float = SPARSE_TOL) -> str:
    """accessory/<id>.usdc (Xform `Accessory` with Mesh `Geom` and Material `Looks/Material`) and its images.

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
    mesh = define_mesh(stage, Sdf.Path("/Accessory/Geom"), np.asarray(acc.vertices, np.float64),
                       np.asarray(acc.faces), acc.uvs, acc.faces_uv)
    bind_skin(mesh.GetPrim(), acc.weights, influences, joint=acc.parent_joint)
    if acc.skinned:
        offsets = accessory_offsets(acc, correctives)
        if offsets.shape[2]:
            shapes = dataclasses.replace(correctives, offsets=offsets)
            define_blend_shapes(stage, mesh, shapes, None, sparse_tol)
    UsdGeom.Scope.Define(stage, "/Accessory/Looks")
    material = define_material(stage, Sdf.Path("/Accessory/Looks/Material"), spec)
    bind_material(mesh.GetPrim(), material.GetPath())
    stage.GetRootLayer().Save()
    return f"accessory/{vid}.usdc"


# ------------------------------------------------------------------------------------------------ variant sets


def add_texture_variants(layer: Sdf.Layer, root: Sdf.Path, layers: dict[str, str], default: str) -> None:
    """Variant set `texture` on `root`: variant id references the layer layers[id] onto <root>/Looks/Skin."""
    vset = _variant_set(layer, root, "texture", default)
    for vid, rel in layers.items():
        variant = Sdf.VariantSpec(vset, vid)
        looks = Sdf.PrimSpec(variant.primSpec, "Looks", Sdf.SpecifierDef, "Scope")
        skin = Sdf.PrimSpec(looks, "Skin", Sdf.SpecifierDef, "Material")
        skin.referenceList.Prepend(Sdf.Reference(f"./{rel}"))


def add_accessory_variants(layer: Sdf.Layer, root: Sdf.Path, layers: dict[str, str], default: str = "none") -> None:
    """Variant set `accessory` on `root`: `none` (empty) and one variant per accessory payloading layers[id] onto
    <root>/Accessory."""
    vset = _variant_set(layer, root, "accessory", default)
    Sdf.VariantSpec(vset, "none")
    for vid, rel in layers.items():
        variant = Sdf.VariantSpec(vset, vid)
        acc = Sdf.PrimSpec(variant.primSpec, "Accessory", Sdf.SpecifierDef, "Xform")
        acc.payloadList.Prepend(Sdf.Payload(f"./{rel}"))


def _variant_set(layer: Sdf.Layer, root: Sdf.Path, name: str, default: str) -> Sdf.VariantSetSpec:
    prim = layer.GetPrimAtPath(root)
    vset = Sdf.VariantSetSpec(prim, name)
    prim.variantSetNameList.Append(name)
    prim.variantSelections[name] = default
    return vset
