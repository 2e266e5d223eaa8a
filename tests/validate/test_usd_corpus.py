"""USD: the good package is clean, and every rule fires on its broken copy (at the right prim, with the exit code
the CLI would return)."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from package_parts import RING_ID, TEXTURE_IDS, write_png
from corpus import (ALBEDO, GEOM, HAND, ROUGH, SKEL, add_fin, add_variant, array, change, copy_package, edit,
                    edit_faces, remove_property, scale_matrix, set_array, set_payload)
from pxr import Sdf

from darthand.validate.asset import Limits
from darthand.validate.run import validate_paths

DEFAULT_TEX, OTHER_TEX = TEXTURE_IDS      # the asset opens with the first; the second is checked layer by layer
RING_LAYER = f"accessory/{RING_ID}.usdc"
GLOVE_LAYER = "accessory/glove_01_latex.usdc"


def payload(fn):
    return lambda pkg: edit(pkg / "payload.usdc", fn)


def texture_layer(tid, fn):
    return lambda pkg: edit(pkg / "texture" / f"{tid}.usda", fn)


def ring(fn):
    return lambda pkg: edit(pkg / RING_LAYER, fn)


def interface(fn):
    return lambda pkg: edit(pkg / "right.usda", fn)


def nan_at(i):
    def fn(a):
        a = a.astype(float)
        a.reshape(len(a), -1)[i, 0] = np.nan
        return a.astype(np.float32)
    return fn


def rows(fn):
    """Edit per-point rows of the hand's joint weights (k per point)."""
    def edit_weights(layer):
        w = array(layer, f"{HAND}.primvars:skel:jointWeights")
        k = len(w) // len(array(layer, f"{HAND}.points"))
        w = w.reshape(-1, k).astype(np.float64)
        fn(w)
        set_array(layer, f"{HAND}.primvars:skel:jointWeights", w.reshape(-1).astype(np.float32))
    return edit_weights


def scale_row(w):
    w[0] *= 0.9


def negative(w):
    w[0, -1] -= 0.05
    w[0, 0] += 0.05


def nonfinite_weight(w):
    w[0, 0] = np.nan


def set_first(prop, value):
    def fn(a):
        a = a.copy()
        a.reshape(len(a), -1)[0] = value
        return a
    return lambda layer: change(layer, prop, fn)


def uv_used_first(value):
    def fn(layer):
        st = array(layer, f"{HAND}.primvars:st").astype(np.float64)
        st[array(layer, f"{HAND}.primvars:st:indices")[0]] = value
        set_array(layer, f"{HAND}.primvars:st", st.astype(np.float32))
    return fn


def joints_reparented(layer):
    joints = list(layer.GetAttributeAtPath(f"{SKEL}.joints").default)
    joints = [j.replace("wrist/middle1", "wrist/index1/middle1") for j in joints]
    set_array(layer, f"{SKEL}.joints", joints)


def translate_bind(layer):
    def fn(m):
        m = m.copy()
        m[7, 3, :3] += 0.01
        return m
    change(layer, f"{SKEL}.bindTransforms", fn)


def drop_corrective(layer):
    names = list(layer.GetAttributeAtPath(f"{HAND}.skel:blendShapes").default)
    set_array(layer, f"{HAND}.skel:blendShapes", names[:3] + names[4:])
    rel = layer.GetRelationshipAtPath(f"{HAND}.skel:blendShapeTargets")
    targets = list(rel.targetPathList.explicitItems or rel.targetPathList.prependedItems)
    rel.targetPathList.ClearEdits()
    rel.targetPathList.explicitItems = targets[:3] + targets[4:]


SHAPE = f"{HAND}/pose_index1_r00_neg"


def no_skeleton(layer):
    remove_property(layer, "/RightHand.skel:skeleton")
    del layer.GetPrimAtPath("/RightHand").nameChildren["RightHandSkeleton"]


def truncate(path: Path, keep: float = 0.5):
    data = path.read_bytes()
    path.write_bytes(data[:int(len(data) * keep)])


def outside_png(pkg: Path) -> Path:
    return write_png(pkg.parent / "outside.png", 32, 32, 9)


def symlink_out(pkg: Path):
    target = pkg / "texture" / DEFAULT_TEX / "albedo.png"
    target.unlink()
    os.symlink(outside_png(pkg), target)


def flip_idat_byte(pkg: Path):
    path = pkg / "texture" / DEFAULT_TEX / "albedo.png"
    data = bytearray(path.read_bytes())
    i = data.index(b"IDAT") + 20
    data[i] ^= 0xFF
    path.write_bytes(bytes(data))


def layer_outside(pkg: Path):
    outside = pkg.parent / "elsewhere"
    outside.mkdir()
    shutil.copy(pkg / RING_LAYER, outside / "ring.usdc")
    edit(pkg / "right.usda", lambda layer: set_payload(layer, f"/RightHand{{accessory={RING_ID}}}RightHandAccessory",
                                                       str(outside / "ring.usdc")))


def drop_api(prim: str, schema: str):
    def fn(layer):
        spec = layer.GetPrimAtPath(prim)
        kept = [x for x in spec.GetInfo("apiSchemas").prependedItems if x != schema]
        spec.SetInfo("apiSchemas", Sdf.TokenListOp.Create(prependedItems=kept))
    return fn


def absolute_path(pkg: Path):
    path = str(pkg / "texture" / OTHER_TEX / "albedo.png")
    edit(pkg / "texture" / f"{OTHER_TEX}.usda", lambda layer: setattr(
        layer.GetAttributeAtPath(f"{ALBEDO}.inputs:file"), "default", Sdf.AssetPath(path)))


def escaping_path(pkg: Path):
    outside_png(pkg)
    edit(pkg / "texture" / f"{DEFAULT_TEX}.usda", lambda layer: setattr(
        layer.GetAttributeAtPath(f"{ALBEDO}.inputs:file"), "default", Sdf.AssetPath("../../outside.png")))



# (rule that must fire, edit of the package copy)
CASES = {
    # mesh
    "nan-point": ("mesh.nonfinite-point", payload(lambda layer: change(layer, f"{HAND}.points", nan_at(3)))),
    "degenerate-face": ("mesh.degenerate-face", payload(lambda layer: edit_faces(
        layer, lambda f, uv: (np.vstack([[f[0, 0], f[0, 0], f[0, 2]], f[1:]]), uv)))),
    "duplicate-face": ("mesh.duplicate-face", payload(lambda layer: edit_faces(
        layer, lambda f, uv: (np.vstack([f, f[10]]), np.vstack([uv, uv[10]]))))),
    "flipped-face": ("mesh.winding", payload(lambda layer: edit_faces(
        layer, lambda f, uv: (np.vstack([f[:20], f[20, ::-1], f[21:]]), np.vstack([uv[:20], uv[20, ::-1], uv[21:]]))))),
    "non-manifold": ("mesh.non-manifold-edge", payload(add_fin)),
    "hole": ("mesh.open-boundary", payload(lambda layer: edit_faces(
        layer, lambda f, uv: (np.delete(f, 40, 0), np.delete(uv, 40, 0))))),
    "face-index": ("mesh.face-index", payload(set_first(f"{HAND}.faceVertexIndices", 100000))),
    "face-counts": ("file.malformed", payload(set_first(f"{HAND}.faceVertexCounts", 4))),
    "uv-outside": ("mesh.uv-range", payload(uv_used_first((1.5, 0.5)))),
    "uv-nan": ("mesh.uv-nonfinite", payload(uv_used_first((np.nan, 0.5)))),
    "uv-index": ("mesh.uv-index", payload(set_first(f"{HAND}.primvars:st:indices", 100000))),
    # rig
    "weights-sum": ("rig.weights-sum", payload(rows(scale_row))),
    "weights-negative": ("rig.weights-negative", payload(rows(negative))),
    "weights-nan": ("rig.weights-nonfinite", payload(rows(nonfinite_weight))),
    "joint-index": ("rig.joint-index", payload(set_first(f"{HAND}.primvars:skel:jointIndices", 16))),
    "skin-layout": ("rig.skin-layout", payload(lambda layer: change(
        layer, f"{HAND}.primvars:skel:jointWeights", lambda w: w[:-1]))),
    "no-skin": ("rig.no-skin", payload(lambda layer: [remove_property(layer, f"{HAND}.primvars:skel:{p}")
                                                      for p in ("jointIndices", "jointWeights")])),
    "no-skeleton": ("rig.no-skeleton", payload(no_skeleton)),
    "scaled-bind": ("rig.bind-transform", payload(lambda layer: scale_matrix(layer, f"{SKEL}.bindTransforms", 5))),
    "scaled-rest": ("rig.rest-transform", payload(lambda layer: scale_matrix(layer, f"{SKEL}.restTransforms", 5))),
    "bind-rest": ("rig.bind-rest-mismatch", payload(translate_bind)),
    "hierarchy": ("rig.hierarchy", payload(joints_reparented)),
    "joint-count": ("rig.joint-count", payload(lambda layer: change(layer, f"{SKEL}.joints", lambda j: j[:15]))),
    "joint-names": ("rig.joint-names", payload(lambda layer: change(
        layer, f"{SKEL}.jointNames", lambda n: ["root"] + list(n[1:])))),
    "corrective-missing": ("rig.correctives-missing", payload(drop_corrective)),
    "blendshape-index": ("rig.blendshape-index", payload(set_first(f"{SHAPE}.pointIndices", 100000))),
    "blendshape-duplicate": ("rig.blendshape-duplicate-index", payload(lambda layer: change(
        layer, f"{SHAPE}.pointIndices", lambda a: np.r_[a[1], a[1:]].astype(np.int32)))),
    "blendshape-nan": ("rig.blendshape-nonfinite", payload(lambda layer: change(layer, f"{SHAPE}.offsets",
                                                                                   nan_at(0)))),
    "blendshape-layout": ("rig.blendshape-layout", payload(lambda layer: change(
        layer, f"{SHAPE}.pointIndices", lambda a: a[:-1]))),
    # textures (the default texture's layer is composed into the asset, the other one is checked on its own)
    "texture-missing": ("tex.missing", lambda pkg: (pkg / "texture" / OTHER_TEX / "albedo.png").unlink()),
    "texture-absolute": ("tex.absolute-path", absolute_path),
    "texture-escapes": ("tex.path-escapes", escaping_path),
    "texture-symlink": ("tex.symlink-outside", symlink_out),
    "texture-npot": ("tex.not-power-of-two",
                     lambda pkg: write_png(pkg / "texture" / DEFAULT_TEX / "roughness.png", 48, 32, 5)),
    "albedo-raw": ("tex.albedo-colorspace", texture_layer(DEFAULT_TEX, lambda layer: setattr(
        layer.GetAttributeAtPath(f"{ALBEDO}.inputs:sourceColorSpace"), "default", "raw"))),
    "roughness-srgb": ("tex.data-colorspace", texture_layer(DEFAULT_TEX, lambda layer: setattr(
        layer.GetAttributeAtPath(f"{ROUGH}.inputs:sourceColorSpace"), "default", "sRGB"))),
    "png-truncated": ("tex.unreadable", lambda pkg: truncate(pkg / "texture" / OTHER_TEX / "albedo.png")),
    "png-garbage": ("tex.unreadable", lambda pkg: (pkg / "texture" / DEFAULT_TEX / "albedo.png").write_bytes(
        b"this is not an image" * 8)),
    "texture-id": ("tex.unknown-id", interface(lambda layer: add_variant(layer, "texture", "my_own_skin",
                                                                          DEFAULT_TEX))),
    # accessories
    "ring-joint-99": ("acc.bad-joint", ring(lambda layer: set_array(
        layer, f"{GEOM.format(RING_ID)}.primvars:skel:jointIndices", np.array([99], np.int32)))),
    "ring-floating": ("acc.distance", ring(lambda layer: change(
        layer, f"{GEOM.format(RING_ID)}.points", lambda p: (p + [0.0, 0.11, 0.0]).astype(np.float32)))),
    "ring-unbound": ("acc.binding", ring(lambda layer: [
        remove_property(layer, f"{GEOM.format(RING_ID)}.primvars:skel:{p}")
        for p in ("jointIndices", "jointWeights")])),
    "accessory-id": ("acc.unknown-id", interface(lambda layer: add_variant(layer, "accessory", "mystery_ring",
                                                                            RING_ID))),
    "glove-weights": ("rig.weights-sum", lambda pkg: edit(pkg / GLOVE_LAYER, lambda layer: change(
        layer, f"{GEOM.format('glove_01_latex')}.primvars:skel:jointWeights", lambda w: (w * 0.5).astype(np.float32)))),
    # packaging and OpenUSD's validators
    "layer-outside": ("usd.layer-outside-package", layer_outside),
    "no-meters-per-unit": ("usd.usdGeomValidators:StageMetadataChecker", interface(
        lambda layer: layer.pseudoRoot.ClearInfo("metersPerUnit"))),
    "no-skel-binding-api": ("usd.usdSkelValidators:SkelBindingApiAppliedValidator",
                            payload(drop_api(HAND, "SkelBindingAPI"))),
    "no-material-binding-api": ("usd.usdShadeValidators:MaterialBindingApiAppliedValidator",
                                ring(drop_api(GEOM.format(RING_ID), "MaterialBindingAPI"))),
    "texture-layer-missing": ("usd.usdValidation:CompositionErrorTest",
                              lambda pkg: (pkg / "texture" / f"{OTHER_TEX}.usda").unlink()),
    "payload-truncated": ("file.unreadable", lambda pkg: truncate(pkg / "payload.usdc")),
}


# Where the finding must point (a prim path inside the variant it was found under), for some cases.
EXPECTED_PATH = {
    "nan-point": HAND,
    "ring-joint-99": f"/RightHand{{accessory={RING_ID}}}RightHandAccessory/Right_{RING_ID}",
    "glove-weights": "/RightHand{accessory=glove_01_latex}RightHandAccessory/Right_glove_01_latex",
    "texture-absolute": f"/RightHand{{texture={OTHER_TEX}}}RightHandSkin/AlbedoTexture",
    "albedo-raw": "/RightHand/RightHandSkin/AlbedoTexture",
    "scaled-bind": SKEL,
}


def broken(good: Path, tmp_path: Path, name: str) -> Path:
    pkg = copy_package(good, tmp_path / "case")
    CASES[name][1](pkg)
    return pkg


def rules_of(report) -> set[str]:
    return {f.rule for f in report.findings}


# ------------------------------------------------------------------------------------------------ tests


def test_good_package_is_clean(good_usd):
    report = validate_paths([good_usd])
    assert report.exit_code == 0, [f for f in report.findings]
    assert report.findings == []          # no errors, and no warnings or infos either


@pytest.mark.parametrize("name", sorted(CASES))
def test_rule_fires_on_its_fixture(good_usd, tmp_path, name):
    rule = CASES[name][0]
    pkg = broken(good_usd, tmp_path, name)
    report = validate_paths([pkg])
    found = [f for f in report.findings if f.rule == rule]
    assert found, f"{rule} did not fire; findings: {[(f.rule, f.path, f.message) for f in report.findings]}"
    if rule == "file.unreadable":
        assert report.exit_code == 2
    elif found[0].severity == "error":
        assert report.exit_code == 1
    else:   # a warning alone does not fail the package
        assert report.exit_code == 0 and {f.severity for f in report.findings} == {"warning"}
    if name in EXPECTED_PATH:
        assert EXPECTED_PATH[name] in {f.path for f in found}, [f.path for f in found]


def test_corrupt_idat_needs_the_deep_check(good_usd, tmp_path):
    pkg = copy_package(good_usd, tmp_path / "case")
    flip_idat_byte(pkg)
    assert "tex.unreadable" not in rules_of(validate_paths([pkg]))   # header and IEND are intact
    deep = validate_paths([pkg], deep=True)
    assert "tex.unreadable" in rules_of(deep) and deep.exit_code == 1


def test_huge_arrays_are_refused(good_usd):
    report = validate_paths([good_usd], limits=Limits(max_points=100))
    assert "file.array-too-large" in rules_of(report)
    assert not {r for r in rules_of(report) if r.startswith("mesh.")}     # the refused mesh is not looked at


@pytest.mark.parametrize("name, content", [("truncated.usdc", None), ("hand.usda", b"hello, not USD\n"),
                                           ("hand.usdc", bytes(range(256)) * 4), ("empty.usdz", b"")])
def test_unreadable_files_exit_2(good_usd, tmp_path, name, content):
    path = tmp_path / name
    if content is None:
        path.write_bytes((good_usd / "payload.usdc").read_bytes()[:4000])
    else:
        path.write_bytes(content)
    report = validate_paths([path])
    assert report.exit_code == 2
    (f,) = report.findings
    assert f.rule == "file.unreadable" and "\n" not in f.message and f.message


def test_usdz_of_the_package_is_clean(good_usd, tmp_path):
    from darthand.export.usdz import export_usdz

    out = tmp_path / "right.usdz"
    export_usdz(good_usd, out, texture=OTHER_TEX, accessory=RING_ID)
    report = validate_paths([out])
    assert report.exit_code == 0, report.findings
    assert report.packages[0].format == "usdz"


def test_real_open_hand_packages_validate_clean(small_build):
    """The open hand as `make assets` builds it, small (tests/conftest.py: the model step, catalogue textures at
    64 px, a fitted ring, the CLI's USD and glTF writers): every package validates with no finding at all."""
    packages = [small_build / "usd" / "right", small_build / "glb" / "right.glb", small_build / "gltf" / "right.gltf"]
    report = validate_paths(packages)
    assert [p.format for p in report.packages] == ["usd", "glb", "gltf"]
    assert report.exit_code == 0 and not report.findings, report.findings[:10]


def test_ids_are_checked_against_a_built_catalogue_beside_the_package(good_usd, tmp_path):
    """In a build folder (build/usd/right next to build/textures/ and build/accessories/) the built catalogues
    decide, not the committed specs: ids the specs know but these catalogues lack are reported."""
    import json

    build = tmp_path / "build"
    pkg = copy_package(good_usd, build / "usd")
    (build / "textures").mkdir()
    (build / "textures" / "catalog.json").write_text(json.dumps({"entries": [{"id": DEFAULT_TEX}]}))
    (build / "accessories" / "right").mkdir(parents=True)
    (build / "accessories" / "right" / "catalog.json").write_text(json.dumps({"accessories": [{"id": RING_ID}]}))
    found = {(f.rule, f.path) for f in validate_paths([pkg]).findings}
    assert found == {("tex.unknown-id", f"/RightHand{{texture={OTHER_TEX}}}"),
                     ("acc.unknown-id", "/RightHand{accessory=glove_01_latex}")}
