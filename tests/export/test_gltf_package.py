"""The glTF package: Khronos validator verdicts, texture variants, images, accessories, catalogues and the command.

The validator must report 0 errors on every written file. If `node` is missing the validator tests skip with that
reason; if node is there but the npm package is not installed (`npm ci`), they fail.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

from export_catalogs import write_accessory_catalog, write_png, write_texture_catalog  # noqa: E402
from synthetic import tube_hand  # noqa: E402
from test_gltf_reference import (GltfFile, global_matrices, posed_mesh, sample_animation,  # noqa: E402
                                 skinned_positions, static_positions)

from darthand.errors import InputError  # noqa: E402
from darthand.export import commands_gltf  # noqa: E402
from darthand.accessories.loader import Accessory, load_accessory_catalog  # noqa: E402
from darthand.textures.loader import TextureSet, load_texture_catalog  # noqa: E402
from darthand.export.gltf_export import GltfOptions, export_gltf  # noqa: E402
from darthand.export.gltf_validator import ValidatorUnavailable, validate  # noqa: E402
from darthand.model.anatomy import sample_poses  # noqa: E402
from darthand.model.forward import forward, pose_feature  # noqa: E402
from darthand.model.layout import JOINT_NAMES  # noqa: E402
from darthand.model.npz_io import save_npz  # noqa: E402
from darthand.model.topology import vertex_normals  # noqa: E402
from darthand.model.wrist import add_wrist  # noqa: E402

COLORS = {"tan": (200, 150, 120), "brown": (120, 80, 50), "pale": (240, 210, 190)}


def validated(path):
    """The validator's report for `path`, asserting 0 errors (skip only when node itself is absent)."""
    if shutil.which("node") is None:
        pytest.skip("node is not installed on this machine: the Khronos glTF validator cannot run")
    report = validate(path)
    errors = report.issues("errors")
    assert report.errors == 0, f"{report.summary()}: {errors[:5]}"
    print(report.summary())   # warnings and infos are shown with -s / in the failure output
    return report


def read_png(data: bytes, tmp: Path):
    import OpenImageIO as oiio

    p = tmp / "read.png"
    p.write_bytes(data)
    buf = oiio.ImageBuf(str(p))
    return buf.spec().width, buf.spec().height, np.asarray(buf.get_pixels(oiio.UINT8))


@pytest.fixture(scope="module")
def model():
    return add_wrist(tube_hand(5))


@pytest.fixture()
def textures(tmp_path):
    sets = [TextureSet(name, write_png(tmp_path / "tex" / f"{name}.png", rgb)) for name, rgb in COLORS.items()]
    rough = write_png(tmp_path / "tex" / "tan_rough.png", (128, 128, 128))
    return [TextureSet(sets[0].id, sets[0].albedo, rough)] + sets[1:]


def gestures(model, n=2):
    return [f"pose{i}" for i in range(n)], sample_poses(model, n, np.random.default_rng(11), include_root=True)


def image_bytes(f: GltfFile, image_index: int) -> bytes:
    img = f.doc.images[image_index]
    if img.uri is not None:
        assert not Path(img.uri).is_absolute() and ".." not in Path(img.uri).parts
        return (f.path.parent / img.uri).read_bytes()
    view = f.doc.bufferViews[img.bufferView]
    return f.buffer(view.buffer)[view.byteOffset:view.byteOffset + view.byteLength]


def variant_base_color_files(f: GltfFile) -> dict[str, bytes]:
    """{variant name: bytes of the base colour image its material uses}, through KHR_materials_variants."""
    names = [v["name"] for v in f.doc.extensions["KHR_materials_variants"]["variants"]]
    prim = f.doc.meshes[0].primitives[0]
    out = {}
    for mapping in prim.extensions["KHR_materials_variants"]["mappings"]:
        mat = f.doc.materials[mapping["material"]]
        tex = f.doc.textures[mat.pbrMetallicRoughness.baseColorTexture.index]
        for v in mapping["variants"]:
            out[names[v]] = image_bytes(f, tex.source)
    return out


# ------------------------------------------------------------------------------------------------ validator


@pytest.mark.parametrize("influences", [4, 8, None])
def test_glb_validates_for_every_influence_count(model, tmp_path, influences):
    out = tmp_path / "hand.glb"
    export_gltf(model, out, options=GltfOptions(influences=influences), gestures=gestures(model))
    report = validated(out)
    assert report.info.get("animationCount") == 2
    assert report.info.get("hasMorphTargets") and report.info.get("hasSkins")


def test_validator_reports_a_broken_file(model, tmp_path):
    """The runner really reports errors (so '0 errors' above means something)."""
    if shutil.which("node") is None:
        pytest.skip("node is not installed on this machine: the Khronos glTF validator cannot run")
    out = tmp_path / "hand.gltf"
    export_gltf(model, out, gestures=([], np.zeros((0, 48))))
    doc = json.loads(out.read_text())
    doc["accessors"][0]["count"] += 1000          # reads past its bufferView
    attributes = doc["meshes"][0]["primitives"][0]["attributes"]
    attributes["WEIGHTS_0"] = attributes["NORMAL"]            # weights that are not weights
    out.write_text(json.dumps(doc))
    report = validate(out)
    codes = {m["code"] for m in report.issues("errors")}
    assert report.errors > 0 and "ACCESSOR_TOO_LONG" in codes, report.summary()
    # the command exits 1 on it and 0 on a good file
    good = tmp_path / "good.glb"
    export_gltf(model, good, gestures=([], np.zeros((0, 48))))
    assert commands_gltf.validate(argparse.Namespace(paths=[str(out)], json=False)) == 1
    assert commands_gltf.validate(argparse.Namespace(paths=[str(good)], json=False)) == 0


def test_missing_validator_package_is_an_error_naming_the_fix(tmp_path, monkeypatch):
    from darthand.export import gltf_validator

    if shutil.which("node") is None:
        pytest.skip("node is not installed on this machine")
    with pytest.raises(ValidatorUnavailable, match="npm ci"):
        gltf_validator.validator_package(tmp_path)
    monkeypatch.setattr(gltf_validator.shutil, "which", lambda name: None)
    with pytest.raises(ValidatorUnavailable, match="node is not installed"):
        gltf_validator.validator_package()


# ------------------------------------------------------------------------------------------------ textures


def test_glb_variants_map_each_variant_to_its_own_albedo(model, textures, tmp_path):
    out = tmp_path / "variants.glb"
    report = export_gltf(model, out, textures=textures, gestures=gestures(model))
    validated(out)
    f = GltfFile(out)
    assert "KHR_materials_variants" in f.doc.extensionsUsed
    files = variant_base_color_files(f)
    assert list(files) == [t.id for t in textures] == report.variants
    for t in textures:
        assert files[t.id] == t.albedo.read_bytes()
    # the default material is the first variant's, and roughness comes from the roughness map's G channel
    default = f.doc.materials[f.doc.meshes[0].primitives[0].material]
    assert image_bytes(f, f.doc.textures[default.pbrMetallicRoughness.baseColorTexture.index].source) == \
        textures[0].albedo.read_bytes()
    mr = default.pbrMetallicRoughness
    assert mr.metallicFactor == 0 and mr.metallicRoughnessTexture is not None


def test_gltf_package_references_images_relatively(model, textures, tmp_path):
    out = tmp_path / "pkg" / "right.gltf"
    result = export_gltf(model, out, textures=textures, gestures=gestures(model),
                         options=GltfOptions(influences=None))
    validated(out)       # reads the .bin and every image through their relative URIs
    f = GltfFile(out)
    assert f.doc.buffers[0].uri == "right.bin"
    assert all(img.uri and img.uri.startswith("textures/") for img in f.doc.images)
    files = variant_base_color_files(f)
    for t in textures:
        assert files[t.id] == t.albedo.read_bytes()
    assert all(Path(p).is_file() for p in result.files)
    # the geometry is the same as in a .glb of the same hand
    names, poses = gestures(model)
    ids = f.attr(f.doc.meshes[0].primitives[0], "_VERTEX_ID")[:, 0].astype(int)
    np.testing.assert_allclose(posed_mesh(f, "RightHand", names[1], 1.0), forward(model, poses[1]).vertices[0][ids],
                               atol=1e-5)


def test_texture_size_downsizes_embedded_images(model, textures, tmp_path):
    out = tmp_path / "small.glb"
    export_gltf(model, out, textures=textures[:1], options=GltfOptions(texture_size=8),
                gestures=([], np.zeros((0, 48))))
    validated(out)
    f = GltfFile(out)
    assert "KHR_materials_variants" not in (f.doc.extensionsUsed or [])   # one texture: no variants
    mat = f.doc.materials[f.doc.meshes[0].primitives[0].material]
    w, h, px = read_png(image_bytes(f, f.doc.textures[mat.pbrMetallicRoughness.baseColorTexture.index].source),
                        tmp_path)
    assert (w, h) == (8, 8)
    assert np.abs(px.reshape(-1, 3).astype(int) - COLORS["tan"]).max() <= 1   # a flat colour stays that colour


def test_textures_need_uvs_in_both_writers(textures, tmp_path):
    from darthand.export.usd_asset import export_usd

    bare = add_wrist(tube_hand(1, with_uvs=False))
    with pytest.raises(InputError, match="no UVs, so the skin textures cannot be mapped"):
        export_gltf(bare, tmp_path / "bare.glb", textures=textures, gestures=([], np.zeros((0, 48))))
    with pytest.raises(InputError, match="no UVs, so the skin textures cannot be mapped"):
        export_usd(bare, tmp_path / "bare", textures=textures, gestures=(["flat"], np.zeros((1, 48))))
    assert not list(tmp_path.glob("bare*"))


def test_untextured_export_has_a_plain_skin_material(model, tmp_path):
    out = tmp_path / "plain.glb"
    export_gltf(model, out, gestures=([], np.zeros((0, 48))))
    validated(out)
    f = GltfFile(out)
    mat = f.doc.materials[f.doc.meshes[0].primitives[0].material].pbrMetallicRoughness
    assert mat.baseColorTexture is None and mat.metallicFactor == 0 and not f.doc.images


# ------------------------------------------------------------------------------------------------ accessories


def ring_on(model, joint: int, radius=0.035, n=24):
    """A closed square-section ring around the bone from `joint` to its child, in the rest frame."""
    J = np.asarray(model.J_regressor @ model.v_template)
    centre = J[joint] + 0.4 * (J[joint + 1] - J[joint])
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    rings = []
    for dx, r in [(-0.003, radius), (0.003, radius), (0.003, radius + 0.002), (-0.003, radius + 0.002)]:
        rings.append(np.stack([np.full(n, dx), r * np.cos(a), r * np.sin(a)], 1))
    verts = centre + np.concatenate(rings)
    faces = []
    for s in range(4):
        for k in range(n):
            p, q = s * n + k, s * n + (k + 1) % n
            p2, q2 = ((s + 1) % 4) * n + k, ((s + 1) % 4) * n + (k + 1) % n
            faces += [(p, q, p2), (q, q2, p2)]
    uvs = np.stack([a / (2 * np.pi), np.zeros(n)], 1).repeat(4, 0)[:4 * n]
    return Accessory(id="ring", vertices=verts, faces=np.array(faces), uvs=uvs,
                     faces_uv=np.array(faces), parent_joint=joint,
                     material={"base_color": (0.9, 0.7, 0.2, 1.0), "metallic": 1.0, "roughness": 0.3})


def glove_of(model, thickness=0.002):
    """A glove: the hand surface pushed out along its normals, skinned and corrected like the hand."""
    verts = model.v_template + thickness * vertex_normals(model.v_template, model.faces)
    return Accessory(id="glove", vertices=verts, faces=model.faces, uvs=model.uvs, faces_uv=model.faces_uv,
                     weights=model.weights, posedirs=model.posedirs, material={"base_color": (0.1, 0.1, 0.1, 1)})


@pytest.mark.parametrize("correctives", ["full", "pca:16", "pose-pca:16"])
def test_rigid_accessory_follows_its_joint_and_glove_follows_the_skin(model, tmp_path, correctives):
    ring, glove = ring_on(model, 4), glove_of(model)
    names, poses = gestures(model)
    out = tmp_path / "acc.glb"
    result = export_gltf(model, out, accessories=[ring, glove], gestures=(names, poses),
                         options=GltfOptions(influences=None, correctives=correctives))
    validated(out)
    assert result.accessories == ["ring", "glove"]
    f = GltfFile(out)
    ring_node = f.node_index("Right_ring")
    assert ring_node in f.doc.nodes[f.node_index(JOINT_NAMES[4])].children
    posed = forward(model, poses)
    feature = pose_feature(posed.rotations)
    for i, name in enumerate(names):
        trs, weights = sample_animation(f, name, 1.0)
        g = global_matrices(f, trs)
        # rigid: G_4 [v, 1]; the file stores its vertices in the joint's frame, in its own vertex order
        G = posed.transforms[i, 4]
        truth = ring.vertices @ G[:3, :3].T + G[:3, 3]
        got = static_positions(f, ring_node, g)
        d = np.linalg.norm(got[:, None] - truth[None], axis=2).min(1)
        assert d.max() <= 1e-5 and len(got) >= len(truth)
        # glove: LBS of its own vertices with its weights and its correctives
        if correctives == "full":
            node = f.node_index("Right_glove")
            v = glove.vertices + np.einsum("vck,k->vc", glove.posedirs, feature[i])
            T = np.einsum("vj,jab->vab", glove.weights, posed.transforms[i])
            truth = np.einsum("vab,vb->va", T[:, :3, :3], v) + T[:, :3, 3]
            got = skinned_positions(f, node, g, weights.get(node))
            d = np.linalg.norm(got[:, None] - truth[None], axis=2).min(1)
            assert d.max() <= 1e-5


def test_accessory_catalog_round_trip(model, tmp_path):
    """The accessories stage's catalogue layout (schemas/accessory_catalog.schema.json): a ring and a glove."""
    ring = dataclasses.replace(ring_on(model, 10), id="ring_a", kind="ring",
                               base_color_png=write_png(tmp_path / "src" / "ring_bc.png", (220, 180, 60)),
                               metallic_roughness_png=write_png(tmp_path / "src" / "ring_mr.png", (0, 60, 255)),
                               material={"base_color": [0.8, 0.6, 0.2], "metallic": 1.0, "roughness": 0.2})
    glove = dataclasses.replace(glove_of(model), id="glove_a", kind="glove")
    catalog = write_accessory_catalog(tmp_path / "acc", [ring, glove])
    ring_a, glove_a = load_accessory_catalog(catalog)
    assert ring_a.parent_joint == 10 and not ring_a.skinned and ring_a.base_color_png.is_file()
    assert glove_a.skinned and glove_a.posedirs.shape == (model.num_vertices, 3, 135)
    np.testing.assert_array_equal(ring_a.faces, ring.faces)
    # the catalogue format always has textures; an accessory given in code may have none
    plain = dataclasses.replace(glove_a, id="glove_b", base_color_png=None, metallic_roughness_png=None,
                                material={"base_color": [0.1, 0.1, 0.1], "metallic": 0.0, "roughness": 0.8})
    out = tmp_path / "acc.glb"
    export_gltf(model, out, accessories=[ring_a, plain], gestures=gestures(model))
    validated(out)
    f = GltfFile(out)
    by_name = {m.name: m.pbrMetallicRoughness for m in f.doc.materials}
    # textured channels carry factor 1 (glTF multiplies), untextured ones the material's values
    ring, glove = by_name["Right_ring_a_material"], by_name["Right_glove_b_material"]
    assert ring.baseColorFactor == [1, 1, 1, 1] and ring.metallicFactor == 1
    assert glove.baseColorFactor == [0.1, 0.1, 0.1, 1] and glove.roughnessFactor == 0.8
    with pytest.raises(InputError, match="nope"):
        load_accessory_catalog(catalog, ["nope"])
    doc = json.loads(catalog.read_text())
    doc["accessories"][0]["parent_joint"] = "elbow"
    (tmp_path / "acc" / "bad.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match="elbow"):
        load_accessory_catalog(tmp_path / "acc" / "bad.json")


def test_bad_accessory_is_rejected_by_name(model, tmp_path):
    ring = ring_on(model, 4)
    bad = Accessory(id="bad", vertices=ring.vertices, faces=ring.faces, parent_joint=None)
    with pytest.raises(InputError, match="'bad'.*exactly one"):
        export_gltf(model, tmp_path / "x.glb", accessories=[bad], gestures=([], np.zeros((0, 48))))


# ------------------------------------------------------------------------------------------------ catalogues, CLI


def catalog_of(textures, folder: Path) -> Path:
    """A textures-stage catalogue of the fixture's albedos, with the stage's ids (`light_<name>_00`)."""
    return write_texture_catalog(folder, [(f"light_{t.id}_00", t.albedo, None) for t in textures])


def test_texture_catalog(tmp_path, textures):
    catalog = catalog_of(textures, tmp_path / "catalog")
    sets = load_texture_catalog(catalog)
    assert [s.id for s in sets] == [f"light_{name}_00" for name in COLORS]
    assert sets[1].albedo.read_bytes() == textures[1].albedo.read_bytes()
    doc = json.loads(catalog.read_text())
    del doc["entries"][0]["files"]["albedo"]
    (tmp_path / "bad.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match="entries.0.*albedo"):
        load_texture_catalog(tmp_path / "bad.json")
    with pytest.raises(InputError, match="no such texture catalogue"):
        load_texture_catalog(tmp_path / "missing.json")


def gltf_args(**options) -> argparse.Namespace:
    """What cli.py parses for `darthand export gltf MODEL --out OUT`: its defaults, updated with `options` (which
    must give model and out)."""
    return argparse.Namespace(**{"textures": None, "texture": None,
                                 "all_textures": False, "texture_size": None, "accessories": None, "accessory": None,
                                 "influences": "4", "correctives": "full", "validate": False,
                                 **options})


def test_command_writes_and_validates(model, textures, tmp_path, capsys):
    if shutil.which("node") is None:
        pytest.skip("node is not installed on this machine: the Khronos glTF validator cannot run")
    save_npz(model, tmp_path / "right.npz")
    catalog = catalog_of(textures, tmp_path / "catalog")
    out = tmp_path / "out" / "right.gltf"
    code = commands_gltf.gltf(gltf_args(model=str(tmp_path / "right.npz"), out=str(out), textures=str(catalog),
                                        all_textures=True, correctives="pca:8", influences="8", validate=True))
    printed = capsys.readouterr().out
    assert code == 0 and "0 errors" in printed
    assert "8 influences" in printed and "16 morph targets (pca:8) + 8 shape dials" in printed
    assert "3 textures" in printed
    doc = json.loads(out.read_text())
    assert len(doc["extensions"]["KHR_materials_variants"]["variants"]) == 3
    # correctives (16) then the shape dials (2 per shape direction of the model)
    assert all(len(p["targets"]) == 16 + 2 * model.num_betas for m in doc["meshes"] for p in m["primitives"]
               if "targets" in p)
    assert (out.parent / "right.bin").is_file() and len(list((out.parent / "textures").glob("*.png"))) == 3


@pytest.mark.parametrize("options, message", [
    ({"correctives": "pca:0"}, "correctives"),
    ({"texture": ["tan"]}, "need --textures"),
    ({"out": "x.obj"}, ".glb or .gltf"),
])
def test_command_rejects_bad_arguments(model, tmp_path, options, message):
    save_npz(model, tmp_path / "m.npz")
    with pytest.raises(InputError, match=message):
        commands_gltf.gltf(gltf_args(**{"model": str(tmp_path / "m.npz"), "out": str(tmp_path / "a.glb"), **options}))


def test_sparse_morph_targets_validate(model, tmp_path):
    posedirs = model.posedirs * (np.random.default_rng(0).random((model.num_vertices, 1, 135)) < 0.2)
    posedirs[:, :, 0] = 0.0
    out = tmp_path / "sparse.glb"
    export_gltf(model.replace(posedirs=posedirs), out, gestures=gestures(model))
    validated(out)
