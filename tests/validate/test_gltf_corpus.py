"""glTF: the good .glb and .gltf packages are clean, and every rule fires on its broken copy.

The Khronos glTF-Validator runs inside `validate_paths` when node and `npm ci`'s gltf-validator are installed; the
tests of darthand's own rules do not depend on it (without it the package gets one info finding saying so)."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from package_parts import RING_ID, TEXTURE_IDS, write_png
from corpus import accessor, copy_package, edit_glb, edit_gltf, hand_attr, reparent, ring_node

from darthand.validate.run import validate_paths

ACCEPTED_INFOS = {"gltf.UNUSED_OBJECT", "gltf.validator-unavailable"}   # the glove has UVs but no texture


def khronos_available() -> bool:
    root = Path(__file__).resolve().parents[2]
    return shutil.which("node") is not None and (root / "node_modules" / "gltf-validator" / "package.json").is_file()


def patch(attr: str, fn):
    """fn(array view) on one of the hand's accessors."""
    return lambda doc, blob: fn(accessor(doc, blob, hand_attr(doc, attr)))


def set_item(index, value):
    def fn(a):
        a[index] = value
    return fn


def degenerate(a):
    a[1, 0] = a[0, 0]


def flip(a):
    f = a.reshape(-1, 3)
    f[20, [1, 2]] = f[20, [2, 1]]


def duplicate(a):
    f = a.reshape(-1, 3)
    f[30] = f[31]


def scale_weights(a):
    a[0] *= 0.9


def negative(a):
    a[0, 3] = a[0, 3] - 0.05
    a[0, 0] = a[0, 0] + 0.05


def scale_ibm(doc, blob):
    ibm = accessor(doc, blob, doc["skins"][0]["inverseBindMatrices"]).reshape(-1, 4, 4)   # column-major
    ibm[5, :3, :3] *= 1.1                                                                   # not rigid


def node_edit(fn):
    return lambda doc, blob: fn(doc["nodes"])


def nan_target(doc, blob):
    sparse = doc["accessors"][doc["meshes"][0]["primitives"][0]["targets"][0]["POSITION"]]["sparse"]
    view = doc["bufferViews"][sparse["values"]["bufferView"]]
    np.frombuffer(memoryview(blob)[view.get("byteOffset", 0):view.get("byteOffset", 0) + 12], np.float32)[0] = np.nan


def rename_target(doc, blob):
    doc["meshes"][0]["extras"]["targetNames"][3] = "not_a_corrective"


def ring_to_root(doc, blob):
    reparent(doc, ring_node(doc), None)


def middle_under_index(doc, blob):
    reparent(doc, 4, 1)


def float_ring(doc, blob):
    node = doc["nodes"][ring_node(doc)]
    node["translation"] = list(np.add(node.get("translation", [0, 0, 0]), [0.0, 0.11, 0.0]))


def more_positions(doc, blob):
    doc["accessors"][hand_attr(doc, "POSITION")]["count"] += 1000


def huge_positions(doc, blob):
    doc["accessors"][hand_attr(doc, "POSITION")]["count"] = 2 ** 31


GLB_CASES = {
    "nan-point": ("mesh.nonfinite-point", patch("POSITION", set_item((3, 0), np.nan))),
    "degenerate-face": ("mesh.degenerate-face", patch("indices", degenerate)),
    "flipped-face": ("mesh.winding", patch("indices", flip)),
    "duplicate-face": ("mesh.duplicate-face", patch("indices", duplicate)),
    "face-index": ("mesh.face-index", patch("indices", set_item(0, 60000))),
    "uv-outside": ("mesh.uv-range", patch("TEXCOORD_0", set_item(0, (1.5, 0.5)))),
    "weights-sum": ("rig.weights-sum", patch("WEIGHTS_0", scale_weights)),
    "weights-negative": ("rig.weights-negative", patch("WEIGHTS_0", negative)),
    "weights-nan": ("rig.weights-nonfinite", patch("WEIGHTS_0", set_item((0, 0), np.nan))),
    "joint-index": ("rig.joint-index", patch("JOINTS_0", set_item((0, 0), 20))),
    "scaled-bind": ("rig.bind-transform", scale_ibm),
    "scaled-rest": ("rig.rest-transform", node_edit(lambda nodes: nodes[6].update(scale=[1.1, 1.1, 1.1]))),
    "bind-rest": ("rig.bind-rest-mismatch", node_edit(lambda nodes: nodes[7].update(
        translation=list(np.add(nodes[7]["translation"], [0.01, 0.0, 0.0]))))),
    "hierarchy": ("rig.hierarchy", middle_under_index),
    "joint-names": ("rig.joint-names", node_edit(lambda nodes: nodes[1].update(name="root"))),    # node 0: the hand
    "corrective-missing": ("rig.correctives-missing", rename_target),
    "blendshape-nan": ("rig.blendshape-nonfinite", nan_target),
    "ring-unbound": ("acc.binding", ring_to_root),
    "ring-floating": ("acc.distance", float_ring),
    "accessory-id": ("acc.unknown-id", node_edit(lambda nodes: nodes[17].update(
        extras={"darthand": {"accessory": "mystery_ring"}}))),
    "texture-id": ("tex.unknown-id", lambda doc, blob: doc["extensions"]["KHR_materials_variants"]["variants"][1]
                   .update(name="my_own_skin")),
    "accessor-overrun": ("file.malformed", more_positions),
    "huge-accessor": ("file.array-too-large", huge_positions),
}


def gltf_texture(name: str) -> str:
    return f"textures/{TEXTURE_IDS[0]}_{name}.png"


def image_uri(uri: str):
    def fn(doc, blob):
        doc["images"][0]["uri"] = uri
    return fn


def symlink_outside(gltf: Path):
    target = gltf.parent / gltf_texture("albedo")
    target.unlink()
    os.symlink(write_png(gltf.parent.parent / "outside.png", 32, 32, 9), target)


def escaping(gltf: Path):
    write_png(gltf.parent.parent / "outside.png", 32, 32, 9)
    edit_gltf(gltf, image_uri("../outside.png"))


def buffer_outside(gltf: Path):
    shutil.copy(gltf.parent / "right.bin", gltf.parent.parent / "right.bin")
    doc = json.loads(gltf.read_text())
    doc["buffers"][0]["uri"] = "../right.bin"
    gltf.write_text(json.dumps(doc))


GLTF_CASES = {
    "texture-missing": ("tex.missing", lambda g: (g.parent / gltf_texture("albedo")).unlink()),
    "texture-absolute": ("tex.absolute-path", lambda g: edit_gltf(g, image_uri(str(g.parent / gltf_texture(
        "albedo"))))),
    "texture-escapes": ("tex.path-escapes", escaping),
    "texture-symlink": ("tex.symlink-outside", symlink_outside),
    "texture-npot": ("tex.not-power-of-two", lambda g: write_png(g.parent / gltf_texture("roughness"), 48, 32, 5)),
    "png-truncated": ("tex.unreadable", lambda g: (g.parent / gltf_texture("albedo")).write_bytes(
        (g.parent / gltf_texture("albedo")).read_bytes()[:200])),
    "buffer-outside": ("gltf.buffer-path", buffer_outside),
    "uv-outside": ("mesh.uv-range", lambda g: edit_gltf(g, patch("TEXCOORD_0", set_item(0, (-0.5, 0.5))))),
}

EXPECTED_PATH = {
    "nan-point": "/meshes/0/primitives/0",
    "scaled-bind": "/skins/0",
    "ring-floating": "/meshes/1/primitives/0",
    "texture-missing": "/images/0",
}


def rules_of(report) -> set[str]:
    return {f.rule for f in report.findings}


def check_fires(report, rule: str, name: str):
    found = [f for f in report.findings if f.rule == rule]
    assert found, f"{rule} did not fire; findings: {[(f.rule, f.path, f.message) for f in report.findings]}"
    if found[0].severity == "error":
        assert report.exit_code == 1
    if name in EXPECTED_PATH:
        assert EXPECTED_PATH[name] in {f.path for f in found}, [f.path for f in found]


@pytest.mark.parametrize("good", ["good_glb", "good_gltf"])
def test_good_packages_are_clean(good, request):
    report = validate_paths([request.getfixturevalue(good)])
    assert report.exit_code == 0, report.findings
    assert {f.rule for f in report.findings} <= ACCEPTED_INFOS
    assert {f.severity for f in report.findings} <= {"info"}


@pytest.mark.parametrize("name", sorted(GLB_CASES))
def test_rule_fires_on_its_glb_fixture(good_glb, tmp_path, name):
    rule, fn = GLB_CASES[name]
    path = copy_package(good_glb, tmp_path / "case")
    edit_glb(path, fn)
    check_fires(validate_paths([path]), rule, name)


@pytest.mark.parametrize("name", sorted(GLTF_CASES))
def test_rule_fires_on_its_gltf_fixture(good_gltf, tmp_path, name):
    rule, fn = GLTF_CASES[name]
    path = copy_package(good_gltf, tmp_path / "case")
    fn(path)
    check_fires(validate_paths([path]), rule, name)


def test_khronos_validator_findings_pass_through(good_glb, tmp_path):
    if not khronos_available():
        pytest.skip("node or node_modules/gltf-validator is missing (npm ci): the Khronos validator cannot run")
    path = copy_package(good_glb, tmp_path / "case")
    edit_glb(path, GLB_CASES["weights-sum"][1])
    report = validate_paths([path])
    assert "gltf.ACCESSOR_WEIGHTS_NON_NORMALIZED" in rules_of(report)
    assert "rig.weights-sum" in rules_of(report)


@pytest.mark.parametrize("name, content", [
    ("truncated.glb", None), ("garbage.glb", b"not a binary glTF at all" * 10), ("broken.gltf", b'{"asset": '),
    ("other.gltf", b'{"hello": "world"}'), ("text.gltf", "a hand".encode())])
def test_unreadable_files_exit_2(good_glb, tmp_path, name, content):
    path = tmp_path / name
    path.write_bytes(good_glb.read_bytes()[:5000] if content is None else content)
    report = validate_paths([path])
    assert report.exit_code == 2
    (f,) = report.findings
    assert f.rule == "file.unreadable" and f.message and "\n" not in f.message


def test_rigid_accessory_is_measured_in_the_hand_frame(good_glb):
    """The ring is stored relative to its joint; read back into the hand frame it sits on the finger."""
    from darthand.validate.gltf_reader import read_gltf

    pkg, _ = read_gltf(good_glb)
    (ring,) = [m for m in pkg.accessories if m.accessory_id == RING_ID]
    assert ring.rigid_joint == 5
    radius = np.linalg.norm(ring.points[:, 1:], axis=1)       # the tube's axis is X
    assert 0.0295 < radius.min() and radius.max() < 0.032
