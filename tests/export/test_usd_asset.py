"""The USD asset package: interface layer, payload, variant sets (texture, accessory), materials, OpenUSD
validation, usdz, the commands, atomic writing."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest
from pxr import Kind, Sdf, Usd, UsdGeom, UsdShade, UsdSkel, UsdUtils
from synthetic import tube_hand

from darthand.errors import InputError
from darthand.export import commands_usd
from darthand.accessories.loader import Accessory
from darthand.textures.loader import TextureSet
from darthand.export.usd_asset import ExportOptions, export_usd
from darthand.export.usd_evaluate import skinned_points
from darthand.export.usd_validate import errors, select_variants, validate_file, validate_stage, validate_variants
from darthand.export.usdz import export_usdz, usdz_contents
from darthand.fileio import sha256_file
from darthand.model.forward import forward, pose_feature
from darthand.model.npz_io import save_npz
from darthand.model.wrist import add_wrist


def write_png(path: Path, size: int, seed: int) -> Path:
    img = np.random.default_rng(seed).random((size, size, 3)).astype(np.float32)
    path.parent.mkdir(parents=True, exist_ok=True)
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(size, size, 3, "uint8"))
    out.write_image(img)
    out.close()
    return path


@pytest.fixture(scope="module")
def model():
    return add_wrist(tube_hand(0))


@pytest.fixture(scope="module")
def sources(model, tmp_path_factory):
    """Two skin textures, a ring rigidly on joint 5 (index middle phalanx), a glove skinned like the hand with its
    own correctives."""
    src = tmp_path_factory.mktemp("src")
    textures = [TextureSet("skin_000", write_png(src / "s0" / "albedo.png", 32, 0),
                           write_png(src / "s0" / "rough.png", 32, 1)),
                TextureSet("skin_001", write_png(src / "s1" / "albedo.png", 32, 2))]
    ring_v = model.v_template[:48] * 0.5 + [-0.1, 0, 0]
    ring_f = np.array([[0, 1, 2], [2, 1, 3], [4, 5, 6]])
    accessories = [
        Accessory("ring_01", ring_v, ring_f, uvs=np.random.default_rng(3).random((7, 2)),
                  faces_uv=np.array([[0, 1, 2], [2, 1, 3], [4, 5, 6]]), parent_joint=5,
                  base_color_png=write_png(src / "ring" / "base.png", 16, 4),
                  metallic_roughness_png=write_png(src / "ring" / "mr.png", 16, 5),
                  material={"base_color": [1, 0.8, 0.3, 1], "metallic": 1.0, "roughness": 0.3}, kind="ring"),
        Accessory("glove_01", model.v_template * 1.02, model.faces, uvs=model.uvs, faces_uv=model.faces_uv,
                  weights=model.weights, posedirs=model.posedirs * 0.5, kind="glove"),
    ]
    return textures, accessories


@pytest.fixture(scope="module")
def gestures():
    p = np.random.default_rng(11).normal(0, 0.5, (4, 48))
    p[0] = 0
    return ["flat", "a", "b", "c"], p


@pytest.fixture(scope="module")
def package(model, sources, gestures, tmp_path_factory):
    textures, accessories = sources
    out = tmp_path_factory.mktemp("usd") / "right"
    info = export_usd(model, out, textures=textures, default_texture="skin_001", accessories=accessories,
                      gestures=gestures)
    return out, info


def open_with(package_dir: Path, **selections) -> Usd.Stage:
    stage = Usd.Stage.Open(str(package_dir / "right.usda"), Usd.Stage.LoadAll)
    select_variants(stage, selections)
    return stage


# ------------------------------------------------------------------------------------------------ structure


def test_interface_layer_follows_the_asset_structure(package):
    out, info = package
    stage = Usd.Stage.Open(str(out / "right.usda"), Usd.Stage.LoadNone)
    prim = stage.GetDefaultPrim()
    assert prim.GetPath() == Sdf.Path("/RightHand") and prim.GetTypeName() == "SkelRoot"
    assert Usd.ModelAPI(prim).GetKind() == Kind.Tokens.component
    asset_info = Usd.ModelAPI(prim).GetAssetInfo()
    assert asset_info["name"] == "darthand_right" and asset_info["identifier"].path == "./right.usda"
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0 and UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y
    assert prim.HasPayload() and not stage.GetPrimAtPath("/RightHand/RightHandSkeleton").IsDefined()  # payload only
    layer = stage.GetRootLayer()
    assert [p.assetPath for p in layer.GetPrimAtPath("/RightHand").payloadList.prependedItems] == ["./payload.usdc"]
    assert stage.GetStartTimeCode() == 0 and stage.GetEndTimeCode() == 3
    vsets = prim.GetVariantSets()
    assert vsets.GetNames() == ["texture", "accessory", "gesture"]
    assert vsets.GetVariantSet("gesture").GetVariantSelection() == "all"
    assert vsets.GetVariantSet("texture").GetVariantNames() == ["skin_000", "skin_001"]
    assert vsets.GetVariantSet("texture").GetVariantSelection() == "skin_001"
    assert vsets.GetVariantSet("accessory").GetVariantNames() == ["glove_01", "none", "ring_01"]
    assert vsets.GetVariantSet("accessory").GetVariantSelection() == "none"
    assert json.loads((out / "asset.json").read_text())["variants"]["accessory"] == ["none", "ring_01", "glove_01"]


def test_all_asset_paths_are_relative_and_inside_the_package(package):
    out, _ = package
    layers, assets, unresolved = UsdUtils.ComputeAllDependencies(Sdf.AssetPath(str(out / "right.usda")))
    assert not unresolved
    names = {Path(layer.realPath).relative_to(out).as_posix() for layer in layers}
    assert {"right.usda", "payload.usdc", "texture/skin_000.usda", "texture/skin_001.usda",
            "accessory/ring_01.usdc", "accessory/glove_01.usdc"} <= names
    assert {Path(a).relative_to(out).as_posix() for a in assets} >= {"texture/skin_000/albedo.png",
                                                                      "accessory/ring_01/mr.png"}
    for layer in layers:
        for ref in layer.GetCompositionAssetDependencies() + list(_asset_values(layer)):
            assert not Path(ref).is_absolute() and ref.startswith("./"), (layer.identifier, ref)


def _asset_values(layer: Sdf.Layer):
    found = []

    def visit(path):
        if path.IsPropertyPath():
            spec = layer.GetPropertyAtPath(path)
            if isinstance(spec, Sdf.AttributeSpec) and isinstance(spec.default, Sdf.AssetPath):
                found.append(spec.default.path)

    layer.Traverse(Sdf.Path.absoluteRootPath, visit)
    return found


def test_variant_selection_loads_only_its_layers(package):
    out, _ = package
    used = used_layers(open_with(out, texture="skin_000", accessory="ring_01"))
    assert {"skin_000.usda", "ring_01.usdc"} <= used
    assert not used & {"skin_001.usda", "glove_01.usdc"}
    used = used_layers(open_with(out))
    assert "skin_001.usda" in used and not used & {"skin_000.usda", "ring_01.usdc", "glove_01.usdc"}


def used_layers(stage: Usd.Stage) -> set[str]:
    return {Path(layer.realPath).name for layer in stage.GetUsedLayers() if layer.realPath}


def test_materials_preview_surface_and_colour_spaces(package):
    out, _ = package
    stage = open_with(out, texture="skin_000", accessory="ring_01")
    mesh = stage.GetPrimAtPath("/RightHand/RightHandMesh")
    material, _ = UsdShade.MaterialBindingAPI(mesh).ComputeBoundMaterial()
    assert material.GetPath() == Sdf.Path("/RightHand/RightHandSkin")
    surface = material.ComputeSurfaceSource()[0]
    assert surface.GetIdAttr().Get() == "UsdPreviewSurface"
    albedo = UsdShade.Shader(stage.GetPrimAtPath("/RightHand/RightHandSkin/AlbedoTexture"))
    rough = UsdShade.Shader(stage.GetPrimAtPath("/RightHand/RightHandSkin/RoughnessTexture"))
    assert albedo.GetInput("sourceColorSpace").Get() == "sRGB" and rough.GetInput("sourceColorSpace").Get() == "raw"
    resolved = Path(albedo.GetInput("file").Get().resolvedPath)
    assert resolved == out / "texture" / "skin_000" / "albedo.png" and resolved.is_file()
    assert surface.GetInput("diffuseColor").GetConnectedSources()[0][0].source.GetPath() == albedo.GetPath()
    ring_mat, _ = UsdShade.MaterialBindingAPI(
        stage.GetPrimAtPath("/RightHand/RightHandAccessory/Right_ring_01")).ComputeBoundMaterial()
    assert ring_mat.GetPath().name == "Right_ring_01_material"
    mr = UsdShade.Shader(stage.GetPrimAtPath(ring_mat.GetPath().AppendChild("MetallicRoughnessTexture")))
    assert mr.GetInput("sourceColorSpace").Get() == "raw"
    st = UsdGeom.PrimvarsAPI(mesh).GetPrimvar("st")
    assert st.GetInterpolation() == UsdGeom.Tokens.faceVarying and st.IsIndexed()


def test_openusd_validation_finds_no_errors_in_any_variant(package):
    out, _ = package
    issues = validate_variants(out / "right.usda")
    assert errors(issues) == [], "\n".join(map(str, issues))


def test_validation_does_report_errors():
    """The validators are live: a stage without defaultPrim, metersPerUnit and upAxis is reported."""
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.Xform.Define(stage, "/A")
    found = {i.validator for i in errors(validate_stage(stage))}
    assert {"usdValidation:StageMetadataChecker", "usdGeomValidators:StageMetadataChecker"} <= found


# ------------------------------------------------------------------------------------------------ accessories


def test_rigid_accessory_follows_its_joint(model, package, sources, gestures):
    out, _ = package
    ring = sources[1][0]
    stage = open_with(out, accessory="ring_01")
    binding = stage.GetPrimAtPath("/RightHand/RightHandAccessory/Right_ring_01")
    indices = UsdSkel.BindingAPI(binding).GetJointIndicesPrimvar()
    # per point: Blender reads it
    assert indices.GetInterpolation() == UsdGeom.Tokens.vertex and set(indices.Get()) == {5}
    points = skinned_points(stage)["/RightHand/RightHandAccessory/Right_ring_01"]
    G = forward(model, gestures[1]).transforms[:, 5]                          # (B, 4, 4)
    expected = np.einsum("bij,nj->bni", G[:, :3, :3], ring.vertices) + G[:, None, :3, 3]
    assert np.linalg.norm(points - expected, axis=-1).max() < 1e-6


def test_glove_is_skinned_like_the_hand_with_its_correctives(model, package, sources, gestures):
    out, _ = package
    glove = sources[1][1]
    points = skinned_points(open_with(out, accessory="glove_01"))
    posed = forward(model, gestures[1])
    v = glove.vertices[None] + np.einsum("nck,bk->bnc", glove.posedirs, pose_feature(posed.rotations))
    T = np.einsum("nj,bjxy->bnxy", glove.weights, posed.transforms)
    expected = np.einsum("bnxy,bny->bnx", T[..., :3, :3], v) + T[..., :3, 3]
    assert np.linalg.norm(points["/RightHand/RightHandAccessory/Right_glove_01"] - expected, axis=-1).max() < 1e-6
    assert np.linalg.norm(points["/RightHand/RightHandMesh"] - posed.vertices, axis=-1).max() < 1e-6


# ------------------------------------------------------------------------------------------------ usdz


def test_usdz_of_one_variant_combination(model, package, gestures, tmp_path):
    out, _ = package
    usdz = tmp_path / "hand.usdz"
    files = export_usdz(out, usdz, texture="skin_000", accessory="ring_01")
    assert files[0] == "right.usdc" and files == usdz_contents(usdz)
    assert set(files[1:]) == {"texture/skin_000/albedo.png", "texture/skin_000/rough.png",
                              "accessory/ring_01/base.png", "accessory/ring_01/mr.png"}
    assert errors(validate_file(usdz)) == []
    stage = Usd.Stage.Open(str(usdz))
    assert not stage.GetDefaultPrim().GetVariantSets().GetNames()
    points = skinned_points(stage)
    reference = skinned_points(open_with(out, texture="skin_000", accessory="ring_01"))
    for path in ("/RightHand/RightHandMesh", "/RightHand/RightHandAccessory/Right_ring_01"):
        np.testing.assert_array_equal(points[path], reference[path])
    err = np.linalg.norm(points["/RightHand/RightHandMesh"] - forward(model, gestures[1]).vertices, axis=-1).max()
    assert err < 1e-6


def test_usdz_rejects_unknown_variants(package, tmp_path):
    out, _ = package
    with pytest.raises(InputError, match="no variant 'skin_999'"):
        export_usdz(out, tmp_path / "x.usdz", texture="skin_999")
    assert not list(tmp_path.iterdir())


# ------------------------------------------------------------------------------------------------ writing


def test_texture_size_resamples_into_the_package(model, sources, gestures, tmp_path):
    info = export_usd(model, tmp_path / "right", textures=sources[0][:1], gestures=gestures,
                      options=ExportOptions(texture_size=8))
    spec = oiio.ImageInput.open(str(tmp_path / "right" / "texture" / "skin_000" / "albedo.png")).spec()
    assert (spec.width, spec.height) == (8, 8)
    assert info["files"]["texture/skin_000/albedo.png"] < (tmp_path / "right" / "payload.usdc").stat().st_size


def test_failed_export_keeps_the_previous_package(model, sources, gestures, tmp_path):
    out = tmp_path / "right"
    export_usd(model, out, gestures=gestures)
    before = sorted(p.relative_to(out) for p in out.rglob("*"))
    broken = [TextureSet("skin_bad", tmp_path / "missing.png")]
    with pytest.raises(InputError, match="missing.png: texture file not found"):
        export_usd(model, out, textures=broken, gestures=gestures)
    assert sorted(p.relative_to(out) for p in out.rglob("*")) == before
    assert [p.name for p in tmp_path.iterdir()] == ["right"]          # no temporary folder left behind
    export_usd(model, out, textures=sources[0], gestures=gestures)     # and a rewrite replaces it whole
    assert (out / "texture" / "skin_000.usda").is_file() and not (out / "texture" / "plain.usda").exists()


def test_bad_ids_are_input_errors(model, gestures, tmp_path):
    with pytest.raises(InputError, match="texture id 'skin 1'"):
        export_usd(model, tmp_path / "a", textures=[TextureSet("skin 1", tmp_path / "x.png")], gestures=gestures)
    with pytest.raises(InputError, match="accessory id 'none' is used twice"):
        export_usd(model, tmp_path / "b", gestures=gestures,
                   accessories=[Accessory("none", np.zeros((3, 3)), np.array([[0, 1, 2]]), parent_joint=0)])


# ------------------------------------------------------------------------------------------------ commands


def test_commands_export_check_and_usdz(model, tmp_path, capsys):
    npz = tmp_path / "right.npz"
    save_npz(model, npz)
    args = argparse.Namespace(model=str(npz), out=str(tmp_path / "usd" / "right"), textures=None, accessories=None,
                              influences="8", correctives="pca:16", texture_size=None, name=None, atlas_res=2048)
    assert commands_usd.usd(args) == 0
    info = json.loads((tmp_path / "usd" / "right" / "asset.json").read_text())
    # 16 PCA directions, a _pos and a _neg shape each, then the shape dials (two per shape direction)
    assert info["rig"]["influences"] == 8 and info["rig"]["blend_shapes"] == 32 + 2 * model.num_betas
    assert commands_usd.check(argparse.Namespace(package=str(tmp_path / "usd" / "right"), all_variants=True)) == 0
    assert "0 errors" in capsys.readouterr().out
    usdz_args = argparse.Namespace(package=str(tmp_path / "usd" / "right"), out=str(tmp_path / "h.usdz"),
                                   texture="plain", accessory="none")
    assert commands_usd.usdz(usdz_args) == 0 and (tmp_path / "h.usdz").is_file()
    with pytest.raises(InputError, match="--influences"):
        commands_usd.usd(argparse.Namespace(**{**vars(args), "influences": "3.5"}))


def test_export_is_deterministic(model, sources, gestures, tmp_path):
    a = export_usd(model, tmp_path / "a", textures=sources[0], accessories=sources[1], gestures=gestures)
    b = export_usd(model, tmp_path / "b", textures=sources[0], accessories=sources[1], gestures=gestures)
    assert a["files"] == b["files"]
    for name in list(a["files"]) + ["asset.json"]:
        assert sha256_file(tmp_path / "a" / name) == sha256_file(tmp_path / "b" / name), name


def test_rewrite_is_seen_by_a_process_that_had_the_old_package_open(model, gestures, tmp_path):
    out = tmp_path / "right"
    export_usd(model, out, gestures=gestures)
    held = Usd.Stage.Open(str(out / "right.usda"), Usd.Stage.LoadAll)        # keeps the old layers registered
    assert len(blend_shape_names(held)) == 225 + 2 * model.num_betas                     # correctives, shape dials
    export_usd(model, out, gestures=gestures, options=ExportOptions(correctives="pca:8", shape_dials=0))
    assert len(blend_shape_names(Usd.Stage.Open(str(out / "right.usda"), Usd.Stage.LoadAll))) == 16


def blend_shape_names(stage: Usd.Stage) -> list:
    return list(UsdSkel.BindingAPI(stage.GetPrimAtPath("/RightHand/RightHandMesh")).GetBlendShapesAttr().Get() or [])
